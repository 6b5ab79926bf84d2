"""Compiled float64 kernels of the product cone's hot operations (numba).

The interior-point iteration spends most of its time outside the factorisation in a dozen
cone operations on flat vectors of a few thousand cones.  Written with numpy, each is twenty
to forty array passes of a few microseconds each; compiled, each is one pass.  These kernels
are the formulas of :mod:`rfverify.jordan` transcribed operation by operation, in the same
order, so for the inputs they accept their results are bit for bit the numpy row
operations' (numba does not fuse a multiply and an add, and both call the C library's
hypot); ``tests/test_kernels.py`` holds them to that.

Layout: a flat vector of length 3·n3 + n1 holds the L3 cones (x0, x1, x2) first, then the
L1 cones.  The kernels trust their inputs to be float64 and moderate
(:func:`rfverify.jordan.moderate`: no row needs rescaling, every entry finite) —
:class:`~rfverify.solver.cones.ProductCone` checks that before calling one and otherwise
takes the numpy route, which rescales extreme rows.  Kernels with a domain (a strictly
interior point, an invertible arrow matrix) return the index of the first cone outside it,
or -1; the caller then repeats the operation in numpy, which raises the precise
:class:`~rfverify.errors.ConeDomainError`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

njit = numba.njit(cache=True, nogil=True)


@numba.njit(cache=True, inline="always")
def _lam(x0, x1, x2):
    """(λ1, λ2) of an L3 cone: x0 ± hypot(x1, x2)."""
    n = math.hypot(x1, x2)
    return x0 + n, x0 - n


@numba.njit(cache=True, inline="always")
def _quad3(x0, x1, x2, y0, y1, y2, d):
    """Q_x y of one L3 cone with det x = d given: 2(xᵀy)x − d R y."""
    h = x0 * y0
    h += x1 * y1
    h += x2 * y2
    h *= 2
    return h * x0 - d * y0, h * x1 + d * y1, h * x2 + d * y2


@njit
def quad_det(n3, x, det):
    """det x per cone (λ1·λ2; x0·x0 for L1 cones) into ``det`` (n_cones,)."""
    for c in range(n3):
        i = 3 * c
        l1, l2 = _lam(x[i], x[i + 1], x[i + 2])
        det[c] = l1 * l2
    for k in range(x.size - 3 * n3):
        i = 3 * n3 + k
        det[n3 + k] = x[i] * x[i]


@njit
def quad_apply(n3, x, det, y, out):
    """Q_x y = 2(xᵀy)x − det(x) R y cone by cone into ``out`` (det from :func:`quad_det`)."""
    for c in range(n3):
        i = 3 * c
        out[i], out[i + 1], out[i + 2] = _quad3(x[i], x[i + 1], x[i + 2], y[i], y[i + 1], y[i + 2], det[c])
    for k in range(x.size - 3 * n3):
        i = 3 * n3 + k
        h = x[i] * y[i]
        h *= 2
        out[i] = h * x[i] - det[n3 + k] * y[i]


@njit
def quad_blocks(n3, x, out):
    """Q_x = 2xxᵀ − det(x) R as 3×3 blocks, row-major, then one value per L1 cone (the order
    of ProductCone.bd_rows, bd_cols)."""
    for c in range(n3):
        i = 3 * c
        l1, l2 = _lam(x[i], x[i + 1], x[i + 2])
        d = l1 * l2
        o = 9 * c
        for a in range(3):
            ta = 2 * x[i + a]
            for b in range(3):
                out[o + 3 * a + b] = ta * x[i + b]
        out[o] -= d
        out[o + 4] += d
        out[o + 8] += d
    for k in range(x.size - 3 * n3):
        i = 3 * n3 + k
        out[9 * n3 + k] = 2 * x[i] * x[i] - x[i] * x[i]


@njit
def nt_scaling(n3, z, s, p, p_inv, lam, cond):
    """NT scaling of an interior pair, cone by cone, into p, p⁻¹, λ (flat) and cond(Q_p)
    (n_cones,): the closed forms of :func:`rfverify.jordan._formulas._nt`.  Returns the first cone
    where z or s is not strictly interior, or -1."""
    for c in range(n3 + z.size - 3 * n3):
        if c < n3:
            i = 3 * c
            k = 3
            l1z, l2z = _lam(z[i], z[i + 1], z[i + 2])
            l1s, l2s = _lam(s[i], s[i + 1], s[i + 2])
        else:
            i = 3 * n3 + (c - n3)
            k = 1
            l1z = l2z = z[i]
            l1s = l2s = s[i]
        if not (l2z > 0 and l2s > 0):
            return c
        rz = math.sqrt(l1z) * math.sqrt(l2z)
        rs = math.sqrt(l1s) * math.sqrt(l2s)
        z0, s0 = z[i] / rz, s[i] / rs
        dot = z0 * s0
        if k == 3:
            zb1, zb2 = z[i + 1] / rz, z[i + 2] / rz
            sb1, sb2 = s[i + 1] / rs, s[i + 2] / rs
            dot = dot + zb1 * sb1
            dot = dot + zb2 * sb2
        g = math.sqrt((1 + dot) / 2)
        g2 = 2 * g
        wb0 = (s0 + z0) / g2
        den = math.sqrt(2 * (wb0 + 1))
        v0 = (wb0 + 1) / den
        q = math.sqrt(math.sqrt(rs / rz))
        d = g2 + z0 + s0
        cz, cs = (g + z0) / d, (g + s0) / d
        root = math.sqrt(rs * rz)
        lam[i] = g * root
        p[i] = q * v0
        p_inv[i] = v0 / q
        l1v = v0
        if k == 3:
            vb1 = ((sb1 - zb1) / g2) / den
            vb2 = ((sb2 - zb2) / g2) / den
            lam[i + 1] = (cz * sb1 + cs * zb1) * root
            lam[i + 2] = (cz * sb2 + cs * zb2) * root
            p[i + 1], p[i + 2] = q * vb1, q * vb2
            p_inv[i + 1], p_inv[i + 2] = -vb1 / q, -vb2 / q
            l1v = v0 + math.hypot(vb1, vb2)
        l1v2 = l1v * l1v
        cond[c] = l1v2 * l1v2
    return -1


@njit
def step_point(n3, x, w, det):
    """x^{-1/2} per cone into ``w`` and its det into ``det``: the point of the step-length
    test (:func:`rfverify.jordan.step_point_rows`).  Returns the first cone where x is not
    strictly interior, or -1."""
    for c in range(n3 + x.size - 3 * n3):
        if c < n3:
            i = 3 * c
            l1, l2 = _lam(x[i], x[i + 1], x[i + 2])
        else:
            i = 3 * n3 + (c - n3)
            l1 = l2 = x[i]
        if not l2 > 0:
            return c
        r1, r2 = math.sqrt(l1), math.sqrt(l2)
        t = r1 + r2
        safe = t if t > 0 else 1.0
        rr = r1 * r2
        w0 = (t / 2) / rr
        w[i] = w0
        if c < n3:
            w1 = -(x[i + 1] / safe) / rr
            w2 = -(x[i + 2] / safe) / rr
            w[i + 1], w[i + 2] = w1, w2
            lw1, lw2 = _lam(w0, w1, w2)
            det[c] = lw1 * lw2
        else:
            det[c] = w0 * w0
    return -1


@njit
def min_ray_lambda2_at(n3, w, det, d):
    """(min over cones of λ2(Q_w d), the first cone that has it) for a step point (w, det) of
    :func:`step_point` ((+inf, -1) for no cones): x + α d stays in the cone iff 1 + α·λ2 ≥ 0,
    so that cone is the one whose boundary sets the step."""
    lo = math.inf
    at = -1
    for c in range(n3):
        i = 3 * c
        head, b1, b2 = _quad3(w[i], w[i + 1], w[i + 2], d[i], d[i + 1], d[i + 2], det[c])
        l2 = head - math.hypot(b1, b2)
        if l2 < lo:
            lo, at = l2, c
    for k in range(w.size - 3 * n3):
        i = 3 * n3 + k
        h = w[i] * d[i]
        h *= 2
        l2 = h * w[i] - det[n3 + k] * d[i]
        if l2 < lo:
            lo, at = l2, n3 + k
    return lo, at


@njit
def lambda2(n3, x, out):
    """λ2 per cone into ``out`` (n_cones,)."""
    for c in range(n3):
        i = 3 * c
        out[c] = x[i] - math.hypot(x[i + 1], x[i + 2])
    for k in range(x.size - 3 * n3):
        out[n3 + k] = x[3 * n3 + k]


@njit
def product(n3, x, y, out):
    """x∘y = (xᵀy; x0 ȳ + y0 x̄) cone by cone into ``out``."""
    for c in range(n3):
        i = 3 * c
        h = x[i] * y[i]
        h += x[i + 1] * y[i + 1]
        h += x[i + 2] * y[i + 2]
        out[i] = h
        out[i + 1] = x[i] * y[i + 1] + y[i] * x[i + 1]
        out[i + 2] = x[i] * y[i + 2] + y[i] * x[i + 2]
    for k in range(x.size - 3 * n3):
        i = 3 * n3 + k
        out[i] = x[i] * y[i]


@njit
def arrow_solve(n3, x, y, out):
    """d with x∘d = y cone by cone into ``out``.  Returns the first cone where Arw(x) is
    singular (λ1, λ2 or x0 zero), or -1."""
    for c in range(n3):
        i = 3 * c
        l1, l2 = _lam(x[i], x[i + 1], x[i + 2])
        x0 = x[i]
        if l1 == 0 or l2 == 0 or x0 == 0:
            return c
        bar = x[i + 1] * y[i + 1]
        bar += x[i + 2] * y[i + 2]
        d0 = ((x0 * y[i] - bar) / l1) / l2
        out[i] = d0
        out[i + 1] = (y[i + 1] - d0 * x[i + 1]) / x0
        out[i + 2] = (y[i + 2] - d0 * x[i + 2]) / x0
    for k in range(x.size - 3 * n3):
        i = 3 * n3 + k
        x0 = x[i]
        if x0 == 0:
            return n3 + k
        out[i] = ((x0 * y[i] - 0.0) / x0) / x0
    return -1


def warm_up():
    """Compile (or load from numba's cache) every kernel on a tiny problem, so that the first
    solve of a process does not pay for it inside its timings."""
    x = np.array([2.0, 0.5, -0.25, 1.5])
    det, w, out = np.empty(2), np.empty(4), np.empty(4)
    quad_det(1, x, det)
    quad_apply(1, x, det, x, out)
    quad_blocks(1, x, np.empty(10))
    nt_scaling(1, x, x, np.empty(4), np.empty(4), np.empty(4), np.empty(2))
    step_point(1, x, w, det)
    min_ray_lambda2_at(1, w, det, x)
    lambda2(1, x, np.empty(2))
    product(1, x, x, out)
    arrow_solve(1, x, x, out)
