"""Double-double kernels (numba) on the per-contact blocks of G = J Q_{p⁻²} Jᵀ, which both
Newton-system back ends use.

Kept rows of one contact are contiguous (``ExtendedData.row_start``, ``row_count``: at most 5
rows, a friction cone and a rolling cone sharing their head).  Blocks are stored as (n, 5, 5)
high and low arrays, zero past a contact's kept rows:

* :func:`contact_Ginv` — G_c⁻¹ in closed form (the dof-space form, :mod:`.dofspace`);
* :func:`contact_factor_inverse` — F_c⁻¹ for F_c F_cᵀ = G_c (the scaled contact-space form,
  :mod:`.contactspace`);
* :func:`block_apply`, :func:`small_product`, :func:`scatter_add` — products with the blocks
  and the accumulation of block entries into a factor's value array.
"""

from __future__ import annotations

import numba
import numpy as np

from . import cones as C
from . import dd
from .workers import split

njit = numba.njit(cache=True, nogil=True)  # nogil: run on threads by .workers


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
def _single_cone_blocks(n, kinds, fric, roll, normal, spec, power, Bh, Bl):
    """Zero every block, then B_c = Q_{p^power} (power 1 or 2) on the contacts with a single
    cone: :func:`.cones.quad_pow_matrix` on an L3 cone, p^(2·power) on a normal ray (Q_x y =
    x²y in L1).  Full contacts (two cones sharing their head) are left to the caller."""
    Qh = np.zeros((3, 3))
    Ql = np.zeros((3, 3))
    for c in range(n):
        Bh[c, :, :] = 0.0
        Bl[c, :, :] = 0.0
        k = kinds[c]
        if k == 3:
            t, tl = dd.mul(spec[normal[c], 0], spec[normal[c], 1], spec[normal[c], 0], spec[normal[c], 1])
            if power == 2:
                t, tl = dd.mul(t, tl, t, tl)
            Bh[c, 0, 0], Bl[c, 0, 0] = t, tl
        elif k == 1 or k == 2:
            C.quad_pow_matrix(fric[c] if k == 1 else roll[c], power, spec, Qh, Ql)
            for a in range(3):  # entry by entry: see contact_factor_inverse
                for b in range(3):
                    Bh[c, a, b], Bl[c, a, b] = Qh[a, b], Ql[a, b]


@njit
def contact_Ginv(n, kinds, fric, roll, normal, spec, Gh, Gl):
    """G_c⁻¹ per contact in closed form from the spectral data of p: one cone G⁻¹ = Q_{p²};
    a full contact by the Schur complement on the shared head, s = 1/P_f,00 + 1/P_r,00
    (see :func:`_schur_parts_spectral`); a normal ray p⁴."""
    _single_cone_blocks(n, kinds, fric, roll, normal, spec, np.int64(2), Gh, Gl)
    for c in range(n):
        if kinds[c] != 0:
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
def block_apply(n, row_start, row_count, Fh, Fl, transpose, xh, xl, oh, ol):
    """o = blockdiag(B_c) x over the kept rows, or blockdiag(B_cᵀ) x with ``transpose``
    (B_c: the (n, 5, 5) blocks Fh + Fl)."""
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
def small_product(Ah, Al, Bh, Bl, rows, cols, inner, Th, Tl):
    """T[:rows, :cols] = A[:rows, :inner] · B[:inner, :cols] in double-double (small dense blocks)."""
    for a in range(rows):
        for j in range(cols):
            sh, sl = 0.0, 0.0
            for b in range(inner):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, b], Al[a, b], Bh[b, j], Bl[b, j])
            Th[a, j] = sh
            Tl[a, j] = sl


@njit
def scatter_add(pos, vh, vl, Sh, Sl):
    """S[pos[k]] += v[k] in double-double, skipping pos[k] < 0."""
    for k in range(pos.size):
        q = pos[k]
        if q >= 0:
            Sh[q], Sl[q] = dd.add(Sh[q], Sl[q], vh[k], vl[k])


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
    _single_cone_blocks(n, kinds, fric, roll, normal, spec, np.int64(1), Fh, Fl)  # L1: F⁻¹ = Q_p = p²
    Qh = np.zeros((3, 3))
    Ql = np.zeros((3, 3))
    At_h = np.zeros((6, 5))
    At_l = np.zeros((6, 5))
    Rh = np.zeros((5, 5))
    Rl = np.zeros((5, 5))
    for c in range(n):
        if kinds[c] != 0:
            continue
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


# The contact-by-contact kernels over the threads (:mod:`.workers`): contacts lo … hi as one
# call on array views, bit for bit the single call's result.

def block_apply_threaded(n, row_start, row_count, Fh, Fl, transpose, xh, xl, oh, ol) -> None:
    """:func:`block_apply` over the threads."""
    def run(lo, hi):
        block_apply(hi - lo, row_start[lo:hi], row_count[lo:hi], Fh[lo:hi], Fl[lo:hi], transpose, xh, xl, oh, ol)

    split(n, run, min_items=8192)  # 0.2 µs a contact


def applied_blocks(data, Bh, Bl, transpose: bool, xh, xl, *, threaded: bool = False) -> tuple:
    """(hi, lo) of the per-contact blocks ``B`` (e.g. the factor F⁻¹; ``transpose``: Bᵀ) applied
    to the double-double vector x over ``data``'s kept rows (:class:`.contactspace.ContactSpace`'s
    F⁻¹ and F⁻ᵀ), ``threaded`` over the CPUs (bit for bit the one-call result)."""
    oh, ol = np.empty(data.nk), np.empty(data.nk)
    (block_apply_threaded if threaded else block_apply)(data.n, data.row_start, data.row_count, Bh, Bl, transpose,
                                                        np.ascontiguousarray(xh), np.ascontiguousarray(xl), oh, ol)
    return oh, ol


def contact_factor_inverse_threaded(n, kinds, fric, roll, normal, spec, Fh, Fl) -> int:
    """:func:`contact_factor_inverse` over the threads: the first contact whose factor is
    singular, or -1."""
    def run(lo, hi):
        bad = contact_factor_inverse(hi - lo, kinds[lo:hi], fric[lo:hi], roll[lo:hi], normal[lo:hi], spec,
                                     Fh[lo:hi], Fl[lo:hi])
        return lo + bad if bad >= 0 else -1

    found = [b for b in split(n, run, min_items=512) if b >= 0]  # 4 µs a contact
    return min(found) if found else -1
