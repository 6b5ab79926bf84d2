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
                   lower triangle (CHOLMOD from cvxopt's wheel, a dependency, called through
                   ctypes with options of its own: :mod:`.cholmod_nogil`; AMD, or the
                   better of AMD and nested dissection on large matrices; symbolic analysis
                   once); the ``schur`` form, and the double-double phase's float64 oracle on
                   large contact-space matrices (:class:`rfverify.extended.mixed.CholmodMixed`)

Every factorisation after the first must have the first one's sparsity pattern (same
``indptr``/``indices``): the engines that keep a symbolic analysis rely on it.
"""

from __future__ import annotations

import contextlib
import contextvars
from typing import Protocol

import numpy as np
import scipy.sparse as sp

from . import cholmod_nogil

_on_factoring: contextvars.ContextVar = contextvars.ContextVar("rfverify_on_factoring", default=None)
"""The hook :func:`on_factoring` sets for the engines made inside its block (None: none)."""


@contextlib.contextmanager
def on_factoring(hook):
    """Within this block (of this thread), every GIL-free engine made calls ``hook()`` once, as
    its first numeric factorisation begins: the moment other threads can run beside it.  The
    k-digit path starts its set-up thread so (:class:`rfverify.verify.prepare.Preparation`)."""
    token = _on_factoring.set(hook)
    try:
        yield
    finally:
        _on_factoring.reset(token)


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
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return (f"{what} needs CHOLMOD from cvxopt, a dependency of rfverify that is missing here: "
                "pip install cvxopt (a wheel: no system library)")
    return (f"{what} needs CHOLMOD, called directly in cvxopt's libcholmod, which is not usable here (no "
            "libcholmod of CHOLMOD 3-5 found among the loaded libraries or in cvxopt's wheel): reinstall cvxopt "
            "from its wheel (pip install --force-reinstall cvxopt)")


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

    Every CHOLMOD call goes through :mod:`.cholmod_nogil` (ctypes, the GIL released) with a
    ``cholmod_common`` of this engine's own: cvxopt's module-global ``cvxopt.cholmod.options``
    is neither read nor written, so a user's settings there change nothing here and rfverify's
    never show there."""

    triangle = "lower"

    def __init__(self, what: str = "the cholmod engine"):
        try:
            import cvxopt.cholmod  # noqa: F401  (fails here, with the fix, when absent)
        except ImportError:
            raise ImportError(cholmod_missing_message(what)) from None
        self._chol = cholmod_nogil.session()
        if self._chol is None:
            raise ImportError(cholmod_missing_message(what))
        self._pattern = None
        self._on_factoring = _on_factoring.get()  # called once, at the first factorisation (on_factoring)
        self.factorisations = 0
        self.ordering = None  # "AMD" or "nested dissection or AMD, the less fill", after the analysis

    @property
    def releases_gil(self) -> bool:
        """True: the analysis, the factorisations and the solves run without the GIL
        (:mod:`.cholmod_nogil`); other threads of the process run meanwhile."""
        return True

    def analyse(self, K: sp.csc_matrix) -> None:
        """The symbolic analysis (fill-reducing order, supernodes) of the pattern of ``K``'s
        lower triangle, values ignored; the first :meth:`factor` of a matrix with this pattern
        then only factors.  Does nothing once analysed."""
        if self._pattern is None:
            self._analyse(self._lower(K))

    @staticmethod
    def _lower(K) -> sp.csc_matrix:
        K = sp.csc_matrix(K)
        K.sort_indices()
        return K

    def _analyse(self, K: sp.csc_matrix) -> None:
        n = K.shape[0]
        perm = nested_dissection(K) if n >= ND_MIN_ROWS else None
        if not self._chol.analyse(K.indptr, K.indices, perm):
            raise MemoryError(f"CHOLMOD: the symbolic analysis of a matrix of order {n} failed (out of memory)")
        # CHOLMOD tries a given order and AMD and keeps the one with less fill
        self.ordering = "AMD" if perm is None else "nested dissection or AMD, whichever fills less"
        self._pattern = (K.indptr.copy(), K.indices.copy())

    def factor(self, K: sp.csc_matrix) -> None:
        K = self._lower(K)
        n = K.shape[0]
        if self._pattern is None:
            self._analyse(K)
        elif not (np.array_equal(K.indptr, self._pattern[0]) and np.array_equal(K.indices, self._pattern[1])):
            raise ValueError("CholmodEngine: the matrix's pattern differs from the first one's")
        if self._on_factoring is not None:
            hook, self._on_factoring = self._on_factoring, None
            hook()
        column = self._chol.factorize(K.data)
        if column is None:
            raise MemoryError(f"CHOLMOD: the factorisation of a matrix of order {n} failed (out of memory or "
                              "invalid input)")
        if column < n:
            raise ArithmeticError(f"CHOLMOD: not positive definite (column {column})")
        self.factorisations += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        return self._chol.solve(rhs)

    def column_counts(self) -> np.ndarray | None:
        """Nonzeros per column of L below the diagonal, in CHOLMOD's order (statistics: nnz(L),
        Σ c_j²), read from the analysed factor itself; None before the analysis or after
        :meth:`release`."""
        found = self._chol.counts() if self._pattern is not None else None
        return None if found is None else found[1] - 1

    def permutation(self) -> np.ndarray | None:
        """CHOLMOD's fill-reducing order P (L Lᵀ = K[P][:, P]) from the symbolic analysis —
        also after a numeric factorisation that failed — or None before the analysis (or
        after :meth:`release`)."""
        if self._pattern is None:
            return None
        found = self._chol.counts()
        return None if found is None else found[0]

    def release(self) -> None:
        """Drop the factor (and its symbolic analysis): the next ``factor`` starts afresh."""
        self._chol.release()
        self._pattern = None


def cholmod_available() -> bool:
    """True when cvxopt's CHOLMOD can be called here (cvxopt is a dependency of rfverify; False
    only on a broken or hand-trimmed install, or where its libcholmod cannot be called directly:
    the forms then fall back to QDLDL)."""
    try:
        import cvxopt.cholmod  # noqa: F401
    except ImportError:
        return False
    return cholmod_nogil.available()


def schur_engine() -> FactorEngine:
    """The engine of the ``schur`` form: CHOLMOD (cvxopt, a dependency), else QDLDL where cvxopt's
    CHOLMOD cannot be called (the same factorisation of the same SPD matrix, without supernodes: 24–44×
    slower on a 10⁴-contact factor)."""
    return CholmodEngine("the schur form") if cholmod_available() else QDLDLEngine()


def schur_engine_name() -> str:
    """"CHOLMOD" or "QDLDL": which engine :func:`schur_engine` gives here."""
    return "CHOLMOD" if cholmod_available() else "QDLDL"
