"""The ``bench`` and ``report`` subcommands of the ``rfverify`` CLI."""

from __future__ import annotations

import argparse
import shlex
import sys

from ..cli import _dumps, _nonneg_int, _out_path, _positive_float, _positive_int, _tolerance
from ..solver.result import METHODS
from .runner import DEFAULT_METHODS as _METHODS

DEFAULT_METHODS = ",".join(_METHODS)
DEFAULT_TOLS = "1e-8,1e-9,1e-10"


def _method_list(text: str) -> list:
    items = [t.strip() for t in text.split(",") if t.strip()]
    bad = [t for t in items if t not in METHODS]
    if bad or not items:
        raise argparse.ArgumentTypeError(f"unknown method(s) {', '.join(bad) or '(none given)'}; "
                                         f"choose from {', '.join(METHODS)}")
    return list(dict.fromkeys(items))


def _tol_list(text: str) -> list:
    items = [t.strip() for t in text.split(",") if t.strip()]
    if not items:
        raise argparse.ArgumentTypeError("give at least one tolerance")
    return sorted({_tolerance(t) for t in items}, reverse=True)


def add_parsers(sub) -> None:
    bench = sub.add_parser(
        "bench", help="run every method on every problem at every tolerance, verified independently",
        description="Run each method on each problem at each tolerance, one process per run "
                    "(--jobs at a time, each killed after --time-limit seconds; on a Dask "
                    "cluster with --scheduler), save every "
                    "solution and trace under RUN_DIR/runs/, and count a run as solved only when "
                    "an independent 30-digit recomputation of the stopping criterion from the "
                    "saved solution meets the tolerance. Also, per problem: a trajectory of each "
                    "Algorithm 1 method at --trajectory-tol with every iterate rechecked "
                    "(work-precision data, how far double precision gets), and, for problems with "
                    "at most --reference-max-contacts contacts, the mixed-precision --digits path "
                    "with its certificate (whose independent reference gives correct digits). "
                    "Resumable: a finished run is reused only when the problem file's content, "
                    "the method, tolerance, settings and rfverify version are unchanged "
                    "(--retry-failed also redoes timed-out, crashed and failed runs); one bench "
                    "at a time per RUN_DIR. "
                    "Then run `rfverify report RUN_DIR`.",
    )
    bench.add_argument("inputs", nargs="+", metavar="DIR_OR_FILE",
                       help="problem files, directories of them (the directory name is the "
                            "collection), 'bundled' (every bundled problem) or 'bundled:NAME'")
    bench.add_argument("--out", required=True, metavar="RUN_DIR", type=_out_path,
                       help="run directory (created or resumed)")
    bench.add_argument("--methods", type=_method_list, default=_method_list(DEFAULT_METHODS), metavar="M,M,...",
                       help=f"comma-separated methods (default: {DEFAULT_METHODS}; all: {','.join(METHODS)})")
    bench.add_argument("--tol", type=_tol_list, default=_tol_list(DEFAULT_TOLS), metavar="T,T,...",
                       help=f"comma-separated tolerances (default: {DEFAULT_TOLS})")
    bench.add_argument("--jobs", type=_positive_int, default=None, metavar="K",
                       help="runs in parallel (default: 1; parallel runs share the machine, so "
                            "times are comparable only within one bench run); with --scheduler, "
                            "the most runs in flight on the cluster (default: twice its worker "
                            "threads)")
    bench.add_argument("--time-limit", type=_positive_float, default=600.0, metavar="S",
                       help="wall-clock limit per run in seconds (default: %(default)g)")
    bench.add_argument("--max-iter", type=_positive_int, default=100, metavar="K",
                       help="iteration limit of each solve (default: %(default)s)")
    bench.add_argument("--trajectory-tol", type=_tolerance, default=1e-14, metavar="T",
                       help="tolerance of the per-iterate trajectory runs (default: %(default)g)")
    bench.add_argument("--no-trajectories", action="store_true", help="skip the trajectory runs")
    bench.add_argument("--digits", type=_nonneg_int, default=10, metavar="K",
                       help="digits of the mixed-precision path (0 skips it; default: %(default)s)")
    bench.add_argument("--reference-max-contacts", type=_nonneg_int, default=60, metavar="N",
                       help="largest problem (contacts) given the mixed-precision path and a "
                            "reference solution; the reference costs ~1 min at 100 contacts "
                            "(default: %(default)s)")
    bench.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="run the tasks on a Dask distributed cluster whose scheduler listens "
                            "at ADDRESS (tcp://HOST:8786; needs pip install 'rfverify[distributed]' "
                            "here and on every worker). Each run executes in a subprocess on a "
                            "worker, killed there at --time-limit; problem files are sent with the "
                            "tasks (no shared filesystem needed); this process writes the records, "
                            "the same as a local run's. See docs/DISTRIBUTED.md")
    bench.add_argument("--retry-failed", action="store_true",
                       help="also re-run runs recorded as Timeout, Crashed or Error (e.g. with a "
                            "longer --time-limit); other finished runs are reused as usual")
    bench.add_argument("--quiet", action="store_true", help="no progress output")
    bench.add_argument("--json", action="store_true", help="print the outcome as JSON")
    bench.set_defaults(func=cmd_bench)

    report = sub.add_parser(
        "report", help="write RUN_DIR/report.html and RUN_DIR/summary.md from a bench run",
        description="Build the report of a bench run directory: Dolan–Moré performance profiles "
                    "of time and iterations per tolerance, verified error against run time, a "
                    "success table per collection × method × tolerance with shifted geometric "
                    "mean times, how far double precision gets, the cost of the mixed-precision "
                    "path, per-iteration lockstep diagnostics (double against reference) of the "
                    "worst cases, and every failure with its diagnosed cause. PNG figures are "
                    "written beside report.html.",
    )
    report.add_argument("run_dir", metavar="RUN_DIR")
    report.add_argument("--diagnose", type=_nonneg_int, default=3, metavar="N",
                        help="lockstep-diagnose the N worst cases (default: %(default)s; 0 skips)")
    report.add_argument("--diagnose-max-contacts", type=_positive_int, default=40, metavar="N",
                        help="only diagnose problems with at most N contacts (default: %(default)s)")
    report.add_argument("--dps", type=_positive_int, default=40, metavar="D",
                        help="digits of the lockstep reference steps (default: %(default)s)")
    report.add_argument("--quiet", action="store_true", help="no progress output")
    report.add_argument("--json", action="store_true", help="print paths and counts as JSON")
    report.set_defaults(func=cmd_report)


