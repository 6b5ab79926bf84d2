"""The scaled contact-space matrix S' = I + F⁻¹W̃F⁻ᵀ applied through its factors: W̃ = H̃M⁻¹H̃ᵀ
= ZZᵀ with Z = H̃L⁻ᵀ (M = LLᵀ block by block, in double-double), so that

    S'p = p + F⁻¹ Z (Zᵀ (F⁻ᵀ p)).

On a granular bed Z has H̃'s pattern, and this product reads 2·nnz(H̃) + 2·Σ_c k_c² entries where
the stored upper triangle of S' is read for 2·nnz(S'); on the 9675-contact turned touching bed
that is 1.3 M against 2.5 M double-double multiply-adds, 5.6 ms on the thread pool (10.5 ms on one
thread) against 19–21 ms a conjugate-gradient step (docs/DECISIONS.md, "A product through the
factors").  The two agree to about
1e-31 of |S'||p| (the rounding of either); the conjugate gradients that use it
(:func:`.krylov.conjugate_gradients_in_double_double` with ``product``) still recompute the
residual they return from the stored S'."""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from . import dd
from .blocks import applied_blocks
from .data import DDMatrix

njit = numba.njit(cache=True, nogil=True)


@njit
def dense_half(Mh, Ml, Hh, Hl, Yh, Yl):
    """Y = L⁻¹Hᵀ (s × k) for a small dense SPD M = L Lᵀ (double-double Cholesky), so that
    H M⁻¹ Hᵀ = YᵀY.  Returns False if M is not positive definite."""
    s = Mh.shape[0]
    k = Hh.shape[0]
    Lh = np.zeros((s, s))
    Ll = np.zeros((s, s))
    for j in range(s):
        ah, al = Mh[j, j], Ml[j, j]
        for q in range(j):
            ah, al = dd.fms_acc(ah, al, Lh[j, q], Ll[j, q], Lh[j, q], Ll[j, q])
        if not ah > 0.0:
            return False
        dh, dl = dd.sqrt(ah, al)
        Lh[j, j], Ll[j, j] = dh, dl
        for i in range(j + 1, s):
            ah, al = Mh[i, j], Ml[i, j]
            for q in range(j):
                ah, al = dd.fms_acc(ah, al, Lh[i, q], Ll[i, q], Lh[j, q], Ll[j, q])
            Lh[i, j], Ll[i, j] = dd.div(ah, al, dh, dl)
    for c in range(k):
        for i in range(s):
            ah, al = Hh[c, i], Hl[c, i]
            for q in range(i):
                ah, al = dd.fms_acc(ah, al, Lh[i, q], Ll[i, q], Yh[q, c], Yl[q, c])
            Yh[i, c], Yl[i, c] = dd.div(ah, al, Lh[i, i], Ll[i, i])
    return True


@njit
def block_system(b, dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds, rows_all,
                 h_dofs, h_hi, h_lo, local):
    """The dense pieces of block b of M: (rows, H_b, M_b) — the kept rows of H̃ that touch the
    block (sorted), H̃ restricted to them and to the block's dofs (rows × s), and M_b (s × s), in
    double-double (hi and lo arrays), the block's dofs numbered 0 … s−1 in ``local``.
    ``order[bounds[b]:bounds[b + 1]]``: the nonzeros of H̃ in block b, by row."""
    lo, hi = bounds[b], bounds[b + 1]
    s = dof_bounds[b + 1] - dof_bounds[b]
    for i in range(s):
        local[dof_order[dof_bounds[b] + i]] = i
    rows = np.empty(hi - lo, dtype=np.int64)
    slot = np.empty(hi - lo, dtype=np.int64)
    r = 0
    for q in range(lo, hi):
        row = rows_all[order[q]]
        if r == 0 or rows[r - 1] != row:
            rows[r] = row
            r += 1
        slot[q - lo] = r - 1
    Hbh, Hbl = np.zeros((r, s)), np.zeros((r, s))
    for q in range(lo, hi):
        k = order[q]
        Hbh[slot[q - lo], local[h_dofs[k]]] = h_hi[k]
        Hbl[slot[q - lo], local[h_dofs[k]]] = h_lo[k]
    Mbh, Mbl = np.zeros((s, s)), np.zeros((s, s))
    for q in range(m_bounds[b], m_bounds[b + 1]):
        k = m_order[q]
        Mbh[local[mr[k]], local[mc[k]]] = mh[k]
        Mbl[local[mr[k]], local[mc[k]]] = ml[k]
    return rows[:r], Hbh, Hbl, Mbh, Mbl


