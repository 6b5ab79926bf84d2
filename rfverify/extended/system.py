"""The lifted problem in exact double-double form, and the two Newton-system back ends of
the extended-precision phase.

Every back end solves the same 2×2 block system (dz already eliminated)

    [ M    −H̃ᵀ ] [dv ]   [a]
    [ H̃     G  ] [dr̃] = [t],      G = J Q_{p⁻²} Jᵀ  (block diagonal, one block per contact),

and differs only in what it factors (both are symmetric positive definite):

* :class:`DofSpace` — S_v = M + H̃ᵀ G⁻¹ H̃ (m × m), with G⁻¹ in closed form per contact.
  The pattern couples bodies that share a contact: least fill for rigid-body scenes.
* :class:`ContactSpace` — S_r = H̃ M⁻¹ H̃ᵀ + G (nk × nk), the reference implementation's
  form, with W̃ = H̃ M⁻¹ H̃ᵀ computed once.  Cheaper when H̃ is dense (lifted local problems).

:func:`choose_backend` compares the symbolic factorisation cost of both.
"""

from __future__ import annotations

import numba
import numpy as np
import scipy.sparse as sp

from ..lifting import KIND_COULOMB, KIND_FULL, KIND_NORMAL, KIND_ROLLING, lift
from ..problem import SPACEDIM, Problem
from . import cones as C
from . import dd
from .ldl import CholmodMixed, DDCholesky, MixedCholesky, cholmod_available

njit = numba.njit(cache=True)
DENSE_BLOCK = 200  # blocks of M up to this size are inverted densely when forming W̃
DENSE_Y_ENTRIES = 2e7  # largest m × nk of a dense Y = blockdiag(L_b⁻¹)Hᵀ (2 float64 each: 320 MB)


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
        oh = np.empty(self.shape[0])
        ol = np.empty(self.shape[0])
        dd.csr_matvec(self.indptr, self.indices, self.hi, self.lo, np.ascontiguousarray(xh),
                      np.ascontiguousarray(xl), oh, ol)
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
        return self.M.matvec(vh, vl)

    def velocity(self, vh, vl, rh, rl):
        """ũ = H̃v + w̃ (global) or W̃r̃ + q̃ (local), double-double (hi, lo)."""
        if self.local:
            ah, al = self.Wt.matvec(rh, rl)
        else:
            ah, al = self.Ht.matvec(vh, vl)
        oh, ol = np.empty(self.nk), np.empty(self.nk)
        dd.vadd(ah, al, self.w_t[0], self.w_t[1], oh, ol)
        return oh, ol


# ---------------------------------------------------------------------- per-contact blocks
@njit
def _schur_parts_spectral(spec, c):
    """For x = p² of L3 cone c, from the spectral data of p (λ1(x) = a², λ2(x) = b², frame
    direction v̂): P00 = (Q_x)_00 = (λ1² + λ2²)/2, the vector −2x0x̄/P00 =
    −(λ1² − λ2²)/(λ1² + λ2²)·v̂, and A⁻¹ = λ1λ2 ŷŷᵀ + 2λ1²λ2²/(λ1² + λ2²) v̂v̂ᵀ (ŷ ⊥ v̂):
    only sums of positive terms, so no eigenvalue is lost to cancellation."""
    l1, l1l = dd.mul(spec[c, 0], spec[c, 1], spec[c, 0], spec[c, 1])
    l2, l2l = dd.mul(spec[c, 2], spec[c, 3], spec[c, 2], spec[c, 3])
    s1, s1l = dd.mul(l1, l1l, l1, l1l)
    s2, s2l = dd.mul(l2, l2l, l2, l2l)
    ss, ssl = dd.add(s1, s1l, s2, s2l)
    P, Pl = 0.5 * ss, 0.5 * ssl
    df, dfl = dd.sub(s1, s1l, s2, s2l)  # λ1² − λ2² ≥ 0 (λ1 ≥ λ2): no cancellation in the result's use
    k, kl = dd.div(df, dfl, ss, ssl)
    d1h, d1l, d2h, d2l = spec[c, 4], spec[c, 5], spec[c, 6], spec[c, 7]
    c1, c1l = dd.mul(-k, -kl, d1h, d1l)
    c2, c2l = dd.mul(-k, -kl, d2h, d2l)
    det, detl = dd.mul(l1, l1l, l2, l2l)
    e, el = dd.mul(det, detl, det, detl)
    e, el = dd.div(2.0 * e, 2.0 * el, ss, ssl)
    xs = ((d1h, d1l), (d2h, d2l))
    ys = ((-d2h, -d2l), (d1h, d1l))
    A = np.zeros((2, 2, 2))
    for a in range(2):
        for b in range(2):
            t, tl = dd.mul(ys[a][0], ys[a][1], ys[b][0], ys[b][1])
            t, tl = dd.mul(t, tl, det, detl)
            u, ul = dd.mul(xs[a][0], xs[a][1], xs[b][0], xs[b][1])
            t, tl = dd.fma_acc(t, tl, u, ul, e, el)
            A[0, a, b] = t
            A[1, a, b] = tl
    return P, Pl, c1, c1l, c2, c2l, A


