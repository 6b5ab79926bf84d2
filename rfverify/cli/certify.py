"""``rfverify certify``: prove how many digits of a stored solution are right."""

from __future__ import annotations

import numpy as np

from .coulomb import add_problem_option, certify_physical
from .argtypes import digit_count, out_path, seconds, witness_digits
from .common import (DOCS_NOTE, EXIT_NOT_SOLVED, EXIT_OK, PROBLEM_HELP, dumps, end_problem_command, exit_codes,
                     is_hdf5_input, load_problem, print_quantities, progress_printer, require_same_problem,
                     same_problem)

HELP = "prove how many digits of a solution are right (a rigorous error bound)"

DESCRIPTION = """\
Prove a lower bound on the correct significant digits of a solution (v, u, r) of the convex
relaxation (DESIGN §6): an extended-precision point near the solution set (stored in
the solution file by 'solve --digits --out', or computed by a double solve and double-double
iterations, continued in 320-bit arithmetic where double-double stalls) is evaluated in exact
arithmetic, and the bound ||v - v*||_Ms <= (sqrt(g'Ms^-1 g) + sqrt(g'Ms^-1 g + 4 r'u))/2 is
carried to the solution. The verdict names the problem it proves (with (M + Mᵀ)/2 unless
--as-stored). A /certificate already in the solution file is checked against the /solution it
holds and the problem it is read with (its digests of both) and the output says whether it is
about them. Exit code 0 only when --digits are proven. --problem coulomb proves a backward-error
certificate of the physical problem instead (see --problem)."""


def add_parser(sub) -> None:
    """The ``certify`` subcommand."""
    cert = sub.add_parser("certify", help=HELP, description=DESCRIPTION,
                          epilog=exit_codes("--digits are proven", "they are not (the verdict says which quantity and why)")
                          + " " + DOCS_NOTE)
    cert.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    cert.add_argument("--solution", metavar="SOL.h5",
                      help="FCLIB file whose /solution/{v,u,r} is certified (default: the "
                           "problem file's own /solution); its /certificate/point is used when present")
    cert.add_argument("--digits", type=digit_count, default=10, metavar="K",
                      help="digits to prove, 1-15 (default: %(default)s)")
    cert.add_argument("--cross-check", action="store_true",
                      help="also run the independent mpmath reference and report the digits of "
                           "agreement (a second opinion; slow beyond a few hundred contacts)")
    cert.add_argument("--dps", type=witness_digits, default=None, metavar="D",
                      help="accuracy of the --cross-check reference in decimal digits, at least 34: a reference "
                           "must be far more accurate than the float64 answer it measures (default: 50)")
    cert.add_argument("--relative", action="store_true",
                      help="demand K relative (significant) digits of every quantity; a quantity whose exact "
                           "value may be zero is then not certified, instead of being proven zero within "
                           "10^-K of its data scale (DESIGN §6.3)")
    cert.add_argument("--json", action="store_true", help="print the certificate as JSON")
    cert.add_argument("--out", metavar="CERT.h5", type=out_path,
                      help="write the problem, the given solution and /certificate (the point, "
                           "exactly and as decimal strings, the bound and every intermediate norm)")
    cert.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    cert.add_argument("--time-limit", type=seconds, default=None, metavar="S",
                      help="stop the search for a proof point after S seconds and report the best proof "
                           "reached (status MaxTime when short of --digits, exit 1)")
    add_problem_option(cert)
    end_problem_command(cert, cmd_certify, check_outputs)


def check_outputs(args) -> None:
    """Refuse an unusable --out (an input of the command, ...) before any work."""
    from ..errors import InvalidArgumentError
    from ..io.output import check_output_file

    if args.dps is not None and not args.cross_check:  # refused, not silently ignored
        raise InvalidArgumentError("--dps", "sets the accuracy of the --cross-check reference, which is not run",
                                   fix="add --cross-check, or drop --dps")
    if args.dps is None:
        args.dps = 50
    if args.out is not None:
        args.out_target = check_output_file(args.out, inputs=[args.problem, args.solution])


