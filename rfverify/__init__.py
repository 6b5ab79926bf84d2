"""rfverify — verification-focused, mixed-precision toolkit for rolling-friction contact problems.

Public API (this release):

- :func:`load` / :func:`save` — FCLIB HDF5 and Siconos ``.dat`` problem files.
- :class:`Problem` — a validated global rolling-friction problem (FCLIB conventions).
- :func:`check_solution` — recompute the residuals of a candidate (v, u, r).
- :func:`solve` — Algorithm 1 (forms jqinv, qp2, reduced, reduced_factored, noscaling) or the
  Clarabel peer; :func:`solve_to_digits` — the certified k-digit path.
- :func:`certify` — proven digits of a solution (a rigorous error bound, DESIGN §6), with the
  mpmath reference as an optional cross-check; :func:`diagnose` — lockstep double/reference run.
- :mod:`rfverify.jordan` — Jordan algebra of Lorentz cones, vectorised, float64/longdouble.
- Errors: :class:`RfverifyError`, :class:`InvalidProblemError`, :class:`ProblemFileError`,
  :class:`InvalidArgumentError`, :class:`OutputPathError`, :class:`ConeDomainError`; the
  warning :class:`DataWarning` (optional file metadata read with a stated change or skipped).
"""

import functools as _functools

from .check import SolutionCheck, check_solution
from ._version import __version__
from .errors import (ConeDomainError, DataWarning, InvalidArgumentError, InvalidProblemError,
                     OutputPathError, ProblemFileError, RfverifyError)
from .io import bundled_problems, load, save
from .problem import Problem, StoredSolution
from .certificate import Certificate
from .certification import certify
from .diagnosis import Diagnosis, diagnose
from .digits import DigitsSolution, solve_to_digits
from .solver import SolveResult, Settings, Status, solve


def _checked(func, *, tol=False):
    """``func`` with its ``problem`` (and ``tol``, ``max_iter``, ``method``) arguments checked
    first, so that wrong types raise InvalidArgumentError (an RfverifyError naming the fix)
    instead of a TypeError/AttributeError from deep inside."""
    import inspect

    from .errors import require_positive_int, require_positive_number
    from .problem import require_problem

    signature = inspect.signature(func)

    @_functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            given = signature.bind(*args, **kwargs).arguments
        except TypeError as exc:
            raise InvalidArgumentError(func.__name__, str(exc),
                                       fix=f"see help(rfverify.{func.__name__})") from None
        require_problem(given.get("problem"))
        if tol and "tol" in given:
            require_positive_number(given["tol"], "tol")
        if tol and "max_iter" in given:
            require_positive_int(given["max_iter"], "max_iter")
        if tol and given.get("options"):
            from .solver import Settings as _Settings

            unknown = sorted(set(given["options"]) - set(_Settings.names()) - {"keep_iterates"})
            if unknown:
                raise InvalidArgumentError(", ".join(unknown), "unknown solver option(s)",
                                           fix=f"use fields of rfverify.Settings: {', '.join(_Settings.names())}")
        method = given.get("method")
        if tol and method is not None:
            from .solver.result import METHODS

            if not isinstance(method, str) or method not in METHODS:
                raise InvalidArgumentError("method", f"{method!r} is not one of {', '.join(METHODS)}",
                                           fix="pass method='auto' (the default) or another listed method")
        return func(*args, **kwargs)

    return wrapper


def _posing(func, physical: str):
    """``func`` with the keyword ``problem="relaxation" | "coulomb"`` (issue 51): "relaxation"
    (default) calls ``func`` itself, unchanged; "coulomb" calls ``rfverify.coulomb.<physical>``,
    the physical problem with De Saxcé's term, with the same arguments (DESIGN §1).  A Problem
    passed as ``problem=`` is the problem to solve, as before."""

    @_functools.wraps(func)
    def wrapper(*args, **kwargs):
        kind = kwargs.get("problem")
        if not isinstance(kind, str):
            return func(*args, **kwargs)
        from . import coulomb

        coulomb.check_problem_kind(kwargs.pop("problem"))
        if kind == "relaxation":
            return func(*args, **kwargs)
        checked = _checked(getattr(coulomb, physical), tol=physical != "certify_coulomb")
        return checked(*args, **kwargs)

    return wrapper


solve = _posing(_checked(solve, tol=True), "solve_coulomb")
diagnose = _checked(diagnose, tol=True)
solve_to_digits = _posing(_checked(solve_to_digits, tol=True), "coulomb_to_digits")
certify = _posing(_checked(certify), "certify_coulomb")
check_solution = _checked(check_solution)


__all__ = [
    "Problem", "StoredSolution", "load", "save", "bundled_problems", "check_solution",
    "SolutionCheck", "RfverifyError", "InvalidProblemError", "ProblemFileError",
    "InvalidArgumentError", "OutputPathError",
    "ConeDomainError", "DataWarning", "__version__", "solve", "SolveResult", "Settings", "Status",
    "certify",
    "solve_to_digits", "DigitsSolution", "diagnose", "Diagnosis", "Certificate",
]