@njit
def contact_Ginv(n, kinds, fric, roll, normal, spec, Gh, Gl):
    """G_c⁻¹ per contact in closed form from the spectral data of p: one cone G⁻¹ = Q_{p²};
    a full contact by the Schur complement on the shared head, s = 1/P_f,00 + 1/P_r,00
    (see :func:`_schur_parts_spectral`); a normal ray p⁴."""
    Qh = np.zeros((3, 3))
    Ql = np.zeros((3, 3))
    for c in range(n):
        Gh[c, :, :] = 0.0
        Gl[c, :, :] = 0.0
        k = kinds[c]
        if k == 3:  # G⁻¹ = p⁴ on L1
            t, tl = dd.mul(spec[normal[c], 0], spec[normal[c], 1], spec[normal[c], 0], spec[normal[c], 1])
            Gh[c, 0, 0], Gl[c, 0, 0] = dd.mul(t, tl, t, tl)
            continue
        if k == 1 or k == 2:
            C.quad_pow_matrix(fric[c] if k == 1 else roll[c], np.int64(2), spec, Qh, Ql)
            for a in range(3):  # entry by entry: see contact_factor_inverse
                for b in range(3):
                    Gh[c, a, b], Gl[c, a, b] = Qh[a, b], Ql[a, b]
            continue
        Pa, Pal, ca1, ca1l, ca2, ca2l, Aa = _schur_parts_spectral(spec, fric[c])
        Pb, Pbl, cb1, cb1l, cb2, cb2l, Ab = _schur_parts_spectral(spec, roll[c])
        # 1/s = Pa·Pb / (Pa + Pb)
        num, numl = dd.mul(Pa, Pal, Pb, Pbl)
        den, denl = dd.add(Pa, Pal, Pb, Pbl)
        si, sil = dd.div(num, numl, den, denl)
        cvec = ((ca1, ca1l), (ca2, ca2l), (cb1, cb1l), (cb2, cb2l))
        Gh[c, 0, 0], Gl[c, 0, 0] = si, sil
        for a in range(4):
            t, tl = dd.mul(cvec[a][0], cvec[a][1], si, sil)
            Gh[c, 0, a + 1], Gl[c, 0, a + 1] = -t, -tl
            Gh[c, a + 1, 0], Gl[c, a + 1, 0] = -t, -tl
            for b in range(4):
                u, ul = dd.mul(t, tl, cvec[b][0], cvec[b][1])
                if a < 2 and b < 2:
                    u, ul = dd.add(u, ul, Aa[0, a, b], Aa[1, a, b])
                elif a >= 2 and b >= 2:
                    u, ul = dd.add(u, ul, Ab[0, a - 2, b - 2], Ab[1, a - 2, b - 2])
                Gh[c, a + 1, b + 1], Gl[c, a + 1, b + 1] = u, ul


@njit
def contact_block_apply(n, row_start, row_count, Gh, Gl, xh, xl, oh, ol):
    """o = blockdiag(G_c) x over the kept rows."""
    for c in range(n):
        r0 = row_start[c]
        k = row_count[c]
        for a in range(k):
            sh, sl = 0.0, 0.0
            for b in range(k):
                sh, sl = dd.fma_acc(sh, sl, Gh[c, a, b], Gl[c, a, b], xh[r0 + b], xl[r0 + b])
            oh[r0 + a] = sh
            ol[r0 + a] = sl


@njit
def _small_product(Ah, Al, Bh, Bl, rows, cols, inner, Th, Tl):
    """T[:rows, :cols] = A[:rows, :inner] · B[:inner, :cols] in double-double (small dense blocks)."""
    for a in range(rows):
        for j in range(cols):
            sh, sl = 0.0, 0.0
            for b in range(inner):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, b], Al[a, b], Bh[b, j], Bl[b, j])
            Th[a, j] = sh
            Tl[a, j] = sl


@njit
def _assemble_dof(n, row_start, row_count, loc_dofs, loc_cnt, Hh, Hl, Gih, Gil, pos, Sh, Sl):
    """S += Σ_c H̃_cᵀ G_c⁻¹ H̃_c (upper entries only; pos[c, a, b] = -1 off the upper half)."""
    dmax = Hh.shape[2]
    tmph = np.zeros((5, dmax))
    tmpl = np.zeros((5, dmax))
    for c in range(n):
        k = row_count[c]
        d = loc_cnt[c]
        _small_product(Gih[c], Gil[c], Hh[c], Hl[c], k, d, k, tmph, tmpl)  # tmp = G⁻¹ H̃_c (k × d)
        for i in range(d):
            for j in range(d):
                q = pos[c, i, j]
                if q < 0:
                    continue
                sh, sl = Sh[q], Sl[q]
                for a in range(k):
                    sh, sl = dd.fma_acc(sh, sl, Hh[c, a, i], Hl[c, a, i], tmph[a, j], tmpl[a, j])
                Sh[q] = sh
                Sl[q] = sl


@njit
def _dense_half(Mh, Ml, Hh, Hl, Yh, Yl):
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
def _row_gram(Ah, Al, Wh, Wl):
    """W = A Aᵀ (double-double) over the rows of A, each pair once: rows are contiguous, so
    this is the cache-friendly form for a tall Y stored transposed."""
    k = Ah.shape[0]
    for a in range(k):
        for b in range(a, k):
            sh, sl = 0.0, 0.0
            for i in range(Ah.shape[1]):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, i], Al[a, i], Ah[b, i], Al[b, i])
            Wh[a, b], Wl[a, b] = sh, sl
            Wh[b, a], Wl[b, a] = sh, sl


