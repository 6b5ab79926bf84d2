"""``rfverify solve``: Algorithm 1 (or the Clarabel peer), and with ``--digits`` the proven
k-digit path; ``--out`` writes the solution (and certificate) through :mod:`rfverify.io`."""

from __future__ import annotations

import numpy as np

from ..solver import attempt_words
from ..solver.result import AUTO_SCHUR_MIN_CONTACTS, AUTO_SCHUR_MIN_FILL, METHODS, PEER_METHODS, SIGMA_RULES
from .coulomb import add_problem_option, add_start_option, solve_physical
from .argtypes import digit_count, out_path, seconds
from .common import (DOCS_NOTE, EXIT_NOT_SOLVED, EXIT_OK, PROBLEM_HELP, PROGRESS_AFTER, PROGRESS_AFTER_ENV,
                     IterationProgress, add_run_limits, dumps, end_problem_command, exit_codes, is_hdf5_input,
                     load_problem, print_quantities, print_warnings, progress_after, progress_printer,
                     recorded_warnings, warning_summary)

HELP = "solve a problem with Algorithm 1 (or the Clarabel peer)"

DESCRIPTION = """\
Solve the convex relaxation of a rolling-friction problem with the mixed-precision
interior-point method (Algorithm 1, DESIGN §4). Exit code 0 only when the criterion
(DESIGN §4.5: residuals of the returned v, u, r scaled by their terms and by the data)
is <= --tol; 1 when the solver stopped without reaching it (the status says why). The paper's
pinfeas, dinfeas and mu are printed beside it. A 3-D FCLIB file (/fclib_global, /fclib_local)
is solved as its convex relaxation, exactly the rolling problem with mu_r = 0 and no rolling
rows (DESIGN §7.2); a local problem (/fclib_local, Siconos local .dat) through its lifting to
global form, its answer judged and proven on its own W. --problem coulomb solves the physical
problem instead (De Saxcé's term kept; see --problem)."""


