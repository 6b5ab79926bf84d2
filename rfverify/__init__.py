"""rfverify — verification-focused, mixed-precision toolkit for rolling-friction contact problems.

Public API (this release):

- :func:`load` / :func:`save` — FCLIB HDF5 and Siconos ``.dat`` problem files.
- :class:`Problem` — a validated global rolling-friction problem (FCLIB conventions).
- :func:`check_solution` — recompute the residuals of a candidate (v, u, r).
- :func:`solve` — Algorithm 1 (forms jqinv, qp2, reduced, reduced_factored, noscaling) or the
  Clarabel peer; :func:`solve_to_digits` — the certified k-digit path.
- :func:`certify` — digits of a solution against the mpmath reference; :func:`diagnose` —
  lockstep double/reference run.
- :mod:`rfverify.jordan` — Jordan algebra of Lorentz cones, vectorised, float64/longdouble.
- Errors: :class:`RfverifyError`, :class:`InvalidProblemError`, :class:`ProblemFileError`,
  :class:`ConeDomainError`.
"""

from .check import SolutionCheck, check_solution
from .errors import ConeDomainError, InvalidProblemError, ProblemFileError, RfverifyError
from .io import bundled_problems, load, save
from .problem import Problem, StoredSolution
from .certification import Certificate, certify
from .diagnosis import diagnose
from .refine import RefinedSolution, solve_to_digits
from .solver import SolveResult, Settings, Status, solve


__version__ = "0.1.0"

__all__ = [
    "Problem", "StoredSolution", "load", "save", "bundled_problems", "check_solution",
    "SolutionCheck", "RfverifyError", "InvalidProblemError", "ProblemFileError",
    "ConeDomainError", "__version__", "solve", "SolveResult", "Settings", "Status", "certify",
    "solve_to_digits", "RefinedSolution", "diagnose", "Certificate",
]
