"""The lifted problem (DESIGN §2) in exact double-double form, as the extended phase reads it.

:class:`ExtendedData` holds H̃ = P Hᵀ, w̃ = P w and M = (M + Mᵀ)/2 as double-double
(:class:`DDMatrix`, CSR with a high and a low array), formed with exact products and sums;
:func:`contact_dof_pattern` and :func:`contact_local_H` give each contact's dense block of H̃
over the dofs it touches, which the dof-space back ends (:mod:`.dofspace`, :mod:`.wide`)
assemble from.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..model.lifting import lift
from ..model.problem import SPACEDIM, Problem
from . import dd
from .workers import split

MATVEC_SPLIT_NNZ = 100_000
"""Fewest stored entries a double-double matrix-vector product is split over threads for (about
1 ms of work; :mod:`.workers`)."""


def _two_prod_np(a, b):
    """Vectorised exact product a·b = p + e (numpy rounds each operation correctly)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    p = a * b
    s = 134217729.0
    t = s * a
    ah = t - (t - a)
    al = a - ah
    t = s * b
    bh = t - (t - b)
    bl = b - bh
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


def _two_sum_np(a, b):
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


class DDMatrix:
    """CSR matrix with double-double entries; ``matvec`` in double-double."""

    def __init__(self, shape, indptr, indices, hi, lo):
        self.shape = shape
        self.indptr = np.ascontiguousarray(indptr, dtype=np.int64)
        self.indices = np.ascontiguousarray(indices, dtype=np.int64)
        self.hi = np.ascontiguousarray(hi, dtype=np.float64)
        self.lo = np.ascontiguousarray(lo, dtype=np.float64)

    @staticmethod
    def from_scipy(A, hi=None, lo=None) -> "DDMatrix":
        A = sp.csr_matrix(A)
        A.sort_indices()
        hi = A.data if hi is None else hi
        lo = np.zeros_like(hi) if lo is None else lo
        return DDMatrix(A.shape, A.indptr, A.indices, hi, lo)

    def coo(self):
        """(rows, cols, hi, lo) of the stored entries."""
        rows = np.repeat(np.arange(self.shape[0], dtype=np.int64), np.diff(self.indptr))
        return rows, self.indices, self.hi, self.lo

    def transpose(self) -> "DDMatrix":
        rows = np.repeat(np.arange(self.shape[0]), np.diff(self.indptr))
        order = np.lexsort((rows, self.indices))
        counts = np.bincount(self.indices, minlength=self.shape[1])
        indptr = np.concatenate(([0], np.cumsum(counts)))
        return DDMatrix((self.shape[1], self.shape[0]), indptr, rows[order], self.hi[order], self.lo[order])

    def matvec(self, xh, xl):
        """A x for x = xh + xl (double-double), rows split over the threads (:mod:`.workers`)."""
        oh = np.empty(self.shape[0])
        ol = np.empty(self.shape[0])
        xh, xl = np.ascontiguousarray(xh), np.ascontiguousarray(xl)

        def rows(lo, hi):
            dd.csr_matvec(self.indptr[lo:hi + 1], self.indices, self.hi, self.lo, xh, xl, oh[lo:hi], ol[lo:hi])

        split(self.shape[0], rows, min_items=0 if self.indices.size >= MATVEC_SPLIT_NNZ else math.inf)
        return oh, ol


