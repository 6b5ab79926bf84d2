"""Cost and outcome of the proven k-digit path (``solve --digits``) at FCLIB sizes.

For each problem: the double solve alone (timed separately), then the whole k-digit path
(double solve, double-double phase, the multiple-precision tail where double-double stalled,
proof), the solution and certificate written to an FCLIB file, and the certificate rechecked
from that file alone in exact arithmetic (as ``rfverify certify PROBLEM --solution FILE``
does).  Prints one row per problem:

    contacts, dofs, double s, extended s (double-double), mp s (multiple-precision tail, "–"
    when it did not run), proof s, total s, total/double, recheck s (recheck/total), proven
    digits of v / u / Hr / r (r: "–" where not unique)

Not a test: timings on a shared 2-core machine are noisy; compare ratios from one run.

    python benchmarks/bench_digits.py                       # the issue's problem set (generated once into --cache)
    python benchmarks/bench_digits.py --files A.hdf5 B.hdf5 # your own files
    python benchmarks/bench_digits.py --quick               # small problems only
    python benchmarks/bench_digits.py --family Chute:16:2   # every problem of one generated family
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import rfverify
from rfverify.io import save
from rfverify.io.certificate import read_point, write_certificate
from rfverify.model.problem import StoredSolution
from rfverify.scenes.random_problems import random_local_problem

sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)

# (label, scene, size, count, which problem of the trace): published-size scenes as the issue lists them
SCENES = [
    ("SpheresPile", "SpheresPile", None, 1, 0),
    ("Chute", "Chute", 700, 1, 0),
    ("PrimitiveSoup", "PrimitiveSoup", None, 1, 0),
    ("Lattice (hyperstatic)", "Lattice", 100, 1, 0),
    ("MassRatio 1e6", "MassRatio", None, 1, 0),
]


FAMILIES = [("Chute", 16, 1)]
"""(scene, count, seed): whole generated families, every problem a row (issue 45: a quarter of
the generated Chutes carry a self-stress, which the family shows end to end)."""

SCENE_CACHE = Path(tempfile.gettempdir()) / "rfverify-bench-digits"
"""Where generated scene problems are kept between runs (this script, bench_clarabel.py and
peers/siconos/compare.py share the folder)."""


def problem_parser(doc: str) -> argparse.ArgumentParser:
    """The parser of a script on the cached scenes, described by the first paragraph of ``doc``,
    with the options every such script takes: ``--files`` (your own problem files, run instead
    of the default set) and ``--cache`` (the folder of the generated scenes)."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--files", nargs="*", default=[], help="problem files to run instead of the default set")
    ap.add_argument("--cache", default=str(SCENE_CACHE), help=f"folder of the generated scenes (default {SCENE_CACHE})")
    return ap


def comparison_parser(doc: str, *, tol: float, methods: str) -> argparse.ArgumentParser:
    """:func:`problem_parser` plus the options of a timed comparison of methods: ``--tol``
    (each method's stopping tolerance), ``--repeat`` (alternating timed solves, median kept)
    and ``--methods`` (comma-separated ``rfverify.solve`` methods, or a peer's name)."""
    ap = problem_parser(doc)
    ap.add_argument("--tol", type=float, default=tol, help=f"stopping tolerance of every method (default {tol:g})")
    ap.add_argument("--repeat", type=int, default=3, help="timed solves per method, alternating; the median is kept (default 3)")
    ap.add_argument("--methods", default=methods, help=f"comma-separated methods (default {methods})")
    return ap


def scene_file(cache: Path, scene: str, size, count: int, index: int) -> Path:
    from rfverify.scenes import generate, save_collection

    tag = f"{scene}-{size or 'default'}-{count}"
    folder = cache / tag
    files = sorted(folder.glob("*.hdf5")) if folder.is_dir() else []
    if not files:
        folder.mkdir(parents=True, exist_ok=True)
        kwargs = {} if size is None else {"size": size}
        problems = generate(scene, count=count, seed=0, **kwargs)
        save_collection(problems, folder)
        files = sorted(folder.glob("*.hdf5"))
    return files[min(index, len(files) - 1)]


def family_files(cache: Path, scene: str, count: int, seed: int) -> list[Path]:
    """Every problem of ``rfverify generate SCENE --count COUNT --seed SEED``, generated once."""
    from rfverify.scenes import generate, save_collection

    folder = cache / f"{scene}-family-{count}-seed{seed}"
    files = sorted(folder.glob("*.hdf5")) if folder.is_dir() else []
    if len(files) < count:
        folder.mkdir(parents=True, exist_ok=True)
        save_collection(generate(scene, count=count, seed=seed), folder)
        files = sorted(folder.glob("*.hdf5"))
    return sorted(files, key=lambda f: rfverify.load(f).n_contacts)


def parse_family(text: str) -> tuple[str, int, int]:
    """``SCENE:COUNT:SEED`` (the --family option)."""
    try:
        scene, count, seed = text.split(":")
        return scene, int(count), int(seed)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not SCENE:COUNT:SEED, e.g. Chute:16:1") from None


