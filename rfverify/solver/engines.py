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
                   lower triangle (CHOLMOD from cvxopt's wheel, a dependency; AMD, or the
                   better of AMD and nested dissection on large matrices; symbolic analysis
                   once); the ``schur`` form, and the double-double phase's float64 oracle on
                   large contact-space matrices (:class:`rfverify.extended.mixed.CholmodMixed`)

Every factorisation after the first must have the first one's sparsity pattern (same
``indptr``/``indices``): the engines that keep a symbolic analysis rely on it.
"""

from __future__ import annotations

import threading
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from . import cholmod_nogil


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
    return (f"{what} needs CHOLMOD from cvxopt, a dependency of rfverify that is missing here: "
            "pip install cvxopt (a wheel: no system library)")


ND_MIN_ROWS = 2000
"""From this order on, the analysis is offered a nested-dissection ordering (METIS, through
pymetis) beside CHOLMOD's AMD, and CHOLMOD keeps the one with less fill (measured: AMD wins on
random problems, nested dissection on granular beds, by 5.7× in time and 2.4× in memory on a
96k-contact bed; docs/DECISIONS.md, "A supernodal Cholesky from a wheel").  Below it the
ordering costs more than it can save."""


def nested_dissection(K: sp.spmatrix) -> np.ndarray | None:
    """A nested-dissection order of the graph of the symmetric matrix given by one triangle
    ``K`` (pymetis), or None where pymetis is not installed (a platform without its wheel)."""
    try:
        import pymetis
    except ImportError:
        return None
    G = sp.csr_matrix(K, copy=True)
    G.data[:] = 1.0
    G = (G + G.T).tocsr()
    G.setdiag(0)
    G.eliminate_zeros()
    G.sort_indices()
    xadj, adjncy = G.indptr.astype(np.int64), G.indices.astype(np.int64)
    if hasattr(pymetis, "CSRAdjacency"):  # pymetis 2025: xadj=/adjncy= are deprecated, to be removed in 2027
        perm, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(xadj, adjncy))
    else:
        perm, _ = pymetis.nested_dissection(xadj=xadj, adjncy=adjncy)
    return np.asarray(perm, dtype=np.int64)


class CholmodEngine:
    """Supernodal Cholesky LLᵀ of a symmetric positive definite matrix given as its lower
    triangle (CSC), by CHOLMOD as cvxopt's wheel ships it (SuiteSparse with OpenBLAS inside; no
    system library): the symbolic analysis on the first call — AMD, or for large matrices the
    better of AMD and nested dissection (:data:`ND_MIN_ROWS`) — then a numeric refactorisation
    per call, dense BLAS-3 kernels on the supernodes.  A matrix that is not positive definite
    raises :class:`ArithmeticError` naming the column CHOLMOD stopped at.

    cvxopt's CHOLMOD options are module-global: each call sets the ones it relies on
    (supernodal LLᵀ, so that an indefinite matrix is refused rather than given an LDLᵀ) and
    restores the caller's."""

    triangle = "lower"

    def __init__(self, what: str = "the cholmod engine"):
        try:
            import cvxopt.cholmod  # noqa: F401  (fails here, with the fix, when absent)
        except ImportError:
            raise ImportError(cholmod_missing_message(what)) from None
        self._factor = None
        self._A = None
        self._pattern = None
        self._pattern64 = None  # (indptr, indices) as int64, for the GIL-free call
        self._numeric = False  # a numeric factorisation has succeeded since the analysis
        self._nogil = cholmod_nogil.factorizer()  # None: cvxopt's own call (it holds the GIL)
        self.factorisations = 0
        self.ordering = None  # "AMD" or "nested dissection or AMD, the less fill", after the analysis

    @property
    def releases_gil(self) -> bool:
        """True when the numeric factorisations run without the GIL
        (:mod:`.cholmod_nogil`): other threads of the process run meanwhile."""
        return self._nogil is not None

    def analyse(self, K: sp.csc_matrix) -> None:
        """The symbolic analysis (fill-reducing order, supernodes) of the pattern of ``K``'s
        lower triangle, values ignored; the first :meth:`factor` of a matrix with this pattern
        then only factors.  Does nothing once analysed."""
        if self._factor is None:
            self._analyse(self._lower(K))

    @staticmethod
    def _lower(K) -> sp.csc_matrix:
        K = sp.csc_matrix(K)
        K.sort_indices()
        return K

    def _analyse(self, K: sp.csc_matrix) -> None:
        import cvxopt
        from cvxopt import cholmod

        n = K.shape[0]
        cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(K.indptr))
        A = cvxopt.spmatrix(cvxopt.matrix(np.ascontiguousarray(K.data, dtype=np.float64)),
                            cvxopt.matrix(K.indices.astype(np.int64)), cvxopt.matrix(cols), (n, n))
        perm = nested_dissection(K) if n >= ND_MIN_ROWS else None
        with _cholmod_options(supernodal=2):
            if perm is None:
                factor = cholmod.symbolic(A, uplo="L")
                ordering = "AMD"
            else:  # CHOLMOD tries the given order and AMD and keeps the one with less fill
                factor = cholmod.symbolic(A, p=cvxopt.matrix(perm.astype(np.int64)), uplo="L")
                ordering = "nested dissection or AMD, whichever fills less"
        self._A, self._factor, self.ordering = A, factor, ordering
        self._numeric = False
        self._pattern = (K.indptr.copy(), K.indices.copy())
        self._pattern64 = (K.indptr.astype(np.int64), K.indices.astype(np.int64))

    def factor(self, K: sp.csc_matrix) -> None:
        import cvxopt
        from cvxopt import cholmod

        K = self._lower(K)
        n = K.shape[0]
        if self._factor is None:
            self._analyse(K)
        elif not (np.array_equal(K.indptr, self._pattern[0]) and np.array_equal(K.indices, self._pattern[1])):
            raise ValueError("CholmodEngine: the matrix's pattern differs from the first one's")
        values = np.ascontiguousarray(K.data, dtype=np.float64)
        column = None
        if self._nogil is not None:
            column = self._nogil.factorize(self._factor, *self._pattern64, values)
        if column is None:  # cvxopt's own call: no GIL-free path, or CHOLMOD reported an error (it says which)
            self._A.V = cvxopt.matrix(values)
            with _cholmod_options(supernodal=2):
                try:
                    cholmod.numeric(self._A, self._factor)
                except ArithmeticError as exc:
                    raise ArithmeticError(f"CHOLMOD: not positive definite (column {exc})") from None
        elif column < n:
            raise ArithmeticError(f"CHOLMOD: not positive definite (column {column})")
        self._numeric = True
        self.factorisations += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        import cvxopt
        from cvxopt import cholmod

        b = cvxopt.matrix(np.array(rhs, dtype=np.float64).reshape(-1))
        cholmod.solve(self._factor, b)
        return np.array(b, dtype=np.float64).reshape(-1)

    def column_counts(self) -> np.ndarray | None:
        """Nonzeros per column of L below the diagonal, in CHOLMOD's order (statistics: nnz(L),
        Σ c_j²), read from the analysed factor itself; None before the analysis, after
        :meth:`release`, or where the factor's fields cannot be read here
        (:func:`.cholmod_nogil.factor_counts`)."""
        if self._factor is None or self._nogil is None:
            return None
        found = cholmod_nogil.factor_counts(self._factor)
        return None if found is None else found[1] - 1

    def permutation(self) -> np.ndarray | None:
        """CHOLMOD's fill-reducing order P (L Lᵀ = K[P][:, P]), or None before the first
        numeric factorisation (or after :meth:`release`)."""
        if self._factor is None or not self._numeric:  # cvxopt solves only with a numeric factor
            return None
        found = cholmod_nogil.factor_counts(self._factor) if self._nogil is not None else None
        if found is not None:
            return found[0]
        import cvxopt
        from cvxopt import cholmod

        n = self._A.size[0]
        p = cvxopt.matrix(np.arange(n, dtype=np.float64))
        cholmod.solve(self._factor, p, sys=7)  # x = P b
        return np.array(p, dtype=np.float64).reshape(-1).astype(np.int64)

    def release(self) -> None:
        """Drop the factor (and its symbolic analysis): the next ``factor`` starts afresh."""
        self._factor = None
        self._A = None
        self._pattern = None
        self._pattern64 = None
        self._numeric = False


