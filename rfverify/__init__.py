"""rfverify — verification-focused, mixed-precision toolkit for rolling-friction contact problems.

Public API (this release):

- :func:`load` / :func:`save` — FCLIB HDF5 and Siconos ``.dat`` problem files.
- :class:`Problem` — a validated global rolling-friction problem (FCLIB conventions).
- :func:`check_solution` — recompute the residuals of a candidate (v, u, r).
- :mod:`rfverify.jordan` — Jordan algebra of Lorentz cones, vectorised, float64/longdouble.
- Errors: :class:`RfverifyError`, :class:`InvalidProblemError`, :class:`ProblemFileError`,
  :class:`ConeDomainError`.
"""

from .check import SolutionCheck, check_solution
from .errors import ConeDomainError, InvalidProblemError, ProblemFileError, RfverifyError
from .io import bundled_problems, load, save
from .problem import Problem, StoredSolution

__version__ = "0.1.0"

__all__ = [
    "Problem", "StoredSolution", "load", "save", "bundled_problems", "check_solution",
    "SolutionCheck", "RfverifyError", "InvalidProblemError", "ProblemFileError",
    "ConeDomainError", "__version__",
]
