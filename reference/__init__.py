"""Independent arbitrary-precision (mpmath) reference implementation of Algorithm 1.

- :mod:`reference.jordan` — Jordan algebra of Lorentz cones on mpmath numbers.
- :class:`reference.Solver` — Algorithm 1 at a chosen precision (default 50 digits) on one
  problem: the build (exact data, lifting, block inverses of M, W̃ = H̃M⁻¹H̃ᵀ, Cholesky
  ordering) once, then ``step`` (one iteration from a given iterate: lockstep) and ``run``
  (independent mode from the standard infeasible start, warm mode from a given iterate).
- :func:`reference.solve` — ``Solver(problem, dps).run(...)`` in one call.

By design this package does not import rfverify's numerics: it reads the problem container
(``M_sym``, ``H``, ``f``, ``w``, ``mu``, ``mu_r`` of an :class:`rfverify.Problem`) and does
everything else itself, so that agreement between the two is evidence, not an echo.  Its
precision lives in a private ``mpmath.MPContext``; the global ``mpmath.mp`` is never changed.
"""

from .ipm import Iterate, ReferenceResult, Residuals, Solver, Step, solve

__all__ = ["solve", "Solver", "Iterate", "Residuals", "Step", "ReferenceResult"]