_options_lock = threading.RLock()


class _cholmod_options:
    """Set cvxopt's global CHOLMOD options for a block, restoring the caller's afterwards; one
    block at a time in the process (the k-digit path analyses on a second thread), so that two
    blocks cannot restore each other's settings."""

    def __init__(self, **options):
        self.options = options

    def __enter__(self):
        from cvxopt import cholmod

        _options_lock.acquire()
        try:
            self.saved = dict(cholmod.options)
            cholmod.options.update(self.options)
        except BaseException:
            _options_lock.release()
            raise

    def __exit__(self, *exc):
        from cvxopt import cholmod

        try:
            cholmod.options.clear()
            cholmod.options.update(self.saved)
        finally:
            _options_lock.release()
        return False


def cholmod_available() -> bool:
    """True when cvxopt's CHOLMOD imports here (a dependency of rfverify; False only on a
    broken or hand-trimmed install, where the forms fall back to QDLDL)."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


def schur_engine() -> FactorEngine:
    """The engine of the ``schur`` form: CHOLMOD (cvxopt, a dependency), else QDLDL where cvxopt
    does not import (the same factorisation of the same SPD matrix, without supernodes: 24–44×
    slower on a 10⁴-contact factor)."""
    return CholmodEngine("the schur form") if cholmod_available() else QDLDLEngine()


def schur_engine_name() -> str:
    """"CHOLMOD" or "QDLDL": which engine :func:`schur_engine` gives here."""
    return "CHOLMOD" if cholmod_available() else "QDLDL"
