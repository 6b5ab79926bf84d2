"""The Newton solve of the multiple-precision tail (:mod:`.wide`): per-contact factors
F_c⁻¹ of G_c = J_c Q_{p⁻²} J_cᵀ and the dof-space matrix S = M + H̃ᵀG⁻¹H̃ = M + BᵀB
(B = F⁻¹H̃), formed and Cholesky-factored in ``bits``-bit mpfr in a minimum-degree order —
sparsely (:class:`SparseDofSpace`, the tail's factor) or densely (:class:`DenseDofSpace`, the
reference it is tested against).  Both take a :class:`rfverify.jordan.mpfr.Scaling` in
``update`` and solve M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t."""

from __future__ import annotations

import gmpy2
import numpy as np
import scipy.sparse as sp

from ..jordan.mpfr import Scaling, quad_matrix
from .data import ExtendedData, contact_dof_pattern, contact_local_H
from .ldl import _numeric_double, _symbolic, _workspace, fill_reducing_order
from .wide_data import WideData, dot, from_dd, zeros

_sqrt = np.frompyfunc(gmpy2.sqrt, 1, 1)


def contact_factor_inverse(data: ExtendedData, sc: Scaling) -> np.ndarray:
    """F_c⁻¹ per contact, (n, 5, 5) mpfr, for F_c F_cᵀ = G_c = J_c Q_{p⁻²} J_cᵀ: the formulas
    of :func:`.blocks.contact_factor_inverse` (Q_p for one cone, p² for a normal ray, (R⁻¹)ᵀ
    of a Householder QR of (J_c Q_{p⁻¹})ᵀ for a full contact), vectorised over contacts.
    Raises ArithmeticError if a factor is singular."""
    n = data.n
    F = np.empty((n, 5, 5), dtype=object)
    F[:] = gmpy2.mpfr(0)
    kinds = data.kinds
    ray = np.flatnonzero(kinds == 3)
    if ray.size:
        F[ray, 0, 0] = sc.q1[data.normal_cone[ray] - data.n3] ** 2
    for kind, cones in ((1, data.fric_cone), (2, data.roll_cone)):
        sel = np.flatnonzero(kinds == kind)
        if sel.size:
            F[sel, :3, :3] = quad_matrix(sc, 1, cones[sel])
    full = np.flatnonzero(kinds == 0)
    if full.size:
        nf = full.size
        At = np.empty((nf, 6, 5), dtype=object)
        At[:] = gmpy2.mpfr(0)
        At[:, :3, :3] = quad_matrix(sc, -1, data.fric_cone[full])
        At[:, 3:, [0, 3, 4]] = quad_matrix(sc, -1, data.roll_cone[full])
        R = At
        for j in range(5):
            norm = _sqrt(np.sum(R[:, j:, j] * R[:, j:, j], axis=1))
            if not (norm > 0).astype(bool).all():
                raise ArithmeticError("a contact's factor is singular")
            alpha = np.where((R[:, j, j] > 0).astype(bool), -norm, norm)
            vcol = R[:, j:, j].copy()
            vcol[:, 0] = vcol[:, 0] - alpha
            beta = 2 / np.sum(vcol * vcol, axis=1)
            for c in range(j + 1, 5):
                proj = np.sum(vcol * R[:, j:, c], axis=1) * beta
                R[:, j:, c] = R[:, j:, c] - proj[:, None] * vcol
            R[:, j, j] = alpha
        Rinv_T = np.empty((nf, 5, 5), dtype=object)
        Rinv_T[:] = gmpy2.mpfr(0)
        for c in range(5):  # column c of R⁻¹, stored as row c of (R⁻¹)ᵀ
            for r in range(c, -1, -1):
                acc = np.full(nf, gmpy2.mpfr(1 if r == c else 0), dtype=object)
                for q in range(r + 1, c + 1):
                    acc = acc - R[:, r, q] * Rinv_T[:, c, q]
                Rinv_T[:, c, r] = acc / R[:, r, r]
        F[full] = Rinv_T
    return F