def cmd_certify(args) -> int:
    from ..compilation import announcing
    from ..errors import ProblemFileError
    from ..io import load
    from ..io.certificate import read_point, read_stored_certificate
    from ..verify.certification import certify

    problem = load_problem(args)
    point = stored = None
    if args.solution:
        other = load(args.solution, max_asymmetry=np.inf)
        sol = other.solution
        if "psd_shift" in problem.provenance and not same_problem(problem, other):
            # an FCLIB local file's solution file holds the file's W (its v is W's lifting's); a
            # .dat file's holds the lifting of W + D itself, the case above
            from ..proof.psd_shift import relifted

            require_same_problem(load(args.problem, max_asymmetry=np.inf), other, args.solution)
            sol = relifted(sol, problem.H)
        else:
            require_same_problem(problem, other, args.solution)
        where = args.solution
        point = read_point(_resolve(args.solution))
        stored = read_stored_certificate(_resolve(args.solution), problem)
    else:
        sol, where = problem.solution, args.problem
        if is_hdf5_input(args.problem):
            point = read_point(_resolve(args.problem))
            stored = read_stored_certificate(_resolve(args.problem), problem)
    # A 3-D file's /solution (3 per contact; local: u and r, v = H r) is read into the rolling
    # layout by load(), so it is certified like any other.
    if sol is None or sol.v is None or sol.r is None:
        need = "r" if problem.provenance.get("format") == "fclib_local" else "v and r"
        raise ProblemFileError(where, f"has no /solution with {need} to certify",
                               fix="pass --solution SOL.h5 (written by rfverify solve --out)")
    if point is not None and (point.v_hi.size != problem.n_dofs or point.r_hi.size != 5 * problem.n_contacts):
        raise ProblemFileError(where, "/certificate/point does not match the problem's sizes",
                               location="/certificate/point", fix="certify the solution file written for this problem")
    say = progress_printer(args)
    if args.problem_kind == "coulomb":  # the stored point is the relaxation's: not used
        with announcing(say):
            return certify_physical(args, problem, sol, say,
                                    where if args.solution or is_hdf5_input(args.problem) else None)
    with announcing(say):  # a cold cache's compilation is named as it starts
        cert = _certify_with(problem, sol, args, point, say)
    u = sol.u if sol.u is not None else _velocity(problem, sol)
    if args.out:
        _write_certificate(args, problem, sol, u, cert)
    stored_note = _stored_certificate_note(stored, where, problem)
    coulomb_note = None
    if args.solution or is_hdf5_input(args.problem):
        from ..coulomb.storage import read_shift

        if read_shift(_resolve(args.solution or args.problem), problem.n_contacts) is not None:
            # the De Saxcé shift stored beside it: an answer to the physical problem, judged here as the relaxation's
            coulomb_note = (f"note: {where} holds an answer to the physical problem (/coulomb/shift beside it); this "
                            "is about the convex relaxation: certify it with --problem coulomb")
    if args.json:
        print(dumps({**cert.as_dict(), "stored_certificate": None if stored is None else
                     {**stored, "note": stored_note}, **({"note": coulomb_note} if coulomb_note else {})}, indent=2))
    else:
        print(cert.verdict)
        print_quantities(cert)
        for note in (stored_note, coulomb_note):
            if note:
                print(note)
        src = cert.extra.get("point_source")
        print(f"point: {'stored in ' + where if src == 'given' else 'computed (' + str(src) + ')'}; "
              f"time {cert.seconds:.2f} s")
        if cert.cross_check is not None:
            cc = cert.cross_check
            shown = ", ".join(f"{k[7:]} {v:.1f}" for k, v in cc.items() if k.startswith("digits_") and v is not None)
            said = f"agreement {shown}" if shown else cc.get("note", "no agreement to report")
            print(f"cross-check against the mpmath reference ({cc.get('reference_status')}): {said}")
    return EXIT_OK if cert.certified else EXIT_NOT_SOLVED


