"""``rfverify diagnose``: why a double run stalled, shown by the same algorithm in exact
arithmetic, and a remedy the diagnosis has tried."""

from __future__ import annotations

import math

from ..solver.result import ALGORITHM1_METHODS
from .argtypes import nonneg_float, out_path, seconds, witness_digits
from .common import (EXIT_NOT_SOLVED, EXIT_OK, PROBLEM_HELP, add_load_options, add_run_limits, dumps, load_problem,
                     print_warnings, progress_printer, recorded_warnings, warning_summary)

HELP = "why a run stalled: the same algorithm in exact arithmetic, and a remedy it has tried"

DESCRIPTION = """\
Run --method in double, then find out why it missed --tol (DESIGN §5):

lockstep: from every double iterate, the exact step (Algorithm 1 in double-double, every
Newton solve refined to that arithmetic's floor, with the run's own step fraction and sigma
rule); the digits of agreement of the next double iterate with it, on v, u and Hr (and r and z
where r is unique), each relative to the larger of its exact size and its data scale. The
first step whose digits fall below its threshold (or that loses a λ2) is the departure: the
threshold is the fewer of the digits the tolerance needs, -log10(tol), and the digits the
form's conditioning leaves a double step, -log10(N*u*kappa) (N the order of the form's matrix,
u = 2^-53, kappa = cond(Q_p)^2 for qp2, reduced and schur, cond(Q_p) for jqinv and
reduced_factored): a step below it lost more than its conditioning explains. The first step
below -log10(tol) whatever the reason is reported too (the shortfall).

counterfactual: the same algorithm continued in exact arithmetic from the run's own iterate at
the departure or the shortfall, whichever comes first (or at its best iterate): if it meets --tol within --max-iter the cause is
"precision"; later, "iterations"; never, "data". The mpmath reference repeats the deciding
steps within --witness-time seconds.

remedy: another --method, more --max-iter, --digits K, run as 'rfverify solve' runs them; the
first whose answer meets --tol is printed with its figures.

The first line states the cause and the remedy. The run diagnosed is the one 'rfverify solve
--method M' makes (M = --method, jqinv by default), not the auto sequence of a plain 'rfverify
solve', which goes on to other forms where one stalls; the lockstep's run is the same form as one system (no split into independent
components), every linear solve refined to 4*eps (solver setting refine_tol=None) and the
longdouble arithmetic from the first iteration (longdouble_below=None), so that the digits measure
the rounding of one arithmetic. Where that run meets --tol and the plain one does not, the cause
is the precision of the default linear solves."""

EPILOG = """\
Exit codes: 0 the double run was Solved; 1 it was not (MaxIterations, NumericalError, ...) —
the diagnosis is printed either way; 2 bad input or option; 3 internal error; 130 interrupted;
141 stdout closed early."""


PLOT_HELP = ("write the figure (PNG; PDF, SVG or EPS by the file's extension): digits of agreement with the threshold, cond(Q_p), λ2 of z and Jᵀr̃ in double "
             "and exactly, and the criterion of the run beside the exact continuation, per iteration, the departure "
             "marked")

def add_parser(sub) -> None:
    """The ``diagnose`` subcommand."""
    diag = sub.add_parser("diagnose", help=HELP, description=DESCRIPTION, epilog=EPILOG)
    diag.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    diag.add_argument("--method", choices=ALGORITHM1_METHODS, default="jqinv",
                      help="linear-system form of the double run (default: %(default)s)")
    add_run_limits(diag, tol_help="tolerance of the double run; set it below what double precision reaches (e.g. "
                                  "1e-25) to watch it fail (default: %(default)g)",
                   max_iter_help="iteration limit of the double run, and of the exact continuation for the cause "
                                 "'precision' (default: %(default)s)")
    diag.add_argument("--plot", type=out_path, default=None, metavar="FILE", help=PLOT_HELP)
    diag.add_argument("--dps", type=witness_digits, default=40, metavar="D",
                      help="digits of the mpmath witness, at least 34: it checks double-double steps (default: %(default)s)")
    diag.add_argument("--witness-time", type=nonneg_float, default=None, metavar="S",
                      help="seconds the mpmath witness may take (default: 90; 0: no witness)")
    diag.add_argument("--no-remedy", action="store_true", help="try no remedy")
    diag.add_argument("--json", action="store_true", help="print the diagnosis as JSON")
    diag.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    diag.add_argument("--time-limit", type=seconds, default=None, metavar="S",
                      help="stop after S seconds: the double run gets the limit, and each later stage stops at "
                           "its first step past it, keeping what was done (status MaxTime, exit 1)")
    add_load_options(diag)
    diag.set_defaults(func=cmd_diagnose, check_outputs=check_outputs)