def add_parser(sub) -> None:
    """The ``solve`` subcommand."""
    sol = sub.add_parser("solve", help=HELP, description=DESCRIPTION,
                         epilog=exit_codes("Solved (with --digits: certified)",
                                           "not Solved (with --digits: not certified), the status says why")
                         + " " + DOCS_NOTE)
    sol.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    sol.add_argument("--method", choices=METHODS, default="auto",
                     help="linear-system form: jqinv (14), qp2 (11), reduced (15), "
                          "reduced_factored (16), noscaling (6), schur ((16) reduced to the dofs and "
                          "factored by CHOLMOD's supernodal Cholesky (cvxopt, installed with rfverify); "
                          "fastest where the factorisation fills in: large piles, "
                          "beds, random problems); auto, jqinv then reduced then noscaling until one "
                          "is Solved, or, on a problem of at least "
                          f"{AUTO_SCHUR_MIN_CONTACTS} contacts whose factor costs at least "
                          f"{AUTO_SCHUR_MIN_FILL:g} per contact (rfverify.solver.body_fill), schur then "
                          "jqinv then noscaling; after every form stalled, jqinv with --sigma-rule paper "
                          "unless --sigma-rule is given, its answer returned only if Solved (the 'method' "
                          "line of the output names the form that ran, why "
                          "auto took it first and what it tried before); or clarabel, the same problem handed to Clarabel; or siconos, "
                          "Siconos's GRFC3D_IPM, the paper's own solver, in a child process (needs a build: "
                          "bash benchmarks/peers/siconos/build.sh, then RFVERIFY_SICONOS=<its prefix>) "
                          "(default: %(default)s)")
    add_run_limits(sol, tol_help="stop when the criterion of DESIGN §4.5 is <= T (default: %(default)g)",
                   max_iter_help="iteration limit (default: %(default)s)")
    sol.add_argument("--out", metavar="SOL.h5", type=out_path,
                     help="write the problem data plus /solution/{v,u,r} (FCLIB layout) here, in "
                          "the input's own layout (3-D /fclib_global: 3 per contact; /fclib_local: "
                          "u and r only); naming the input .hdf5 file itself replaces only its "
                          "/solution (and /certificate with --digits) and "
                          "keeps everything else in it")
    sol.add_argument("--json", action="store_true",
                     help="print status, iterations, time and final residuals as JSON (with the trace and "
                          "steps_held: each step a cone cut short, with its contact, part and side; with "
                          "--digits, the certificate and its extended_steps_held)")
    sol.add_argument("--quiet", action="store_true",
                     help="no progress lines on stderr (otherwise: a numba compilation as it starts; once a run "
                          f"has taken {PROGRESS_AFTER:g} s ({PROGRESS_AFTER_ENV}=S sets another threshold), its "
                          "iterations, at most two lines a second, with the form, mu, the criterion and the "
                          "step that led to the iterate, with the contact whose cone cut it short (--verbose "
                          "prints every one on stdout instead); with --digits, one line per stage and extended "
                          "iteration too, with the step that led to it and the contact whose cone cut it "
                          "short); --json also has none")
    sol.add_argument("--verbose", action="store_true",
                     help="print a settings header and each iteration as it happens (every independent "
                          "component, labelled; the last column names the cone that cut the row's step short); "
                          "with --method clarabel, Clarabel's own log")
    sol.add_argument("--time-limit", type=seconds, default=None, metavar="S",
                     help="stop after S seconds with the best iterate (status MaxTime, exit 1); with --digits "
                          "the whole path stops there (each extended iteration checks it, and a long double-double "
                          "factorisation is stopped, or not started where it cannot end in time) and the best "
                          "proof reached is the result, written with --out")
    sol.add_argument("--digits", type=digit_count, default=None, metavar="K",
                     help="produce a solution proven right to K significant digits (1-15): the "
                          "double solve, then Algorithm 1 continued in double-double (and, if that "
                          "stalls short of a proof on a problem whose sparse factor costs at most 2e7 "
                          "operations, in 320-bit arithmetic) until the "
                          "rigorous error bound of DESIGN §6 proves K digits of v, u and Hr "
                          "(and r where it is unique); exit code 0 only when proven. With --out the "
                          "file also gets /certificate (the point and the bound, to recheck with "
                          "'rfverify certify'). The double-double phase uses every CPU available (and "
                          "with two or more is set up beside the double solve); RFVERIFY_THREADS=N "
                          "sets how many (the answer is the same bit for bit)")
    sol.add_argument("--relative", action="store_true",
                     help="with --digits: demand K relative (significant) digits of every quantity; a "
                          "quantity whose exact value may be zero is then not certified, instead of being "
                          "proven zero within 10^-K of its data scale (DESIGN §6.3)")
    sol.add_argument("--sigma-rule", choices=SIGMA_RULES, default=None,
                     help="Algorithm 1's centring rule: hybrid (Mehrotra's cubic sigma, floored at 0.2 while the "
                          "criterion is above 1e-4, then the paper's; the default), paper (the paper's rule, as the "
                          "double solve of --digits runs it) or siconos (GRFC3D_IPM's); 'rfverify diagnose' "
                          "offers paper as a remedy where a stalled run needs it")
    sol.add_argument("--no-presolve", action="store_true",
                     help="switch off the presolve reductions (cone reduction for mu = 0 / "
                          "mu_r = 0 requires them; such problems are refused)")
    add_problem_option(sol)
    add_start_option(sol)
    end_problem_command(sol, cmd_solve, check_outputs)


def check_outputs(args) -> None:
    """Refuse an unusable --out before any work; FCLIB keeps /solution beside the problem, so
    naming the input .hdf5 file itself is allowed."""
    from ..io.output import check_output_file

    if args.out is not None:
        args.out_target = check_output_file(args.out, inputs=[args.problem, getattr(args, "start", None)],
                                            in_place_ok=is_hdf5_input(args.problem))


def _refuse_ignored_flags(args) -> None:
    """Flags that would do nothing in this combination are refused, not silently ignored."""
    from ..errors import InvalidArgumentError

    if args.relative and args.digits is None:
        raise InvalidArgumentError("--relative", "applies to the digits --digits K proves; without --digits nothing "
                                                 "is proven", fix="add --digits K, or drop --relative")
    if args.verbose and args.json:
        raise InvalidArgumentError("--verbose", "prints the iteration table on stdout, where --json writes its JSON",
                                   fix="drop --verbose (the JSON's trace holds every iteration) or --json")


