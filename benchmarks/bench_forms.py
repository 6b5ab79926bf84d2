"""Wall time and independently verified accuracy of the linear-system forms and Clarabel.

Runs every method on the same problems in one process, one after the other, several
repetitions each (median kept), and prints a table plus the time ratios to Clarabel.
Accuracy is rfverify's criterion recomputed in longdouble from the returned (v, u, r)
(:func:`rfverify.model.measures.measures`), never the solver's own numbers; a run counts as solved at
a tolerance only when that recomputation meets it.  Not a test: timings on a shared 2-core
machine are noisy, so compare the ratios measured within one run.

    python benchmarks/bench_forms.py                 # default sizes
    python benchmarks/bench_forms.py --sizes 100,500,1000 --seeds 3 --repeat 3
    python benchmarks/bench_forms.py --sizes "" --files DIR   # FCLIB files, e.g. from `rfverify generate`
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
import statistics
import time

import numpy as np

import rfverify
from rfverify.bench.runner import BenchInputError, discover_problems
from rfverify.model.measures import measures
from rfverify.scenes.random_problems import random_problem
from rfverify.solver import METHODS, solve
from rfverify.solver.result import method_unavailable

sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)

TOLS = [1e-8, 1e-9, 1e-10]


def problems(sizes, seeds, files=()):
    for name in ("chute", "cube", "sphere", "sphere-from-global"):
        yield f"bundled:{name}", rfverify.load(f"bundled:{name}")
    for path in files:
        yield Path(path).stem, rfverify.load(path)
    for n in sizes:
        for seed in range(seeds):
            nb = max(2, int(0.6 * n))
            yield (f"random-n{n}-s{seed}",
                   random_problem(nb, n, seed=seed, mu_zero_fraction=0.05, mu_r_zero_fraction=0.1,
                                  free_bodies=nb // 10))


@recorded("bench_forms")
def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="50,200,500,1000", help="contact counts of generated problems")
    ap.add_argument("--seeds", type=int, default=2, help="problems per size")
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions per run (median kept)")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--files", nargs="*", default=[],
                    help="problem files, directories of them or bundled:NAME (added to the bundled and generated problems)")
    args = ap.parse_args(argv)
    try:  # the bench's own discovery: files, directories of them, bundled:NAME
        files = [Path(e.path) for e in discover_problems(args.files)] if args.files else []
    except BenchInputError as exc:
        ap.error(f"--files: {exc}")
    sizes = [int(s) for s in args.sizes.split(",") if s]
    methods = args.methods.split(",")
    for method in [m for m in methods if method_unavailable(m) is not None]:
        print(f"skipped {method}: {method_unavailable(method)}")  # an optional method this machine lacks
        methods.remove(method)
    rows = []
    print(f"{'problem':40s} {'n':>5s} {'method':10s} {'status':22s} {'nit':>4s} {'time[s]':>8s} {'verified':>9s}")
    for name, prob in problems(sizes, args.seeds, files):
        for method in methods:
            times = []
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                res = solve(prob, method=method, tol=min(TOLS))
                times.append(time.perf_counter() - t0)
            err = measures(prob, res.v, res.u, res.r, "longdouble").max
            t = statistics.median(times)
            rows.append((name, prob.n_contacts, method, t, err))
            print(f"{name[:40]:40s} {prob.n_contacts:5d} {method:10s} {str(res.status):22s} {res.nit:4d} "
                  f"{t:8.3f} {err:9.1e}", flush=True)
    print("\nshare of problems whose verified criterion meets the tolerance")
    print(f"{'method':10s} " + " ".join(f"{tol:>8.0e}" for tol in TOLS))
    for method in methods:
        errs = [r[4] for r in rows if r[2] == method]
        print(f"{method:10s} " + " ".join(f"{np.mean([e <= tol for e in errs]):8.0%}" for tol in TOLS))
    if "clarabel" in methods:
        print("\nmedian time ratio method / clarabel over problems with n >= 500 (both verified at 1e-8)")
        for method in methods:
            ratios = []
            for name in {r[0] for r in rows if r[1] >= 500}:
                mine = [r for r in rows if r[0] == name and r[2] == method]
                peer = [r for r in rows if r[0] == name and r[2] == "clarabel"]
                if mine and peer and mine[0][4] <= 1e-8 and peer[0][4] <= 1e-8:
                    ratios.append(mine[0][3] / peer[0][3])
            if ratios:
                print(f"{method:10s} {statistics.median(ratios):6.2f}x  ({len(ratios)} problems)")


if __name__ == "__main__":
    main()