def dof_space_ordering(data: ExtendedData, CD=None):
    """(minimum-degree order of M + H̃ᵀG⁻¹H̃'s pattern, the number of multiply-subtract pairs
    its Cholesky factor costs in that order: Σ_j c_j² over the column counts c_j of L)."""
    CD = contact_dof_pattern(data) if CD is None else CD
    pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
    perm = fill_reducing_order(pattern)
    n = pattern.shape[0]
    P = (abs(pattern) + abs(pattern.T) + sp.identity(n, format="csc")).tocsc()
    U = sp.triu(P[perm][:, perm], format="csc")
    U.sort_indices()
    _, Lp = _symbolic(n, U.indptr.astype(np.int64), U.indices.astype(np.int64))
    counts = np.diff(Lp).astype(np.float64)
    return perm, float(np.sum(counts * counts))


class DenseDofSpace:
    """The dof-space Newton matrix S = M + H̃ᵀG⁻¹H̃ = M + BᵀB (B = F⁻¹H̃, per contact) as a
    dense m × m mpfr matrix with a Cholesky factor in its lower triangle, in a minimum-degree
    order that skips exact zeros: Σ c_j² multiply-subtract pairs per factorisation
    (:func:`dof_space_ordering`), O(m³) at worst.  The tail uses :class:`SparseDofSpace`
    (same order, same arithmetic, memory O(nnz(L))); this dense form is its reference.

    Why not the double-double back ends: S and the contact-space S' = I + F⁻¹W̃F⁻ᵀ both have
    condition numbers near 1/μ along redundant sticking contacts (W̃ singular), and near
    μ = 1e-40 their float64 and double-double factors lose definiteness (measured on a
    274-contact Lattice, DECISIONS).  A factor in ``bits``-bit arithmetic does not."""

    name = "dense dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"

    def __init__(self, data: ExtendedData, W: WideData, perm: np.ndarray | None = None):
        m = data.m
        CD = self._ordered(data, W, perm)
        loc_dofs, Hh, Hl = contact_local_H(data, CD)
        self.valid = loc_dofs >= 0
        self.loc = np.where(self.valid, self.iperm[np.maximum(loc_dofs, 0)], -1)
        self.Hc = from_dd(Hh, Hl) if Hh.size else np.empty(Hh.shape, dtype=object)  # (n, 5, d)
        S = zeros(m * m).reshape(m, m)
        mr, mc, mh, ml = data.M.coo()
        S[self.iperm[mr], self.iperm[mc]] = from_dd(mh, ml)
        self.M_dense = S
        self.L = None
        self.Finv = None

    def _ordered(self, data: ExtendedData, W: WideData, perm):
        """Keep the data and put rows and columns in a minimum-degree order (``perm`` if the
        caller has it already): the factor keeps M + BᵀB's sparsity and the elimination skips
        the exact zeros.  Returns the contact–dof pattern."""
        self.data = data
        self.W = W
        CD = contact_dof_pattern(data)
        self.perm = dof_space_ordering(data, CD)[0] if perm is None else np.asarray(perm, dtype=np.int64)
        self.iperm = np.empty_like(self.perm)
        self.iperm[self.perm] = np.arange(data.m)
        return CD

    def update(self, sc: Scaling) -> bool:
        """Form and factor S at the scaling ``sc``; False if a pivot is not positive."""
        data, m = self.data, self.data.m
        self.Finv = contact_factor_inverse(data, sc)  # (n, 5, 5); zero past a contact's kept rows
        B = np.matmul(self.Finv, self.Hc)  # (n, 5, d)
        blocks = np.matmul(np.transpose(B, (0, 2, 1)), B)  # (n, d, d) = B_cᵀB_c
        S = self.M_dense.copy()
        d = self.loc.shape[1]
        ii = np.broadcast_to(self.loc[:, :, None], (data.n, d, d))
        jj = np.broadcast_to(self.loc[:, None, :], (data.n, d, d))
        ok = self.valid[:, :, None] & self.valid[:, None, :]
        np.add.at(S, (ii[ok], jj[ok]), blocks[ok])
        L = S
        for j in range(m):
            piv = L[j, j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            L[j, j] = piv
            rows = j + 1 + np.flatnonzero((L[j + 1:, j] != 0).astype(bool))
            if rows.size:
                col = L[rows, j] / piv
                L[rows, j] = col
                # the lower triangle only, one target column at a time (3× faster than the
                # full square update on a 600-dof Lattice; the upper triangle is never read)
                for t, target in enumerate(rows):
                    L[rows[t:], target] -= col[t:] * col[t]
        self.L = L
        return True

    def _G_inv(self, x):
        """G⁻¹x = F⁻ᵀ(F⁻¹x), contact by contact (x over the kept rows)."""
        data = self.data
        X = zeros(data.n * 5).reshape(data.n, 5)
        rows_local = np.arange(data.nk) - np.repeat(data.row_start, data.row_count)
        cont = np.repeat(np.arange(data.n), data.row_count)
        X[cont, rows_local] = x
        Y = np.matmul(self.Finv, X[:, :, None])
        Z = np.matmul(np.transpose(self.Finv, (0, 2, 1)), Y)[:, :, 0]
        return Z[cont, rows_local]

    def _chol_solve(self, b):
        L, m = self.L, self.data.m
        y = b.copy()
        for j in range(m):
            y[j] = y[j] / L[j, j]
            y[j + 1:] -= L[j + 1:, j] * y[j]
        for j in range(m - 1, -1, -1):
            y[j] = (y[j] - dot(L[j + 1:, j], y[j + 1:])) / L[j, j]
        return y

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (mpfr)."""
        W = self.W
        rhs = a + W.HtT @ self._G_inv(t)
        dv = np.empty_like(rhs)
        dv[self.perm] = self._chol_solve(rhs[self.perm])
        dr = self._G_inv(t - W.Ht @ dv)
        return dv, dr


def _factor_pattern(pattern: sp.spmatrix, perm: np.ndarray):
    """The structure of the Cholesky factor of ``pattern`` in the order ``perm``: (Lp, Li) of
    its strictly lower part in CSC (rows ascending in each column), and the lower triangle of
    the permuted pattern (CSC, sorted), whose entries the factor reads."""
    n = pattern.shape[0]
    P = (abs(pattern) + abs(pattern.T) + sp.identity(n, format="csc")).tocsc()
    P = P[perm][:, perm].tocsc()
    U = sp.triu(P, format="csc")
    U.sort_indices()
    Ap, Ai = U.indptr.astype(np.int64), U.indices.astype(np.int64)
    parent, Lp = _symbolic(n, Ap, Ai)
    # the structure itself from a float64 factorisation of a strictly diagonally dominant
    # matrix on the pattern (its kernel writes every structural entry; no pivot can fail)
    vals = np.where(Ai == np.repeat(np.arange(n), np.diff(Ap)), float(n + 1), 1.0)
    Li, Lx = np.zeros(int(Lp[-1]), dtype=np.int64), np.zeros(int(Lp[-1]))
    if _numeric_double(n, Ap, Ai, vals, Lp, parent, Li, Lx, np.zeros(n), np.zeros(n), *_workspace(n)) >= 0:
        raise AssertionError("a diagonally dominant matrix lost a pivot")
    lower = sp.tril(P, format="csc")
    lower.sort_indices()
    return Lp, Li, lower


class SparseDofSpace(DenseDofSpace):
    """:class:`DenseDofSpace` with S = M + BᵀB stored and factored sparsely: the same
    minimum-degree order, the same multiply-subtract pairs (Σ c_j² over the column counts of
    L), but memory O(nnz(L)) mpfr numbers instead of a dense m × m array, so the tail has no
    limit in dofs, only in its predicted cost (:mod:`rfverify.digits`).

    The factorisation is left-looking by columns: column j of L gathers the updates of the
    columns k that have an entry in row j (one vectorised object-array operation per entry of
    L, the same count of Python-level steps as the dense version's per-target updates), then
    is scaled by its pivot √d_j.  A solve is two sweeps over the columns."""

    name = "sparse dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"

    def __init__(self, data: ExtendedData, W: WideData, perm: np.ndarray | None = None):
        m = data.m
        CD = self._ordered(data, W, perm)
        pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
        self.Lp, self.Li, lower = _factor_pattern(pattern, self.perm)
        self.S_indptr, self.S_indices = lower.indptr.astype(np.int64), lower.indices.astype(np.int64)
        keys = np.repeat(np.arange(m, dtype=np.int64), np.diff(self.S_indptr)) * m + self.S_indices

        def where(rows, cols):  # position in the lower CSC of permuted entries (rows ≥ cols)
            return np.searchsorted(keys, np.asarray(cols, dtype=np.int64) * m + np.asarray(rows, dtype=np.int64))

        loc_dofs, Hh, Hl = contact_local_H(data, CD)
        valid = loc_dofs >= 0
        loc = np.where(valid, self.iperm[np.maximum(loc_dofs, 0)], -1)
        self.Hc = from_dd(Hh, Hl) if Hh.size else np.empty(Hh.shape, dtype=object)  # (n, 5, d)
        d = loc.shape[1]
        ii = np.broadcast_to(loc[:, :, None], (data.n, d, d))
        jj = np.broadcast_to(loc[:, None, :], (data.n, d, d))
        self.block_take = valid[:, :, None] & valid[:, None, :] & (ii >= jj)  # lower half of each B_cᵀB_c
        self.block_pos = where(ii[self.block_take], jj[self.block_take])
        mr, mc, mh, ml = data.M.coo()
        pr, pc = self.iperm[mr], self.iperm[mc]
        low = pr >= pc
        self.M_values = zeros(keys.size)
        np.add.at(self.M_values, where(pr[low], pc[low]), from_dd(mh[low], ml[low]))
        # row j of L: the columns k < j with an entry there, each with the offset of that entry
        # in column k (the column's entries at rows ≥ j start there: rows ascend)
        cols_of = np.repeat(np.arange(m, dtype=np.int64), np.diff(self.Lp))
        order = np.lexsort((cols_of, self.Li))
        self.row_ptr = np.concatenate(([0], np.cumsum(np.bincount(self.Li, minlength=m)))).astype(np.int64)
        self.row_cols = cols_of[order]
        self.row_entry = order.astype(np.int64)  # index into Li / Lx
        self.Lx = None
        self.Ld = None
        self.Finv = None

    @property
    def ops(self) -> float:
        """Multiply-subtract pairs per factorisation (Σ c_j² over the columns of L)."""
        c = np.diff(self.Lp).astype(np.float64) + 1.0
        return float(np.sum(c * c))

    def update(self, sc: Scaling) -> bool:
        """Form and factor S at the scaling ``sc``; False if a pivot is not positive."""
        data, m = self.data, self.data.m
        self.Finv = contact_factor_inverse(data, sc)
        B = np.matmul(self.Finv, self.Hc)  # (n, 5, d)
        blocks = np.matmul(np.transpose(B, (0, 2, 1)), B)  # (n, d, d) = B_cᵀB_c
        S = self.M_values.copy()
        np.add.at(S, self.block_pos, blocks[self.block_take])
        Lp, Li = self.Lp, self.Li
        Lx = np.empty(Li.size, dtype=object)
        Ld = np.empty(m, dtype=object)
        w = zeros(m)  # the column being built, scattered by row
        for j in range(m):
            a, b = self.S_indptr[j], self.S_indptr[j + 1]
            w[self.S_indices[a:b]] = S[a:b]
            for t in range(self.row_ptr[j], self.row_ptr[j + 1]):
                e = self.row_entry[t]  # L[j, k]: the first entry of column k at a row ≥ j
                end = Lp[self.row_cols[t] + 1]
                w[Li[e:end]] -= Lx[e:end] * Lx[e]
            piv = w[j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            Ld[j] = piv
            rows = Li[Lp[j]:Lp[j + 1]]
            Lx[Lp[j]:Lp[j + 1]] = w[rows] / piv
            w[j] = gmpy2.mpfr(0)
            w[rows] = gmpy2.mpfr(0)
        self.Lx, self.Ld = Lx, Ld
        return True

    def _chol_solve(self, b):
        Lp, Li, Lx, Ld, m = self.Lp, self.Li, self.Lx, self.Ld, self.data.m
        y = b.copy()
        for j in range(m):
            y[j] = y[j] / Ld[j]
            a, e = Lp[j], Lp[j + 1]
            if e > a:
                y[Li[a:e]] -= Lx[a:e] * y[j]
        for j in range(m - 1, -1, -1):
            a, e = Lp[j], Lp[j + 1]
            y[j] = (y[j] - dot(Lx[a:e], y[Li[a:e]])) / Ld[j]
        return y