def cmd_solve(args) -> int:
    import time

    from ..compilation import announcing
    from ..solver import solve

    t_start = time.perf_counter()
    after = progress_after()  # a bad RFVERIFY_PROGRESS_AFTER is refused before any work
    _refuse_ignored_flags(args)
    problem = load_problem(args)
    options = {}
    if args.no_presolve:
        options.update(reduce_cones=False, drop_free_bodies=False, split_components=False)
        for name, coefficient in (("mu", problem.mu), ("mu_r", problem.mu_r)):
            if np.any(coefficient == 0):  # the field that holds the zeros is the one named
                from ..errors import InvalidProblemError

                raise InvalidProblemError(name, f"has zero coefficients ({int(np.sum(coefficient == 0))} contacts), "
                                                "which the unreduced lifting would divide by", fix="drop --no-presolve")
    if args.sigma_rule is not None:
        if args.method in PEER_METHODS:
            from ..errors import InvalidArgumentError

            raise InvalidArgumentError("--sigma-rule", f"is Algorithm 1's centring rule; --method {args.method} runs its "
                                                       "own", fix="drop --sigma-rule, or use an Algorithm 1 method")
        options["sigma_rule"] = args.sigma_rule
    say = progress_printer(args)
    if args.start is not None and args.problem_kind != "coulomb":
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("--start", "is for the physical problem only (the relaxation's solver has no "
                                              "warm start)", fix="add --problem coulomb, or drop --start")
    if args.problem_kind == "coulomb":
        return solve_physical(args, problem, options, say,
                              lambda v, u, r, more: _write_solution_file(args, problem, v, u, r, more=more))
    if args.digits is not None:
        return _solve_digits(args, problem, options, say, after, t_start)
    t0 = time.perf_counter()
    # --verbose: the solver prints its header and each iteration as it happens (Clarabel its own log).
    options["verbose"] = bool(args.verbose and not args.json)
    if args.time_limit is not None:
        options["time_limit"] = args.time_limit
    # Progress: the iterations once the run is long (Algorithm 1), a line if a peer is (it reports
    # none); --verbose prints every iteration already.
    peer = args.method in PEER_METHODS
    show = None if options["verbose"] else say
    callback = None if show is None or peer else IterationProgress(show, after, t_start)
    with recorded_warnings() as caught, announcing(say), _peer_notice(show if peer else None, args.method,
                                                                      after - (t0 - t_start)):
        result = solve(problem, method=args.method, tol=args.tol, max_iter=args.max_iter, callback=callback,
                       **options)
    wall = time.perf_counter() - t0
    if args.out:
        _write_solution_file(args, problem, result.v, result.u, result.r)
    summary = {
        "status": str(result.status), "success": result.success, "message": result.message,
        "problem": problem.statement, "equations": problem.equations,
        "method": result.method, "requested_method": args.method,
        "attempts": result.extras.get("attempts", []), "iterations": result.nit, "time": wall, "tol": args.tol,
        "criterion": result.criterion,
        "measures": result.measures.as_dict() if result.measures is not None else None,
        "pinfeas": result.pinfeas, "dinfeas": result.dinfeas, "mu": result.mu,
        "presolve": result.presolve, "out": args.out,
        "numerical_warnings": warning_summary(caught),
        "timings": result.timings,
        "steps_held": result.steps_held,
        "trace": {k: np.asarray(v).tolist() for k, v in result.trace.items()},
        "component_traces": [{"status": str(c["status"]), "message": c["message"], "nit": c["nit"],
                              "trace": {k: np.asarray(v).tolist() for k, v in c["trace"].items()}}
                             for c in result.extras.get("component_runs", [])],
    }
    if args.json:
        print(dumps(summary, indent=2))
    else:
        hint = result.extras.get("hint")
        if hint:  # the reason first, the solver's own account after it
            print(f"status {result.status}: {hint}")
            print(f"  solver: {result.message[:-len(hint) - 2]}")
        else:
            print(f"status {result.status}: {result.message}")
        print(method_line(result, args.method))
        if problem.statement != "the convex relaxation":
            print(f"problem: {problem.statement}{_stored_hint(problem)}")
        m = result.measures
        if m is not None:
            print(f"criterion {m.max:.2e} (dynamics {m.dynamics:.1e}, velocity {m.velocity:.1e}, cone "
                  f"{m.cone:.1e}, complementarity {m.complementarity:.1e}; rfverify.model.measures)")
        compiled = result.timings.get("compile", 0.0)
        compiled = f" (compiling kernels {compiled:.2f} s)" if compiled >= 0.005 else ""
        print(f"iterations {result.nit}, time {wall:.3f} s{compiled}; the paper's measures: pinfeas "
              f"{result.pinfeas:.2e}, dinfeas {result.dinfeas:.2e}, mu {result.mu:.2e}")
        if args.out:
            print(f"solution written to {args.out}")
        print_warnings(summary["numerical_warnings"], "during the solve (the status above is "
                        "judged by the recomputed criterion, not by these)")
    if result.extras.get("interrupted"):
        return _interrupted("the best iterate so far is reported above" + (f" and written to {args.out}" if args.out else ""))
    return EXIT_OK if result.success else EXIT_NOT_SOLVED


