"""``rfverify info``: describe a problem (sizes, coefficients, M asymmetry, stored solution)."""

from __future__ import annotations

from .argtypes import tolerance
from .common import (exit_codes, EXIT_OK, PROBLEM_HELP, add_load_options, dumps, load_problem, print_warnings,
                     recorded_warnings, warning_summary)

HELP = "describe a problem: sizes, coefficients, M asymmetry, stored solution"

DESCRIPTION = """\
Load and validate a problem, then report its sizes (m dofs, n contacts, nnz), the ranges of mu
and mu_r and how many contacts have mu = 0 or mu_r = 0, the asymmetry of M (entrywise, the
measure --max-asymmetry limits, and normwise) and what was symmetrised for solving, the block
structure of M, the storage formats, and an independent check of the stored /solution (never
trusted). For a 3-D FCLIB file (/fclib_global, /fclib_local) it also says how it was read:
convex relaxation, mu_r = 0 in the rolling layout, a local problem lifted (rank, dropped
eigenvalues)."""


def add_parser(sub) -> None:
    """The ``info`` subcommand."""
    info = sub.add_parser("info", help=HELP, description=DESCRIPTION,
                          epilog=exit_codes("the problem was read (warnings about optional metadata included)"))
    info.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    info.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    info.add_argument("--quiet", action="store_true",
                      help="accepted by every command; info prints no progress lines anyway (its result is stdout)")
    add_load_options(info)
    info.add_argument("--solution-tol", type=tolerance, default=1e-6, metavar="TOL",
                      help="relative residual up to which a stored solution is called "
                           "consistent (default: %(default)g)")
    info.set_defaults(func=cmd_info)


def cmd_info(args) -> int:
    from ..model.summary import format_summary, problem_summary

    problem = load_problem(args)
    with recorded_warnings() as caught:
        summary = problem_summary(problem, solution_tol=args.solution_tol,
                                  max_asymmetry=args.max_asymmetry)
    if caught:
        summary["numerical_warnings"] = warning_summary(caught)
    _physical_solution(problem, summary, args.solution_tol)
    if args.json:
        print(dumps(summary, indent=2))
    else:
        print(format_summary(summary))
        print_warnings(summary.get("numerical_warnings"), "while describing the problem")
    return EXIT_OK


def _physical_solution(problem, summary: dict, tol: float) -> None:
    """A /solution written by ``solve --problem coulomb --out`` answers the physical problem (the
    /coulomb shift beside it says so): it is checked as such, not as the relaxation's answer."""
    if problem.solution is None or not str(problem.source).lower().endswith((".h5", ".hdf5")):
        return
    from ..coulomb.model import check_physical_solution
    from ..coulomb.storage import read_shift
    from ..io import resolve_path

    shift = read_shift(resolve_path(problem.source), problem.n_contacts)
    if shift is not None:
        summary["solution"] = check_physical_solution(problem, problem.solution, shift, tol)
