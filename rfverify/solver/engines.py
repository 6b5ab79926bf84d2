"""Float64 sparse factorisation engines: the second half of a Newton solve, behind one interface.

A linear-system form (:mod:`.forms`) decides *which* matrix Algorithm 1 factors and how one
solve recovers (dv, dr̃, dz) from it; an engine only factors a matrix it is handed and solves
with the factor.  It knows nothing of contacts, cones or the KKT system.  Three engines:

``QDLDLEngine``    LDLᵀ without pivoting of a symmetric quasi-definite matrix given as its upper
                   triangle (QDLDL: AMD ordering, symbolic analysis kept from one factorisation
                   to the next); the forms (11), (14), (15), (16), and the float64 oracle
                   the double-double phase refines by default
                   (:class:`rfverify.extended.mixed.MixedCholesky`)
``SuperLUEngine``  LU with partial pivoting of a general square matrix (SuperLU, a new
                   factorisation each time); the unsymmetric form (6)
``CholmodEngine``  supernodal Cholesky of a symmetric positive definite matrix given as its
                   lower triangle (CHOLMOD through scikit-sparse, the optional extra
                   ``cholmod``; AMD ordering, symbolic analysis once); the ``schur`` form
                   (QDLDL without the extra), and the double-double phase's oracle where it
                   is installed (:class:`rfverify.extended.mixed.CholmodMixed`)

Every factorisation after the first must have the first one's sparsity pattern (same
``indptr``/``indices``): the engines that keep a symbolic analysis rely on it.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import scipy.sparse as sp


class FactorEngine(Protocol):
    """What a form asks of a factorisation engine.

    ``triangle`` says which part of a matrix ``factor`` reads: ``"upper"``, ``"lower"`` (a
    symmetric matrix given as that triangle) or ``"full"``.
    ``factor(K)`` replaces the factor with that of ``K`` (scipy CSC, float64, n × n, as
    ``triangle`` says); it raises :class:`ArithmeticError`,
    ``RuntimeError`` or ``ValueError`` when the engine detects that the matrix cannot be
    factored (a zero or non-positive pivot, a singular matrix; see :class:`QDLDLEngine` for
    the one case its library does not report).
    ``solve(rhs)`` returns K⁻¹ rhs for a float64 vector of length n, as a new array.
    ``factorisations`` counts the calls of ``factor`` that succeeded."""

    factorisations: int
    triangle: str

    def factor(self, K: sp.csc_matrix) -> None: ...

    def solve(self, rhs: np.ndarray) -> np.ndarray: ...


class QDLDLEngine:
    """LDLᵀ of a symmetric quasi-definite matrix given as its upper triangle, by QDLDL.

    The symbolic analysis (AMD ordering, elimination tree) of the first factorisation is kept
    and only the numeric factorisation is repeated.  A factorisation QDLDL refuses (its
    constructor raises ``RuntimeError`` on a zero pivot) drops the analysis, so that the next
    call starts afresh.

    Known limit, passed through unchanged: qdldl 0.1.9's ``update`` does not report a zero
    pivot; D comes back with zero or non-finite entries and the solves are not those of the
    new matrix.  The forms never trust a solve unjudged (refinement measures every solution
    against the unreduced operator, and the factorisation without δ is kept only when
    :meth:`pivots` shows the right inertia); docs/DECISIONS.md, "Factorisation engines",
    says how often this happens and why it is not changed here."""

    triangle = "upper"

    def __init__(self):
        self._solver = None
        self.factorisations = 0

    def factor(self, K: sp.csc_matrix) -> None:
        import qdldl

        try:
            if self._solver is None:
                self._solver = qdldl.Solver(K, upper=True)
            else:
                self._solver.update(K, upper=True)
        except (RuntimeError, ValueError):
            self._solver = None
            raise
        self.factorisations += 1

    def pivots(self) -> np.ndarray:
        """The diagonal D of the last factorisation, in the engine's elimination order: its
        signs are the matrix's inertia (Sylvester); a zero or non-finite entry means the
        factorisation failed."""
        return self._solver.factors()[1]

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._solver.solve(np.asarray(rhs, dtype=np.float64))


class SuperLUEngine:
    """LU with partial pivoting of a general square matrix (scipy's SuperLU), factored anew at
    every call (the pivots change with the values)."""

    triangle = "full"

    def __init__(self):
        self._lu = None
        self.factorisations = 0

    def factor(self, K: sp.csc_matrix) -> None:
        from scipy.sparse.linalg import splu

        self._lu = None
        self._lu = splu(K)  # a singular K raises RuntimeError
        self.factorisations += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._lu.solve(np.asarray(rhs, dtype=np.float64))


def cholmod_missing_message(what: str) -> str:
    """Why ``what`` cannot run without CHOLMOD, and how to install it (one message for the
    ``schur`` form and the ``cholmod`` engine of the double-double phase)."""
    return (f"{what} needs CHOLMOD through scikit-sparse: pip install 'rfverify[cholmod]' "
            "(and libsuitesparse-dev, an optimised BLAS such as libopenblas0, to build and run it)")


class CholmodEngine:
    """Supernodal Cholesky of a symmetric positive definite matrix given as its lower triangle
    (CSC), by CHOLMOD (scikit-sparse): AMD ordering and symbolic analysis on the first call,
    dense BLAS-3 kernels on the supernodes.  A matrix that is not positive definite raises
    :class:`ArithmeticError` naming CHOLMOD's complaint."""

    triangle = "lower"

    def __init__(self, what: str = "the cholmod engine"):
        try:
            import sksparse.cholmod  # noqa: F401  (fails here, with the fix, when absent)
        except ImportError:
            raise ImportError(cholmod_missing_message(what)) from None
        self._factor = None
        self.factorisations = 0

    def factor(self, K: sp.csc_matrix) -> None:
        from sksparse import cholmod

        try:
            if self._factor is None:
                self._factor = cholmod.analyze(K, mode="supernodal", ordering_method="amd")
            self._factor.cholesky_inplace(K)
        except cholmod.CholmodError as exc:
            raise ArithmeticError(f"CHOLMOD: {exc}") from None
        self.factorisations += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return np.asarray(self._factor(np.asarray(rhs, dtype=np.float64)), dtype=np.float64).reshape(-1)

    def permutation(self) -> np.ndarray | None:
        """CHOLMOD's fill-reducing order, or None before the first analysis (or after
        :meth:`release`)."""
        return None if self._factor is None else self._factor.P()

    def release(self) -> None:
        """Drop the factor (and its symbolic analysis): the next ``factor`` starts afresh."""
        self._factor = None


def cholmod_available() -> bool:
    """True when scikit-sparse's CHOLMOD imports here (the optional extra ``cholmod``)."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def schur_engine() -> FactorEngine:
    """The engine of the ``schur`` form: CHOLMOD where it imports, else QDLDL (the same
    factorisation of the same SPD matrix, without supernodes: slower on a factor that fills)."""
    return CholmodEngine("the schur form") if cholmod_available() else QDLDLEngine()


def schur_engine_name() -> str:
    """"CHOLMOD" or "QDLDL": which engine :func:`schur_engine` gives here."""
    return "CHOLMOD" if cholmod_available() else "QDLDL"
