"""Siconos GRFC3D_IPM (the paper's own implementation) beside jqinv and Clarabel, judged by proven
digits (issue 30).

For each problem: every method solves at ``--tol`` (``--repeat`` times alternating, median wall
time kept), its answer is judged by rfverify's criterion (:func:`rfverify.model.measures.measures` in
longdouble, never the solver's word), and then proven: :func:`rfverify.certify` bounds the error
of each answer (v, u, r) against one extended-precision point per problem (computed once, from
the first method's answer, and shared so the three are bounded against the same point).
A Siconos crash (segfault in its unchecked LDLᵀ) is counted, not fatal.  Needs the peer built
(``bash benchmarks/peers/siconos/build.sh``; RFVERIFY_SICONOS or the default cache).
Not a test: compare ratios measured in one run on this shared machine.

    python benchmarks/peers/siconos/compare.py                     # bundled + generated FCLIB-size problems
    python benchmarks/peers/siconos/compare.py --files A.hdf5 ...  # your own problems

What it prints also goes to benchmarks/results/peers/siconos/compare.md, stamped with the commit,
date and machine (benchmarks/_results.py).
"""

from __future__ import annotations

import math
import statistics
import sys
import time
from pathlib import Path

import rfverify
from rfverify.model.measures import measures

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from _results import recorded  # noqa: E402  (stamped results file, benchmarks/_results.py)
from bench_digits import comparison_parser, scene_file, user_files  # noqa: E402  (the same cached scenes)


BUNDLED = "chute,cube,sphere"
SCENES = [("SpheresPile", None, 1, 0), ("SpheresPile", None, 3, 2), ("Chute", 700, 1, 0), ("Chute", None, 2, 0),
          ("Lattice", 100, 1, 0), ("MassRatio", None, 1, 0), ("MassRatio", 250, 1, 0), ("Millimetre", None, 1, 0),
          ("PrimitiveSoup", None, 1, 0)]
"""(scene, size, count, index) of the generated problems (files sorted by name: index 2 of SpheresPile's 3 is
its 375-contact stage)."""
HARD = Path(__file__).resolve().parents[3] / "tests" / "data" / "hard" / "Chute-ndof-1200-nc-240-3.hdf5"
"""A committed Chute on which GRFC3D_IPM crashes (zero pivot in its LDLᵀ)."""


def problem_set(args):
    if args.files:
        yield from user_files(args.files)
        return
    for name in BUNDLED.split(","):
        yield f"bundled:{name}", rfverify.load(f"bundled:{name}")
    for scene, size, count, index in SCENES:
        f = scene_file(Path(args.cache), scene, size, count, index)
        yield f.stem, rfverify.load(f)
    if HARD.is_file():
        yield HARD.stem + " (tests/data/hard)", rfverify.load(HARD)


def _dig(x) -> str:
    return "–" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.1f}"


@recorded("peers/siconos/compare")
def main(argv=None):
    ap = comparison_parser(__doc__, tol=1e-10, methods="jqinv,clarabel,siconos")
    ap.add_argument("--digits", type=int, default=10, help="digits certify is asked to prove (default: 10)")
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    from rfverify.solver import kernels
    from rfverify.solver.result import method_unavailable

    for m in methods:
        why = method_unavailable(m)
        if why:
            sys.exit(f"compare.py: {why}")
    kernels.warm_up()
    print(f"tol {args.tol:g}; per method: median wall time (s) of {args.repeat} runs, rfverify criterion of the "
          f"answer, iterations, proven digits of v and u (rfverify.certify, --digits {args.digits}); "
          "siconos also its own residual and info")
    head = f"{'problem':<44} {'n':>5} " + " ".join(f"| {m:<8} {'s':>7} {'crit':>8} {'it':>3} {'dv':>4} {'du':>4} "
                                                   for m in methods)
    print(head)
    summary = {m: {"ratio": [], "digits_v": [], "solved": 0, "runs": 0, "crashed": 0, "refuted": 0} for m in methods}
    base = methods[0]
    for label, p in problem_set(args):
        times = {m: [] for m in methods}
        res = {}
        for _ in range(args.repeat):
            for m in methods:
                t0 = time.perf_counter()
                res[m] = rfverify.solve(p, method=m, tol=args.tol)
                times[m].append(time.perf_counter() - t0)
        point, cells, notes, verified = None, [], [], {}
        for m in methods:
            r = res[m]
            s = summary[m]
            s["runs"] += 1
            crit = measures(p, r.v, r.u, r.r, "longdouble").max
            crashed = bool(r.extras.get("no_answer")) and r.extras.get("siconos_signal") is not None
            s["crashed"] += crashed
            dv = du = None
            if not r.extras.get("no_answer"):
                cert = rfverify.certify(p, r.v, r.u, r.r, digits=args.digits, point=point)
                point = point or cert.point
                dv, du = cert.digits.get("v"), cert.digits.get("u")
            t = statistics.median(times[m])
            verified[m] = crit <= args.tol
            if verified[m]:
                s["solved"] += 1
                if verified.get(base):
                    s["ratio"].append(t / statistics.median(times[base]))
            if dv is not None:
                s["digits_v"].append(dv)
            own = r.extras.get("siconos_status", r.extras.get("clarabel_status", str(r.status)))
            if own == "Solved" and not crit <= args.tol:
                s["refuted"] += 1
            if m == "siconos":
                notes.append(f"siconos: {r.message}" if r.extras.get("no_answer") else
                             f"siconos own residual {r.extras['siconos_residual']:.1e} info {r.extras['siconos_info']}"
                             f" (its solve {r.extras['siconos_seconds']:.3f} s)")
            cells.append(f"| {'':<8} {t:>7.3f} {crit:>8.1e} {r.nit:>3d} {_dig(dv):>4} {_dig(du):>4} ")
        print(f"{label:<44} {p.n_contacts:>5} " + " ".join(cells) + ("   " + "; ".join(notes) if notes else ""),
              flush=True)
    print()
    for m, s in summary.items():
        dig = s["digits_v"]
        print(f"{m:<9} verified solved {s['solved']}/{s['runs']}, crashed {s['crashed']}, refuted claims {s['refuted']}; "
              f"proven digits of v: median {_dig(statistics.median(dig) if dig else None)}, "
              f"range {_dig(min(dig) if dig else None)}–{_dig(max(dig) if dig else None)}; "
              f"time / {base}'s on the {len(s['ratio'])} problems both verified: median "
              f"{statistics.median(s['ratio']) if s['ratio'] else float('nan'):.2f}")


if __name__ == "__main__":
    main()