def method_line(result, requested: str) -> str:
    """The text output's account of what ran: the form (or peer) that returned the answer and,
    under ``auto``, why that form came first and what ran before it."""
    if requested != "auto":
        return f"method {result.method} (as requested)"
    auto = result.extras.get("auto")
    if auto is None:  # nothing iterated (f = 0 and w = 0)
        return f"method {result.method} (auto: no iteration needed)"
    forms, attempts = auto["forms"], result.extras.get("attempts") or []
    head = f"method {result.method} (auto: {forms[0]} first, as {auto['why']}"
    if len(attempts) <= 1:
        rest = list(forms[1:]) + ([auto["last_resort"]] if auto.get("last_resort") else [])
        return head + (f"; next {', then '.join(rest)}, had it stalled)" if rest else ")")
    tried = ", then ".join(f"{attempt_words(a)} {a['status']} at criterion {a['criterion']:.1e} after {a['nit']} "
                           f"iterations ({a['seconds']:.2f} s)" for a in attempts)
    chosen = "" if result.success else f"; {result.method}'s answer has the smallest criterion"
    return f"{head}; {tried}{chosen})"


class _peer_notice:
    """While a peer solver runs (it reports no iterations to rfverify): one line through ``say``
    if it is still running ``after`` seconds from now."""

    def __init__(self, say, method: str, after: float):
        self.say, self.method, self.after, self.timer = say, method, max(after, 0.0), None

    def __enter__(self):
        import threading

        if self.say is not None and self.after <= 0:
            self.say(self._message())
        elif self.say is not None:
            self.timer = threading.Timer(self.after, lambda: self.say(self._message()))
            self.timer.daemon = True
            self.timer.start()
        return self

    def _message(self) -> str:
        return (f"{self.method} is running (a peer solver: it reports no iterations to rfverify; --verbose shows "
                "its own log)")

    def __exit__(self, *exc):
        if self.timer is not None:
            self.timer.cancel()
        return False


def _stored_hint(problem) -> str:
    """Where the stored M (W of a local file) is unsymmetric and the symmetrised equations were
    solved: how to solve the stored ones."""
    if problem.matrix_is_symmetric or problem.equations == "stored":
        return ""
    X = "W" if problem.local is not None else "M"
    return f" ({X} as stored is unsymmetric and its equations have another solution: --as-stored solves them)"


