"""Command-line interface: ``rfverify <command> ...``.

Exit codes: 0 success; 2 bad input (unreadable or invalid problem, bad arguments) with a
one-line message on stderr; 3 an internal error (a bug: please report it; set
``RFVERIFY_DEBUG=1`` for the traceback).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys

import numpy as np

from . import __version__
from .errors import RfverifyError

EXIT_OK = 0
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
    parser = _Parser(
        prog="rfverify",
        description="Verification-focused toolkit for rolling-friction contact problems "
                    "(FCLIB conventions: M v = H r + f, u = Hᵀ v + w, K* ∋ u ⊥ r ∈ K).",
        epilog="Exit codes: 0 success, 2 bad input or arguments, 3 internal error.",
    )
    parser.add_argument("--version", action="version", version=f"rfverify {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    info = sub.add_parser(
        "info", help="describe a problem: sizes, coefficients, M asymmetry, stored solution",
        description="Load and validate a problem, then report its sizes (m dofs, n contacts, "
                    "nnz), the ranges of mu and mu_r and how many contacts have mu = 0 or "
                    "mu_r = 0, the asymmetry of M (which is symmetrised for solving), the "
                    "block structure of M, the storage formats, and an independent check of "
                    "the stored /solution (never trusted).",
    )
    info.add_argument("problem", metavar="PROBLEM", help=PROBLEM_HELP)
    info.add_argument("--json", action="store_true", help="print one JSON object instead of text")
    _add_load_options(info)
    info.add_argument("--solution-tol", type=_positive_float, default=1e-6, metavar="TOL",
                      help="relative residual up to which a stored solution is called "
                           "consistent (default: %(default)g)")
    info.set_defaults(func=cmd_info)
    return parser


def _add_load_options(p: argparse.ArgumentParser):
    p.add_argument("--max-asymmetry", type=_nonneg_float, default=None, metavar="X",
                   help="largest accepted scaled asymmetry max|M_ij - M_ji|/sqrt(M_ii M_jj) "
                        "before M is refused (default: 1e-2; 'inf' accepts any). An accepted "
                        "M is symmetrised as (M + Mᵀ)/2.")


def _positive_float(text: str) -> float:
    val = _float(text)
    if not val > 0:
        raise argparse.ArgumentTypeError(f"{text!r} must be > 0")
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
def problem_summary(problem, *, solution_tol: float = 1e-6) -> dict:
    """JSON-able description of a problem (what ``rfverify info --json`` prints)."""
    from .check import check_solution

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
    add(f"source     {s['source']} ({s['format']}; M {s['storage'].get('M')}, H {s['storage'].get('H')})")
    if s.get("significant_digits"):
        add(f"precision  matrices printed with {s['significant_digits']} significant digits")
    if s.get("lifted_from_local"):
        lf = s["lifted_from_local"]
        add(f"lifted     local problem W = HᵀH: rank {lf['rank']}, {lf['dropped']} eigenvalue(s) "
            f"≤ {lf['rank_tol']:.1e}·‖W‖ dropped (smallest {lf['min_eigenvalue']:.2e})")
    add(f"sizes      m = {s['m']} dofs, n = {s['n']} contacts (5n = {5 * s['n']}), "
        f"nnz(M) = {s['nnz']['M']}, nnz(H) = {s['nnz']['H']}")
    b = s["M_blocks"]
    add(f"M blocks   {b['count']} diagonal block(s): "
        + ", ".join(f"{c} of size {k}" for k, c in b["sizes"].items())
        + f"; {b['contact_free_blocks']} contact-free ({b['contact_free_dofs']} dofs)")
    if b["min_eigenvalue"] is not None:
        add(f"           positive definite: smallest block eigenvalue {b['min_eigenvalue']:.3e}")
    a = s["M_asymmetry"]
    if a["symmetrised"]:
        add(f"M asym.    scaled {a['scaled']:.3e} at {tuple(a['at'])}, Frobenius {a['frobenius']:.3e}"
            " — symmetrised (M + Mᵀ)/2 for solving")
    else:
        add("M asym.    0 (exactly symmetric)")
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
    summary = problem_summary(problem, solution_tol=args.solution_tol)
    if args.json:
        print(json.dumps(summary, indent=2, default=_json_default, allow_nan=True))
    else:
        print(_format_info(summary))
    return EXIT_OK


def _json_default(obj):
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")


# ---------------------------------------------------------------------- entry point
def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RfverifyError as exc:
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


def _one_line(exc) -> str:
    return " ".join(str(exc).split())


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
