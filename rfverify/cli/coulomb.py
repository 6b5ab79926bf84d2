"""``--problem coulomb`` of ``solve``, ``solve --digits`` and ``certify``: the physical problem
(De Saxcé's term kept; :mod:`rfverify.coulomb`), its output and exit codes."""

from __future__ import annotations

import time

from .common import EXIT_NOT_SOLVED, EXIT_OK, dumps, print_quantities

PROBLEM_OPTION_HELP = (
    "which problem to solve or prove: relaxation (default), the convex relaxation of DESIGN §1 (De "
    "Saxcé's term dropped); or coulomb, the physical problem of Coulomb friction and rolling resistance, "
    "u_N + mu|u_T| + mu_r|u_R| in the dual cone, solved as a fixed point of the shift s = mu|u_T| + "
    "mu_r|u_R| in the convex problem with w_N + s (Anderson acceleration over double solves; with "
    "--digits, over proven solves) and certified by a proven backward error: the exact solution it names "
    "solves the physical problem exactly for data whose w_N differs from the file's by delta, with |delta| "
    "bounded rigorously (JSON: \"backward_error\", relative to the data scale of u). Physical solutions "
    "need not be unique. Exit code 0 only when the fixed point is reached to --tol (with --digits / "
    "certify: the digits are proven and the relative backward error is <= 10^-K)")


def add_problem_option(p) -> None:
    """``--problem {relaxation,coulomb}`` (dest ``problem_kind``: the positional PROBLEM is the file)."""
    from ..coulomb import PROBLEMS

    p.add_argument("--problem", dest="problem_kind", choices=PROBLEMS, default="relaxation",
                   help=PROBLEM_OPTION_HELP)


START_OPTION_HELP = (
    "with --problem coulomb: start the fixed point on the shift from the answer in SOL.h5 (an FCLIB "
    "file of this same problem with /solution, e.g. written by Siconos or by 'rfverify solve --out'): "
    "its stored /coulomb/shift if it has one, else mu|u_T| + mu_r|u_R| of its u (default: start from 0, "
    "the relaxation's answer). The physical problem's solutions need not be unique, and from 0 the "
    "iteration can stall where no fixed point is near; the answer is proven all the same, whatever "
    "the start")


def add_start_option(p) -> None:
    """``solve --start SOL.h5`` (dest ``start``)."""
    p.add_argument("--start", metavar="SOL.h5", default=None, help=START_OPTION_HELP)


def start_from_file(args, problem):
    """The first shift of ``solve --problem coulomb --start SOL.h5``: the file's /coulomb/shift,
    else Φ of its u (Hᵀv + w where it stores no u); None without --start.  The file must hold
    this problem and a /solution with v and r (r for a local file)."""
    import numpy as np

    from ..coulomb.model import phi, physical_velocity
    from ..coulomb.storage import read_shift
    from ..errors import ProblemFileError
    from ..io import load, resolve_path
    from .common import require_same_problem

    if args.start is None:
        return None
    other = load(args.start, max_asymmetry=np.inf)
    require_same_problem(problem, other, args.start)
    sol = other.solution
    if sol is None or sol.r is None or (sol.v is None and problem.local is None):
        raise ProblemFileError(args.start, "has no /solution with v and r to start from",
                               fix="pass a solution file of this problem (rfverify solve ... --out SOL.h5)")
    shift = read_shift(resolve_path(args.start), problem.n_contacts)
    if shift is None:
        u = sol.u if sol.u is not None else physical_velocity(problem, sol.v, sol.r)
        shift = phi(problem, u)
    if not (np.all(np.isfinite(shift)) and np.all(shift >= 0)):
        raise ProblemFileError(args.start, "gives a shift with NaN, Inf or negative entries",
                               location="/solution" if sol.u is None else "/coulomb/shift or /solution/u",
                               fix="pass a finite solution of this problem")
    return shift


def _print_outer(out) -> None:
    run = out.outer
    print(f"fixed point ({run.method}{', from the --start shift' if run.started else ''}): residual {run.residual:.1e} of the data scale of u after {run.total_evaluations} "
          f"convex solves ({run.total_inner_iterations} iterations); {run.message}")


def solve_physical(args, problem, options: dict, say, write) -> int:
    """``solve --problem coulomb`` (with or without ``--digits``); ``write(v, u, r, more)`` writes
    --out: /solution and /coulomb/shift (no /certificate: its proof is about the shifted problem;
    ``certify --problem coulomb`` proves the answer again from the file, with that shift)."""
    from ..coulomb import coulomb_to_digits, solve_coulomb

    t0 = time.perf_counter()
    common = dict(method=args.method, tol=args.tol, max_iter=args.max_iter, progress=say,
                  time_limit=args.time_limit, start=start_from_file(args, problem), **options)
    if args.digits is not None:
        out = coulomb_to_digits(problem, digits=args.digits, relative=args.relative, **common)
    else:
        out = solve_coulomb(problem, **common)
    wall = time.perf_counter() - t0
    if args.out:
        from ..coulomb.result import STATEMENT
        from ..coulomb.storage import write_shift

        be = out.backward_error if args.digits is not None else None
        write(out.v, out.u, out.r, lambda fh: write_shift(fh, out.shift, STATEMENT, be))
    if args.json:
        print(dumps({**out.as_dict(), "time": wall, "out": args.out}, indent=2))
    else:
        _print_outer(out)
        if args.digits is not None:
            cert = out.certificate
            print(f"proven rounds: {len(out.rounds)} (the shift updated from each proven answer)")
            print(f"status {out.status}: {cert.verdict}")
            print_quantities(cert)
            print(f"  {cert.backward.describe()}")
        else:
            print(f"status {out.status}: {out.message}")
            res = out.residuals
            print(f"physical conditions (long double, of the data scale of u): fixed point {res.fixed_point:.1e}, "
                  f"u_N >= 0 violated by {res.normal:.1e}, cone {res.cone:.1e}, complementarity r'u~ "
                  f"{res.complementarity:.1e}")
        print(f"time {wall:.2f} s" + (f"; solution and shift written to {args.out} (recheck them with "
                                      f"'rfverify certify PROBLEM --solution {args.out} --problem coulomb')"
                                      if args.out else ""))
    return EXIT_OK if out.success else EXIT_NOT_SOLVED


def certify_physical(args, problem, sol, say, where=None) -> int:
    """``certify --problem coulomb``: a backward-error certificate of the stored (v, u, r), with
    the shift stored beside it in ``where`` (an .hdf5 file) if any, else ŝ = Φ(u)."""
    from ..coulomb import certify_coulomb
    from ..errors import InvalidArgumentError

    if args.cross_check or args.out:
        raise InvalidArgumentError("--cross-check" if args.cross_check else "--out",
                                   "is for the convex relaxation only (the reference and the certificate file "
                                   "prove that problem)", fix="drop it, or drop --problem coulomb")
    shift = None
    if where is not None:
        from ..coulomb.storage import read_shift
        from ..io import resolve_path

        shift = read_shift(resolve_path(where), problem.n_contacts)
    cert = certify_coulomb(problem, sol.v, sol.u, sol.r, digits=args.digits, relative=args.relative, progress=say,
                           time_limit=args.time_limit, shift=shift)
    if args.json:
        print(dumps(cert.as_dict(), indent=2))
    else:
        print(cert.verdict)
        print_quantities(cert)
        print(f"  {cert.backward.describe()}")
        print(f"shift: {'stored in ' + str(where) if shift is not None else 'Φ(u) of the solution'}; "
              f"time {cert.seconds:.2f} s")
    return EXIT_OK if cert.certified else EXIT_NOT_SOLVED
