"""``rfverify diagnose``: the double solver and the mpmath reference in lockstep."""

from __future__ import annotations

from ..solver.result import ALGORITHM1_METHODS
from .argtypes import positive_float, positive_int, tolerance
from .common import (EXIT_NOT_SOLVED, EXIT_OK, PROBLEM_HELP, add_load_options, dumps, load_problem,
                     print_warnings, progress_printer, recorded_warnings, warning_summary)

HELP = "run the double solver and the reference in lockstep"

DESCRIPTION = """\
For every iteration of a double-precision run, take the exact step from the double iterate with
the mpmath reference and print the digits of agreement of the next iterate, max cond(Q_p), min
λ2 of z and Jᵀr̃ in double and in the reference (flagging double λ2 that underflowed or went
non-positive while the exact one is positive), and where and why a failed run stopped.

The double run refines every linear solve to 4·eps (solver setting refine_tol=None), not to the
default inexact-Newton stop, and uses the extended arithmetic from the first iteration (setting
extended_below=None), not the default float64 start, so that the digits measure the rounding of
one arithmetic alone."""

EPILOG = """\
Exit codes: 0 the double run was Solved; 1 it was not (MaxIterations, NumericalError, ...) —
the diagnosis is printed either way; 2 bad input or option; 3 internal error."""


def add_parser(sub) -> None:
    """The ``diagnose`` subcommand."""
    diag = sub.add_parser("diagnose", help=HELP, description=DESCRIPTION, epilog=EPILOG)
    diag.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    diag.add_argument("--method", choices=ALGORITHM1_METHODS, default="jqinv",
                      help="linear-system form of the double run (default: %(default)s)")
    diag.add_argument("--tol", type=tolerance, default=1e-10, metavar="T",
                      help="tolerance of the double run; set it below what double precision "
                           "reaches (e.g. 1e-25) to watch it fail (default: %(default)g)")
    diag.add_argument("--max-iter", type=positive_int, default=100, metavar="K",
                      help="iteration limit of the double run (default: %(default)s)")
    diag.add_argument("--dps", type=positive_int, default=40, metavar="D",
                      help="digits of the reference steps (default: %(default)s)")
    diag.add_argument("--json", action="store_true", help="print the diagnosis as JSON")
    diag.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    diag.add_argument("--time-limit", type=positive_float, default=None, metavar="S",
                      help="stop after S seconds: the double run gets the limit, and the lockstep stops at the "
                           "first exact step past it, keeping the steps done (status MaxTime, exit 1)")
    add_load_options(diag)
    diag.set_defaults(func=cmd_diagnose)


COLUMNS = ("columns: digits of agreement of each double iterate with the exact step from the same point, "
           "for v, r~ (the lifted reactions r̃ = P⁻¹r, DESIGN §2) and z (the lifted velocities); cond(Qp): the "
           "largest condition number of the NT scaling; λ2: the smallest spectral value of z and of "
           "s = Jᵀr̃, in double (dbl) and exactly (ref); a flag marks a λ2 lost to rounding")


def cmd_diagnose(args) -> int:
    from ..compilation import announcing
    from ..diagnosis import diagnose

    problem = load_problem(args)
    with recorded_warnings() as caught:
        limit = {} if args.time_limit is None else {"time_limit": args.time_limit}
        say = progress_printer(args)
        with announcing(say):  # a cold cache's compilation is named as it starts
            d = diagnose(problem, method=args.method, tol=args.tol, max_iter=args.max_iter, dps=args.dps,
                         progress=say, **limit).to_dict()
    d["numerical_warnings"] = warning_summary(caught)
    # The exit code is the double run's outcome, so scripts can tell a failing run apart.
    code = EXIT_OK if d["status"] == "Solved" else EXIT_NOT_SOLVED
    if args.json:
        print(dumps(d, indent=2))
        return code
    print(f"double run ({d['method']}): {d['status']} after {d['nit']} iterations: {d['message']}")
    print(COLUMNS)
    head = (f"{'iter':>4} {'mu':>9} {'digits v':>8} {'r~':>5} {'z':>5} {'cond(Qp)':>9} "
            f"{'λ2(z) dbl':>10} {'λ2(z) ref':>10} {'λ2(s) dbl':>10} {'λ2(s) ref':>10}  flags")
    print(head)
    print("-" * len(head))
    for r in d["iterations"]:
        print(f"{r['iter']:>4} {r['mu']:>9.2e} {r['digits_v']:>8.1f} {r['digits_r_t']:>5.1f} "
              f"{r['digits_z']:>5.1f} {r['max_cond_Qp']:>9.1e} {r['min_lam2_z']['double']:>10.2e} "
              f"{r['min_lam2_z']['reference']:>10.2e} {r['min_lam2_s']['double']:>10.2e} "
              f"{r['min_lam2_s']['reference']:>10.2e}  {'; '.join(r['flags'])}")
    if d["failure"]:
        flagged = [r for r in d["iterations"] if r["flags"]]
        first = f"; first flagged iteration {flagged[0]['iter']}: {flagged[0]['flags'][0]}" if flagged else ""
        print(f"failure: {d['failure']}{first}")
    print(d["conclusion"])
    print_warnings(d["numerical_warnings"], "in the double run")
    return code