def cmd_bench(args) -> int:
    from . import run_bench

    command = "rfverify " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["bench"] else None
    out = run_bench(args.inputs, args.out, methods=tuple(args.methods), tols=tuple(args.tol), jobs=args.jobs,
                    time_limit=args.time_limit, trajectory_tol=args.trajectory_tol,
                    trajectories=not args.no_trajectories, digits=args.digits,
                    reference_max_contacts=args.reference_max_contacts, max_iter=args.max_iter,
                    quiet=args.quiet, command=command, retry_failed=args.retry_failed,
                    scheduler=args.scheduler)
    if args.json:
        out = dict(out, counts=[{"method": m, "tol": t, "solved": s, "total": n}
                                for (m, t), (s, n) in out["counts"].items()])
        print(_dumps(out))
    else:
        print(f"bench: {out['ran']} runs done, {out['skipped']} already finished, {out['timeouts']} timed out; "
              f"records in {out['run_dir']}/runs. Next: rfverify report {out['run_dir']}")
        for (method, tol), (solved, total) in sorted(out["counts"].items(), key=lambda kv: (kv[0][0], -kv[0][1])):
            print(f"  {method:<16} tol {tol:g}: {solved}/{total} verified solved")
    return 0


def cmd_report(args) -> int:
    from ..report import make_report

    out = make_report(args.run_dir, diagnose_count=args.diagnose,
                      diagnose_max_contacts=args.diagnose_max_contacts, diagnose_dps=args.dps,
                      quiet=args.quiet)
    if out["issues"]:
        first = out["issues"][0].split("; fix:")[0]
        print(f"rfverify report: warning: {args.run_dir}: {len(out['issues'])} record(s) or array "
              f"file(s) missing or damaged, e.g. {first} (all listed in summary.md under 'Missing or "
              "damaged records'); fix: re-run the bench command, which redoes them", file=sys.stderr)
    if args.json:
        print(_dumps({"report": out["report"], "summary": out["summary"], "issues": out["issues"],
                      "bench_running": out["running"],
                      "counts": [{"collection": c, "method": m, "tol": t, "solved": s, "total": n}
                                 for (c, m, t), (s, n) in out["counts"].items()]}))
    else:
        print(f"report: {out['report']}\nsummary: {out['summary']}")
    return 0