def _exact_symmetric(A: sp.spmatrix, n: int):
    """(A + Aᵀ)/2 of a float matrix exactly as double-double: (CSR pattern, hi, lo).  Each entry
    is the double-double sum of at most two floats (plus repeated triplets), halved exactly."""
    Ac = sp.coo_matrix(A)
    rows = np.concatenate((Ac.row, Ac.col))
    cols = np.concatenate((Ac.col, Ac.row))
    vals = np.concatenate((Ac.data, Ac.data)).astype(np.float64)
    key = rows.astype(np.int64) * n + cols
    order = np.argsort(key, kind="stable")
    key, vals = key[order], vals[order]
    uniq, first = np.unique(key, return_index=True)
    last = np.append(first[1:], key.size)
    sh = np.zeros(uniq.size)
    sl = np.zeros(uniq.size)
    for k in range(int(np.max(last - first, initial=0))):
        take = first + k < last
        idx = first[take] + k
        h2, l2 = _two_sum_np(sh[take], vals[idx])
        sh[take], sl[take] = h2, sl[take] + l2
    sh, sl = _two_sum_np(sh, sl)
    pattern = sp.csr_matrix((np.ones(uniq.size), (uniq // n, uniq % n)), shape=(n, n))
    pattern.sort_indices()  # csr of the unique keys is in key order already
    return pattern, sh * 0.5, sl * 0.5


def _dd_times(h, l, a):
    """(h + l)·a for float a, rounded once to double-double (vectorised)."""
    p, e = _two_prod_np(h, a)
    return _two_sum_np(p, e + l * a)


class ExtendedData:
    """The lifted problem (DESIGN §2) with exact double-double data.

    H̃ = P Hᵀ and w̃ = P w are formed with exact products (μ·h is a double-double), and
    M = (M + Mᵀ)/2 with exact sums, so the extended phase converges to the solution of the
    problem in the file, not of a rounded copy.

    A problem read from a local file (``problem.local``) is run in its **local form**: no
    dofs (m = 0), and the contact-space operator W̃ = P (W + Wᵀ)/2 P of the file's own W
    (``Wt``, double-double, one rounding of the exact product), so that ũ = W̃ r̃ + q̃ — the
    lifting's HᵀH ≈ W plays no part beyond the double solve's start.
    """

    def __init__(self, problem: Problem):
        self.problem = problem
        lp = lift(problem, reduce_cones=True)
        self.lp = lp
        self.local = problem.local is not None
        self.m = 0 if self.local else problem.n_dofs
        self.nk, self.nz = lp.nk, lp.nz
        self.n3, self.n1 = lp.n3, lp.n1
        self.n = problem.n_contacts
        # Each contact's index in the problem a user posed, where this one is another's on a face
        # (FaceReduction.refine sets it; −1 − e: the face's edge contact e); None: its own.
        self.contact_names = None
        if self.local:
            HT = sp.csr_matrix((lp.nk, 0))
        else:
            HT = problem.H.T.tocsr()[lp.keep]  # rows = kept components, exact entries
        HT.sort_indices()
        scale_rows = np.repeat(lp.scale, np.diff(HT.indptr))
        hi, lo = _two_prod_np(scale_rows, HT.data)
        self.Ht = DDMatrix(HT.shape, HT.indptr, HT.indices, hi, lo)  # H̃ (nk × m)
        self.HtT = self.Ht.transpose()
        wh, wl = _two_prod_np(lp.scale, problem.w[lp.keep])
        self.w_t = (wh, wl)
        self.f = (np.zeros(self.m), np.zeros(self.m)) if self.local else \
            (problem.f.astype(np.float64).copy(), np.zeros(self.m))
        Msrc = sp.csr_matrix((0, 0)) if self.local else problem.M
        Msym, sh, sl = _exact_symmetric(Msrc, self.m)
        self.M = DDMatrix((self.m, self.m), Msym.indptr, Msym.indices, sh, sl)
        self.M_pattern = Msym
        # The M of the posed equations (residuals, refinement): the stored one for an
        # ``as_stored`` problem, exactly; the Newton matrices always use the symmetric M.
        self.M_eq = self.M
        if problem.as_stored and not self.local:
            Mst = sp.csr_matrix(problem.M, dtype=np.float64)
            Mst.sort_indices()
            self.M_eq = DDMatrix.from_scipy(Mst)
        self.Wt = None
        if self.local:
            Wk = sp.csr_matrix(problem.local.W)[lp.keep][:, lp.keep]
            Wp, wh_, wl_ = _exact_symmetric(Wk, lp.nk)
            rows = np.repeat(np.arange(lp.nk), np.diff(Wp.indptr))
            wh_, wl_ = _dd_times(wh_, wl_, lp.scale[rows])
            wh_, wl_ = _dd_times(wh_, wl_, lp.scale[Wp.indices])
            self.Wt = DDMatrix((lp.nk, lp.nk), Wp.indptr, Wp.indices, wh_, wl_)
        self.J = DDMatrix.from_scipy(lp.J)
        self.JT = DDMatrix.from_scipy(lp.J.T)
        # contact structure: kept rows of contact c are contiguous, starting at row_start[c]
        contact_of_row = lp.keep // SPACEDIM
        self.row_start = np.searchsorted(contact_of_row, np.arange(self.n)).astype(np.int64)
        self.row_count = np.bincount(contact_of_row, minlength=self.n).astype(np.int64)
        self.kinds = lp.kinds.astype(np.int64)
        # cone indices per contact (friction cone, rolling cone; -1 if absent), L1 cones after L3
        self.fric_cone = np.full(self.n, -1, dtype=np.int64)
        self.roll_cone = np.full(self.n, -1, dtype=np.int64)
        self.normal_cone = np.full(self.n, -1, dtype=np.int64)
        parts = lp.cone_part
        for part, target in ((0, self.fric_cone), (1, self.roll_cone), (2, self.normal_cone)):
            idx = np.flatnonzero(parts == part)
            target[lp.cone_contact[idx]] = idx

    # ---- residual-level operators (double-double)
    def M_apply(self, vh, vl):
        """M v of the posed equations (``M_eq``), double-double."""
        return self.M_eq.matvec(vh, vl)

    def velocity(self, vh, vl, rh, rl):
        """ũ = H̃v + w̃ (global) or W̃r̃ + q̃ (local), double-double (hi, lo)."""
        if self.local:
            ah, al = self.Wt.matvec(rh, rl)
        else:
            ah, al = self.Ht.matvec(vh, vl)
        oh, ol = np.empty(self.nk), np.empty(self.nk)
        dd.vadd(ah, al, self.w_t[0], self.w_t[1], oh, ol)
        return oh, ol



def contact_dof_pattern(data: ExtendedData) -> sp.csr_matrix:
    """(n × m) pattern of the dofs each contact's kept rows of H̃ touch, sorted per row."""
    Ht = sp.csr_matrix((np.ones_like(data.Ht.hi), data.Ht.indices, data.Ht.indptr), shape=data.Ht.shape)
    contact_of_row = np.repeat(np.arange(data.n), data.row_count)
    C = sp.csr_matrix((np.ones(data.nk), (contact_of_row, np.arange(data.nk))), shape=(data.n, data.nk))
    CD = (C @ Ht).tocsr()
    CD.sort_indices()
    return CD


def contact_local_H(data: ExtendedData, CD: sp.csr_matrix):
    """Each contact's dense block of H̃: local dof lists (n, d) padded with -1, and H̃_c as
    (n, 5, d) double-double (rows: the contact's kept rows, columns: its local dofs)."""
    n = data.n
    loc_cnt = np.diff(CD.indptr).astype(np.int64)
    dmax = int(loc_cnt.max(initial=1))
    loc_dofs = np.full((n, dmax), -1, dtype=np.int64)
    slot = np.arange(CD.nnz) - np.repeat(CD.indptr[:-1], loc_cnt)
    loc_dofs[np.repeat(np.arange(n), loc_cnt), slot] = CD.indices
    Hh = np.zeros((n, 5, dmax))
    Hl = np.zeros((n, 5, dmax))
    contact_of_row = np.repeat(np.arange(n), data.row_count)
    row_local = np.arange(data.nk) - data.row_start[contact_of_row]
    rows = np.repeat(np.arange(data.nk), np.diff(data.Ht.indptr))
    cont = contact_of_row[rows]
    # position of each nonzero's dof in its contact's sorted local list (one searchsorted
    # over keys contact·m + dof, which are sorted segment by segment)
    key = cont.astype(np.int64) * data.m + data.Ht.indices
    seg_keys = np.repeat(np.arange(n), loc_cnt).astype(np.int64) * data.m + CD.indices
    local = np.searchsorted(seg_keys, key) - CD.indptr[cont]
    Hh[cont, row_local[rows], local] = data.Ht.hi
    Hl[cont, row_local[rows], local] = data.Ht.lo
    return loc_dofs, Hh, Hl
