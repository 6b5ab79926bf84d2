"""Growth benchmark (issue 27): time, iterations, verified accuracy and peak memory of jqinv,
schur and Clarabel as the number of contacts grows, on structured granular beds
(``rfverify generate GranularBed``: spheres on a simple cubic lattice, built without any
solve) and on random rigid-body problems (``random_problem(0.3 n, n, seed=5)``, the issue's).

Each (problem, method) runs in a fresh child process that generates the problem, warms
numba's kernels (as ``rfverify bench`` does), solves once and reports the wall time, the
iterations, the criterion recomputed in longdouble from the returned (v, u, r) (never the
solver's own number), and the peak resident memory of the child above what it held before the
solve (``resource.getrusage(...).ru_maxrss``: the solve's own peak, with the problem data
counted in the baseline) — per contact in the table.  Runs are sequential, so the times of one
invocation are comparable; on a shared machine compare ratios within one invocation.  Set
``OPENBLAS_NUM_THREADS=1`` on a loaded machine (CHOLMOD through OpenBLAS oversubscribes the
cores otherwise; docs/DECISIONS.md).

Prints a markdown table, which :mod:`_results` also writes to
``benchmarks/results/bench_scale.md`` stamped with commit, date and machine, and beside it
``bench_scale.json`` (the rows) and ``bench_scale.png`` (log-log time against contacts, one line
per method and problem kind).  ``--no-memory`` runs everything in this process instead (no
memory column; this is how the ``auto`` threshold was measured: one process, warm, methods
interleaved per problem).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_scale.py                 # 1e3, 3e3, 1e4
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_scale.py --large         # also 3e4 and 1e5
    python benchmarks/bench_scale.py --sizes 500,1000,2000 --no-memory --repeat 3 --kinds bed,random
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from _results import recording  # noqa: E402  (stamped results file)

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SIZES = (1000, 3000, 10000)
LARGE_SIZES = (30000, 100000)
DEFAULT_METHODS = "jqinv,schur,clarabel"
KINDS = ("bed", "generic", "touching", "random")
BED_PARAMS = {"bed": {}, "generic": {"orientation": 1.0},
              "touching": {"orientation": 1.0, "gap_jitter": 0.0}}
"""GranularBed parameters of each bed kind: ``bed`` the lattice axes (normals vertical and
horizontal, about 20 nonzeros of H per contact); ``generic`` the same bed turned by a random 3-D
rotation (generic contact frames, about 40 per contact); ``touching`` turned, with zero gaps:
every lattice contact touches (hyperstatic: H has more columns on its loaded contacts than
rows, r is not unique)."""


def bed_side(n_contacts: int) -> int:
    """Side k of the simple cubic k x k x k GranularBed whose contact count 3k^3 - 2k^2 is
    nearest ``n_contacts``."""
    k = max(1, round((n_contacts / 3.0) ** (1.0 / 3.0)))
    return min((c for c in (k - 1, k, k + 1) if c >= 1), key=lambda c: abs(3 * c ** 3 - 2 * c ** 2 - n_contacts))


def make_problem(kind: str, size: int, seed: int):
    """The problem of one row: a bed (GranularBed, simple cubic, about ``size`` contacts,
    :data:`BED_PARAMS`) or ``random`` (random_problem with 0.3 size bodies and ``size`` contacts)."""
    if kind in BED_PARAMS:
        from rfverify.scenes import generate

        k = bed_side(size)
        return generate("GranularBed", seed=seed, size=k ** 3, **BED_PARAMS[kind])[0]
    if kind == "random":
        from rfverify.scenes.random_problems import random_problem

        return random_problem(max(2, int(round(0.3 * size))), size, seed=seed)
    raise ValueError(f"unknown problem kind {kind!r}; kinds: {', '.join(KINDS)}")


def _maxrss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB


def run_one(kind: str, size: int, seed: int, method: str, tol: float, time_limit: float, problem=None) -> dict:
    """Solve one problem with one method here; the row of the table (without memory when the
    problem was given, i.e. when several runs share this process)."""
    import rfverify
    from rfverify.model.measures import measures
    from rfverify.solver import kernels
    from rfverify.engines.factor import cholmod_available

    t0 = time.perf_counter()
    own = problem is None
    if own:
        problem = make_problem(kind, size, seed)
    t_gen = time.perf_counter() - t0
    kernels.warm_up()
    if method == "schur" and cholmod_available():
        import cvxopt.cholmod  # noqa: F401  (its library load is not the solve, as Clarabel's is not)
    before = _maxrss_bytes()
    t0 = time.perf_counter()
    res = rfverify.solve(problem, method=method, tol=tol, time_limit=time_limit)
    seconds = time.perf_counter() - t0
    peak = _maxrss_bytes()
    crit = float(measures(problem, res.v, res.u, res.r, "longdouble").max)
    row = {"kind": kind, "size": size, "seed": seed, "method": method, "contacts": problem.n_contacts,
           "dofs": problem.n_dofs, "status": str(res.status), "iterations": int(res.nit), "time": seconds,
           "factor_time": float(res.timings.get("factor", float("nan"))), "criterion": crit,
           "verified": bool(crit <= tol), "generate_time": t_gen}
    if own:
        row.update(peak_rss=peak, solve_rss=max(0, peak - before), baseline_rss=before)
    return row


def run_child(kind, size, seed, method, tol, time_limit) -> dict:
    """:func:`run_one` in a fresh interpreter (its peak memory is its own); killed after twice
    the time limit plus a minute (the solver stops itself at the limit)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child",
           json.dumps({"kind": kind, "size": size, "seed": seed, "method": method, "tol": tol,
                       "time_limit": time_limit})]
    try:
        out = subprocess.run(cmd, capture_output=True, text=True, timeout=2 * time_limit + 60, check=False)
    except subprocess.TimeoutExpired:
        return {"kind": kind, "size": size, "seed": seed, "method": method, "status": "Killed",
                "time": float("nan"), "iterations": 0, "criterion": float("nan"), "verified": False}
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or not lines:
        tail = " ".join((out.stderr or "").strip().splitlines()[-1:])
        return {"kind": kind, "size": size, "seed": seed, "method": method, "status": "Error",
                "message": tail, "time": float("nan"), "iterations": 0, "criterion": float("nan"),
                "verified": False}
    return json.loads(lines[-1])


