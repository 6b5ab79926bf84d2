"""Sparse LDLᵀ factorisation in double-double arithmetic (compiled with numba).

The algorithm is T. Davis's up-looking LDL (the "LDL" package, ACM TOMS 2005; the same one
QDLDL uses): a symbolic pass computes the elimination tree and the column counts of L once
for a sparsity pattern, and each numeric factorisation computes row k of L by a sparse
triangular solve along the tree.  Only the upper triangle of the (symmetrically permuted)
matrix is read, in CSC form.  Used for symmetric positive definite systems, where LDLᵀ
without pivoting is backward stable.

The fill-reducing ordering is scipy's multiple minimum degree on AᵀA + A (SuperLU's
``MMD_AT_PLUS_A``), computed once from the pattern.
"""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp

from . import dd


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
def _symbolic(n, Ap, Ai):
    """(elimination tree parent, column pointers Lp of L) of the upper-CSC pattern (Ap, Ai)."""
    parent = np.full(n, -1, dtype=np.int64)
    Lp = np.zeros(n + 1, dtype=np.int64)
    _symbolic_kernel(n, Ap, Ai, parent, np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int64), Lp)
    return parent, Lp


@numba.njit(cache=True)
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


def _workspace(n):
    """flag and pattern for :func:`_row_pattern`; lnz, the entries of each column of L so far."""
    return np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64), np.zeros(n, dtype=np.int64)


@numba.njit(cache=True, inline="always")
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


@numba.njit(cache=True)
def _numeric(n, Ap, Ai, Axh, Axl, Lp, parent, Li, Lxh, Lxl, Dh, Dl, yh, yl, flag, pattern, lnz):
    """Returns -1 on success, else the index of the first non-positive pivot.  Work arrays:
    yh, yl zero (n,); flag, pattern, lnz from :func:`_workspace`."""
    for k in range(n):
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


@numba.njit(cache=True)
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


