"""Command-line interface: ``rfverify <command> ...``.

Exit codes: 0 success; 1 a solve that did not reach its tolerance; 2 bad input (unreadable or invalid problem, bad arguments) with a
one-line message on stderr; 3 an internal error (a bug: please report it; set
``RFVERIFY_DEBUG=1`` for the traceback); 141 stdout closed early (``| head``), silently.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import sys
import warnings

import numpy as np

from . import __version__
from .errors import RfverifyError

EXIT_OK = 0
EXIT_NOT_SOLVED = 1
EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 3

PROBLEM_HELP = ("problem file: FCLIB .hdf5 (fclib_global_rolling) or Siconos .dat (local problems "
                "are lifted to global form), or bundled:NAME for a problem shipped with rfverify "
                "(bundled:chute, bundled:chute-dat, bundled:sphere, bundled:cube, "
                "bundled:sphere-from-global)")


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error format and exit code 2."""

    def error(self, message):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    from .solver.result import ALGORITHM1_METHODS, METHODS

    parser = _Parser(
        prog="rfverify",
        description="Verification-focused toolkit for rolling-friction contact problems "
                    "(FCLIB conventions: M v = H r + f, u = Hᵀ v + w, K* ∋ u ⊥ r ∈ K). "
                    "Conventions, cones, the algorithm, the stopping criterion and what a "
                    "certificate proves: docs/DESIGN.md in the source repository; a walk-through "
                    "with your own file: docs/TUTORIAL.md.",
        epilog="Exit codes: 0 success, 1 tolerance not reached (solve) or not certified "
               "(solve --digits, certify), 2 bad input or arguments, 3 internal error, 130 "
               "interrupted, 141 stdout closed early (e.g. | head), 143 bench stopped by SIGTERM "
               "(per command: README, 'Guarantees'). "
               "--json output is strict JSON: non-finite numbers are null.",
    )
    parser.add_argument("--version", action="version", version=f"rfverify {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    info = sub.add_parser(
        "info", help="describe a problem: sizes, coefficients, M asymmetry, stored solution",
        description="Load and validate a problem, then report its sizes (m dofs, n contacts, "
                    "nnz), the ranges of mu and mu_r and how many contacts have mu = 0 or "
                    "mu_r = 0, the asymmetry of M (entrywise, the measure --max-asymmetry limits, "
                    "and normwise) and what was symmetrised for solving, the "
                    "block structure of M, the storage formats, and an independent check of "
                    "the stored /solution (never trusted). For a 3-D FCLIB file (/fclib_global, "
                    "/fclib_local) it also says how it was read: convex relaxation, mu_r = 0 in "
                    "the rolling layout, a local problem lifted (rank, dropped eigenvalues).",
    )
    info.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    info.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    _add_load_options(info)
    info.add_argument("--solution-tol", type=_tolerance, default=1e-6, metavar="TOL",
                      help="relative residual up to which a stored solution is called "
                           "consistent (default: %(default)g)")
    info.set_defaults(func=cmd_info)

    sol = sub.add_parser(
        "solve", help="solve a problem with Algorithm 1 (or the Clarabel peer)",
        description="Solve the convex relaxation of a rolling-friction problem with the "
                    "mixed-precision interior-point method (Algorithm 1, docs/DESIGN.md §4). "
                    "Exit code 0 only when the criterion (docs/DESIGN.md §4.5: residuals of the "
                    "returned v, u, r scaled by their terms and by the data) is <= --tol; 1 when "
                    "the solver stopped without reaching it (the status says why). The paper's "
                    "pinfeas, dinfeas and mu are printed beside it.",
    )
    sol.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    sol.add_argument("--method", choices=METHODS, default="jqinv",
                     help="linear-system form: jqinv (14), qp2 (11), reduced (15), "
                          "reduced_factored (16), noscaling (6), or clarabel, the same problem "
                          "handed to Clarabel (default: %(default)s)")
    sol.add_argument("--tol", type=_tolerance, default=1e-10, metavar="T",
                     help="stop when the criterion of docs/DESIGN.md §4.5 is <= T (default: "
                          "%(default)g)")
    sol.add_argument("--max-iter", type=_positive_int, default=100, metavar="K",
                     help="iteration limit (default: %(default)s)")
    sol.add_argument("--out", metavar="SOL.h5", type=_out_path,
                     help="write the problem data plus /solution/{v,u,r} (FCLIB layout) here, in "
                          "the input's own layout (3-D /fclib_global: 3 per contact; /fclib_local: "
                          "u and r only); naming the input .hdf5 file itself replaces only its "
                          "/solution (and /certificate with --digits) and "
                          "keeps everything else in it")
    sol.add_argument("--json", action="store_true",
                     help="print status, iterations, time and final residuals as JSON")
    sol.add_argument("--verbose", action="store_true",
                     help="print a settings header and each iteration as it happens (every independent "
                          "component, labelled); with --method clarabel, Clarabel's own log")
    sol.add_argument("--time-limit", type=_positive_float, default=None, metavar="S",
                     help="stop after S seconds with the best iterate (status MaxTime, exit 1)")
    sol.add_argument("--digits", type=_digits, default=None, metavar="K",
                     help="produce a solution proven right to K significant digits (1-15): the "
                          "double solve, then Algorithm 1 continued in double-double until the "
                          "rigorous error bound of docs/DESIGN.md §6 proves K digits of v, u and Hr "
                          "(and r where it is unique); exit code 0 only when proven. With --out the "
                          "file also gets /certificate (the point and the bound, to recheck with "
                          "'rfverify certify')")
    sol.add_argument("--no-presolve", action="store_true",
                     help="switch off the presolve reductions (cone reduction for mu = 0 / "
                          "mu_r = 0 requires them; such problems are refused)")
    _add_load_options(sol)
    sol.set_defaults(func=cmd_solve)

    cert = sub.add_parser(
        "certify", help="prove how many digits of a solution are right (a rigorous error bound)",
        description="Prove a lower bound on the correct significant digits of a solution (v, u, r) "
                    "of the convex relaxation (docs/DESIGN.md §6): an extended-precision point near "
                    "the solution set (stored in the solution file by 'solve --digits --out', or "
                    "computed by a double solve and double-double iterations) is evaluated in "
                    "exact arithmetic, and the bound "
                    "||v - v*||_M <= sqrt(g'M^-1 g + 2 r'u) is carried to the solution. Exit code 0 "
                    "only when --digits are proven.",
    )
    cert.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    cert.add_argument("--solution", metavar="SOL.h5",
                      help="FCLIB file whose /solution/{v,u,r} is certified (default: the "
                           "problem file's own /solution); its /certificate/point is used when present")
    cert.add_argument("--digits", type=_digits, default=10, metavar="K",
                      help="digits to prove, 1-15 (default: %(default)s)")
    cert.add_argument("--cross-check", action="store_true",
                      help="also run the independent mpmath reference and report the digits of "
                           "agreement (a second opinion; slow beyond a few hundred contacts)")
    cert.add_argument("--dps", type=_positive_int, default=50, metavar="D",
                      help="accuracy of the --cross-check reference in decimal digits (default: %(default)s)")
    cert.add_argument("--json", action="store_true", help="print the certificate as JSON")
    cert.add_argument("--out", metavar="CERT.h5", type=_out_path,
                      help="write the problem, the given solution and /certificate (the point, "
                           "exactly and as decimal strings, the bound and every intermediate norm)")
    cert.add_argument("--quiet", action="store_true", help="no progress lines on stderr")
    _add_load_options(cert)
    cert.set_defaults(func=cmd_certify)

    diag = sub.add_parser(
        "diagnose", help="run the double solver and the reference in lockstep",
        description="For every iteration of a double-precision run, take the exact step from the "
                    "double iterate with the mpmath reference and print the digits of agreement "
                    "of the next iterate, max cond(Q_p), min λ2 of z and Jᵀr̃ in double and in "
                    "the reference (flagging double λ2 that underflowed or went non-positive "
                    "while the exact one is positive), and where and why a failed run stopped.",
        epilog="Exit codes: 0 the double run was Solved; 1 it was not (MaxIterations, "
               "NumericalError, ...) — the diagnosis is printed either way; 2 bad input or "
               "option; 3 internal error.",
    )
    diag.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    diag.add_argument("--method", choices=ALGORITHM1_METHODS, default="jqinv",
                      help="linear-system form of the double run (default: %(default)s)")
    diag.add_argument("--tol", type=_tolerance, default=1e-10, metavar="T",
                      help="tolerance of the double run; set it below what double precision "
                           "reaches (e.g. 1e-25) to watch it fail (default: %(default)g)")
    diag.add_argument("--max-iter", type=_positive_int, default=100, metavar="K",
                      help="iteration limit of the double run (default: %(default)s)")
    diag.add_argument("--dps", type=_positive_int, default=40, metavar="D",
                      help="digits of the reference steps (default: %(default)s)")
    diag.add_argument("--json", action="store_true", help="print the diagnosis as JSON")
    _add_load_options(diag)
    diag.set_defaults(func=cmd_diagnose)

    from .bench.commands import add_parsers as add_bench_parsers

    add_bench_parsers(sub)

    from .scenes import ALL_SCENES, DEFAULT_STEPS

    gen = sub.add_parser(
        "generate", help="generate FCLIB problem collections from rigid-body and finite-element scenes",
        description="Build a rigid-body scene by a fast geometric method, take a few "
                    "Moreau-Jean steps (theta = 1, velocity level) from each stage of its run and "
                    "write the one-step problems as FCLIB HDF5 files SCENE-ndof-M-nc-N-K.hdf5 "
                    "(K = index in the trace).\n\n"
                    "Reproducibility: the files are bit-for-bit the same for the same scene, seed\n"
                    "and options, run with the same rfverify and the same numpy, scipy and QDLDL\n"
                    "builds on one platform (thread counts and PYTHONHASHSEED do not matter). What\n"
                    "varies and why: the scene's motion is simulated with rfverify's own solver\n"
                    "(each step's contact problem is solved by rfverify.solve), and granular motion\n"
                    "amplifies small differences, so a change to the solver or to numpy/scipy/QDLDL\n"
                    "that changes any result, even in its last bit, changes the later positions and\n"
                    "contacts: the values, and which contacts (hence the nonzeros of H) a problem has.\n\n"
                    "scenes:\n" + "\n".join(f"  {k}: {v.summary}" for k, v in ALL_SCENES.items()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    gen.add_argument("scene", metavar="SCENE", nargs="?", type=_scene_name,
                     help="scene name (case-insensitive): " + ", ".join(ALL_SCENES))
    gen.add_argument("--list", action="store_true",
                     help="list the scenes with their default size and parameters, then exit")
    gen.add_argument("--count", type=_positive_int, default=1, metavar="N",
                     help="problems in the trace; problem K comes from stage K/(N-1) of the run "
                          "(default: %(default)s)")
    gen.add_argument("--seed", type=_nonneg_int, default=0, metavar="S",
                     help="random seed (default: %(default)s)")
    gen.add_argument("--size", type=_positive_int, default=None, metavar="K",
                     help="bodies at the last stage (default: the scene's published size, "
                          "e.g. 250 for SpheresPile; use e.g. 20 for quick small instances)")
    gen.add_argument("--steps", type=_positive_int, default=DEFAULT_STEPS, metavar="J",
                     help="Moreau-Jean steps per stage; the last is dumped (default: %(default)s)")
    gen.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                     help="override a numeric scene parameter (repeatable; see --list)")
    gen.add_argument("--out", metavar="DIR", type=_out_path,
                     help="directory for the HDF5 files (created if missing); required "
                          "unless --list")
    gen.add_argument("--quiet", action="store_true",
                     help="no progress on stderr (otherwise a redrawn bar on a terminal, one line per "
                          "completed tenth when stderr is not a terminal; --json also silences it)")
    gen.add_argument("--json", action="store_true",
                     help="print one JSON object describing the written files")
    gen.set_defaults(func=cmd_generate)
    return parser


def _scene_name(text: str) -> str:
    from .scenes import resolve_scene
    from .scenes.stepper import SceneError

    try:
        return resolve_scene(text).name
    except SceneError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _nonneg_int(text: str) -> int:
    try:
        val = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if val < 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be ≥ 0")
    return val


def _add_load_options(p: argparse.ArgumentParser):
    p.add_argument("--max-asymmetry", type=_nonneg_float, default=None, metavar="X",
                   help="largest accepted entrywise asymmetry max|M_ij - M_ji|/sqrt(M_ii M_jj) "
                        "before M (W of a local problem) is refused (default: 1e-2; 'inf' accepts "
                        "any); the refusal and 'info' also show the normwise "
                        "||M - Mᵀ||_F/||M||_F. An accepted M is symmetrised as (M + Mᵀ)/2.")


def _positive_float(text: str) -> float:
    val = _float(text)
    if not val > 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
    return val


def _tolerance(text: str) -> float:
    """A tolerance: a finite number > 0 (inf would stop at once and call anything solved)."""
    val = _positive_float(text)
    if math.isinf(val):
        raise argparse.ArgumentTypeError(f"{text!r} must be a finite number > 0, e.g. 1e-10")
    return val


def _out_path(text: str) -> str:
    """An output path: not empty (an empty --out would silently write nothing)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path writes nothing; give a file name or "
                                         "leave the option out")
    return text


def _digits(text: str) -> int:
    from .errors import InvalidArgumentError
    from .proof import validate_digits

    try:
        return validate_digits(int(text))
    except ValueError as exc:
        if isinstance(exc, InvalidArgumentError):
            raise argparse.ArgumentTypeError(f"{text}: {exc.problem}; fix: {exc.fix}") from None
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer; fix: give K in 1 … 15") from None


def _positive_int(text: str) -> int:
    try:
        val = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if val < 1:
        raise argparse.ArgumentTypeError(f"{text!r} must be ≥ 1")
    return val


def _nonneg_float(text: str) -> float:
    val = _float(text)
    if not val >= 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be ≥ 0")
    return val


def _float(text: str) -> float:
    try:
        val = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if math.isnan(val):
        raise argparse.ArgumentTypeError("NaN is not allowed")
    return val


def _load(args):
    from .io import load
    from .problem import DEFAULT_MAX_ASYMMETRY

    limit = DEFAULT_MAX_ASYMMETRY if args.max_asymmetry is None else args.max_asymmetry
    return load(args.problem, max_asymmetry=limit)


# ---------------------------------------------------------------------- info
def problem_summary(problem, *, solution_tol: float = 1e-6, max_asymmetry: float | None = None) -> dict:
    """JSON-able description of a problem (what ``rfverify info --json`` prints)."""
    from .check import check_solution
    from .io.fclib3d import ROLLING, SOLUTION_LAYOUT, describe_symmetrised, file_layout, symmetrised
    from .problem import DEFAULT_MAX_ASYMMETRY

    mu, mu_r = problem.mu, problem.mu_r
    blocks = problem.blocks
    sizes, counts = np.unique(blocks.sizes, return_counts=True)
    free = problem.contact_free_dofs
    free_blocks = int(np.unique(blocks.labels[free]).size) if free.size else 0
    eig = blocks.min_eigenvalues
    finite = np.isfinite(eig)
    summary = {
        "title": problem.title,
        "description": problem.description.strip(),
        "source": problem.source,
        "format": problem.provenance.get("format", "fclib-hdf5"),
        "storage": dict(problem.storage),
        "m": problem.n_dofs,
        "n": problem.n_contacts,
        "spacedim": problem.spacedim,
        "nnz": {"M": int(problem.M.nnz), "H": int(problem.H.nnz)},
        "mu": {"min": float(mu.min()), "max": float(mu.max()), "zero_count": int(np.sum(mu == 0))},
        "mu_r": {"min": float(mu_r.min()), "max": float(mu_r.max()),
                 "zero_count": int(np.sum(mu_r == 0))},
        "both_zero_count": int(np.sum((mu == 0) & (mu_r == 0))),
        "M_asymmetry": {
            "scaled": problem.symmetry.scaled,
            "frobenius": problem.symmetry.frobenius,
            "entrywise": problem.symmetry.scaled,
            "normwise": problem.symmetry.frobenius,
            "at": None if problem.symmetry.row is None else [problem.symmetry.row, problem.symmetry.col],
            "symmetrised": problem.symmetry.scaled > 0,
        },
        "M_blocks": {
            "count": blocks.count,
            "sizes": {str(int(s)): int(c) for s, c in zip(sizes, counts)},
            "contact_free_blocks": free_blocks,
            "contact_free_dofs": int(free.size),
            "min_eigenvalue": float(eig[finite].min()) if finite.any() else None,
        },
    }
    sym = symmetrised(problem)
    summary["symmetrised"] = {**sym, "text": describe_symmetrised(sym),
                              "limit": DEFAULT_MAX_ASYMMETRY if max_asymmetry is None else max_asymmetry,
                              "limit_measure": "entrywise"}
    layout = file_layout(problem)
    if layout != ROLLING:  # a 3-D FCLIB file read into the rolling layout: say what was done
        pv = problem.provenance
        summary["spacedim"] = pv["spacedim"]
        summary["internal_spacedim"] = problem.spacedim
        summary["file"] = {k: pv[k] for k in ("format", "spacedim", "relaxation", "mu_r", "embedding")}
        summary["file"]["solution_layout"] = SOLUTION_LAYOUT[layout]
        if "lifted" in pv:
            summary["file"]["lifted"] = pv["lifted"]
    if problem.provenance.get("ignored_groups"):
        summary["ignored_groups"] = list(problem.provenance["ignored_groups"])
    if "significant_digits" in problem.provenance:
        summary["significant_digits"] = problem.provenance["significant_digits"]
    if "lift" in problem.provenance:
        summary["lifted_from_local"] = problem.provenance["lift"]
    if problem.solution is None:
        summary["solution"] = None
    else:
        chk = check_solution(problem, problem.solution)
        summary["solution"] = {**chk.as_dict(), "tolerance": solution_tol,
                               "consistent": chk.ok(solution_tol),
                               "verdict": chk.verdict(solution_tol)}
    summary["guesses"] = len(problem.guesses)
    return summary


def _format_info(s: dict) -> str:
    lines = []
    add = lines.append
    add(f"problem    {s['title'] or '(untitled)'}")
    if s["description"]:
        for k, text in enumerate(s["description"].splitlines()):
            add(f"{'' if k else 'about':<11}{text}")
    add(f"source     {s['source']} ({s['format']}; "
        + ", ".join(f"{k} {v}" for k, v in s["storage"].items()) + ")")
    fl = s.get("file")
    if fl:
        add(f"file       3-D Coulomb friction (/{fl['format']}, spacedim {fl['spacedim']}, 3 per contact): "
            f"solved as its convex relaxation (De Saxcé term dropped), embedded in the rolling "
            f"layout with mu_r = 0 and zero rolling rows")
        add(f"           solutions are written back as {fl['solution_layout'].split(': ', 1)[1]}")
        lf = fl.get("lifted")
        if lf:
            add(f"lifted     local problem W ({lf['W_size']}×{lf['W_size']}) lifted to global form: "
                f"M = I, f = 0, w = q, W = HᵀH; rank {lf['rank']}, {lf['dropped']} eigenvalue(s) "
                f"≤ {lf['rank_tol']:.1e}·‖W‖ dropped (smallest {lf['min_eigenvalue']:.2e})")
            add("           v of the lifted problem is not a quantity of the file (a stored "
                "solution's v is recovered as v = H r)")
    if s.get("ignored_groups"):
        add(f"ignored    {', '.join(s['ignored_groups'])}: the file holds several problem groups; "
            f"read the first of /fclib_global_rolling, /fclib_global, /fclib_local")
    if s.get("significant_digits"):
        add(f"precision  matrices printed with {s['significant_digits']} significant digits")
    if s.get("lifted_from_local"):
        lf = s["lifted_from_local"]
        add(f"lifted     local problem W = HᵀH: rank {lf['rank']}, {lf['dropped']} eigenvalue(s) "
            f"≤ {lf['rank_tol']:.1e}·‖W‖ dropped (smallest {lf['min_eigenvalue']:.2e})")
    per = (f"3n = {3 * s['n']} in the file, 5n = {5 * s['n']} in the rolling layout" if fl
           else f"5n = {5 * s['n']}")
    add(f"sizes      m = {s['m']} dofs, n = {s['n']} contacts ({per}), "
        f"nnz(M) = {s['nnz']['M']}, nnz(H) = {s['nnz']['H']}")
    b = s["M_blocks"]
    add(f"M blocks   {b['count']} diagonal block(s): "
        + ", ".join(f"{c} of size {k}" for k, c in b["sizes"].items())
        + f"; {b['contact_free_blocks']} contact-free ({b['contact_free_dofs']} dofs)")
    if b["min_eigenvalue"] is not None:
        add(f"           positive definite: smallest block eigenvalue {b['min_eigenvalue']:.3e}")
    a, sym = s["M_asymmetry"], s["symmetrised"]
    limit = f"limit {sym['limit']:g}, --max-asymmetry"
    rows = [("M", a)] if sym["matrix"] == "M" else [("M", a), ("W", sym)]
    for X, d in rows:
        if d["symmetrised"]:
            at = "" if d["at"] is None else f" at {tuple(d['at'])}"
            add(f"{X} asym.    entrywise max|{X}_ij - {X}_ji|/sqrt({X}_ii {X}_jj) = {d['entrywise']:.3e}{at} "
                f"({limit}); normwise ||{X} - {X}ᵀ||_F/||{X}||_F = {d['normwise']:.3e}")
            use = "solving" if X == "M" else "the lifting (W = HᵀH)"
            add(f"           symmetrised: ({X} + {X}ᵀ)/2 is used for {use}")
        elif X == "M" and sym["matrix"] == "W":
            add("M asym.    0 (M = I of the lifted local problem)")
        else:
            add(f"{X} asym.    0 (exactly symmetric): nothing symmetrised ({limit})")
    for key in ("mu", "mu_r"):
        c = s[key]
        add(f"{key:<11}in [{c['min']:g}, {c['max']:g}]; {c['zero_count']} contact(s) with {key} = 0")
    add(f"           {s['both_zero_count']} contact(s) with mu = mu_r = 0")
    sol = s["solution"]
    add("solution   none stored" if sol is None else f"solution   stored: {sol['verdict']}")
    add(f"guesses    {s['guesses']}")
    return "\n".join(lines)


def cmd_info(args) -> int:
    problem = _load(args)
    with _recorded_warnings() as caught:
        summary = problem_summary(problem, solution_tol=args.solution_tol,
                                  max_asymmetry=args.max_asymmetry)
    if caught:
        summary["numerical_warnings"] = _warning_summary(caught)
    if args.json:
        print(_dumps(summary, indent=2))
    else:
        print(_format_info(summary))
        _print_warnings(summary.get("numerical_warnings"), "while describing the problem")
    return EXIT_OK


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


@contextlib.contextmanager
def _recorded_warnings():
    """Record warnings (numpy floating-point, ...) instead of letting Python print them."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield caught


def _warning_summary(caught) -> list[str]:
    """Distinct warnings with their counts, e.g. ``"RuntimeWarning: overflow in add (×13)"``."""
    counts = {}
    for w in caught:
        key = f"{w.category.__name__}: {' '.join(str(w.message).split())}"
        counts[key] = counts.get(key, 0) + 1
    return [f"{k} (×{n})" if n > 1 else k for k, n in counts.items()]


def _print_warnings(items, where: str) -> None:
    if items:
        print(f"numerical warnings {where}: {'; '.join(items)}")


def _dumps(obj, **kwargs) -> str:
    """Strict JSON (non-finite numbers as null): what every --json output prints."""
    from .io.output import dumps

    return dumps(obj, **kwargs)



# ---------------------------------------------------------------------- solve
def cmd_solve(args) -> int:
    import time

    from .solver import solve

    problem = _load(args)
    options = {}
    if args.no_presolve:
        options.update(reduce_cones=False, drop_free_bodies=False, split_components=False)
        if np.any(problem.mu == 0) or np.any(problem.mu_r == 0):
            from .errors import InvalidProblemError

            raise InvalidProblemError("mu", "has zero coefficients, which the unreduced lifting "
                                            "would divide by", fix="drop --no-presolve")
    if args.digits is not None:
        return _solve_digits(args, problem, options)
    t0 = time.perf_counter()
    # --verbose: the solver prints its header and each iteration as it happens (Clarabel its own log).
    options["verbose"] = bool(args.verbose and not args.json)
    if args.time_limit is not None:
        options["time_limit"] = args.time_limit
    with _recorded_warnings() as caught:
        result = solve(problem, method=args.method, tol=args.tol, max_iter=args.max_iter, **options)
    wall = time.perf_counter() - t0
    if args.out:
        _write_solution_file(args, problem, result.v, result.u, result.r)
    summary = {
        "status": str(result.status), "success": result.success, "message": result.message,
        "method": result.method, "iterations": result.nit, "time": wall, "tol": args.tol,
        "criterion": result.criterion,
        "measures": result.measures.as_dict() if result.measures is not None else None,
        "pinfeas": result.pinfeas, "dinfeas": result.dinfeas, "mu": result.mu,
        "presolve": result.presolve, "out": args.out,
        "numerical_warnings": _warning_summary(caught),
        "timings": result.timings,
        "trace": {k: np.asarray(v).tolist() for k, v in result.trace.items()},
        "component_traces": [{"status": str(c["status"]), "message": c["message"], "nit": c["nit"],
                              "trace": {k: np.asarray(v).tolist() for k, v in c["trace"].items()}}
                             for c in result.extras.get("component_runs", [])],
    }
    if args.json:
        print(_dumps(summary, indent=2))
    else:
        print(f"status {result.status}: {result.message}")
        m = result.measures
        if m is not None:
            print(f"criterion {m.max:.2e} (dynamics {m.dynamics:.1e}, velocity {m.velocity:.1e}, cone "
                  f"{m.cone:.1e}, complementarity {m.complementarity:.1e}; rfverify.measures)")
        print(f"iterations {result.nit}, time {wall:.3f} s; the paper's measures: pinfeas {result.pinfeas:.2e}, "
              f"dinfeas {result.dinfeas:.2e}, mu {result.mu:.2e}")
        if args.out:
            print(f"solution written to {args.out}")
        _print_warnings(summary["numerical_warnings"], "during the solve (the status above is "
                        "judged by the recomputed criterion, not by these)")
    return EXIT_OK if result.success else EXIT_NOT_SOLVED


def _solve_digits(args, problem, options) -> int:
    import time

    from .digits import solve_to_digits

    say = _progress(args)
    t0 = time.perf_counter()
    out = solve_to_digits(problem, digits=args.digits, method=args.method, tol=args.tol,
                          max_iter=args.max_iter, progress=say, **options)
    wall = time.perf_counter() - t0
    cert = out.certificate
    if args.out:
        _write_solution_file(args, problem, out.v, out.u, out.r, certificate=cert)
    summary = {"status": "Certified" if out.success else "NotCertified",
               "success": out.success, "digits_requested": args.digits,
               "certificate": cert.as_dict(), "double_status": str(out.double.status),
               "double_iterations": out.double.nit, "extended_iterations": out.extended.nit,
               "extended_status": out.extended.status, "backend": out.extended.backend,
               "timings": out.timings, "time": wall, "out": args.out}
    if args.json:
        print(_dumps(summary, indent=2))
    else:
        print(f"double solve: {out.double.status} in {out.double.nit} iterations; extended "
              f"(double-double) iterations: {out.extended.nit}")
        print(cert.verdict)
        _print_quantities(cert)
        t = out.timings
        print(f"time {wall:.2f} s (double {t['double']:.2f}, extended {t['setup'] + t['extended']:.2f}, "
              f"proof {t['proof']:.2f})" + (f"; solution and certificate written to {args.out}" if args.out else ""))
    return EXIT_OK if out.success else EXIT_NOT_SOLVED


def _progress(args):
    """One line per stage on stderr, unless --json or --quiet."""
    if getattr(args, "json", False) or getattr(args, "quiet", False):
        return None

    def say(message):
        print(f"rfverify {args.command}: {message}", file=sys.stderr, flush=True)

    return say


def _print_quantities(cert) -> None:
    for q in cert.quantities.values():
        print("  " + q.describe())


# ---------------------------------------------------------------------- diagnose
def cmd_diagnose(args) -> int:
    from .diagnosis import diagnose

    problem = _load(args)
    with _recorded_warnings() as caught:
        d = diagnose(problem, method=args.method, tol=args.tol, max_iter=args.max_iter, dps=args.dps,
                     progress=_progress(args))
    d["numerical_warnings"] = _warning_summary(caught)
    # The exit code is the double run's outcome, so scripts can tell a failing run apart.
    code = EXIT_OK if d["status"] == "Solved" else EXIT_NOT_SOLVED
    if args.json:
        print(_dumps(d, indent=2))
        return code
    print(f"double run ({d['method']}): {d['status']} after {d['nit']} iterations: {d['message']}")
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
    _print_warnings(d["numerical_warnings"], "in the double run")
    return code


# ---------------------------------------------------------------------- certify
def cmd_certify(args) -> int:
    from .certification import certify
    from .errors import ProblemFileError
    from .io import load
    from .io.certificate import read_point

    problem = _load(args)
    point = None
    if args.solution:
        other = load(args.solution, max_asymmetry=np.inf)
        _require_same_problem(problem, other, args.solution)
        sol = other.solution
        where = args.solution
        point = read_point(_resolve(args.solution))
    else:
        sol, where = problem.solution, args.problem
        if _is_hdf5_input(args.problem):
            point = read_point(_resolve(args.problem))
    # A 3-D file's /solution (3 per contact; local: u and r, v = H r) is read into the rolling
    # layout by load(), so it is certified like any other.
    if sol is None or sol.v is None or sol.r is None:
        need = "r" if problem.provenance.get("format") == "fclib_local" else "v and r"
        raise ProblemFileError(where, f"has no /solution with {need} to certify",
                               fix="pass --solution SOL.h5 (written by rfverify solve --out)")
    if point is not None and (point.v_hi.size != problem.n_dofs or point.r_hi.size != 5 * problem.n_contacts):
        raise ProblemFileError(where, "/certificate/point does not match the problem's sizes",
                               location="/certificate/point", fix="certify the solution file written for this problem")
    u = sol.u if sol.u is not None else problem.H.T @ sol.v + problem.w
    cert = certify(problem, sol.v, u, sol.r, digits=args.digits, point=point, cross_check=args.cross_check,
                   dps=args.dps, progress=_progress(args))
    if args.out:
        _write_certificate(args, problem, sol, u, cert)
    if args.json:
        print(_dumps(cert.as_dict(), indent=2))
    else:
        print(cert.verdict)
        _print_quantities(cert)
        src = cert.extra.get("point_source")
        print(f"point: {'stored in ' + where if src == 'given' else 'computed (double solve + double-double phase)'}; "
              f"time {cert.seconds:.2f} s")
        if cert.cross_check is not None:
            cc = cert.cross_check
            shown = ", ".join(f"{k[7:]} {v:.1f}" for k, v in cc.items() if k.startswith("digits_") and v is not None)
            print(f"cross-check against the mpmath reference ({cc.get('reference_status')}): "
                  f"agreement {shown or cc.get('note', '')}")
    return EXIT_OK if cert.certified else EXIT_NOT_SOLVED


def _resolve(spec):
    from .io import resolve_path

    return resolve_path(spec)


def _require_same_problem(problem, other, path):
    """A solution is only certified against the problem it was computed for."""
    from .errors import InvalidProblemError

    same = (problem.M.shape == other.M.shape and problem.H.shape == other.H.shape
            and all(np.array_equal(getattr(problem, k), getattr(other, k)) for k in ("f", "w", "mu", "mu_r"))
            and (problem.M != other.M).nnz == 0 and (problem.H != other.H).nnz == 0)
    if not same:
        raise InvalidProblemError(
            "solution", f"{path} holds a different problem (m = {other.n_dofs}, n = {other.n_contacts} "
                        f"vs m = {problem.n_dofs}, n = {problem.n_contacts}, or different data)",
            fix="pass the solution file written for this problem (rfverify solve ... --out)")


def _write_certificate(args, problem, sol, u, cert):
    """``certify --out``: the problem, the certified solution and /certificate."""
    from .io import save
    from .io.certificate import write_certificate
    from .io.output import check_output_file
    from .problem import StoredSolution

    target = getattr(args, "out_target", None) or check_output_file(args.out, inputs=[args.problem, args.solution])
    save(problem.with_solution(StoredSolution(v=sol.v, u=u, r=sol.r)), target,
         extra=lambda fh: write_certificate(fh, cert))


def cmd_generate(args) -> int:
    import time

    from .progress import Progress
    from .scenes import ALL_SCENES, generate, save_collection, scene_parameters
    from .scenes.stepper import SceneError

    if args.list:
        for name, sc in ALL_SCENES.items():
            print(f"{name} (default size {sc.default_size} {sc.size_unit}): {sc.summary}")
            print("    parameters: " + ", ".join(f"{k}={v:g}" for k, v in sc.defaults.items()))
        return EXIT_OK
    if args.scene is None or args.out is None:
        raise SceneError("generate needs SCENE and --out DIR (or --list)")
    params = {}
    for item in args.param:
        key, sep, val = item.partition("=")
        if not sep or not key.strip():
            raise SceneError(f"--param {item!r}: expected KEY=VALUE")
        params[key.strip()] = val.strip()
    scene_parameters(args.scene, args.size, **params)  # bad names/values fail before any work
    bar = Progress(100, f"generate {args.scene} (%)", quiet=args.quiet or args.json)
    t0 = time.perf_counter()
    try:
        problems = generate(args.scene, count=args.count, seed=args.seed, size=args.size,
                            steps=args.steps, progress=bar.update_fraction, **params)
    finally:
        bar.close()
    paths = save_collection(problems, args.out)
    wall = time.perf_counter() - t0
    files = []
    for path, prob in zip(paths, problems):
        pv = prob.provenance
        files.append({"path": str(path), "m": prob.n_dofs, "n": prob.n_contacts,
                      "trace_index": pv["trace_index"], "failed_solves": pv["failed_solves"],
                      "solves": [s["status"] for s in pv["solves"]]})
        if pv["failed_solves"]:
            print(f"rfverify generate: warning: {path.name}: {pv['failed_solves']} of "
                  f"{len(pv['solves'])} step solve(s) did not reach the tolerance "
                  f"({', '.join(s['status'] for s in pv['solves'])}); advanced with the best "
                  "iterate (recorded in info/description)", file=sys.stderr)
    if args.json:
        print(_dumps({"scene": args.scene, "seed": args.seed, "count": args.count,
                     "size": problems[0].provenance["size"], "time": wall, "files": files},
                    indent=2))
    else:
        for f in files:
            print(f"{f['path']}  m = {f['m']}, n = {f['n']}")
        print(f"{len(files)} problem(s) of {args.scene} written to {args.out} in {wall:.1f} s")
    return EXIT_OK


# ---------------------------------------------------------------------- output files
def _is_hdf5_input(spec) -> bool:
    from .io import resolve_path

    try:
        with open(resolve_path(spec), "rb") as fh:
            return fh.read(8) == b"\x89HDF\r\n\x1a\n"
    except (OSError, RfverifyError):
        return False


def _check_outputs(args) -> None:
    """Refuse an unusable output path before any work (README, "Guarantees")."""
    from .io.output import check_output_dir, check_output_file

    out = getattr(args, "out", None)
    if out is None:
        return
    if args.command == "solve":
        # FCLIB keeps /solution beside the problem: writing it into the input .hdf5 is allowed.
        args.out_target = check_output_file(out, inputs=[args.problem],
                                            in_place_ok=_is_hdf5_input(args.problem))
    elif args.command == "certify":
        args.out_target = check_output_file(out, inputs=[args.problem, args.solution])
    elif args.command == "generate" and not args.list:
        check_output_dir(out)
    elif args.command == "bench":
        check_output_dir(out)


def _write_solution_file(args, problem, v, u, r, certificate=None) -> None:
    """``solve --out``: the problem plus /solution, or only /solution written into the input
    .hdf5 file itself when --out names it (everything else in that file is kept)."""
    from .io import save, write_solution_in_place
    from .io.output import check_output_file
    from .problem import StoredSolution

    target = getattr(args, "out_target", None) or check_output_file(
        args.out, inputs=[args.problem], in_place_ok=_is_hdf5_input(args.problem))
    solution = StoredSolution(v=v, u=u, r=r)
    extra = None
    if certificate is not None:
        from .io.certificate import write_certificate

        def extra(fh):
            write_certificate(fh, certificate)
    if target.in_place:  # the file's own layout (3 per contact for 3-D files), see io/fclib3d.py
        write_solution_in_place(target, problem.with_solution(solution).solution, extra=extra,
                                problem=problem)
    else:
        save(problem.with_solution(solution), target, extra=extra)


# ---------------------------------------------------------------------- entry point
EXIT_BROKEN_PIPE = 141
"""Exit code when stdout is closed early (``rfverify info ... | head -1``): 128 + SIGPIPE, what
a shell reports for a program killed by the signal."""


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        with warnings.catch_warnings(record=True) as caught:
            # numpy/matplotlib warnings are not for the user's terminal: they are recorded and
            # shown only with RFVERIFY_DEBUG (commands turn the ones that matter into messages).
            warnings.simplefilter("always")
            _check_outputs(args)
            code = args.func(args)
            sys.stdout.flush()
        if os.environ.get("RFVERIFY_DEBUG"):
            for w in caught:
                print(f"rfverify {args.command}: debug: {w.category.__name__}: {w.message} "
                      f"({w.filename}:{w.lineno})", file=sys.stderr)
        return code
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except RfverifyError as exc:
        exc = _with_problem_file(exc, args)
        print(f"rfverify {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("rfverify: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug, not bad input: say so in one line unless debugging
        if os.environ.get("RFVERIFY_DEBUG"):
            raise
        print(f"rfverify {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              "(please report; set RFVERIFY_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL


def _silence_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush stays quiet."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (e.g. captured in tests)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)


def _with_problem_file(exc, args):
    """A data error raised after loading names the PROBLEM file it is about."""
    from .errors import InvalidProblemError

    spec = getattr(args, "problem", None)
    if isinstance(exc, InvalidProblemError) and exc.path is None and spec:
        return exc.with_path(spec)
    return exc


def _one_line(exc) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
