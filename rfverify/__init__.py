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
import importlib as _importlib

from ._version import __version__
from .errors import (ConeDomainError, DataWarning, InvalidArgumentError, InvalidProblemError,
                     OutputPathError, ProblemFileError, RfverifyError)

# The public names are attributes made on first use (PEP 562), so that ``import rfverify`` (and
# the console script, rfverify/__main__.py) costs no numpy, scipy or numba until one is asked for.
_HOMES = {
    "load": ".io", "save": ".io", "bundled_problems": ".io",
    "Problem": ".model.problem", "StoredSolution": ".model.problem", "SolutionCheck": ".model.check",
    "Certificate": ".verify.certificate", "Diagnosis": ".verify.diagnosis",
    "DigitsSolution": ".verify.digits", "SolveResult": ".solver", "Settings": ".solver", "Status": ".solver",
    "shift_to_psd": ".proof.psd_shift",
}
_POSED = {"solve": "solve_coulomb", "solve_to_digits": "coulomb_to_digits", "certify": "certify_coulomb"}
"""Entry points that also take ``problem="coulomb"``: the physical problem's function (:func:`_posing`)."""
_CHECKED = {  # name: (module, whether tol, max_iter, method and options are checked too)
    "solve": (".solver", True), "diagnose": (".verify.diagnosis", True),
    "solve_to_digits": (".verify.digits", True), "certify": (".verify.certification", False),
    "check_solution": (".model.check", False),
}
_SUBPACKAGES = {"algorithm", "bench", "cli", "compilation", "data", "engines", "errors", "extended", "io", "jordan",
                "model", "proof", "progress", "report", "scenes", "solver", "verify", "coulomb"}


def __getattr__(name: str):
    if name in _HOMES:
        value = getattr(_importlib.import_module(_HOMES[name], __name__), name)
    elif name in _CHECKED:
        home, tol = _CHECKED[name]
        value = _checked(getattr(_importlib.import_module(home, __name__), name), tol=tol)
        if name in _POSED:
            value = _posing(value, _POSED[name])
    elif name in _SUBPACKAGES:
        value = _importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # made once: later uses find it here
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__) | _SUBPACKAGES)


def _checked(func, *, tol=False):
    """``func`` with its ``problem`` (and ``tol``, ``max_iter``, ``method``) arguments checked
    first, so that wrong types raise InvalidArgumentError (an RfverifyError naming the fix)
    instead of a TypeError/AttributeError from deep inside."""
    import inspect

    from .errors import require_positive_int, require_positive_number
    from .model.problem import require_problem

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

            unknown = sorted(set(given["options"]) - set(_Settings.accepted()) - {"keep_iterates"})
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


__all__ = [
    "Problem", "StoredSolution", "load", "save", "bundled_problems", "check_solution",
    "SolutionCheck", "RfverifyError", "InvalidProblemError", "ProblemFileError",
    "InvalidArgumentError", "OutputPathError",
    "ConeDomainError", "DataWarning", "__version__", "solve", "SolveResult", "Settings", "Status",
    "certify", "shift_to_psd",
    "solve_to_digits", "DigitsSolution", "diagnose", "Diagnosis", "Certificate",
]
