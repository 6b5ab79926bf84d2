"""``rfverify bench``: every method on every problem at every tolerance, rechecked independently
(the work is :func:`rfverify.bench.run_bench`)."""

from __future__ import annotations

import re
import shlex
import sys

from ..bench.coulomb import COULOMB_DEFAULT_METHODS
from ..bench.runner import DEFAULT_METHODS, DEFAULT_TOLS
from ..coulomb.model import PROBLEMS
from ..solver.result import METHODS
from .argtypes import method_list, nonneg_int, out_path, positive_int, seconds, tol_list, tolerance
from .common import (DOCS_NOTE, EXIT_OK, PSD_SHIFT_HELP, add_equations_option, add_load_options, dumps, exit_codes,
                     progress_printer)

NO_LIMIT = 10**9
"""--reference-max-contacts when not given: every problem gets the --digits path."""

HELP = "run every method on every problem at every tolerance, verified independently"

DESCRIPTION = """\
Run each method on each problem at each tolerance, one process per run (--jobs at a time, each
killed after --time-limit seconds; on a Dask cluster with --scheduler), save every solution and
trace under RUN_DIR/runs/, and count a run as solved only when an independent 30-digit
recomputation of the stopping criterion from the saved solution meets the tolerance. Also, per
problem: a trajectory of each Algorithm 1 method at --trajectory-tol with every iterate
rechecked (work-precision data, how far double precision gets), and the mixed-precision
--digits path with its certificate, whose proven point lets `rfverify report` prove the digits
of every saved answer of every method (--reference-max-contacts limits it to smaller problems). Resumable: a finished run is reused only
when the problem file's content, the method, tolerance, settings and rfverify version are
unchanged (--retry-failed also redoes timed-out, crashed and failed runs); one bench at a time
per RUN_DIR. Then run `rfverify report RUN_DIR`.

--problem coulomb runs the physical problem instead (Coulomb friction and rolling resistance
with De Saxce's term; see `solve --help`): per problem, rfverify's Coulomb path at --digits (its
inner solver: each of --methods but siconos; default auto), and with siconos in --methods,
Siconos's own 3-D Coulomb IPM, GFC3D_IPM, at each --tol on every problem it takes (3-D: mu_r = 0
and mu > 0 on every contact; others are recorded as not run, with the reason), each of its
answers certified by the same proven backward error (`certify --problem coulomb`). It prints,
per answer, whether it is certified, its proven backward error and proven digits, or why not.
The records go into the same kind of RUN_DIR (it may also hold the relaxation's runs); `rfverify
report RUN_DIR` shows them beside the relaxation's."""


def add_parser(sub) -> None:
    """The ``bench`` subcommand."""
    bench = sub.add_parser("bench", help=HELP, description=DESCRIPTION,
                           epilog=exit_codes("every task ran (failed solves are results, not errors)",
                                             extra="143 stopped by SIGTERM (the run directory resumes)")
                           + " " + DOCS_NOTE)
    bench.add_argument("inputs", nargs="+", metavar="DIR_OR_FILE",
                       help="problem files, directories of them (the directory name is the "
                            "collection), 'bundled' (every bundled problem) or 'bundled:NAME'")
    bench.add_argument("--out", required=True, metavar="RUN_DIR", type=out_path,
                       help="run directory (created or resumed)")
    bench.add_argument("--methods", type=method_list, default=None, metavar="M,M,...",
                       help=f"comma-separated methods (default: {','.join(DEFAULT_METHODS)}; all: {','.join(METHODS)}; "
                            f"with --problem coulomb: {','.join(COULOMB_DEFAULT_METHODS)}, and siconos adds "
                            "Siconos's GFC3D_IPM)")
    bench.add_argument("--tol", type=tol_list, default=sorted(DEFAULT_TOLS, reverse=True), metavar="T,T,...",
                       help=f"comma-separated tolerances (default: {','.join(map(_short, DEFAULT_TOLS))})")
    bench.add_argument("--jobs", type=positive_int, default=None, metavar="K",
                       help="runs in parallel (default: 1; parallel runs share the machine, so "
                            "times are comparable only within one bench run); with --scheduler, "
                            "the most runs in flight on the cluster (default: twice its worker "
                            "threads)")
    bench.add_argument("--time-limit", type=seconds, default=600.0, metavar="S",
                       help="wall-clock limit per run in seconds (default: %(default)g): its solver stops "
                            "at 80%% of it (a trajectory's at 50%%, which then rechecks every iterate) and the "
                            "record keeps the best answer with status MaxTime; a run still going at the "
                            "limit is killed and recorded as Timeout")
    bench.add_argument("--max-iter", type=positive_int, default=100, metavar="K",
                       help="iteration limit of each solve (default: %(default)s)")
    bench.add_argument("--trajectory-tol", type=tolerance, default=1e-14, metavar="T",
                       help="tolerance of the per-iterate trajectory runs (default: %(default)g)")
    bench.add_argument("--no-trajectories", action="store_true", help="skip the trajectory runs")
    bench.add_argument("--digits", type=nonneg_int, default=10, metavar="K",
                       help="digits of the mixed-precision path (0 skips it; default: %(default)s)")
    bench.add_argument("--reference-max-contacts", type=nonneg_int, default=None, metavar="N",
                       help="largest problem (contacts) given the mixed-precision --digits path, "
                            "whose proven point gives every answer of that problem its proven "
                            "digits in the report (default: no limit; its cost is bounded by "
                            "--time-limit like any run)")
    bench.add_argument("--scheduler", metavar="ADDRESS", default=None,
                       help="run the tasks on a Dask distributed cluster whose scheduler listens "
                            "at ADDRESS (tcp://HOST:8786; needs pip install 'rfverify[distributed]' "
                            "here and on every worker). Each run executes in a subprocess on a "
                            "worker, killed there at --time-limit; problem files are sent with the "
                            "tasks (no shared filesystem needed); this process writes the records, "
                            "the same as a local run's. See DISTRIBUTED.md")
    bench.add_argument("--retry-failed", action="store_true",
                       help="also re-run runs recorded as Timeout, Crashed, Error or MaxTime (e.g. with a "
                            "longer --time-limit); other finished runs are reused as usual")
    bench.add_argument("--problem", dest="problem_kind", choices=PROBLEMS, default="relaxation",
                       help="relaxation (default): the convex relaxation, every method and tolerance as "
                            "above; coulomb: the physical problem, rfverify's Coulomb path and, with siconos "
                            "in --methods, Siconos's GFC3D_IPM at each --tol, each answer certified by a "
                            "proven backward error at --digits (see the description)")
    bench.add_argument("--quiet", action="store_true", help="no progress output")
    add_equations_option(bench)
    bench.add_argument("--psd-shift", action="store_true", help=PSD_SHIFT_HELP + "; applied to every local problem of the run, global ones "
                                                          "are left as they are")
    add_load_options(bench)
    bench.add_argument("--json", action="store_true", help="print the outcome as JSON")
    bench.set_defaults(func=cmd_bench, check_outputs=check_outputs)


