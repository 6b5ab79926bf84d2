"""Independent arbitrary-precision (mpmath) reference implementation of Algorithm 1.

- :mod:`reference.jordan` — Jordan algebra of Lorentz cones on mpmath numbers.
- :func:`reference.solve` — Algorithm 1 at a chosen precision (default 50 digits), independent
  mode (standard infeasible start), reduced SPD system with a sparse Cholesky factorisation.

By design this package does not import rfverify's numerics: it reads the problem container
(``M_sym``, ``H``, ``f``, ``w``, ``mu``, ``mu_r`` of an :class:`rfverify.Problem`) and does
everything else itself, so that agreement between the two is evidence, not an echo.  Its
precision lives in a private ``mpmath.MPContext``; the global ``mpmath.mp`` is never changed.
"""

from .ipm import ReferenceResult, solve

__all__ = ["solve", "ReferenceResult"]
