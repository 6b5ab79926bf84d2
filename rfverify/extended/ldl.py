"""Sparse LDLᵀ factorisation in double-double arithmetic (compiled with numba).

The algorithm is T. Davis's up-looking LDL (the "LDL" package, ACM TOMS 2005; the same one
QDLDL uses): a symbolic pass computes the elimination tree and the column counts of L once
for a sparsity pattern, and each numeric factorisation computes row k of L by a sparse
triangular solve along the tree.  Only the upper triangle of the (symmetrically permuted)
matrix is read, in CSC form.  Used for symmetric positive definite systems, where LDLᵀ
without pivoting is backward stable.

The fill-reducing ordering is scipy's multiple minimum degree on AᵀA + A (SuperLU's
``MMD_AT_PLUS_A``), computed once from the pattern.  The float64 factors refined in
double-double (:mod:`.mixed`) are those of :mod:`rfverify.engines.factor` (QDLDL, CHOLMOD);
the multiple-precision tail takes the structure of L from :func:`numeric_ldl`
(:mod:`.wide_cholesky`).
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from . import dd
from ..algorithm.interfaces import Breakdown, OutOfTime
from .stoppable import announce, run_stoppable, seconds_left


def fill_reducing_order(pattern: sp.spmatrix) -> np.ndarray:
    """perm with A[perm][:, perm] having little fill (minimum degree of the pattern)."""
    from scipy.sparse.linalg import splu

    n = pattern.shape[0]
    A = sp.csc_matrix(pattern, dtype=np.float64)
    A = abs(A) + abs(A.T)
    A.data[:] = 1.0
    A = (A + sp.identity(n, format="csc") * (n + 1.0)).tocsc()  # diagonally dominant: no pivoting
    lu = splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options=dict(SymmetricMode=True))
    return np.argsort(lu.perm_c).astype(np.int64)  # Pr·A·Pc = A[p][:, p]


# The kernels below take their work arrays from the caller: allocating inside compiled code
# compiles numba's np.zeros/np.empty/np.full for each dtype and shape kind, time a cold
# start pays and a warm one does not save (see docs/DECISIONS.md, "Cold start").
def symbolic_ldl(n, Ap, Ai):
    """(elimination tree parent, column pointers Lp of L) of the upper-CSC pattern (Ap, Ai)."""
    parent = np.full(n, -1, dtype=np.int64)
    Lp = np.zeros(n + 1, dtype=np.int64)
    _symbolic_kernel(n, Ap, Ai, parent, np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int64), Lp)
    return parent, Lp


@numba.njit(cache=True, nogil=True)
def _symbolic_kernel(n, Ap, Ai, parent, flag, lnz, Lp):
    for k in range(n):
        flag[k] = k
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            if i < k:
                while flag[i] != k:
                    if parent[i] == -1:
                        parent[i] = k
                    lnz[i] += 1
                    flag[i] = k
                    i = parent[i]
    for k in range(n):
        Lp[k + 1] = Lp[k] + lnz[k]


def ldl_workspace(n):
    """flag and pattern for :func:`_row_pattern`; lnz, the entries of each column of L so far."""
    return np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int64)


@numba.njit(cache=True, nogil=True, inline="always")
def _row_pattern(k, Ap, Ai, parent, flag, pattern, n):
    """The nonzero pattern of row k of L (the columns reached from column k's upper entries
    along the elimination tree), in topological order in pattern[top:n]; returns top."""
    top = n
    flag[k] = k
    for p in range(Ap[k], Ap[k + 1]):
        i = Ai[p]
        if i > k:
            continue
        ln = 0
        while flag[i] != k:
            pattern[ln] = i
            ln += 1
            flag[i] = k
            i = parent[i]
        while ln > 0:
            top -= 1
            ln -= 1
            pattern[top] = pattern[ln]
    return top


@numba.njit(cache=True, nogil=True)
def numeric_ldl(n, Ap, Ai, Axh, Axl, Lp, parent, Li, Lxh, Lxl, Dh, Dl, yh, yl, flag, pattern, lnz, stop):
    """Returns -1 on success, else the index of the first non-positive pivot, or -2 when
    ``stop[0]`` (polled once per row; :mod:`.stoppable`) became nonzero.  Work arrays:
    yh, yl zero (n,); flag, pattern, lnz from :func:`ldl_workspace`."""
    for k in range(n):
        if stop[0] != 0:
            return -2
        for p in range(Ap[k], Ap[k + 1]):
            if Ai[p] <= k:
                yh[Ai[p]], yl[Ai[p]] = dd.add(yh[Ai[p]], yl[Ai[p]], Axh[p], Axl[p])
        top = _row_pattern(k, Ap, Ai, parent, flag, pattern, n)
        dh, dl = yh[k], yl[k]
        yh[k] = 0.0
        yl[k] = 0.0
        while top < n:
            i = pattern[top]
            top += 1
            vh, vl = yh[i], yl[i]
            yh[i] = 0.0
            yl[i] = 0.0
            p2 = Lp[i] + lnz[i]
            for p in range(Lp[i], p2):
                j = Li[p]
                yh[j], yl[j] = dd.fms_acc(yh[j], yl[j], Lxh[p], Lxl[p], vh, vl)
            lh, ll = dd.div(vh, vl, Dh[i], Dl[i])
            dh, dl = dd.fms_acc(dh, dl, lh, ll, vh, vl)
            Li[p2] = k
            Lxh[p2] = lh
            Lxl[p2] = ll
            lnz[i] += 1
        if not dh > 0.0:
            return k
        Dh[k] = dh
        Dl[k] = dl
    return -1


@numba.njit(cache=True, nogil=True)
def _solve(n, Lp, Li, Lxh, Lxl, Dh, Dl, xh, xl):
    """In place: x ← (L D Lᵀ)⁻¹ x (x already permuted)."""
    for j in range(n):
        vh, vl = xh[j], xl[j]
        for p in range(Lp[j], Lp[j + 1]):
            i = Li[p]
            xh[i], xl[i] = dd.fms_acc(xh[i], xl[i], Lxh[p], Lxl[p], vh, vl)
    for j in range(n):
        xh[j], xl[j] = dd.div(xh[j], xl[j], Dh[j], Dl[j])
    for j in range(n - 1, -1, -1):
        sh, sl = xh[j], xl[j]
        for p in range(Lp[j], Lp[j + 1]):
            i = Li[p]
            sh, sl = dd.fms_acc(sh, sl, Lxh[p], Lxl[p], xh[i], xl[i])
        xh[j] = sh
        xl[j] = sl


def symmetric_pattern(pattern: sp.spmatrix) -> sp.csc_matrix:
    """|A| + |Aᵀ| + I of a pattern (CSC, float64): symmetric, with every diagonal entry."""
    n = pattern.shape[0]
    P = sp.csc_matrix(pattern, dtype=np.float64)
    return (abs(P) + abs(P.T) + sp.identity(n, format="csc")).tocsc()


def upper_csc(P: sp.spmatrix):
    """(Ap, Ai, keys) of the upper triangle of the symmetric pattern P in CSC, rows sorted in
    each column; keys[k] = column·n + row of the k-th stored entry, increasing (what
    :func:`upper_positions` searches)."""
    n = P.shape[0]
    U = sp.triu(P, format="csc")
    U.sort_indices()
    Ap = U.indptr.astype(np.int64)
    Ai = U.indices.astype(np.int64)
    cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(Ap))
    return Ap, Ai, cols * n + Ai


def upper_positions(keys: np.ndarray, n: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Index into an upper-CSC value array with stored ``keys`` (:func:`upper_csc`) of the
    entries (a[k], b[k]) in its own order, either triangle (the symmetric partner is found)."""
    wanted = np.maximum(a, b) * n + np.minimum(a, b)
    pos = np.searchsorted(keys, wanted)
    if np.any(pos >= keys.size) or np.any(keys[np.minimum(pos, keys.size - 1)] != wanted):
        raise ValueError("entry outside the sparsity pattern")
    return pos