class DDCholesky:
    """LDLᵀ of symmetric positive definite matrices with a fixed sparsity pattern.

    ``pattern`` (n×n, any symmetric pattern) fixes the ordering and the symbolic factor.
    Numeric values are given as double-double arrays aligned with :attr:`upper` — the upper
    triangle of the permuted pattern in CSC order — whose position of an original entry
    (i, j) is :meth:`positions`.
    """

    def __init__(self, pattern: sp.spmatrix, perm: np.ndarray | None = None):
        n = pattern.shape[0]
        P = sp.csc_matrix(pattern, dtype=np.float64)
        P = (abs(P) + abs(P.T) + sp.identity(n, format="csc")).tocsc()
        self.n = n
        self.perm = fill_reducing_order(P) if perm is None else np.asarray(perm, dtype=np.int64)
        self.iperm = np.empty(n, dtype=np.int64)
        self.iperm[self.perm] = np.arange(n)
        U = sp.triu(P[self.perm][:, self.perm], format="csc")
        U.sort_indices()
        self.Ap = U.indptr.astype(np.int64)
        self.Ai = U.indices.astype(np.int64)
        self.parent, self.Lp = _symbolic(n, self.Ap, self.Ai)
        nnz = int(self.Lp[-1])
        self.Li = np.zeros(nnz, dtype=np.int64)
        self.Lxh = np.zeros(nnz)
        self.Lxl = np.zeros(nnz)
        self.Dh = np.zeros(n)
        self.Dl = np.zeros(n)
        # key of each stored upper entry in permuted coordinates: col * n + row
        cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.Ap))
        self._keys = cols * n + self.Ai
        self.factored = False

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    @property
    def nnz_upper(self) -> int:
        return int(self.Ai.size)

    def positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Index into the upper-CSC value array of the original entries (rows[k], cols[k])
        (either triangle: the symmetric partner is found)."""
        a = self.iperm[np.asarray(rows, dtype=np.int64)]
        b = self.iperm[np.asarray(cols, dtype=np.int64)]
        r, c = np.minimum(a, b), np.maximum(a, b)
        keys = c * self.n + r
        pos = np.searchsorted(self._keys, keys)
        if np.any(pos >= self._keys.size) or np.any(self._keys[np.minimum(pos, self._keys.size - 1)] != keys):
            raise ValueError("entry outside the sparsity pattern")
        return pos

    def factor(self, Axh: np.ndarray, Axl: np.ndarray) -> int:
        """Numeric factorisation; returns -1 on success, else the first non-positive pivot."""
        bad = _numeric(self.n, self.Ap, self.Ai, Axh, Axl, self.Lp, self.parent, self.Li, self.Lxh,
                       self.Lxl, self.Dh, self.Dl, np.zeros(self.n), np.zeros(self.n), *_workspace(self.n))
        self.factored = bad < 0
        return int(bad)

    def solve(self, bh: np.ndarray, bl: np.ndarray):
        """x = A⁻¹ b in double-double (b in original ordering)."""
        xh = np.ascontiguousarray(bh[self.perm])
        xl = np.ascontiguousarray(bl[self.perm])
        _solve(self.n, self.Lp, self.Li, self.Lxh, self.Lxl, self.Dh, self.Dl, xh, xl)
        oh = np.empty(self.n)
        ol = np.empty(self.n)
        oh[self.perm] = xh
        ol[self.perm] = xl
        return oh, ol


@numba.njit(cache=True)
def _numeric_double(n, Ap, Ai, Ax, Lp, parent, Li, Lx, D, y, flag, pattern, lnz):
    """:func:`_numeric` in float64 (same algorithm, same symbolic factor; y zero (n,))."""
    for k in range(n):
        for p in range(Ap[k], Ap[k + 1]):
            if Ai[p] <= k:
                y[Ai[p]] += Ax[p]
        top = _row_pattern(k, Ap, Ai, parent, flag, pattern, n)
        d = y[k]
        y[k] = 0.0
        while top < n:
            i = pattern[top]
            top += 1
            v = y[i]
            y[i] = 0.0
            p2 = Lp[i] + lnz[i]
            for p in range(Lp[i], p2):
                y[Li[p]] -= Lx[p] * v
            li = v / D[i]
            d -= li * v
            Li[p2] = k
            Lx[p2] = li
            lnz[i] += 1
        if not d > 0.0:
            return k
        D[k] = d
    return -1


@numba.njit(cache=True)
def _solve_double(n, Lp, Li, Lx, D, x):
    """In place: x ← (L D Lᵀ)⁻¹ x in float64 (x already permuted)."""
    for j in range(n):
        v = x[j]
        for p in range(Lp[j], Lp[j + 1]):
            x[Li[p]] -= Lx[p] * v
    for j in range(n):
        x[j] /= D[j]
    for j in range(n - 1, -1, -1):
        s = x[j]
        for p in range(Lp[j], Lp[j + 1]):
            s -= Lx[p] * x[Li[p]]
        x[j] = s


@numba.njit(cache=True)
def _symmetric_residual(n, Ap, Ai, Axh, Axl, bh, bl, xh, xl, rh, rl, ax):
    """r = b − A x in double-double, A symmetric given by its upper triangle in CSC; returns
    the componentwise backward error max_i |r_i| / (|A||x| + |b|)_i (Oettli–Prager), which,
    unlike a normwise one, does not let the large rows of a badly scaled matrix hide the
    error in the small ones.  ax: zero work array (n,)."""
    for i in range(n):
        rh[i] = bh[i]
        rl[i] = bl[i]
    for j in range(n):
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            rh[i], rl[i] = dd.fms_acc(rh[i], rl[i], Axh[p], Axl[p], xh[j], xl[j])
            ax[i] += abs(Axh[p] * xh[j])
            if i != j:
                rh[j], rl[j] = dd.fms_acc(rh[j], rl[j], Axh[p], Axl[p], xh[i], xl[i])
                ax[j] += abs(Axh[p] * xh[i])
    worst = 0.0
    for i in range(n):
        den = ax[i] + abs(bh[i])
        if den > 0.0:
            e = abs(rh[i]) / den
            if not e <= worst:  # NaN propagates
                worst = e
    return worst


def refine_in_double_double(Ap, Ai, A, bh, bl, oracle, max_steps: int):
    """Iterative refinement of A x = b to double-double accuracy with a float64 ``oracle``
    (``oracle(r)`` ≈ A⁻¹r in float64: a factor of A rounded to double), as in SoPlex's
    iterative refinement.  ``A`` = (high, low) values of the upper triangle in CSC (``Ap``,
    ``Ai``); b = (bh, bl).  Stops at a componentwise backward error below 1e-31, after
    ``max_steps``, or when a step does not halve it (stalled or NaN: the best iterate is kept).
    Returns (best backward error, (xh, xl), steps taken)."""
    n = Ap.size - 1
    pbh = np.ascontiguousarray(bh, dtype=np.float64)
    pbl = np.ascontiguousarray(bl, dtype=np.float64)
    rh, rl = pbh.copy(), pbl.copy()
    best, best_x = math.inf, (np.zeros(n), np.zeros(n))
    steps = 0
    for steps in range(1, max_steps + 1):
        d = oracle(rh)
        nh, nl = np.empty(n), np.empty(n)
        dd.vadd(best_x[0], best_x[1], d, np.zeros(n), nh, nl)
        backward = _symmetric_residual(n, Ap, Ai, A[0], A[1], pbh, pbl, nh, nl, rh, rl, np.zeros(n))
        if not backward < 0.5 * best:  # stalled (or NaN): keep the best solution
            best = min(best, backward) if backward == backward else best
            break
        best, best_x = backward, (nh, nl)
        if backward < 1e-31:
            break
    return best, best_x, steps


class MixedCholesky(DDCholesky):
    """:class:`DDCholesky` whose factorisation is done in float64 and whose solves are refined
    to double-double accuracy (a double "oracle" with double-double residuals, as in SoPlex's
    iterative refinement): 15–20× cheaper per factorisation.

    Refinement converges when the double factor is accurate in the matrix's own scaling, which
    holds for the scaled contact-space matrix I + F⁻¹W̃F⁻ᵀ while W̃ is well conditioned on the
    contacts that carry load, however small μ is.  Where it does not (the backward error of a
    solve stays above ``backward_target``, or the double factorisation meets a non-positive
    pivot) the matrix is refactored in double-double and every later factorisation stays in
    double-double: :attr:`precision` says which is in use, :attr:`fallback_reason` why.
    """

    def __init__(self, pattern: sp.spmatrix, perm: np.ndarray | None = None,
                 backward_target: float = 1e-29, max_steps: int = 12):
        super().__init__(pattern, perm)
        self.Lx = np.zeros(self.nnz_L)
        self.backward_target = backward_target
        self.max_steps = max_steps
        self.precision = "mixed"
        self.fallback_reason = ""
        self.last_backward_error = math.nan
        self.last_steps = 0
        self.solves = 0  # statistics: solves and refinement steps so far
        self.refinement_steps = 0
        self._A = None

    def _fall_back(self, reason: str) -> int:
        self.precision = "double-double"
        self.fallback_reason = reason
        return super().factor(*self._A)

    def factor(self, Axh: np.ndarray, Axl: np.ndarray) -> int:
        self._A = (np.ascontiguousarray(Axh, dtype=np.float64).copy(),
                   np.ascontiguousarray(Axl, dtype=np.float64).copy())
        if self.precision == "double-double":
            return super().factor(*self._A)
        bad = _numeric_double(self.n, self.Ap, self.Ai, self._A[0], self.Lp, self.parent, self.Li, self.Lx,
                              self.Dh, np.zeros(self.n), *_workspace(self.n))
        if bad >= 0:
            return self._fall_back(f"non-positive pivot {bad} in the float64 factorisation")
        self.factored = True
        return -1

    def solve(self, bh: np.ndarray, bl: np.ndarray):
        """x = A⁻¹ b to double-double accuracy (b in original ordering)."""
        if self.precision == "double-double":
            return super().solve(bh, bl)
        n = self.n

        def oracle(rh):
            d = rh.copy()  # the correction's right-hand side to float64: its error is refined away
            _solve_double(n, self.Lp, self.Li, self.Lx, self.Dh, d)
            return d

        best, best_x, steps = refine_in_double_double(self.Ap, self.Ai, self._A, bh[self.perm], bl[self.perm],
                                                      oracle, self.max_steps)
        self.last_backward_error, self.last_steps = best, steps
        self.solves += 1
        self.refinement_steps += steps
        if not best <= self.backward_target:
            if self._fall_back(f"refinement stalled at backward error {best:.1e}") >= 0:
                return np.full(n, np.nan), np.full(n, np.nan)
            return super().solve(bh, bl)
        oh, ol = np.empty(n), np.empty(n)
        oh[self.perm], ol[self.perm] = best_x
        return oh, ol


def cholmod_available() -> bool:
    """True when CHOLMOD (scikit-sparse, the optional extra ``cholmod``) can be imported."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