def user_files(paths):
    """(label, Problem) for each file named on the command line."""
    for f in paths:
        yield Path(f).stem, rfverify.load(f)


def problem_set(args):
    if args.files:
        yield from user_files(args.files)
        return
    from rfverify.scenes.random_problems import random_problem

    cache = Path(args.cache)
    if args.quick:
        yield "bundled:chute", rfverify.load("bundled:chute")
        yield "random 200", random_problem(100, 200, seed=1)
        yield "local dense 60", random_local_problem(60)
        return
    if not args.family:
        for label, scene, size, count, index in SCENES:
            yield label, rfverify.load(scene_file(cache, scene, size, count, index))
        yield "random 2269", random_problem(1100, 2269, seed=1)
        yield "local dense W", random_local_problem(260)
    for scene, count, seed in (args.family or FAMILIES):
        for k, f in enumerate(family_files(cache, scene, count, seed)):
            yield f"{scene} {k + 1}/{count} s{seed}", rfverify.load(f)


def run_one(label, problem, digits: int, workdir: Path):
    t0 = time.perf_counter()
    double = rfverify.solve(problem, tol=1e-10)
    t_double = time.perf_counter() - t0
    t1 = time.perf_counter()
    out = rfverify.solve_to_digits(problem, digits=digits)
    t_path = time.perf_counter() - t1
    path = workdir / f"{abs(hash(label))}.h5"
    save(problem.with_solution(StoredSolution(v=out.v, u=out.u, r=out.r)), path,
         extra=lambda fh: write_certificate(fh, out.certificate, problem))
    t2 = time.perf_counter()
    stored = rfverify.load(path).solution
    recheck = rfverify.certify(problem, stored, digits=digits, point=read_point(path))
    t_recheck = time.perf_counter() - t2
    q = out.certificate.quantities

    def dig(name):
        x = q.get(name)
        if x is None or x.mode == "information":
            return "–"
        if x.mode == "absolute":
            return f"0±{x.abs_bound:.0e}"
        return "–" if x.digits is None else f"{x.digits:.1f}"

    t = out.timings
    return {"label": label, "n": problem.n_contacts, "m": problem.n_dofs, "double": t_double,
            "extended": t["setup"] + t["extended"], "wide": t["wide"] if out.wide is not None else None,
            "proof": t["proof"], "total": t_path,
            "ratio": t_path / t_double, "recheck": t_recheck, "recheck_frac": t_recheck / t_path,
            "certified": out.success, "recheck_certified": recheck.certified,
            "digits": "/".join(dig(k) for k in ("v", "u", "Hr", "r")), "double_status": str(double.status),
            "ext_iters": out.extended.nit, "wide_iters": None if out.wide is None else out.wide.nit,
            "verdict": out.certificate.verdict}


@recorded("bench_digits")
def main(argv=None):
    ap = problem_parser(__doc__)
    ap.add_argument("--digits", type=int, default=10, help="digits to prove (default 10)")
    ap.add_argument("--quick", action="store_true", help="the small problems only")
    ap.add_argument("--family", action="append", type=parse_family, metavar="SCENE:COUNT:SEED",
                    help="only every problem of a generated family (repeatable); by default the set above "
                         f"and then {', '.join(f'{a}:{b}:{c}' for a, b, c in FAMILIES)}")
    args = ap.parse_args(argv)
    rows = []
    head = (f"{'problem':<22} {'n':>5} {'m':>5} {'double':>7} {'ext':>7} {'mp':>6} {'proof':>6} {'total':>7} "
            f"{'×dbl':>6} {'recheck':>7} {'rc/tot':>6} {'proven':>5}  digits v/u/Hr/r")
    print(head)
    print("-" * len(head))
    with tempfile.TemporaryDirectory() as tmp:
        for label, problem in problem_set(args):
            r = run_one(label, problem, args.digits, Path(tmp))
            rows.append(r)
            mp = "–" if r["wide"] is None else f"{r['wide']:.2f}"
            print(f"{r['label']:<22} {r['n']:>5} {r['m']:>5} {r['double']:>7.2f} {r['extended']:>7.2f} {mp:>6} "
                  f"{r['proof']:>6.2f} {r['total']:>7.2f} {r['ratio']:>6.1f} {r['recheck']:>7.2f} "
                  f"{r['recheck_frac']:>6.1%} {'yes' if r['certified'] and r['recheck_certified'] else 'NO':>5}  "
                  f"{r['digits']}", flush=True)
            if not r["certified"]:
                print(f"    {r['verdict']}", flush=True)
    big = [r for r in rows if r["n"] >= 500]
    if big:
        print(f"\n≥ 500 contacts: median total/double = {np.median([r['ratio'] for r in big]):.1f}×, "
              f"max recheck/total = {max(r['recheck_frac'] for r in big):.1%}")
    return 0 if all(r["certified"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