STOPPABLE_ABOVE = 1e8
"""Multiply-adds (about a second) above which a numeric factorisation runs on a helper thread
that the time limit and Ctrl-C can stop (:mod:`.stoppable`); smaller ones run inline."""
TYPICAL_RATE = 1.35e8
"""Double-double multiply-adds per second of :func:`numeric_ldl`, measured on 3-D Laplacians
of 8000–64 000 rows (1.33e8–1.37e8 on one core of a 2-core AMD EPYC, the other core busy;
docs/DECISIONS.md, "Stoppable kernels"): the expected time a progress line announces."""
FASTEST_RATE = 1e9
"""A rate :func:`numeric_ldl` does not reach (7× :data:`TYPICAL_RATE`): a factorisation that
would take longer than the time left even at this rate is not started."""
ANNOUNCE_ABOVE = 10.0
"""Expected seconds above which a factorisation is announced by a progress line first."""
MEMORY_SHARE = 0.8
"""The share of the memory available (``MemAvailable``) that L's arrays may take."""


class FactorTooLarge(Breakdown):
    """A double-double factorisation refused before it started: its factor does not fit in the
    memory available.  The run ends with the best iterate so far (a :class:`Breakdown`)."""


def memory_available() -> int | None:
    """Bytes the kernel could give this process now without swapping (Linux's ``MemAvailable``),
    or None where that is not known (no ``/proc/meminfo``)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


class DDCholesky:
    """LDLᵀ of symmetric positive definite matrices with a fixed sparsity pattern.

    ``pattern`` (n×n, any symmetric pattern) fixes the ordering and the symbolic factor.
    Numeric values are given as double-double arrays aligned with :attr:`upper` — the upper
    triangle of the permuted pattern in CSC order — whose position of an original entry
    (i, j) is :meth:`positions`.
    """

    def __init__(self, pattern: sp.spmatrix, perm: np.ndarray | None = None):
        n = pattern.shape[0]
        P = symmetric_pattern(pattern)
        self.n = n
        self.perm = fill_reducing_order(P) if perm is None else np.asarray(perm, dtype=np.int64)
        self.iperm = np.empty(n, dtype=np.int64)
        self.iperm[self.perm] = np.arange(n)
        # _keys: col * n + row of each stored upper entry, in permuted coordinates
        self.Ap, self.Ai, self._keys = upper_csc(P[self.perm][:, self.perm])
        self.parent, self.Lp = symbolic_ldl(n, self.Ap, self.Ai)
        self.Li = self.Lxh = self.Lxl = None  # L's entries: allocated by the first factor(), once they fit
        self._multiply_adds = None
        self.Dh = np.zeros(n)
        self.Dl = np.zeros(n)
        self.factored = False

    @property
    def multiply_adds(self) -> float:
        """Double-double multiply-adds of one numeric factorisation: Σ c(c − 1)/2 over the
        column counts c of L (row k of L updates, for each of its entries in a column, the
        entries of that column above row k)."""
        if self._multiply_adds is None:
            c = np.diff(self.Lp).astype(np.float64)
            self._multiply_adds = float(np.sum(c * (c - 1.0)) / 2.0)
        return self._multiply_adds

    @property
    def factor_bytes(self) -> int:
        """Memory of L's entries: a row index and a double-double value each (24 bytes)."""
        return 24 * self.nnz_L

    def _allocate(self) -> None:
        """L's arrays, refused (:class:`FactorTooLarge`) where they would take more than
        :data:`MEMORY_SHARE` of the memory available now (docs/DECISIONS.md, "Stoppable kernels")."""
        if self.Li is not None:
            return
        have = memory_available()
        refusal = (f"the double-double factorisation of {self.n} rows was not started: its factor needs "
                   f"{self.factor_bytes / 2**30:.1f} GiB (nnz(L) = {self.nnz_L:.3g})")
        if have is not None and self.factor_bytes > MEMORY_SHARE * have:
            raise FactorTooLarge(f"{refusal}, {have / 2**30:.1f} GiB is available")
        try:
            self.Li = np.zeros(self.nnz_L, dtype=np.int64)
            self.Lxh = np.zeros(self.nnz_L)
            self.Lxl = np.zeros(self.nnz_L)
        except MemoryError:
            self.Li = self.Lxh = self.Lxl = None
            raise FactorTooLarge(f"{refusal}, and numpy could not allocate it") from None

    def _refuse_past_deadline(self) -> None:
        """:class:`OutOfTime` before starting a factorisation that would end, even at
        :data:`FASTEST_RATE`, after the time limit (:func:`.stoppable.seconds_left`)."""
        left = seconds_left()
        if left is None:
            return
        fastest = self.multiply_adds / FASTEST_RATE
        if fastest > left:
            raise OutOfTime(f"the double-double factorisation of {self.n} rows was not started: its "
                            f"{self.multiply_adds:.2g} multiply-adds take at least {fastest:.0f} s, "
                            f"{max(left, 0.0):.0f} s were left")

    def prepare(self) -> None:
        """Nothing to do ahead: the symbolic analysis is done here, on construction (the float64
        factors a back end may hold instead, :mod:`.mixed`, have the same hook)."""
        return None

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    @property
    def nnz_upper(self) -> int:
        return int(self.Ai.size)

    def positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Index into the upper-CSC value array of the original entries (rows[k], cols[k])
        (either triangle: the symmetric partner is found)."""
        return upper_positions(self._keys, self.n, self.iperm[np.asarray(rows, dtype=np.int64)],
                                self.iperm[np.asarray(cols, dtype=np.int64)])

    def factor(self, Axh: np.ndarray, Axl: np.ndarray) -> int:
        """Numeric factorisation; returns -1 on success, else the first non-positive pivot.
        The first one is refused where L cannot fit in memory (:class:`FactorTooLarge`); a
        large one (:data:`STOPPABLE_ABOVE`) where it cannot end before the time limit
        (:class:`OutOfTime`), and it runs where the time limit and Ctrl-C can stop it
        (:func:`.stoppable.run_stoppable`)."""
        self.factored = False
        self._allocate()
        args = (self.n, self.Ap, self.Ai, Axh, Axl, self.Lp, self.parent, self.Li, self.Lxh, self.Lxl, self.Dh,
                self.Dl, np.zeros(self.n), np.zeros(self.n), *ldl_workspace(self.n))
        if self.multiply_adds < STOPPABLE_ABOVE:
            bad = numeric_ldl(*args, np.zeros(1, dtype=np.int64))
        else:
            self._refuse_past_deadline()
            what = f"the double-double factorisation of {self.n} rows"
            expected = self.multiply_adds / TYPICAL_RATE
            if expected > ANNOUNCE_ABOVE:
                announce(f"{what}: nnz(L) = {self.nnz_L:.3g} ({self.factor_bytes / 2**30:.1f} GiB), "
                         f"{self.multiply_adds:.2g} multiply-adds, about {_duration(expected)} at "
                         f"{TYPICAL_RATE:.2g} a second (Ctrl-C or the time limit stop it)")
            bad = run_stoppable(numeric_ldl, args, f"{what} ({self.multiply_adds:.2g} multiply-adds)")
        self.factored = bad == -1
        return int(bad)

    def solve(self, bh: np.ndarray, bl: np.ndarray):
        """x = A⁻¹ b in double-double (b in original ordering).  Only after a successful
        :meth:`factor`: a failed one leaves a partial factor (or none, where it was refused)."""
        if not self.factored:
            raise RuntimeError("DDCholesky.solve called without a successful factor(): the caller must check "
                               "factor()'s result (-1) or .factored first")
        xh = np.ascontiguousarray(bh[self.perm])
        xl = np.ascontiguousarray(bl[self.perm])
        _solve(self.n, self.Lp, self.Li, self.Lxh, self.Lxl, self.Dh, self.Dl, xh, xl)
        oh = np.empty(self.n)
        ol = np.empty(self.n)
        oh[self.perm] = xh
        ol[self.perm] = xl
        return oh, ol


def _duration(seconds: float) -> str:
    """"40 s", "12 min", "3.4 h"."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"