class CholmodMixed:
    """The interface of :class:`MixedCholesky` (values aligned with :meth:`positions`,
    ``factor``, ``solve`` to double-double accuracy) with the float64 factorisation done by
    CHOLMOD's supernodal Cholesky (scikit-sparse, AMD ordering, symbolic analysis once) and
    every solve refined against the double-double matrix to a componentwise backward error
    ≤ ``backward_target`` — the same refinement as :class:`MixedCholesky`, only the float64
    oracle differs.  CHOLMOD works on dense supernodes with BLAS-3 where the up-looking LDLᵀ
    works entry by entry (measured 10–30× faster at 10³–10⁴ contacts, docs/DECISIONS.md,
    "The 10-digit path at scale").

    The values are stored as the upper triangle of the pattern in its own (natural) order, in
    CSC (:attr:`Ap`, :attr:`Ai`); no fill-reducing order or symbolic LDLᵀ of our own is
    computed unless refinement stalls or CHOLMOD meets a non-positive pivot: then the matrix is
    refactored by :class:`DDCholesky` (double-double) and stays so, as in
    :class:`MixedCholesky` (:attr:`precision`, :attr:`fallback_reason`).
    """

    def __init__(self, pattern: sp.spmatrix, backward_target: float = 1e-29, max_steps: int = 12):
        from sksparse import cholmod  # noqa: F401  (fails early, with the import error, when absent)

        n = pattern.shape[0]
        P = sp.csc_matrix(pattern, dtype=np.float64)
        P = (abs(P) + abs(P.T) + sp.identity(n, format="csc")).tocsc()
        U = sp.triu(P, format="csc")
        U.sort_indices()
        self.n = n
        self.pattern = P
        self.Ap = U.indptr.astype(np.int64)
        self.Ai = U.indices.astype(np.int64)
        cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(self.Ap))
        self._keys = cols * n + self.Ai
        # CHOLMOD reads the lower triangle in CSC: the transpose of U, as a gather map into the values
        T = sp.csc_matrix((np.arange(1, self.Ai.size + 1, dtype=np.float64), self.Ai, self.Ap), shape=(n, n)).T.tocsc()
        T.sort_indices()
        self._lower_map = T.data.astype(np.int64) - 1
        self._lower_indices, self._lower_indptr = T.indices, T.indptr
        self.backward_target = backward_target
        self.max_steps = max_steps
        self.precision = "mixed"
        self.fallback_reason = ""
        self.last_backward_error = math.nan
        self.last_steps = 0
        self.solves = 0  # statistics: solves and refinement steps so far
        self.refinement_steps = 0
        self.factored = False
        self._factor = None
        self._dd = None
        self._A = None

    @property
    def nnz_upper(self) -> int:
        return int(self.Ai.size)

    @property
    def Lp(self) -> np.ndarray:
        """Column pointers of L in CHOLMOD's order (computed on demand: statistics only), or
        of the double-double factor after a fallback."""
        if self._dd is not None:
            return self._dd.Lp
        perm = self._factor.P() if self._factor is not None else np.arange(self.n)
        U = sp.triu(self.pattern[perm][:, perm], format="csc")
        U.sort_indices()
        return _symbolic(self.n, U.indptr.astype(np.int64), U.indices.astype(np.int64))[1]

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    def positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Index into the upper-CSC value array of the entries (rows[k], cols[k]) (either
        triangle: the symmetric partner is found)."""
        a = np.asarray(rows, dtype=np.int64)
        b = np.asarray(cols, dtype=np.int64)
        keys = np.maximum(a, b) * self.n + np.minimum(a, b)
        pos = np.searchsorted(self._keys, keys)
        if np.any(pos >= self._keys.size) or np.any(self._keys[np.minimum(pos, self._keys.size - 1)] != keys):
            raise ValueError("entry outside the sparsity pattern")
        return pos

    def _fall_back(self, reason: str) -> int:
        self.precision = "double-double"
        self.fallback_reason = reason
        self._factor = None  # its memory is not needed any more
        return self._dd_factor()

    def _dd_factor(self) -> int:
        if self._dd is None:
            self._dd = DDCholesky(self.pattern)
            cols = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.Ap))
            self._dd_pos = self._dd.positions(self.Ai, cols)
        h, lo = np.zeros(self._dd.nnz_upper), np.zeros(self._dd.nnz_upper)
        h[self._dd_pos], lo[self._dd_pos] = self._A
        bad = self._dd.factor(h, lo)
        self.factored = bad < 0
        return bad

    def factor(self, Axh: np.ndarray, Axl: np.ndarray) -> int:
        """Numeric factorisation; -1 on success, else a non-positive pivot (in double-double,
        after a fallback)."""
        from sksparse import cholmod

        self._A = (np.ascontiguousarray(Axh, dtype=np.float64).copy(),
                   np.ascontiguousarray(Axl, dtype=np.float64).copy())
        if self.precision == "double-double":
            return self._dd_factor()
        A = sp.csc_matrix((self._A[0][self._lower_map], self._lower_indices, self._lower_indptr),
                          shape=(self.n, self.n))
        try:
            if self._factor is None:
                self._factor = cholmod.analyze(A, mode="supernodal", ordering_method="amd")
            self._factor.cholesky_inplace(A)
        except cholmod.CholmodError as exc:
            return self._fall_back(f"CHOLMOD's float64 factorisation failed ({exc})")
        self.factored = True
        return -1

    def solve(self, bh: np.ndarray, bl: np.ndarray):
        """x = A⁻¹ b to double-double accuracy (b, x in the pattern's order)."""
        if self.precision == "double-double":
            return self._dd.solve(bh, bl)
        n = self.n

        def oracle(rh):  # CHOLMOD's float64 solve on the residual
            return np.asarray(self._factor(rh), dtype=np.float64).reshape(n)

        best, best_x, steps = refine_in_double_double(self.Ap, self.Ai, self._A, bh, bl, oracle, self.max_steps)
        self.last_backward_error, self.last_steps = best, steps
        self.solves += 1
        self.refinement_steps += steps
        if not best <= self.backward_target:
            if self._fall_back(f"refinement stalled at backward error {best:.1e}") >= 0:
                return np.full(n, np.nan), np.full(n, np.nan)
            return self._dd.solve(bh, bl)
        return best_x[0].copy(), best_x[1].copy()