def _solve_digits(args, problem, options, say, after, t_start) -> int:
    import time

    from ..compilation import announcing
    from ..verify.digits import solve_to_digits

    t0 = time.perf_counter()
    callback = None if say is None or args.method in PEER_METHODS else IterationProgress(say, after, t_start)
    with announcing(say):  # a cold cache's compilation is named as it starts
        out = solve_to_digits(problem, digits=args.digits, method=args.method, tol=args.tol,
                              max_iter=args.max_iter, relative=args.relative, progress=say,
                              time_limit=args.time_limit, callback=callback, **options)
    wall = time.perf_counter() - t0
    cert = out.certificate
    if args.out:
        _write_solution_file(args, problem, out.v, out.u, out.r, certificate=cert)
    summary = {**out.as_dict(), "problem": problem.statement, "equations": problem.equations,
               "time": wall, "out": args.out}
    if args.json:
        print(dumps(summary, indent=2))
    else:
        tail = "" if out.wide is None else f"; multiple-precision ({out.wide.bits} bits) iterations: {out.wide.nit}"
        face = cert.extra.get("face")
        if face:  # a self-stress: the problem was solved again on its face (DESIGN §6.8)
            tail += f"; on the face of {len(face['self_stresses'])} self-stress(es): {face.get('reduction', '')}"
        at = cert.extra.get("proven_at") or {}
        if at.get("predicted"):  # the count alone would suggest the proof was at iteration k itself
            tail += f"; the proof's point: {at['where']}"
        chosen = "as requested" if args.method != "auto" else "by auto"
        if out.double.extras.get("zero_data"):
            print("double solve: none needed (f = 0 and w = 0: v = u = r = 0 exactly)")
        else:
            print(f"double solve ({out.double.method} {chosen}): {out.double.status} in {out.double.nit} iterations; "
                  f"extended (double-double) iterations: {out.extended.nit}{tail}")
        print(cert.verdict)
        print_quantities(cert)
        repaired = getattr(cert.proof, "face", None) if cert.proof is not None else None
        if repaired is not None:  # the proof's point was moved onto a self-stress's face
            print(f"  self-stress: {'; '.join(s.describe() for s in repaired.stresses)} (DESIGN §6.8)")
        t = out.timings
        wide_time = f", multiple precision {t['wide']:.2f}" if out.wide is not None else ""
        wide_time += f", on the face {t['face']:.2f}" if t.get("face") else ""
        wide_time += f", the first start (stalled) {t['first_start']:.2f}" if t.get("first_start") else ""
        # numba compiling the kernels (a cold start: first run on a machine) has its own entry
        compile_time = f"compiling kernels {t['compile']:.2f}, " if t.get("compile", 0.0) >= 0.005 else ""
        factored = getattr(out.extended, "factorisation", "")
        factored = f" [{factored}]" if factored else ""
        print(f"time {wall:.2f} s ({compile_time}double {t['double']:.2f}, extended {t['setup'] + t['extended']:.2f}{factored}"
              f"{wide_time}, proof {t['proof']:.2f})"
              + (f"; solution and certificate written to {args.out}" if args.out else ""))
        if out.success and args.digits < 10:
            print(f"note: the path stops at the first point that proves {args.digits} digits, so the digits above "
                  f"are that point's; a larger --digits iterates further and proves more")
    if out.interrupted:
        return _interrupted("the best proof so far is reported above" + (f" and written to {args.out}" if args.out else ""))
    return EXIT_OK if out.success else EXIT_NOT_SOLVED


def _interrupted(what: str) -> int:
    """Ctrl-C ended the solve after it had something to show: one line on stderr, exit 130."""
    import sys

    print(f"rfverify solve: interrupted ({what})", file=sys.stderr)
    return 130


def _write_solution_file(args, problem, v, u, r, certificate=None, more=None) -> None:
    """``solve --out``: the problem plus /solution, or only /solution written into the input
    .hdf5 file itself when --out names it (everything else in that file is kept); ``more(fh)``
    writes further groups in the same atomic write (``--problem coulomb``: /coulomb)."""
    from ..io import save, write_solution_in_place
    from ..io.output import check_output_file
    from ..model.problem import StoredSolution

    target = getattr(args, "out_target", None) or check_output_file(
        args.out, inputs=[args.problem, getattr(args, "start", None)], in_place_ok=is_hdf5_input(args.problem))
    solution = StoredSolution(v=v, u=u, r=r)
    extra = None
    if certificate is not None:
        from ..io.certificate import write_certificate

        def extra(fh):
            write_certificate(fh, certificate, problem)
    if more is not None:
        extra = more
    if target.in_place:  # the file's own layout (3 per contact for 3-D files), see io/fclib3d.py
        write_solution_in_place(target, problem.with_solution(solution).solution, extra=extra,
                                problem=problem)
    else:
        save(problem.with_solution(solution), target, extra=extra)