def available_methods(methods):
    """(methods that can run here, {skipped method: reason})."""
    from rfverify.solver.result import method_unavailable

    skipped = {m: method_unavailable(m) for m in methods if method_unavailable(m) is not None}
    return [m for m in methods if m not in skipped], skipped


def table(rows, tol) -> str:
    """The markdown table: one line per run, with the time ratio to Clarabel on the same problem."""
    clar = {(r["kind"], r.get("contacts", r.get("size"))): r.get("time") for r in rows if r["method"] == "clarabel"}
    head = ("| kind | contacts | dofs | method | status | it | time [s] | factor [s] | /Clarabel | "
            f"criterion (≤ {tol:g}?) | solve peak [MB] | bytes/contact |")
    lines = [head, "|" + "---|" * 12]
    for r in rows:  # a killed or failed child's row has only kind, size, method, status and a message
        c = clar.get((r["kind"], r.get("contacts", r.get("size"))))
        t = r.get("time", float("nan"))
        ratio = f"{t / c:.2f}" if c and r["method"] != "clarabel" and math.isfinite(t) else ""
        mem = r.get("solve_rss")
        crit = r.get("criterion")
        lines.append("| " + " | ".join([
            r["kind"], str(r.get("contacts", f"≈{r.get('size')}")), str(r.get("dofs", "")), r["method"], r["status"],
            str(r.get("iterations", "")), f"{t:.2f}", f"{r.get('factor_time', float('nan')):.2f}", ratio,
            "" if crit is None else f"{crit:.1e} ({'yes' if r['verified'] else 'no'})",
            f"{mem / 1e6:.0f}" if mem is not None else "", f"{mem / r['contacts']:.0f}" if mem else ""]) + " |")
    return "\n".join(lines)