def check_outputs(args) -> None:
    """Refuse an unusable --plot before any work."""
    if args.plot is not None:
        from pathlib import Path

        from ..errors import InvalidArgumentError
        from ..io.output import check_output_file

        if Path(args.plot).suffix.lower() not in (".png", ".pdf", ".svg", ".eps", ".ps"):
            raise InvalidArgumentError("--plot", f"{args.plot}: the extension names no format the figure is written in "
                                                 "(PNG, PDF, SVG, EPS or PS)", fix="name the file .png, .pdf, .svg or .eps")
        check_output_file(args.plot, inputs=[args.problem], option="--plot")


COLUMNS = ("columns, per step k (iterate k → k+1): digits of agreement of the double iterate k+1 with the exact step "
           "from iterate k, for v, u, Hr, and r, z where r is unique ('-': not measured); thr: the threshold (the "
           "fewer of the digits the tolerance needs and those the form's conditioning leaves); cond(Qp): the "
           "largest condition number of the NT scaling at iterate k, double and exact; λ2: the smallest spectral "
           "value of z and of s = Jᵀr̃ of iterate k+1, in double (dbl) and exactly (ex); a flag marks a λ2 lost to "
           "rounding; '<' marks the departure")


def _d(x) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.1f}"


def cmd_diagnose(args) -> int:
    from ..compilation import announcing
    from ..verify.diagnosis import WITNESS_SECONDS, diagnose

    problem = load_problem(args)
    with recorded_warnings() as caught:
        limit = {} if args.time_limit is None else {"time_limit": args.time_limit}
        say = progress_printer(args)
        with announcing(say):  # a cold cache's compilation is named as it starts
            diag = diagnose(problem, method=args.method, tol=args.tol, max_iter=args.max_iter, dps=args.dps,
                            progress=say, remedies=not args.no_remedy,
                            witness_time=WITNESS_SECONDS if args.witness_time is None else args.witness_time,
                            **limit)
    if diag.remedy is not None and args.max_asymmetry is not None:  # the remedy loads the file the same way
        diag.remedy["args"] = diag.remedy["args"] + ["--max-asymmetry", f"{args.max_asymmetry:g}"]
    d = diag.to_dict()
    d["numerical_warnings"] = warning_summary(caught)
    if args.plot:
        from ..report.figures import lockstep_figure

        lockstep_figure(d, args.plot, title=str(args.problem))
        d["plot"] = str(args.plot)
    # The exit code is the double run's outcome, so scripts can tell a failing run apart (the
    # diagnosis's own status is MaxTime where the time limit cut a later stage short).
    run = d["evidence"].get("run") or d
    code = EXIT_OK if run["status"] == "Solved" else EXIT_NOT_SOLVED
    if args.json:
        print(dumps(d, indent=2))
        return code
    print(d["conclusion"].replace("PROBLEM", str(args.problem)))
    print(f"double run (as 'rfverify solve --method {d['method']}' runs it): {run['status']} after {d['nit']} iterations: "
          f"{run['message']}")
    lock = d["evidence"].get("lockstep_run")
    if lock:
        print(f"lockstep's run ({lock['how']}): {lock['status']} after {lock['nit']} iterations, criterion "
              f"{lock['criterion']:.2e}")
    for sentence in d["evidence"].get("text", []):
        print(f"  - {sentence}")
    print(COLUMNS)
    head = (f"{'k':>3} {'mu':>8} {'v':>5} {'u':>5} {'Hr':>5} {'r':>5} {'z':>5} {'thr':>5} {'cond(Qp)':>8} "
            f"{'exact':>8} {'λ2(z)dbl':>9} {'λ2(z)ex':>9} {'λ2(s)dbl':>9} {'λ2(s)ex':>9}  flags")
    print(head)
    print("-" * len(head))
    dep = d["evidence"].get("departure")
    for r in d["iterations"]:
        mark = "<" if dep and r["iter"] == dep["iter"] else " "
        print(f"{r['iter']:>3} {r['mu']:>8.1e} {_d(r['digits_v']):>5} {_d(r['digits_u']):>5} {_d(r['digits_Hr']):>5} "
              f"{_d(r['digits_r_t']):>5} {_d(r['digits_z']):>5} {_d(r.get('threshold')):>5} "
              f"{r['max_cond_Qp']:>8.1e} {r.get('max_cond_Qp_exact', float('nan')):>8.1e} "
              f"{r['min_lam2_z']['double']:>9.2e} {r['min_lam2_z']['reference']:>9.2e} "
              f"{r['min_lam2_s']['double']:>9.2e} {r['min_lam2_s']['reference']:>9.2e}{mark} {'; '.join(r['flags'])}")
    if d["failure"]:
        flagged = [r for r in d["iterations"] if r["flags"]]
        first = f"; first flagged iteration {flagged[0]['iter']}: {flagged[0]['flags'][0]}" if flagged else ""
        print(f"failure: {d['failure']}{first}")
    if args.plot:
        print(f"figure written to {args.plot}")
    print_warnings(d["numerical_warnings"], "in the double run")
    return code
