"""Jordan-algebra kernels of the product cone L3^{n3} × L1^{n1} in double-double (numba).

Layout as in the production solver: a cone vector of length 3·n3 + n1 holds the L3 cones
(x0, x1, x2) first, then the L1 cones.  Each kernel takes the hi and lo arrays and works
cone by cone; the formulas are the cancellation-free ones of :mod:`reference.jordan` and
:mod:`rfverify.jordan` (factored det, CVXOPT-style NT scaling, closed-form square root,
step length through Q_{x^{-1/2}}), so this is a third implementation written from DESIGN §3,
tested against both.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from . import dd
from .workers import split

njit = numba.njit(cache=True, nogil=True)  # nogil: run on threads by .workers


@dd.jit
def _bar_norm(x1h, x1l, x2h, x2l):
    sh, sl = dd.mul(x1h, x1l, x1h, x1l)
    sh, sl = dd.fma_acc(sh, sl, x2h, x2l, x2h, x2l)
    return dd.sqrt(sh, sl)


@dd.jit
def _lams(x0h, x0l, x1h, x1l, x2h, x2l):
    nh, nl = _bar_norm(x1h, x1l, x2h, x2l)
    l1h, l1l = dd.add(x0h, x0l, nh, nl)
    l2h, l2l = dd.sub(x0h, x0l, nh, nl)
    return l1h, l1l, l2h, l2l


@dd.jit
def _root_det(l1h, l1l, l2h, l2l):
    """√(λ1λ2) as √λ1·√λ2: no cancellation when λ2 ≪ λ1."""
    ah, al = dd.sqrt(l1h, l1l)
    bh, bl = dd.sqrt(l2h, l2l)
    return dd.mul(ah, al, bh, bl)


@dd.jit
def _div3(x0h, x0l, x1h, x1l, x2h, x2l, dh, dl):
    """(x0, x1, x2)/d, each component by one double-double division."""
    y0h, y0l = dd.div(x0h, x0l, dh, dl)
    y1h, y1l = dd.div(x1h, x1l, dh, dl)
    y2h, y2l = dd.div(x2h, x2l, dh, dl)
    return y0h, y0l, y1h, y1l, y2h, y2l


@njit
def min_lambda2(n3, xh, xl):
    """(smallest λ2 over all cones as float, index of that cone)."""
    best = math.inf
    arg = -1
    for c in range(n3):
        i = 3 * c
        _, _, l2h, _ = _lams(xh[i], xl[i], xh[i + 1], xl[i + 1], xh[i + 2], xl[i + 2])
        if l2h < best:
            best = l2h
            arg = c
    for k in range(xh.size - 3 * n3):
        i = 3 * n3 + k
        if xh[i] < best:
            best = xh[i]
            arg = n3 + k
    return best, arg


@njit
def nt_scaling(n3, zh, zl, sh, sl, ph, pl, pih, pil, lh, ll, spec):
    """NT point p (Q_p z = Q_{p⁻¹} s = λ), p⁻¹ and λ for every cone, and the spectral data of
    p used by :func:`quad_spectral`: ``spec[c] = (a, a_lo, b, b_lo, d1, d1_lo, d2, d2_lo)`` with
    a = λ1(p) = q·λ1(v), b = λ2(p) = q/λ1(v) (det v = 1, so no cancellation) and
    (d1, d2) = v̄/‖v̄‖ (L1 cones: a = b = p).  Returns the index of the first cone where z or
    s is not strictly interior, or -1."""
    for c in range(n3):
        i = 3 * c
        l1z, l1zl, l2z, l2zl = _lams(zh[i], zl[i], zh[i + 1], zl[i + 1], zh[i + 2], zl[i + 2])
        l1s, l1sl, l2s, l2sl = _lams(sh[i], sl[i], sh[i + 1], sl[i + 1], sh[i + 2], sl[i + 2])
        if not (l2z > 0.0 and l2s > 0.0):
            return c
        rz, rzl = _root_det(l1z, l1zl, l2z, l2zl)
        rs, rsl = _root_det(l1s, l1sl, l2s, l2sl)
        zb0, zb0l, zb1, zb1l, zb2, zb2l = _div3(zh[i], zl[i], zh[i + 1], zl[i + 1],
                                                zh[i + 2], zl[i + 2], rz, rzl)
        sb0, sb0l, sb1, sb1l, sb2, sb2l = _div3(sh[i], sl[i], sh[i + 1], sl[i + 1],
                                                sh[i + 2], sl[i + 2], rs, rsl)
        dot, dotl = dd.mul(zb0, zb0l, sb0, sb0l)
        dot, dotl = dd.fma_acc(dot, dotl, zb1, zb1l, sb1, sb1l)
        dot, dotl = dd.fma_acc(dot, dotl, zb2, zb2l, sb2, sb2l)
        t, tl = dd.add_d(dot, dotl, 1.0)
        g, gl = dd.sqrt(t * 0.5, tl * 0.5)
        g2, g2l = g * 2.0, gl * 2.0
        # w = (s̄ + J z̄)/(2γ), then v = (w0 + 1, w̄)/√(2(w0 + 1)), whose det is 1
        t0, t0l = dd.add(sb0, sb0l, zb0, zb0l)
        t1, t1l = dd.sub(sb1, sb1l, zb1, zb1l)
        t2, t2l = dd.sub(sb2, sb2l, zb2, zb2l)
        w0, w0l, w1, w1l, w2, w2l = _div3(t0, t0l, t1, t1l, t2, t2l, g2, g2l)
        w0p, w0pl = dd.add_d(w0, w0l, 1.0)
        cc, ccl = dd.sqrt(2.0 * w0p, 2.0 * w0pl)
        v0, v0l, v1, v1l, v2, v2l = _div3(w0p, w0pl, w1, w1l, w2, w2l, cc, ccl)
        t, tl = dd.div(rs, rsl, rz, rzl)
        q, ql = dd.sqrt(t, tl)
        q, ql = dd.sqrt(q, ql)
        nv, nvl = _bar_norm(v1, v1l, v2, v2l)
        l1v, l1vl = dd.add(v0, v0l, nv, nvl)
        spec[c, 0], spec[c, 1] = dd.mul(q, ql, l1v, l1vl)
        spec[c, 2], spec[c, 3] = dd.div(q, ql, l1v, l1vl)
        if nv > 0.0:
            spec[c, 4], spec[c, 5] = dd.div(v1, v1l, nv, nvl)
            spec[c, 6], spec[c, 7] = dd.div(v2, v2l, nv, nvl)
        else:
            spec[c, 4], spec[c, 5], spec[c, 6], spec[c, 7] = 1.0, 0.0, 0.0, 0.0
        ph[i], pl[i] = dd.mul(q, ql, v0, v0l)
        ph[i + 1], pl[i + 1] = dd.mul(q, ql, v1, v1l)
        ph[i + 2], pl[i + 2] = dd.mul(q, ql, v2, v2l)
        pih[i], pil[i] = dd.div(v0, v0l, q, ql)
        t, tl = dd.div(v1, v1l, q, ql)
        pih[i + 1], pil[i + 1] = -t, -tl
        t, tl = dd.div(v2, v2l, q, ql)
        pih[i + 2], pil[i + 2] = -t, -tl
        t, tl = dd.mul(rs, rsl, rz, rzl)
        m, mlo = dd.sqrt(t, tl)
        den, denl = dd.add(g2, g2l, zb0, zb0l)
        den, denl = dd.add(den, denl, sb0, sb0l)
        t, tl = dd.add(g, gl, zb0, zb0l)
        cs, csl = dd.div(t, tl, den, denl)
        t, tl = dd.add(g, gl, sb0, sb0l)
        cz, czl = dd.div(t, tl, den, denl)
        lh[i], ll[i] = dd.mul(m, mlo, g, gl)
        t, tl = dd.mul(cs, csl, sb1, sb1l)
        t, tl = dd.fma_acc(t, tl, cz, czl, zb1, zb1l)
        lh[i + 1], ll[i + 1] = dd.mul(m, mlo, t, tl)
        t, tl = dd.mul(cs, csl, sb2, sb2l)
        t, tl = dd.fma_acc(t, tl, cz, czl, zb2, zb2l)
        lh[i + 2], ll[i + 2] = dd.mul(m, mlo, t, tl)
    for k in range(zh.size - 3 * n3):
        i = 3 * n3 + k
        if not (zh[i] > 0.0 and sh[i] > 0.0):
            return n3 + k
        t, tl = dd.div(sh[i], sl[i], zh[i], zl[i])
        q, ql = dd.sqrt(t, tl)
        q, ql = dd.sqrt(q, ql)
        ph[i], pl[i] = q, ql
        spec[n3 + k, 0], spec[n3 + k, 1] = q, ql
        spec[n3 + k, 2], spec[n3 + k, 3] = q, ql
        pih[i], pil[i] = dd.div(1.0, 0.0, q, ql)
        t, tl = dd.mul(zh[i], zl[i], sh[i], sl[i])
        lh[i], ll[i] = dd.sqrt(t, tl)
    return -1


@numba.njit(cache=True, inline="always")
def _det_and_pairing(xh, xl, yh, yl, i, sign):
    """det x = λ1λ2 of the L3 block at i, and x0y0 + sign·x̄ᵀȳ (sign ±1: xᵀy or xᵀRy)."""
    l1, l1l, l2, l2l = _lams(xh[i], xl[i], xh[i + 1], xl[i + 1], xh[i + 2], xl[i + 2])
    d, dl = dd.mul(l1, l1l, l2, l2l)
    t, tl = dd.mul(xh[i], xl[i], yh[i], yl[i])
    for j in (1, 2):
        ph, pl = dd.mul(xh[i + j], xl[i + j], yh[i + j], yl[i + j])
        t, tl = dd.add(t, tl, sign * ph, sign * pl)
    return d, dl, t, tl


@njit
def quad_apply(n3, xh, xl, yh, yl, oh, ol):
    """o = Q_x y = 2(xᵀy)x − det(x) R y, cone by cone (L1: x0² y0)."""
    for c in range(n3):
        i = 3 * c
        d, dl, s, sl_ = _det_and_pairing(xh, xl, yh, yl, i, 1.0)
        s, sl_ = 2.0 * s, 2.0 * sl_
        t, tl = dd.mul(s, sl_, xh[i], xl[i])
        oh[i], ol[i] = dd.fms_acc(t, tl, d, dl, yh[i], yl[i])
        for j in (1, 2):
            t, tl = dd.mul(s, sl_, xh[i + j], xl[i + j])
            oh[i + j], ol[i + j] = dd.fma_acc(t, tl, d, dl, yh[i + j], yl[i + j])
    for k in range(xh.size - 3 * n3):
        i = 3 * n3 + k
        t, tl = dd.mul(xh[i], xl[i], xh[i], xl[i])
        oh[i], ol[i] = dd.mul(t, tl, yh[i], yl[i])


@njit
def product(n3, xh, xl, yh, yl, oh, ol):
    """o = x ∘ y."""
    for c in range(n3):
        i = 3 * c
        t, tl = dd.mul(xh[i], xl[i], yh[i], yl[i])
        t, tl = dd.fma_acc(t, tl, xh[i + 1], xl[i + 1], yh[i + 1], yl[i + 1])
        t, tl = dd.fma_acc(t, tl, xh[i + 2], xl[i + 2], yh[i + 2], yl[i + 2])
        a1, a1l = dd.mul(xh[i], xl[i], yh[i + 1], yl[i + 1])
        a1, a1l = dd.fma_acc(a1, a1l, yh[i], yl[i], xh[i + 1], xl[i + 1])
        a2, a2l = dd.mul(xh[i], xl[i], yh[i + 2], yl[i + 2])
        a2, a2l = dd.fma_acc(a2, a2l, yh[i], yl[i], xh[i + 2], xl[i + 2])
        oh[i], ol[i] = t, tl
        oh[i + 1], ol[i + 1] = a1, a1l
        oh[i + 2], ol[i + 2] = a2, a2l
    for k in range(xh.size - 3 * n3):
        i = 3 * n3 + k
        oh[i], ol[i] = dd.mul(xh[i], xl[i], yh[i], yl[i])


@njit
def arrow_solve(n3, xh, xl, yh, yl, oh, ol):
    """o with x ∘ o = y: o0 = (x0 y0 − x̄ᵀȳ)/det x, ō = (ȳ − o0 x̄)/x0."""
    for c in range(n3):
        i = 3 * c
        d, dl, t, tl = _det_and_pairing(xh, xl, yh, yl, i, -1.0)
        o0, o0l = dd.div(t, tl, d, dl)
        oh[i], ol[i] = o0, o0l
        for j in (1, 2):
            t, tl = dd.fms_acc(yh[i + j], yl[i + j], o0, o0l, xh[i + j], xl[i + j])
            oh[i + j], ol[i + j] = dd.div(t, tl, xh[i], xl[i])
    for k in range(xh.size - 3 * n3):
        i = 3 * n3 + k
        oh[i], ol[i] = dd.div(yh[i], yl[i], xh[i], xl[i])


@njit
def max_step(n3, xh, xl, dxh, dxl):
    """Largest α with x + α dx in the product cone (x interior); inf when unbounded."""
    return max_step_at(n3, xh, xl, dxh, dxl)[0]


@njit
def max_step_at(n3, xh, xl, dxh, dxl):
    """(:func:`max_step`, the cone that sets it): cone c < n3 is the L3 cone of entries 3c … 3c+2,
    cone n3 + k the L1 cone of entry 3·n3 + k; the first such cone on ties, -1 when unbounded."""
    best = math.inf
    at = -1
    for c in range(n3):
        i = 3 * c
        l1, l1l, l2, l2l = _lams(xh[i], xl[i], xh[i + 1], xl[i + 1], xh[i + 2], xl[i + 2])
        r1, r1l = dd.sqrt(l1, l1l)
        r2, r2l = dd.sqrt(l2, l2l)
        t, tl = dd.add(r1, r1l, r2, r2l)
        rd, rdl = dd.mul(r1, r1l, r2, r2l)
        # w = x^{-1/2} = R x^{1/2} / √det x, with x^{1/2} = (t/2 ; x̄/t)
        w0, w0l = dd.div(t * 0.5, tl * 0.5, rd, rdl)
        a, al = dd.div(xh[i + 1], xl[i + 1], t, tl)
        w1, w1l = dd.div(-a, -al, rd, rdl)
        a, al = dd.div(xh[i + 2], xl[i + 2], t, tl)
        w2, w2l = dd.div(-a, -al, rd, rdl)
        # y = Q_w dx
        m1, m1l, m2, m2l = _lams(w0, w0l, w1, w1l, w2, w2l)
        d, dl = dd.mul(m1, m1l, m2, m2l)
        s, sl_ = dd.mul(w0, w0l, dxh[i], dxl[i])
        s, sl_ = dd.fma_acc(s, sl_, w1, w1l, dxh[i + 1], dxl[i + 1])
        s, sl_ = dd.fma_acc(s, sl_, w2, w2l, dxh[i + 2], dxl[i + 2])
        s, sl_ = 2.0 * s, 2.0 * sl_
        t, tl = dd.mul(s, sl_, w0, w0l)
        y0, y0l = dd.fms_acc(t, tl, d, dl, dxh[i], dxl[i])
        t, tl = dd.mul(s, sl_, w1, w1l)
        y1, y1l = dd.fma_acc(t, tl, d, dl, dxh[i + 1], dxl[i + 1])
        t, tl = dd.mul(s, sl_, w2, w2l)
        y2, y2l = dd.fma_acc(t, tl, d, dl, dxh[i + 2], dxl[i + 2])
        _, _, ly2, ly2l = _lams(y0, y0l, y1, y1l, y2, y2l)
        if ly2 < 0.0:
            a = -1.0 / ly2
            if a < best:
                best, at = a, c
    for k in range(xh.size - 3 * n3):
        i = 3 * n3 + k
        if dxh[i] < 0.0:
            a = -xh[i] / dxh[i]
            if a < best:
                best, at = a, n3 + k
    return best, at


def identity(n3, nz):
    """The identity element (1, 0, 0) per L3 cone, 1 per L1 cone (numpy: used once per run,
    not worth a compilation)."""
    eh = np.zeros(nz)
    eh[0:3 * n3:3] = 1.0
    eh[3 * n3:] = 1.0
    return eh


@dd.jit
def _pow_int(xh, xl, k):
    """x^k for k in {-4, …, 4} (double-double)."""
    rh, rl = 1.0, 0.0
    for _ in range(abs(k)):
        rh, rl = dd.mul(rh, rl, xh, xl)
    if k < 0:
        rh, rl = dd.div(1.0, 0.0, rh, rl)
    return rh, rl


@dd.jit
def _spectral_coeffs(spec, c, k):
    """Eigenvalues of Q_{p^k}: A = a^{2k} (frame (1, v̂)/√2), B = b^{2k} (frame (1, −v̂)/√2),
    Cc = (ab)^k (direction (0, ŷ), ŷ ⊥ v̂)."""
    Ah, Al = _pow_int(spec[c, 0], spec[c, 1], 2 * k)
    Bh, Bl = _pow_int(spec[c, 2], spec[c, 3], 2 * k)
    abh, abl = dd.mul(spec[c, 0], spec[c, 1], spec[c, 2], spec[c, 3])
    Ch, Cl = _pow_int(abh, abl, k)
    return Ah, Al, Bh, Bl, Ch, Cl


@njit
def spectral_table(n3, k, spec, table):
    """The eigenvalues of Q_{p^k} for every cone, for :func:`quad_spectral`: ``table[c] = (A, A_lo,
    B, B_lo, C, C_lo)`` (:func:`_spectral_coeffs`; L1 cones: A = p^{2k} only).  Computed once per
    scaling and k: for k < 0 they cost three double-double divisions per cone, more than the
    product itself."""
    for c in range(n3):
        table[c, 0], table[c, 1], table[c, 2], table[c, 3], table[c, 4], table[c, 5] = _spectral_coeffs(spec, c, k)
    for j in range(spec.shape[0] - n3):
        table[n3 + j, 0], table[n3 + j, 1] = _pow_int(spec[n3 + j, 0], spec[n3 + j, 1], 2 * k)


@njit
def quad_spectral(n3, table, spec, yh, yl, oh, ol):
    """o = Q_{p^k} y (k ∈ {-2, -1, 1, 2}, the k of ``table``) from the spectral decomposition Q_{p^k} = A·q1q1ᵀ + B·q2q2ᵀ + C·q3q3ᵀ
    (eigenvalues from :func:`spectral_table`, frame from ``spec``): a sum of positive
    semidefinite terms, so small eigenvalues keep their relative accuracy (the formula
    2(xᵀy)x − det(x)Ry loses them to cancellation once cond(Q) exceeds 1/eps)."""
    for c in range(n3):
        i = 3 * c
        Ah, Al, Bh, Bl, Ch, Cl = table[c, 0], table[c, 1], table[c, 2], table[c, 3], table[c, 4], table[c, 5]
        d1h, d1l, d2h, d2l = spec[c, 4], spec[c, 5], spec[c, 6], spec[c, 7]
        t, tl = dd.mul(d1h, d1l, yh[i + 1], yl[i + 1])
        t, tl = dd.fma_acc(t, tl, d2h, d2l, yh[i + 2], yl[i + 2])  # v̂·ȳ
        s1, s1l = dd.add(yh[i], yl[i], t, tl)
        s1, s1l = 0.5 * s1, 0.5 * s1l
        s2, s2l = dd.sub(yh[i], yl[i], t, tl)
        s2, s2l = 0.5 * s2, 0.5 * s2l
        s3, s3l = dd.mul(-d2h, -d2l, yh[i + 1], yl[i + 1])
        s3, s3l = dd.fma_acc(s3, s3l, d1h, d1l, yh[i + 2], yl[i + 2])  # ŷ·ȳ, ŷ = (−d2, d1)
        a1, a1l = dd.mul(Ah, Al, s1, s1l)
        b2, b2l = dd.mul(Bh, Bl, s2, s2l)
        c3, c3l = dd.mul(Ch, Cl, s3, s3l)
        oh[i], ol[i] = dd.add(a1, a1l, b2, b2l)
        dif, difl = dd.sub(a1, a1l, b2, b2l)
        t, tl = dd.mul(dif, difl, d1h, d1l)
        oh[i + 1], ol[i + 1] = dd.fms_acc(t, tl, c3, c3l, d2h, d2l)
        t, tl = dd.mul(dif, difl, d2h, d2l)
        oh[i + 2], ol[i + 2] = dd.fma_acc(t, tl, c3, c3l, d1h, d1l)
    for j in range(yh.size - 3 * n3):
        i = 3 * n3 + j
        oh[i], ol[i] = dd.mul(table[n3 + j, 0], table[n3 + j, 1], yh[i], yl[i])


@njit
def quad_pow_matrix(c, k, spec, Qh, Ql):
    """Q_{p^k} of L3 cone c as a 3×3 matrix (same spectral sum as :func:`quad_spectral`)."""
    Ah, Al, Bh, Bl, Ch, Cl = _spectral_coeffs(spec, c, k)
    d = ((1.0, 0.0), (spec[c, 4], spec[c, 5]), (spec[c, 6], spec[c, 7]))
    y = ((0.0, 0.0), (-spec[c, 6], -spec[c, 7]), (spec[c, 4], spec[c, 5]))
    for r in range(3):
        for t in range(3):
            # q1q1ᵀ = ½(1, v̂)(1, v̂)ᵀ, q2q2ᵀ = ½(1, −v̂)(1, −v̂)ᵀ
            uh, ul = dd.mul(d[r][0], d[r][1], d[t][0], d[t][1])
            sign = 1.0 if (r == 0) == (t == 0) else -1.0
            ah, al = dd.mul(Ah, Al, 0.5 * uh, 0.5 * ul)
            bh, bl = dd.mul(Bh, Bl, 0.5 * sign * uh, 0.5 * sign * ul)
            vh, vl = dd.add(ah, al, bh, bl)
            wh, wl = dd.mul(y[r][0], y[r][1], y[t][0], y[t][1])
            Qh[r, t], Ql[r, t] = dd.fma_acc(vh, vl, Ch, Cl, wh, wl)


# The kernels above over the threads (:mod:`.workers`): cones lo … hi as calls on array views,
# bit for bit the single call's result.  Each is split from about 1 ms of work (measured per
# cone: nt_scaling 0.7 µs, max_step 0.15 µs, quad_spectral 0.05 µs).

def _pieces(n3: int, lo: int, hi: int):
    """Cones lo … hi of n3 L3 cones followed by L1 cones, as (L3 count, cone rows, entries):
    one piece for the L3 part and one (L3 count 0) for the L1 part, where non-empty."""
    out = []
    a, b = min(lo, n3), min(hi, n3)
    if b > a:
        out.append((b - a, slice(a, b), slice(3 * a, 3 * b)))
    a, b = max(lo, n3), max(hi, n3)
    if b > a:  # L1 cone c holds entry 3·n3 + (c − n3)
        out.append((0, slice(a, b), slice(2 * n3 + a, 2 * n3 + b)))
    return out


def _n_cones(n3: int, size: int) -> int:
    return n3 + (size - 3 * n3)


def nt_scaling_threaded(n3, zh, zl, sh, sl, ph, pl, pih, pil, lh, ll, spec) -> int:
    """:func:`nt_scaling` over the threads: the first cone where z or s is not strictly
    interior, or -1."""
    def run(lo, hi):
        for k3, c, e in _pieces(n3, lo, hi):
            bad = nt_scaling(k3, zh[e], zl[e], sh[e], sl[e], ph[e], pl[e], pih[e], pil[e], lh[e], ll[e], spec[c])
            if bad >= 0:
                return c.start + bad
        return -1

    found = [b for b in split(_n_cones(n3, zh.size), run, min_items=2048) if b >= 0]
    return min(found) if found else -1


def quad_spectral_threaded(n3, table, spec, yh, yl, oh, ol) -> None:
    """:func:`quad_spectral` over the threads."""
    def run(lo, hi):
        for k3, c, e in _pieces(n3, lo, hi):
            quad_spectral(k3, table[c], spec[c], yh[e], yl[e], oh[e], ol[e])

    split(_n_cones(n3, yh.size), run, min_items=16384)


def max_step_threaded(n3, xh, xl, dxh, dxl) -> float:
    """:func:`max_step` over the threads."""
    return max_step_at_threaded(n3, xh, xl, dxh, dxl)[0]


def max_step_at_threaded(n3, xh, xl, dxh, dxl) -> tuple[float, int]:
    """:func:`max_step_at` over the threads: the same step and cone as the single call."""
    def run(lo, hi):
        best = (math.inf, -1)
        for k3, c, e in _pieces(n3, lo, hi):
            step, at = max_step_at(k3, xh[e], xl[e], dxh[e], dxl[e])
            if step < best[0]:  # a piece's cone index counts from the piece's first cone
                best = (step, c.start + at)
        return best

    return min(split(_n_cones(n3, xh.size), run, min_items=8192), key=lambda found: found[0])