@njit
def _dense_schur(Mh, Ml, Hh, Hl, Wh, Wl):
    """W = H M⁻¹ Hᵀ for a small dense SPD M (Y = L⁻¹Hᵀ, W = YᵀY).  Returns False if M is not
    positive definite."""
    Yh = np.zeros((Mh.shape[0], Hh.shape[0]))
    Yl = np.zeros((Mh.shape[0], Hh.shape[0]))
    if not _dense_half(Mh, Ml, Hh, Hl, Yh, Yl):
        return False
    YTh = np.zeros((Hh.shape[0], Mh.shape[0]))  # Yᵀ, copied by hand (np.ascontiguousarray
    YTl = np.zeros((Hh.shape[0], Mh.shape[0]))  # would be one more compilation)
    for i in range(Mh.shape[0]):
        for c in range(Hh.shape[0]):
            YTh[c, i], YTl[c, i] = Yh[i, c], Yl[i, c]
    _row_gram(YTh, YTl, Wh, Wl)
    return True


@njit
def _dense_gram(Ah, Al, Bh, Bl, Wh, Wl):
    """W = A Bᵀ (double-double, rows of A and B)."""
    for a in range(Ah.shape[0]):
        for b in range(Bh.shape[0]):
            sh, sl = 0.0, 0.0
            for i in range(Ah.shape[1]):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, i], Al[a, i], Bh[b, i], Bl[b, i])
            Wh[a, b], Wl[a, b] = sh, sl


@njit
def _scatter_add(pos, vh, vl, Sh, Sl):
    for k in range(pos.size):
        q = pos[k]
        if q >= 0:
            Sh[q], Sl[q] = dd.add(Sh[q], Sl[q], vh[k], vl[k])


class _Backend:
    name = ""
    factorisations = 0

    def flops(self) -> float:
        cc = np.diff(self.chol.Lp).astype(float)
        return float(np.sum(cc * cc) + self.chol.nnz_upper)

    def stats(self) -> dict:
        """What the factorisation costs (for benchmarks): order, stored upper entries, nnz(L)
        and Σ c_j² (column counts of L in the engine's order), factorisations, solves and
        refinement steps of the float64 engines."""
        ch = self.chol
        cc = np.diff(ch.Lp).astype(float)
        return {"engine": getattr(self, "engine", "ldl"), "precision": getattr(ch, "precision", "double-double"),
                "order": int(ch.n), "nnz_upper": int(ch.nnz_upper), "nnz_L": int(cc.sum()),
                "sum_c2": float(np.sum(cc * cc)), "factorisations": int(self.factorisations),
                "solves": int(getattr(ch, "solves", 0)), "refinement_steps": int(getattr(ch, "refinement_steps", 0))}


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