def plot(rows, path: Path) -> bool:
    """Log-log time against contacts, one line per (method, kind); False without matplotlib."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    styles = {"bed": "-", "generic": "-.", "touching": ":", "random": "--"}
    colors = {"jqinv": "tab:blue", "schur": "tab:green", "clarabel": "tab:red", "auto": "tab:purple"}
    for kind in KINDS:
        for method in dict.fromkeys(r["method"] for r in rows):
            pts = sorted((r["contacts"], r["time"], r["verified"]) for r in rows
                         if r["kind"] == kind and r["method"] == method and "contacts" in r
                         and math.isfinite(r.get("time", float("nan"))))
            if pts:
                x, y, ok = zip(*pts)
                color = colors.get(method, "black")
                ax.loglog(x, y, styles[kind], marker="o", color=color,
                          label=f"{method}, {kind if kind != 'bed' else 'granular bed'}")
                bad = [(a, b) for a, b, v in zip(x, y, ok) if not v]
                if bad:  # hollow: not verified at tol (a time limit, or a peer short of tol)
                    ax.loglog(*zip(*bad), "o", color="white", markersize=4, linestyle="none")
    ax.set_xlabel("contacts")
    ax.set_ylabel("solve time [s]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("growth benchmark, one run (hollow: not verified at tol)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return True


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default=",".join(map(str, DEFAULT_SIZES)),
                    help="target contact counts (a bed gets the nearest k x k x k lattice)")
    ap.add_argument("--large", action="store_true", help=f"add {', '.join(map(str, LARGE_SIZES))} contacts")
    ap.add_argument("--kinds", default="bed,random", help="problem kinds: bed (GranularBed, lattice axes), generic (the bed turned: generic contact "
                         "frames), touching (turned, zero gaps: hyperstatic), random")
    ap.add_argument("--methods", default=DEFAULT_METHODS)
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--time-limit", type=float, default=900.0, help="seconds per solve (status MaxTime beyond)")
    ap.add_argument("--repeat", type=int, default=1, help="solves per (problem, method) with --no-memory (median kept)")
    ap.add_argument("--no-memory", action="store_true",
                    help="run every solve in this process (no child processes, no memory column)")
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(run_one(**json.loads(args.child))), flush=True)
        return 0
    kinds = [k for k in args.kinds.split(",") if k]
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        ap.error(f"--kinds: unknown {', '.join(bad)}; kinds: {', '.join(KINDS)}")
    with recording("bench_scale", argv) as path:
        return _run(args, kinds, path)


def _run(args, kinds, path) -> int:
    from rfverify.engines.factor import schur_engine_name

    sizes = [int(s) for s in args.sizes.split(",") if s] + (list(LARGE_SIZES) if args.large else [])
    methods, skipped = available_methods([m for m in args.methods.split(",") if m])
    for m, why in skipped.items():
        print(f"skipped {m}: {why}", flush=True)
    try:
        load = f"{os.getloadavg()[0]:.1f}"
    except OSError:
        load = "unknown"
    print(f"tol {args.tol:g}, seed {args.seed}, OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}, "
          f"load average {load} at the start; schur factored by {schur_engine_name()}; "
          + ("every solve in this process, warm (no memory)" if args.no_memory else
             "each solve in its own child process, one after the other"), flush=True)
    rows = []
    for kind in kinds:
        for size in sizes:
            problem = make_problem(kind, size, args.seed) if args.no_memory else None
            for method in methods:
                if args.no_memory:
                    reps = [run_one(kind, size, args.seed, method, args.tol, args.time_limit, problem)
                            for _ in range(max(1, args.repeat))]
                    row = dict(reps[-1], time=statistics.median(r["time"] for r in reps), repeats=len(reps))
                else:
                    row = run_child(kind, size, args.seed, method, args.tol, args.time_limit)
                rows.append(row)
                mem = row.get("solve_rss")
                print(f"{kind:6s} n={row.get('contacts', size):7d} {method:9s} {row['status']:20s} "
                      f"it {row['iterations']:3d}  {row['time']:9.2f} s  crit {row['criterion']:.1e}"
                      + (f"  solve peak {mem / 1e6:7.0f} MB ({mem / row['contacts']:.0f} B/contact)" if mem else "")
                      + (f"  ({row['message']})" if row.get("message") else ""), flush=True)
    print("\nbed: GranularBed (simple cubic k x k x k spheres on the ground, 3k^3 - 2k^2 contacts); generic: the "
          "same bed turned by a random 3-D rotation (generic contact frames); touching: turned, zero gaps "
          "(hyperstatic); random: "
          "random_problem(0.3 n bodies, n contacts). criterion: rfverify's, recomputed in longdouble from the "
          "returned answer. solve peak: the peak RSS of the solve's process above its RSS before the solve "
          "(problem data excluded).\n")
    print(table(rows, args.tol))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.with_suffix(".json").write_text(json.dumps({"tol": args.tol, "skipped": skipped, "rows": rows},
                                                        indent=1, default=float))
        if plot(rows, path.with_suffix(".png")):
            print(f"\nplot: {path.with_suffix('.png').name} (log-log time against contacts)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
