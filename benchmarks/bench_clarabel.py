"""jqinv against Clarabel at equal verified accuracy on FCLIB-size problems (issue "Faster than
Clarabel").

For each problem with at least ``--min-contacts`` contacts: both methods solve at ``--tol``
(default 1e-8), alternating (jqinv, Clarabel, jqinv, ...) ``--repeat`` times in one process,
median wall time kept; each answer is judged by rfverify's one criterion
(:func:`rfverify.model.measures.measures`, recomputed in longdouble from the returned (v, u, r)),
never by the solver's word.  Prints the per-problem ratio jqinv/Clarabel (over problems both
verified) and its median.  Numba's once-per-process start-up of the compiled cone kernels
(~0.3 s) is paid before the first timed run, as Clarabel's library load is paid at import.
Not a test: compare ratios measured in one run on this shared machine.

    python benchmarks/bench_clarabel.py                    # the generated collections at published size + 2 more
    python benchmarks/bench_clarabel.py --files A.hdf5 ... # your own problems
"""

from __future__ import annotations

import statistics
import sys
import time
from pathlib import Path

import rfverify
from rfverify.model.measures import measures

sys.path.insert(0, str(Path(__file__).parent))
from _results import recorded  # noqa: E402  (stamped results file)
from bench_digits import comparison_parser, scene_file, user_files  # noqa: E402  (the same cached scene files)

SETS = [("SpheresPile", "SpheresPile", None), ("Chute", "Chute", None), ("PrimitiveSoup", "PrimitiveSoup", None),
        ("Chute 888", "Chute", 700), ("Lattice 779", "Lattice", 160)]


def problem_set(args):
    if args.files:
        yield from user_files(args.files)
        return
    for label, scene, size in SETS:
        yield label, rfverify.load(scene_file(Path(args.cache), scene, size, 1, 0))
    from rfverify.scenes.random_problems import random_problem

    yield "random 1000", random_problem(600, 1000, seed=3)


def _value(text: str):
    """An option value: a Python literal (None, True, 1e-6, ...) or else the string itself."""
    import ast

    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


@recorded("bench_clarabel")
def main(argv=None):
    ap = comparison_parser(__doc__, tol=1e-8, methods="jqinv,clarabel")
    ap.add_argument("--min-contacts", type=int, default=750, help="skip problems with fewer contacts (default 750)")
    ap.add_argument("--options", default="",
                    help="solver options for the Algorithm 1 methods, e.g. sigma_rule=siconos,longdouble_below=None")
    args = ap.parse_args(argv)
    options = {k: _value(v) for k, v in (kv.split("=", 1) for kv in args.options.split(",") if kv)}
    methods = args.methods.split(",")
    from rfverify.solver import kernels

    kernels.warm_up()
    print(f"{'problem':<16} {'n':>5} " + " ".join(f"{m + ' s':>12} {'crit':>8} {'it':>3}" for m in methods)
          + "   ratio")
    ratios = {m: [] for m in methods if m != "clarabel"}
    for label, p in problem_set(args):
        if p.n_contacts < args.min_contacts:
            continue
        times = {m: [] for m in methods}
        res = {}
        for _ in range(args.repeat):
            for m in methods:
                t0 = time.perf_counter()
                res[m] = rfverify.solve(p, method=m, tol=args.tol, **({} if m == "clarabel" else options))
                times[m].append(time.perf_counter() - t0)
        cells, ok = [], {}
        for m in methods:
            crit = measures(p, res[m].v, res[m].u, res[m].r, "longdouble").max
            ok[m] = crit <= args.tol
            cells.append(f"{statistics.median(times[m]):>12.3f} {crit:>8.1e} {res[m].nit:>3d}")
        line = f"{label:<16} {p.n_contacts:>5} " + " ".join(cells)
        if "clarabel" in methods:
            for m in ratios:
                if ok[m] and ok["clarabel"]:
                    ratios[m].append(statistics.median(times[m]) / statistics.median(times["clarabel"]))
                    line += f"   {m}/clarabel {ratios[m][-1]:.2f}"
                else:
                    line += f"   {m}/clarabel – (not both verified: {m} {ok[m]}, clarabel {ok['clarabel']})"
        print(line, flush=True)
    for m, r in ratios.items():
        if r:
            print(f"\nmedian {m}/clarabel = {statistics.median(r):.2f}x over {len(r)} problems (both verified at {args.tol:g})")


if __name__ == "__main__":
    main()