class DofSpace(_Backend):
    """S_v = M + H̃ᵀ G⁻¹ H̃ factored in double-double."""

    name = "dof-space (M + H̃ᵀG⁻¹H̃)"

    def __init__(self, data: ExtendedData, max_local_dofs: int = 64):
        self.data = data
        n = data.n
        CD = contact_dof_pattern(data)
        self.loc_cnt = np.diff(CD.indptr).astype(np.int64)
        dmax = int(self.loc_cnt.max(initial=1))
        self.dmax = dmax
        self.too_dense = dmax > max_local_dofs
        self.data_ok = not self.too_dense
        pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
        self.chol = DDCholesky(pattern)
        if self.too_dense:
            return
        self.loc_dofs, self.Hh, self.Hl = contact_local_H(data, CD)
        # positions of the local pairs in the upper CSC storage
        ii, jj = np.meshgrid(np.arange(dmax), np.arange(dmax), indexing="ij")
        valid = (ii[None] < self.loc_cnt[:, None, None]) & (jj[None] < self.loc_cnt[:, None, None])
        gi = np.where(valid, self.loc_dofs[:, :, None].repeat(dmax, 2), 0)
        gj = np.where(valid, self.loc_dofs[:, None, :].repeat(dmax, 1), 0)
        pi, pj = self.chol.iperm[gi], self.chol.iperm[gj]
        upper = valid & (pi <= pj)
        pos = np.full(valid.shape, -1, dtype=np.int64)
        pos[upper] = self.chol.positions(gi[upper], gj[upper])
        self.pos = pos
        mr, mc, mh, ml = data.M.coo()
        keep = self.chol.iperm[mr] <= self.chol.iperm[mc]
        self.M_pos = np.full(mr.size, -1, dtype=np.int64)
        self.M_pos[keep] = self.chol.positions(mr[keep], mc[keep])
        self.M_vals = (np.ascontiguousarray(mh), np.ascontiguousarray(ml))
        self.Gih = np.zeros((n, 5, 5))
        self.Gil = np.zeros((n, 5, 5))

    def update(self, ph, pl, pih, pil, spec) -> bool:
        d = self.data
        contact_Ginv(d.n, d.kinds, d.fric_cone, d.roll_cone, d.normal_cone, spec, self.Gih, self.Gil)
        Sh = np.zeros(self.chol.nnz_upper)
        Sl = np.zeros(self.chol.nnz_upper)
        _scatter_add(self.M_pos, self.M_vals[0], self.M_vals[1], Sh, Sl)
        _assemble_dof(d.n, d.row_start, d.row_count, self.loc_dofs, self.loc_cnt, self.Hh, self.Hl,
                      self.Gih, self.Gil, self.pos, Sh, Sl)
        self.factorisations += 1
        return self.chol.factor(Sh, Sl) < 0

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (local form: (W̃ + G) dr̃ = t)."""
        d = self.data
        if d.local:
            return (np.zeros(0), np.zeros(0)), self._S_solve(np.ascontiguousarray(t[0]), np.ascontiguousarray(t[1]))
        gh, gl = np.empty(d.nk), np.empty(d.nk)
        contact_block_apply(d.n, d.row_start, d.row_count, self.Gih, self.Gil, t[0], t[1], gh, gl)
        yh, yl = d.HtT.matvec(gh, gl)
        rh, rl = np.empty(d.m), np.empty(d.m)
        dd.vadd(a[0], a[1], yh, yl, rh, rl)
        dvh, dvl = self.chol.solve(rh, rl)
        hh, hl = d.Ht.matvec(dvh, dvl)
        eh, el = np.empty(d.nk), np.empty(d.nk)
        dd.vadd(t[0], t[1], -hh, -hl, eh, el)
        drh, drl = np.empty(d.nk), np.empty(d.nk)
        contact_block_apply(d.n, d.row_start, d.row_count, self.Gih, self.Gil, eh, el, drh, drl)
        return (dvh, dvl), (drh, drl)


@njit
def _householder_factor(At_h, At_l, k, Rinv_h, Rinv_l):
    """QR of the m×k matrix Aᵀ (double-double Householder); writes (R⁻¹)ᵀ, so that with
    F = Rᵀ: F Fᵀ = A Aᵀ and F⁻¹ = (R⁻¹)ᵀ.  Returns False if R is singular."""
    m = At_h.shape[0]
    Ah = At_h.copy()
    Al = At_l.copy()
    vh = np.zeros(m)
    vl = np.zeros(m)
    for j in range(k):
        sh, sl = 0.0, 0.0
        for i in range(j, m):
            sh, sl = dd.fma_acc(sh, sl, Ah[i, j], Al[i, j], Ah[i, j], Al[i, j])
        nh, nl = dd.sqrt(sh, sl)
        if nh == 0.0:
            return False
        if Ah[j, j] > 0.0:
            nh, nl = -nh, -nl
        # v = x − α e1 with α = −sign(x0)‖x‖ (no cancellation); R_jj = α
        for i in range(j, m):
            vh[i], vl[i] = Ah[i, j], Al[i, j]
        vh[j], vl[j] = dd.sub(Ah[j, j], Al[j, j], nh, nl)
        th, tl = 0.0, 0.0
        for i in range(j, m):
            th, tl = dd.fma_acc(th, tl, vh[i], vl[i], vh[i], vl[i])
        bh, bl = dd.div(2.0, 0.0, th, tl)
        for c in range(j + 1, k):
            ph, pl = 0.0, 0.0
            for i in range(j, m):
                ph, pl = dd.fma_acc(ph, pl, vh[i], vl[i], Ah[i, c], Al[i, c])
            ph, pl = dd.mul(ph, pl, bh, bl)
            for i in range(j, m):
                Ah[i, c], Al[i, c] = dd.fms_acc(Ah[i, c], Al[i, c], ph, pl, vh[i], vl[i])
        Ah[j, j], Al[j, j] = nh, nl
    # R⁻¹ (upper triangular) by back substitution, stored transposed
    for c in range(k):
        for r in range(k):
            Rinv_h[r, c] = 0.0
            Rinv_l[r, c] = 0.0
    for c in range(k):  # column c of R⁻¹
        for r in range(c, -1, -1):
            sh, sl = (1.0, 0.0) if r == c else (0.0, 0.0)
            for q in range(r + 1, c + 1):
                sh, sl = dd.fms_acc(sh, sl, Ah[r, q], Al[r, q], Rinv_h[c, q], Rinv_l[c, q])
            Rinv_h[c, r], Rinv_l[c, r] = dd.div(sh, sl, Ah[r, r], Al[r, r])
    return True


@njit
def contact_factor_inverse(n, kinds, fric, roll, normal, spec, Fh, Fl):
    """F_c⁻¹ for a factor F_c with F_c F_cᵀ = G_c = J_c Q_{p⁻²} J_cᵀ: Q_p for one cone, p for a
    normal ray, and (R⁻¹)ᵀ from a Householder QR of (J_c Q_{p⁻¹})ᵀ for a full contact (never
    G_c itself: its condition number is the square of the factor's).  Returns the first
    contact whose factor is singular, or -1.

    Compile time (a cold start compiles this on the first solve): blocks are copied entry by
    entry, since a slice assignment's shape check compiles numba's error-message formatting
    (seconds), and integer constants passed to compiled helpers are wrapped as np.int64(k),
    since a bare literal compiles one specialisation of the helper per value."""
    Qh = np.zeros((3, 3))
    Ql = np.zeros((3, 3))
    At_h = np.zeros((6, 5))
    At_l = np.zeros((6, 5))
    Rh = np.zeros((5, 5))
    Rl = np.zeros((5, 5))
    for c in range(n):
        Fh[c, :, :] = 0.0
        Fl[c, :, :] = 0.0
        k = kinds[c]
        if k == 3:  # L1: Q_{p⁻¹} = p⁻², so G = p⁻⁴ and F⁻¹ = Q_p = p²
            Fh[c, 0, 0], Fl[c, 0, 0] = dd.mul(spec[normal[c], 0], spec[normal[c], 1], spec[normal[c], 0],
                                              spec[normal[c], 1])
        elif k == 1 or k == 2:
            C.quad_pow_matrix(fric[c] if k == 1 else roll[c], np.int64(1), spec, Qh, Ql)
            for a in range(3):
                for b in range(3):
                    Fh[c, a, b], Fl[c, a, b] = Qh[a, b], Ql[a, b]
        else:
            At_h[:, :] = 0.0
            At_l[:, :] = 0.0
            C.quad_pow_matrix(fric[c], np.int64(-1), spec, Qh, Ql)
            for i in range(3):
                for j in range(3):
                    At_h[i, j], At_l[i, j] = Qh[i, j], Ql[i, j]
            C.quad_pow_matrix(roll[c], np.int64(-1), spec, Qh, Ql)
            cols = (0, 3, 4)
            for i in range(3):
                for j in range(3):
                    At_h[3 + i, cols[j]], At_l[3 + i, cols[j]] = Qh[i, j], Ql[i, j]
            if not _householder_factor(At_h, At_l, np.int64(5), Rh, Rl):
                return c
            for a in range(5):
                for b in range(5):
                    Fh[c, a, b], Fl[c, a, b] = Rh[a, b], Rl[a, b]
    return -1


@njit
def _scaled_blocks(pc, pd, Wh, Wl, row_count, Fh, Fl, pos, Sh, Sl):
    """S' = F⁻¹ W̃ F⁻ᵀ + I, block pair by block pair (p: contacts pc[p] ≤ pd[p])."""
    Th = np.zeros((5, 5))
    Tl = np.zeros((5, 5))
    for p in range(pc.size):
        c = pc[p]
        d = pd[p]
        kc = row_count[c]
        kd = row_count[d]
        _small_product(Fh[c], Fl[c], Wh[p], Wl[p], kc, kd, kc, Th, Tl)  # T = F_c⁻¹ W̃_cd
        for a in range(kc):
            for b in range(kd):
                q_ = pos[p, a, b]
                if q_ < 0:
                    continue
                sh, sl = (1.0, 0.0) if (c == d and a == b) else (0.0, 0.0)
                for q in range(kd):
                    sh, sl = dd.fma_acc(sh, sl, Th[a, q], Tl[a, q], Fh[d, b, q], Fl[d, b, q])
                Sh[q_] = sh
                Sl[q_] = sl


@njit
def _block_apply(n, row_start, row_count, Fh, Fl, transpose, xh, xl, oh, ol):
    for c in range(n):
        r0 = row_start[c]
        k = row_count[c]
        for a in range(k):
            sh, sl = 0.0, 0.0
            for b in range(k):
                if transpose:
                    sh, sl = dd.fma_acc(sh, sl, Fh[c, b, a], Fl[c, b, a], xh[r0 + b], xl[r0 + b])
                else:
                    sh, sl = dd.fma_acc(sh, sl, Fh[c, a, b], Fl[c, a, b], xh[r0 + b], xl[r0 + b])
            oh[r0 + a] = sh
            ol[r0 + a] = sl


@njit
def _scatter_pairs(pidx, a, b, vh, vl, Wh, Wl):
    for k in range(pidx.size):
        p = pidx[k]
        Wh[p, a[k], b[k]], Wl[p, a[k], b[k]] = dd.add(Wh[p, a[k], b[k]], Wl[p, a[k], b[k]], vh[k], vl[k])


class ContactSpace(_Backend):
    """The contact-space system S = W̃ + G with W̃ = H̃ M⁻¹ H̃ᵀ (built once), factored in its
    scaled form S' = F⁻¹ S F⁻ᵀ = F⁻¹ W̃ F⁻ᵀ + I, where F = blockdiag(F_c), F_c F_cᵀ = G_c.

    G's eigenvalues run from about μ to 1/μ inside one contact block (sliding contacts); the
    Cholesky factor of S then loses definiteness in double-double near μ = 1e-20 (measured
    on a 1368-contact Chute).  S' has every eigenvalue ≥ 1, and F_c comes from the
    Jordan-algebra factors without squaring a condition number.
    """

    @property
    def name(self) -> str:
        how = {"mixed": "float64 factor refined in double-double",
               "double-double": "double-double factor"}[getattr(self.chol, "precision", "double-double")]
        if isinstance(self.chol, CholmodMixed) and self.chol.precision == "mixed":
            how = "float64 CHOLMOD factor refined in double-double"
        reason = getattr(self.chol, "fallback_reason", "")
        form = "I + F⁻¹W̃F⁻ᵀ, W̃ = P W P of the local file" if self.data.local else "I + F⁻¹H̃M⁻¹H̃ᵀF⁻ᵀ"
        return f"contact-space, scaled ({form}), {how}" + (f" ({reason})" if reason else "")

    def __init__(self, data: ExtendedData, mixed: bool = True, engine: str = "auto"):
        from scipy.sparse.csgraph import connected_components

        self.data = data
        m, nk, n = data.m, data.nk, data.n
        self.contact_of_row = np.repeat(np.arange(n), data.row_count)
        C = sp.csr_matrix((np.ones(nk), (self.contact_of_row, np.arange(nk))), shape=(n, nk))
        if data.local:  # W̃ is given: contacts are coupled where it has entries
            self.Mchol = None
            Wp = sp.csr_matrix((np.ones_like(data.Wt.hi), data.Wt.indices, data.Wt.indptr), shape=(nk, nk))
            CW = (C @ Wp @ C.T).tocsr()
            CW.data[:] = 1
            CC = sp.triu(CW + sp.identity(n), format="coo")
        else:
            Mp = sp.csr_matrix((np.ones_like(data.M.hi), data.M.indices, data.M.indptr), shape=(m, m))
            self.Mchol = DDCholesky(Mp)
            nb, labels = connected_components(Mp, directed=False)
            self.n_blocks, self.labels = nb, labels
            Ht = sp.csr_matrix((np.ones_like(data.Ht.hi), data.Ht.indices, data.Ht.indptr), shape=data.Ht.shape)
            B = sp.csr_matrix((np.ones(m), (np.arange(m), labels)), shape=(m, nb))
            CB = (C @ Ht @ B).tocsr()
            CB.data[:] = 1
            CC = sp.triu(CB @ CB.T + sp.identity(n), format="coo")
        order = np.lexsort((CC.col, CC.row))
        self.pc = CC.row[order].astype(np.int64)
        self.pd = CC.col[order].astype(np.int64)
        self._pair_keys = self.pc * n + self.pd
        # kept-row pattern: every pair block is dense
        ii, jj = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
        kc = data.row_count[self.pc][:, None, None]
        kd = data.row_count[self.pd][:, None, None]
        valid = (ii[None] < kc) & (jj[None] < kd)
        gi = np.where(valid, data.row_start[self.pc][:, None, None] + ii[None], 0)
        gj = np.where(valid, data.row_start[self.pd][:, None, None] + jj[None], 0)
        same = (self.pc == self.pd)[:, None, None]
        take = valid & (~same | (ii[None] <= jj[None]))
        pattern = sp.coo_matrix((np.ones(int(take.sum())), (gi[take], gj[take])), shape=(nk, nk))
        self.engine = resolve_engine(engine, nk) if mixed else "ldl"
        if not mixed:
            self.chol = DDCholesky(pattern)
        elif self.engine == "cholmod":
            self.chol = CholmodMixed(pattern)
        else:
            self.chol = MixedCholesky(pattern)
        self.pos = np.full(valid.shape, -1, dtype=np.int64)
        self.pos[take] = self.chol.positions(gi[take], gj[take])
        self._W = None
        self.dense_W = None  # None: choose the construction of W̃ by its cost; True/False: force it
        self.dense_W_used = None
        self.Fh = np.zeros((n, 5, 5))
        self.Fl = np.zeros((n, 5, 5))

    def _pair_index(self, c, d):
        return np.searchsorted(self._pair_keys, c * self.data.n + d)

    def _build_W_local(self):
        """W̃ of a local problem, copied into pair blocks from the file's (scaled) W."""
        d = self.data
        Wh = np.zeros((self.pc.size, 5, 5))
        Wl = np.zeros((self.pc.size, 5, 5))
        rows = np.repeat(np.arange(d.nk), np.diff(d.Wt.indptr))
        cols = d.Wt.indices
        ci, cj = self.contact_of_row[rows], self.contact_of_row[cols]
        keep = ci <= cj
        pidx = self._pair_index(ci[keep], cj[keep])
        a = (rows - d.row_start[ci])[keep]
        b = (cols - d.row_start[cj])[keep]
        Wh[pidx, a, b] = d.Wt.hi[keep]
        Wl[pidx, a, b] = d.Wt.lo[keep]
        self._W = (Wh, Wl)

    def _build_W(self):
        """W̃ = H̃ M⁻¹ H̃ᵀ in pair blocks, block by block of M: W̃ += H_b M_b⁻¹ H_bᵀ over the
        rows touching block b (dense double-double Cholesky of M_b up to DENSE_BLOCK dofs,
        the sparse factor of M above)."""
        d = self.data
        if d.local:
            self._build_W_local()
            return
        mr, mc, mh, ml = d.M.coo()
        Wh = np.zeros((self.pc.size, 5, 5))
        Wl = np.zeros((self.pc.size, 5, 5))
        rows_all = np.repeat(np.arange(d.nk), np.diff(d.Ht.indptr))
        blk_of_nz = self.labels[d.Ht.indices]
        order = np.lexsort((rows_all, blk_of_nz))
        bounds = np.searchsorted(blk_of_nz[order], np.arange(self.n_blocks + 1))
        m_blk = self.labels[mr]
        m_order = np.argsort(m_blk, kind="stable")
        m_bounds = np.searchsorted(m_blk[m_order], np.arange(self.n_blocks + 1))
        dof_order = np.argsort(self.labels, kind="stable")
        dof_bounds = np.searchsorted(self.labels[dof_order], np.arange(self.n_blocks + 1))
        local = np.empty(d.m, dtype=np.int64)
        row_local = np.arange(d.nk) - d.row_start[self.contact_of_row]
        # rows touching each block: Σ rows_b² is what the block-by-block scatter costs; where a
        # few blocks touch most rows (a dense H, as in a lifted local problem with M = I), one
        # dense Y = blockdiag(L_b⁻¹)Hᵀ and W̃ = YᵀY is far cheaper (DECISIONS, "dense W̃")
        touching = np.unique(blk_of_nz.astype(np.int64) * d.nk + rows_all)
        rows_per_block = np.bincount(touching // d.nk, minlength=self.n_blocks).astype(np.float64)
        block_sizes = np.diff(dof_bounds)
        dense_Y = (float(np.sum(rows_per_block ** 2)) > 4.0 * d.nk * d.nk and d.m * d.nk <= DENSE_Y_ENTRIES
                   and int(block_sizes.max(initial=0)) <= DENSE_BLOCK)
        if self.dense_W is not None:  # tests compare both constructions
            dense_Y = bool(self.dense_W) and int(block_sizes.max(initial=0)) <= DENSE_BLOCK
        self.dense_W_used = dense_Y
        if dense_Y:
            YTh, YTl = np.zeros((d.nk, d.m)), np.zeros((d.nk, d.m))  # Yᵀ: rows = kept rows of H̃
        for b in range(self.n_blocks):
            sel = order[bounds[b]:bounds[b + 1]]
            if sel.size == 0:
                continue
            dofs = dof_order[dof_bounds[b]:dof_bounds[b + 1]]
            s_ = dofs.size
            local[dofs] = np.arange(s_)
            rows = np.unique(rows_all[sel])
            rl = np.searchsorted(rows, rows_all[sel])
            Hbh = np.zeros((rows.size, s_))
            Hbl = np.zeros((rows.size, s_))
            Hbh[rl, local[d.Ht.indices[sel]]] = d.Ht.hi[sel]
            Hbl[rl, local[d.Ht.indices[sel]]] = d.Ht.lo[sel]
            if s_ > DENSE_BLOCK:
                Wbh, Wbl = self._schur_sparse(Hbh, Hbl, dofs)
            else:
                ms = m_order[m_bounds[b]:m_bounds[b + 1]]
                Mbh = np.zeros((s_, s_))
                Mbl = np.zeros((s_, s_))
                Mbh[local[mr[ms]], local[mc[ms]]] = mh[ms]
                Mbl[local[mr[ms]], local[mc[ms]]] = ml[ms]
                if dense_Y:
                    Ybh, Ybl = np.zeros((s_, rows.size)), np.zeros((s_, rows.size))
                    if not _dense_half(Mbh, Mbl, Hbh, Hbl, Ybh, Ybl):
                        raise ArithmeticError(f"block {b} of M is not positive definite in double-double")
                    YTh[np.ix_(rows, dofs)], YTl[np.ix_(rows, dofs)] = Ybh.T, Ybl.T
                    continue
                Wbh, Wbl = np.zeros((rows.size, rows.size)), np.zeros((rows.size, rows.size))
                if not _dense_schur(Mbh, Mbl, Hbh, Hbl, Wbh, Wbl):
                    raise ArithmeticError(f"block {b} of M is not positive definite in double-double")
            ii, jj = np.meshgrid(np.arange(rows.size), np.arange(rows.size), indexing="ij")
            ci, cj = self.contact_of_row[rows[ii]], self.contact_of_row[rows[jj]]
            keep = ci <= cj
            pidx = self._pair_index(ci[keep], cj[keep])
            _scatter_pairs(pidx, row_local[rows[ii]][keep], row_local[rows[jj]][keep],
                           np.ascontiguousarray(Wbh[keep]), np.ascontiguousarray(Wbl[keep]), Wh, Wl)
        if dense_Y:
            Gh, Gl = np.zeros((d.nk, d.nk)), np.zeros((d.nk, d.nk))
            _row_gram(YTh, YTl, Gh, Gl)
            ii, jj = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
            valid = (ii[None] < d.row_count[self.pc][:, None, None]) & (jj[None] < d.row_count[self.pd][:, None, None])
            gi = d.row_start[self.pc][:, None, None] + ii[None]
            gj = d.row_start[self.pd][:, None, None] + jj[None]
            Wh[valid], Wl[valid] = Gh[gi[valid], gj[valid]], Gl[gi[valid], gj[valid]]
        self._W = (Wh, Wl)

    def _schur_sparse(self, Hbh, Hbl, dofs):
        """H_b M_b⁻¹ H_bᵀ for a large block through the sparse factor of M (one solve per row)."""
        m = self.data.m
        k = Hbh.shape[0]
        Xh, Xl = np.zeros((k, dofs.size)), np.zeros((k, dofs.size))
        for a in range(k):
            bh, bl = np.zeros(m), np.zeros(m)
            bh[dofs], bl[dofs] = Hbh[a], Hbl[a]
            xh, xl = self.Mchol.solve(bh, bl)
            Xh[a], Xl[a] = xh[dofs], xl[dofs]
        Wh, Wl = np.zeros((k, k)), np.zeros((k, k))
        _dense_gram(Hbh, Hbl, Xh, Xl, Wh, Wl)
        return Wh, Wl

    def _M_upper(self):
        d = self.data
        mr, mc, mh, ml = d.M.coo()
        keep = self.Mchol.iperm[mr] <= self.Mchol.iperm[mc]
        pos = self.Mchol.positions(mr[keep], mc[keep])
        h = np.zeros(self.Mchol.nnz_upper)
        lo = np.zeros(self.Mchol.nnz_upper)
        _scatter_add(pos, np.ascontiguousarray(mh[keep]), np.ascontiguousarray(ml[keep]), h, lo)
        return h, lo

    def update(self, ph, pl, pih, pil, spec) -> bool:
        d = self.data
        if self._W is None:
            if self.Mchol is not None and self.Mchol.factor(*self._M_upper()) >= 0:
                raise ArithmeticError("M is not positive definite in double-double")
            self._build_W()
        if contact_factor_inverse(d.n, d.kinds, d.fric_cone, d.roll_cone, d.normal_cone, spec,
                                  self.Fh, self.Fl) >= 0:
            return False
        Sh = np.zeros(self.chol.nnz_upper)
        Sl = np.zeros(self.chol.nnz_upper)
        _scaled_blocks(self.pc, self.pd, self._W[0], self._W[1], d.row_count, self.Fh, self.Fl, self.pos, Sh, Sl)
        self.factorisations += 1
        return self.chol.factor(Sh, Sl) < 0

    def _S_solve(self, rh, rl):
        """S⁻¹ r = F⁻ᵀ S'⁻¹ F⁻¹ r."""
        d = self.data
        yh, yl = np.empty(d.nk), np.empty(d.nk)
        _block_apply(d.n, d.row_start, d.row_count, self.Fh, self.Fl, False, rh, rl, yh, yl)
        xh, xl = self.chol.solve(yh, yl)
        oh, ol = np.empty(d.nk), np.empty(d.nk)
        _block_apply(d.n, d.row_start, d.row_count, self.Fh, self.Fl, True, xh, xl, oh, ol)
        return oh, ol

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (local form: (W̃ + G) dr̃ = t)."""
        d = self.data
        if d.local:
            return (np.zeros(0), np.zeros(0)), self._S_solve(np.ascontiguousarray(t[0]), np.ascontiguousarray(t[1]))
        yh, yl = self.Mchol.solve(a[0], a[1])
        hh, hl = d.Ht.matvec(yh, yl)
        rh, rl = np.empty(d.nk), np.empty(d.nk)
        dd.vadd(t[0], t[1], -hh, -hl, rh, rl)
        drh, drl = self._S_solve(rh, rl)
        gh, gl = d.HtT.matvec(drh, drl)
        sh, sl = np.empty(d.m), np.empty(d.m)
        dd.vadd(a[0], a[1], gh, gl, sh, sl)
        dvh, dvl = self.Mchol.solve(sh, sl)
        return (dvh, dvl), (drh, drl)


class Hybrid(_Backend):
    """The dof-space form while it is accurate, then the contact-space form.

    The dof-space Schur complement M + H̃ᵀG⁻¹H̃ is 7–12× cheaper to factor on rigid-body
    problems (1.5e7 against 1.1e8 flops on a 769-contact SpheresPile, 2.0e8 against 2.6e9 on a
    2269-contact random problem), but its ill-conditioning is not diagonal: H̃ᵀG⁻¹H̃ carries
    1/μ along sticking contacts, and on that pile its primal residual blew up once μ fell below
    about 1e-9 of its starting value (μ ≈ 2e-21), while the scaled contact-space form reached
    μ = 1e-33.  So the run switches for good when μ falls below ``switch`` × its first value,
    or as soon as a dof-space solve refines badly (relative residual above ``bad_solve``).
    """

    def __init__(self, data: ExtendedData, switch: float = 1e-6, bad_solve: float = 1e-22,
                 dof: DofSpace | None = None, contact: ContactSpace | None = None):
        self.dof = dof or DofSpace(data)
        self.contact = contact or ContactSpace(data)
        self.current = self.dof
        self.switch = switch
        self.bad_solve = bad_solve
        self._mu0 = None
        self.switched_at = None
        self.name = "hybrid: dof-space, then contact-space"

    @property
    def factorisations(self):
        return self.dof.factorisations + self.contact.factorisations

    def observe(self, k: int, mu: float, solve_residual: float | None):
        """Called by the driver once per iteration (before the factorisation)."""
        if self._mu0 is None:
            self._mu0 = mu
        if self.current is self.dof and (mu < self.switch * self._mu0
                                          or (solve_residual is not None and solve_residual > self.bad_solve)):
            self.current = self.contact
            self.switched_at = k

    def update(self, ph, pl, pih, pil, spec) -> bool:
        ok = self.current.update(ph, pl, pih, pil, spec)
        if not ok and self.current is self.dof:  # lost definiteness: switch now
            self.current = self.contact
            ok = self.current.update(ph, pl, pih, pil, spec)
        return ok

    def solve(self, a, t):
        return self.current.solve(a, t)


ENGINES = ("auto", "ldl", "cholmod")
CHOLMOD_MIN_ROWS = 0
"""Smallest contact-space matrix (kept rows) ``engine="auto"`` factors with CHOLMOD when it is
installed: 0, since no size was measured where the compiled LDLᵀ is faster (164 to 9675
contacts; docs/DECISIONS.md "The 10-digit path at scale")."""


def resolve_engine(engine: str, rows: int) -> str:
    """"cholmod" or "ldl": the float64 factorisation engine of the contact-space form.
    ``auto`` takes CHOLMOD (scikit-sparse, optional extra ``cholmod``) when it is importable and
    the matrix has at least :data:`CHOLMOD_MIN_ROWS` rows, else the compiled up-looking LDLᵀ;
    ``cholmod`` demands it (ImportError, saying what to install, when absent)."""
    if engine not in ENGINES:
        raise ValueError(f"engine {engine!r} is not one of {', '.join(ENGINES)}")
    if engine == "ldl":
        return "ldl"
    if engine == "cholmod":
        if not cholmod_available():
            raise ImportError("the cholmod engine needs CHOLMOD through scikit-sparse: pip install "
                              "'rfverify[cholmod]' (and libsuitesparse-dev, an optimised BLAS such as "
                              "libopenblas0, to build and run it)")
        return "cholmod"
    return "cholmod" if rows >= CHOLMOD_MIN_ROWS and cholmod_available() else "ldl"


def choose_backend(data: ExtendedData, backend: str = "auto", engine: str = "auto"):
    """The back end asked for.  ``auto`` is the scaled contact-space form with a float64
    factorisation refined in double-double (:class:`ContactSpace`): with the factorisation in
    float64 it is as fast as or faster than the dof-space and hybrid forms on every problem
    measured (docs/DECISIONS.md), and its accuracy does not depend on μ.  ``contact-dd`` factors
    in double-double throughout; ``dof`` and ``hybrid`` are the dof-space forms.  ``engine``
    (:func:`resolve_engine`) is the float64 factorisation of the contact-space form: CHOLMOD
    where scikit-sparse is installed ("auto"), or forced ("cholmod", "ldl")."""
    if data.local and backend in ("dof", "hybrid"):
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("backend", f"{backend!r} works in the dofs of a global problem; a local "
                                              "problem has none", fix="use backend 'auto', 'contact' or 'contact-dd'")
    if backend == "dof":
        return DofSpace(data, max_local_dofs=10**9)
    if backend in ("auto", "contact"):
        return ContactSpace(data, engine=engine)
    if backend == "contact-dd":
        return ContactSpace(data, mixed=False)
    if backend == "hybrid":
        return Hybrid(data, contact=ContactSpace(data, engine=engine))
    raise ValueError(f"backend {backend!r} is not one of auto, contact, contact-dd, hybrid, dof")