def _stored_certificate_note(stored: dict | None, where, problem) -> str:
    """One line on the /certificate the file already held: whether it is about the problem being
    certified and the /solution the file holds (its digests), and what it claimed."""
    if stored is None:
        return ""
    claim = stored.get("verdict") or "(no verdict)"
    head = f"stored certificate in {where}:"
    recomputed = "the verdict above is the one that does (its point was used only as a proof point)"
    if stored.get("matches_problem") is False:
        data = "W, q, mu, mu_r" if problem.local is not None else "M, H, f, w, mu, mu_r"
        local = ""
        if str(stored.get("theorem") or "").startswith("Local problem") and problem.local is None:
            local = (" (it proves a local problem u = W r + q, such as the .dat file this one was written from, and "
                     "this file holds its global lifting: certify that file with --solution to check the claim)")
        return (f"{head} about ANOTHER problem (written for other data: the digest of the problem's {data} "
                f"differs){local}: its claim does not hold for this problem; {recomputed}")
    if stored["matches_solution"] is False:
        return (f"{head} NOT about this /solution (it was written for another one; digest differs): its claim "
                f"does not hold for the solution now stored; {recomputed}")
    if stored["matches_solution"] is None:
        return (f"{head} written before certificates recorded their solution's digest, so it may be about another "
                f"problem or solution; the verdict above is recomputed for this one")
    if stored.get("digest_kind") != "problem and solution":
        kind = ("of the old kind: it covers only the /solution, not the problem's data" if
                stored.get("digest_kind") == "solution only" else
                f"of a kind this rfverify does not know ({stored.get('digest_kind')})")
        return (f"{head} its digest is {kind}; the /solution matches it, but whether the certificate was written "
                f"for this problem cannot be told; the verdict above is recomputed for this problem (it claimed: "
                f"{claim})")
    return f"{head} about this problem and this /solution (both digests match); it claimed: {claim}"


def _velocity(problem, sol):
    """u of a stored (v, r) when the file has none: W r + q (local problem) or Hᵀv + w."""
    from ..verify.certification import local_velocity

    return local_velocity(problem, sol.r) if problem.local is not None else problem.H.T @ sol.v + problem.w


def _resolve(spec):
    from ..io import resolve_path

    return resolve_path(spec)


def _certify_with(problem, sol, args, point, say):
    """The certificate of ``sol``: with the file's stored point, and where that proves less than
    asked (a certificate copied from another problem, a solution changed since), also with a
    point of its own (the candidate, then a computed one); the better proof is kept."""
    import time

    from ..verify.certificate import cut_short
    from ..verify.driver import ProofDriver
    from ..verify.certification import certify

    t0 = time.perf_counter()
    common = dict(digits=args.digits, cross_check=args.cross_check, dps=args.dps, relative=args.relative,
                  progress=say)
    cert = certify(problem, sol.v, sol.u, sol.r, point=point, time_limit=args.time_limit, **common)
    if point is None or cert.certified or cert.proof is None:
        return cert
    left = None if args.time_limit is None else args.time_limit - (time.perf_counter() - t0)
    if left is not None and left <= 0:
        return cut_short(cert, args.time_limit)
    (say or (lambda message: None))(f"the stored point {'proves' if cert.proof.valid else 'gives'} "
                                    f"{cert.proof.summary()}; now a point of its own")
    own = certify(problem, sol.v, sol.u, sol.r, time_limit=left, **common)
    if own.proof is not None and ProofDriver.score(own.proof) > ProofDriver.score(cert.proof):
        return own
    return cut_short(cert, args.time_limit) if own.status == "MaxTime" else cert


def _write_certificate(args, problem, sol, u, cert):
    """``certify --out``: the problem, the certified solution and /certificate."""
    from ..io import save
    from ..io.certificate import write_certificate
    from ..io.output import check_output_file
    from ..model.problem import StoredSolution

    target = getattr(args, "out_target", None) or check_output_file(args.out, inputs=[args.problem, args.solution])
    save(problem.with_solution(StoredSolution(v=sol.v, u=u, r=sol.r)), target,
         extra=lambda fh: write_certificate(fh, cert, problem))
