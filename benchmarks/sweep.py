"""The robustness sweep of docs/DECISIONS.md: does a change of solver settings still verify
every problem?

Solves each problem with two option sets A and B (JSON, e.g. ``--a '{}' --b
'{"sigma_rule": "siconos"}'``) of one method (``--method``, default ``auto``) at ``--tol`` and
judges each answer by rfverify's one criterion (:func:`rfverify.model.measures.measures`, recomputed
in longdouble from the returned (v, u, r)), never by the solver's status.  Prints one line per
problem and the counts verified, iterations and seconds of A and B.  Not a test: a sweep for
deciding defaults.  It counts verified answers only: forward accuracy at the same criterion
(which the tests of the FE sticking block and of ``certify`` watch) is not in it.

The problem set (77 problems, rebuilt deterministically and cached under ``--cache``): the
bundled problems, ``tests/data`` (hard instances, scene samples, the elastic block), the example
report's scenes, every rigid scene family at seeds 11 and 7 (sizes 80 and 40), two ElasticBlock
problems, Lattices of 176/274/474 contacts, random problems of 100/400/900 contacts, the lifted
local problems with a singular Delassus operator (60/100/160 contacts, seeds 0-2) and
SpheresPile, Chute and PrimitiveSoup at their published sizes.  ``--files`` adds your own;
``--quick`` keeps only the committed files (and ``--files``).

    python benchmarks/sweep.py --b '{"sigma_rule": "siconos"}'
    python benchmarks/sweep.py --a '{"longdouble_below": null}' --tol 1e-8
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import rfverify
from rfverify.model.measures import measures

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)
from bench_digits import scene_file  # noqa: E402  (the same cached scene files)


def committed_files():
    """The problems in the repository: bundled, tests/data, the example report's scenes."""
    data = ROOT / "rfverify" / "data"
    for f in sorted(data.glob("*.hdf5")) + sorted(data.glob("*.dat")):
        yield f"bundled/{f.name}", f
    for f in sorted((ROOT / "tests" / "data").rglob("*.hdf5")):
        yield f"tests/{f.relative_to(ROOT / 'tests' / 'data')}", f
    for f in sorted((ROOT / "reports" / "example" / "problems").rglob("*.hdf5")):
        yield f"example/{f.name}", f


def generated_problems(cache: Path):
    """Fresh problems the defaults were not tuned on (cached after the first run)."""
    from rfverify.scenes.random_problems import random_local_problem, random_problem
    from rfverify.scenes import SCENES, generate, save_collection

    def cached(tag, make):
        folder = cache / tag
        files = sorted(folder.glob("*.hdf5")) if folder.is_dir() else []
        if not files:
            folder.mkdir(parents=True, exist_ok=True)
            save_collection(make(), folder)
            files = sorted(folder.glob("*.hdf5"))
        return files

    for seed, size in ((11, 80), (7, 40)):
        for scene in SCENES:
            for f in cached(f"{scene}-{size}-seed{seed}", lambda: generate(scene, count=1, seed=seed, size=size)):
                yield f"{scene} seed {seed}", rfverify.load(f)
    for size, seed in ((4, 1), (8, 2)):
        for f in cached(f"ElasticBlock-{size}-seed{seed}",
                        lambda: generate("ElasticBlock", count=1, seed=seed, size=size)):
            yield f"ElasticBlock seed {seed}", rfverify.load(f)
    for size in (40, 60, 100):
        for f in cached(f"Lattice-{size}-seed0", lambda: generate("Lattice", count=1, seed=0, size=size)):
            yield f"Lattice {size}", rfverify.load(f)
    for n_bodies, n_contacts in ((60, 100), (250, 400), (500, 900)):
        yield f"random {n_contacts}", random_problem(n_bodies, n_contacts, seed=21)
    for n in (60, 100, 160):
        for seed in range(3):
            yield f"local dense {n} seed {seed}", random_local_problem(n, seed=seed)
    for scene in ("SpheresPile", "Chute", "PrimitiveSoup"):
        yield f"{scene} published", rfverify.load(scene_file(cache, scene, None, 1, 0))


def problem_set(args):
    for label, f in committed_files():
        yield label, rfverify.load(f)
    for f in args.files:
        yield Path(f).name, rfverify.load(f)
    if not args.quick:
        yield from generated_problems(Path(args.cache))


@recorded("sweep")
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--a", default="{}", help="options of run A (JSON)")
    ap.add_argument("--b", default="{}", help="options of run B (JSON)")
    ap.add_argument("--method", default="auto")
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--files", nargs="*", default=[])
    ap.add_argument("--quick", action="store_true", help="only the problems committed to the repository")
    ap.add_argument("--cache", default=str(Path(tempfile.gettempdir()) / "rfverify-bench-digits"))
    args = ap.parse_args(argv)
    runs = [json.loads(args.a), json.loads(args.b)]
    totals = [{"verified": 0, "iterations": 0, "seconds": 0.0, "lost": []} for _ in runs]
    count = 0
    for label, problem in problem_set(args):
        count += 1
        line = f"{label[:44]:<44} {problem.n_contacts:>5}"
        for options, tot in zip(runs, totals):
            t0 = time.perf_counter()
            res = rfverify.solve(problem, method=args.method, tol=args.tol, **options)
            seconds = time.perf_counter() - t0
            crit = measures(problem, res.v, res.u, res.r, "longdouble").max
            good = bool(crit <= args.tol)
            tot["verified"] += good
            tot["iterations"] += res.nit
            tot["seconds"] += seconds
            if not good:
                tot["lost"].append(label)
            line += f" | {str(res.status)[:13]:<13} {crit:8.1e} {res.nit:3d} {seconds:6.2f}"
        print(line, flush=True)
    print(f"\n{count} problems, {args.method} at tol {args.tol:g}")
    for name, options, tot in zip("AB", runs, totals):
        print(f"{name} {json.dumps(options)}: {tot['verified']}/{count} verified, {tot['iterations']} iterations, "
              f"{tot['seconds']:.1f} s" + (f"; not verified: {', '.join(tot['lost'])}" if tot["lost"] else ""))


if __name__ == "__main__":
    main()