@njit
def _z_entries(blocks, starts, dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds, rows_all,
               h_dofs, h_hi, h_lo, local, zr, zc, zh, zl):
    """Z's entries block by block of M (Z_b = H_b L_b⁻ᵀ, :func:`dense_half`), block
    ``blocks[i]`` written from ``starts[i]`` on.  Returns the first block whose M_b is not
    positive definite in double-double, or -1."""
    for i in range(blocks.size):
        b = blocks[i]
        rows, Hbh, Hbl, Mbh, Mbl = block_system(b, dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml,
                                                order, bounds, rows_all, h_dofs, h_hi, h_lo, local)
        r, s = Hbh.shape
        Yh, Yl = np.zeros((s, r)), np.zeros((s, r))
        if not dense_half(Mbh, Mbl, Hbh, Hbl, Yh, Yl):
            return b
        at = starts[i]
        for a in range(r):
            for q in range(s):
                zr[at], zc[at] = rows[a], dof_order[dof_bounds[b] + q]
                zh[at], zl[at] = Yh[q, a], Yl[q, a]
                at += 1
    return -1


def multiply_adds(z_entries: int, row_count: np.ndarray) -> int:
    """Double-double multiply-adds of one product through the factors: Zᵀ and Z (z_entries
    each) and F⁻ᵀ, F⁻¹ (k_c² per contact each)."""
    return 2 * int(z_entries) + 2 * int(np.sum(np.asarray(row_count, dtype=np.int64) ** 2))


def build_z(index: tuple, blocks: np.ndarray, rows_per_block: np.ndarray, shape: tuple) -> DDMatrix | None:
    """Z = H̃L⁻ᵀ (kept rows × dofs, CSR, double-double) over ``blocks`` (every block of M that H̃
    touches; each at most :data:`.contactspace.DENSE_BLOCK` dofs), from
    :meth:`.contactspace.ContactSpace._block_index`'s ``index``; None where an M_b is not
    positive definite in double-double."""
    dof_bounds = index[1]
    sizes = (rows_per_block * np.diff(dof_bounds))[blocks].astype(np.int64)
    starts = np.concatenate(([0], np.cumsum(sizes)[:-1])).astype(np.int64)
    total = int(sizes.sum())
    zr, zc = np.empty(total, dtype=np.int64), np.empty(total, dtype=np.int64)
    zh, zl = np.empty(total), np.empty(total)
    local = np.empty(shape[1], dtype=np.int64)
    if _z_entries(blocks.astype(np.int64), starts, *index, local, zr, zc, zh, zl) >= 0:
        return None
    Z = sp.csr_matrix((np.arange(total, dtype=np.float64), (zr, zc)), shape=shape)
    Z.sort_indices()
    at = Z.data.astype(np.int64)  # each (row, dof) once: the values are the entries' positions
    return DDMatrix(shape, Z.indptr, Z.indices, zh[at], zl[at])


class ScaledProduct:
    """q = S'p = p + F⁻¹Z(Zᵀ(F⁻ᵀp)) in double-double over the kept rows, with the contact space's
    per-contact factors ``Fh``/``Fl`` as they are at the call (refilled in place at each
    scaling) and Z from :func:`build_z`, made by ``make_z()`` at the first call: a run whose
    solves never need the conjugate gradients never builds it."""

    def __init__(self, data, Fh: np.ndarray, Fl: np.ndarray, make_z):
        self.data, self.Fh, self.Fl = data, Fh, Fl
        self._make_z = make_z
        self.Z = self.ZT = None

    def __call__(self, ph: np.ndarray, pl: np.ndarray):
        if self.Z is None:
            self.Z = self._make_z()
            self.ZT = self.Z.transpose()
        th, tl = applied_blocks(self.data, self.Fh, self.Fl, True, ph, pl, threaded=True)
        yh, yl = self.ZT.matvec(th, tl)
        wh, wl = self.Z.matvec(yh, yl)
        qh, ql = applied_blocks(self.data, self.Fh, self.Fl, False, wh, wl, threaded=True)
        dd.vadd(qh, ql, np.ascontiguousarray(ph), np.ascontiguousarray(pl), wh, wl)
        return wh, wl