def _short(tol: float) -> str:
    """1e-08 as 1e-8."""
    return re.sub(r"e([+-])0+(\d)", r"e\1\2", f"{tol:g}")


def check_outputs(args) -> None:
    """Refuse an unusable RUN_DIR before any work."""
    from ..io.output import check_output_dir

    check_output_dir(args.out)


def cmd_bench(args) -> int:
    from ..bench import run_bench
    from ..compilation import announcing

    command = "rfverify " + " ".join(shlex.quote(a) for a in sys.argv[1:]) if sys.argv[1:2] == ["bench"] else None
    coulomb = args.problem_kind == "coulomb"
    methods = args.methods or list(COULOMB_DEFAULT_METHODS if coulomb else DEFAULT_METHODS)
    if coulomb and args.digits == 0:
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("--digits", "is 0, but --problem coulomb certifies every answer at --digits",
                                   fix="pass --digits K with K >= 1 (default 10)")
    with announcing(progress_printer(args)):  # a compilation here or in a forked local task is named
        out = run_bench(args.inputs, args.out, methods=tuple(methods), tols=tuple(args.tol), jobs=args.jobs,
                        time_limit=args.time_limit, trajectory_tol=args.trajectory_tol,
                        trajectories=not args.no_trajectories, digits=args.digits,
                        reference_max_contacts=NO_LIMIT if args.reference_max_contacts is None
                        else args.reference_max_contacts, max_iter=args.max_iter,
                        quiet=args.quiet, command=command, retry_failed=args.retry_failed,
                        scheduler=args.scheduler, as_stored=args.as_stored, problem_kind=args.problem_kind,
                        load_options={"max_asymmetry": args.max_asymmetry, "psd_shift": args.psd_shift})
    if args.json:
        out = dict(out, counts=[{"method": m, "tol": t, "solved": s, "total": n}
                                for (m, t), (s, n) in out["counts"].items()])
        print(dumps(out))
    elif coulomb:
        print(f"bench --problem coulomb: {out['ran']} runs done, {out['skipped']} already finished, "
              f"{out['timeouts']} timed out; records in {out['run_dir']}/runs. Next: rfverify report {out['run_dir']}")
        for line in coulomb_lines(out["coulomb"], args.digits):
            print(line)
    else:
        print(f"bench: {out['ran']} runs done, {out['skipped']} already finished, {out['timeouts']} timed out; "
              f"records in {out['run_dir']}/runs. Next: rfverify report {out['run_dir']}")
        for (method, tol), (solved, total) in sorted(out["counts"].items(), key=lambda kv: (kv[0][0], -kv[0][1])):
            print(f"  {method:<16} tol {tol:g}: {solved}/{total} verified solved")
    return EXIT_OK


def coulomb_lines(summaries, digits: int) -> list[str]:
    """``bench --problem coulomb``'s output: per problem, each answer — certified or not, its
    proven backward error and proven digits, iterations and time — or why it has none."""
    lines = []
    for problem in dict.fromkeys(s["problem"] for s in summaries):
        lines.append(f"  {problem}:")
        for s in (x for x in summaries if x["problem"] == problem):
            t = f", {s['time']:.2f} s" if isinstance(s["time"], (int, float)) else ""
            it = f", {s['outer']}" if s["outer"] else ""
            if s["backward_error"] is None:  # no answer, or no proof: the reason is the record's message
                lines.append(f"    {s['solver']:<30} {s['status']}: {s['why'][:300]}")
                continue
            digs = " ".join(f"{k} {'-' if d is None else f'{d:.1f}'}" for k, d in s["digits"].items()) or "none"
            verdict = f"certified to {digits} digits" if s["certified"] else f"not certified to {digits} digits"
            peer = f" (GFC3D says {s['peer_status']})" if s["peer_status"] else ""
            lines.append(f"    {s['solver']:<30} {verdict}{peer}: backward error {s['backward_error']:.1e}, "
                         f"proven digits {digs}{it}{t}")
    return lines
