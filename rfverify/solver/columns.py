"""Column-wise Jordan kernels for the solver's hot path on L3^{n3} × L1^{n1}.

:mod:`rfverify.jordan` is the general, validated implementation: every call checks its
arguments for NaN/Inf, rescales rows of extreme magnitude by powers of two and works on
(N, k) arrays.  For the cones of the lifted problem (k = 3 and k = 1) and for data of
moderate magnitude, the same formulas can be evaluated on the three columns of the flat
L3 vector and on the L1 tail directly, which removes most of the per-call overhead: on a
1380-contact problem in longdouble the step length fell from 5.6 ms to about 1 ms.

Contract: each kernel returns ``None`` when it cannot vouch for its answer — some entry is
outside [2^-T, 2^T] (T = maxexp/8 of the dtype, the bound under which :mod:`rfverify.jordan`
itself skips rescaling), a point is not interior, or the result is not finite.  The caller
then repeats the operation with :mod:`rfverify.jordan`, which either succeeds with rescaling
or raises its precise :class:`~rfverify.errors.ConeDomainError`.  So the fast path never
changes what is reported, only how fast the common case is; for moderate data the two agree
to rounding (the same formulas, summed in the same order up to einsum's internal order).
"""

from __future__ import annotations

import numpy as np

_BOUNDS = {}


def _bounds(dtype):
    """[2^-T, 2^T] for the dtype, as float64 numbers (0 and inf where float64 cannot
    represent a bound: every nonzero finite float64 then satisfies it)."""
    b = _BOUNDS.get(dtype)
    if b is None:
        t = np.finfo(dtype).maxexp // 8
        hi = np.ldexp(1.0, t) if t < 1024 else np.inf
        lo = np.ldexp(1.0, -t) if t < 1074 else 0.0
        b = _BOUNDS[dtype] = (hi, lo)
    return b


def moderate(*arrays) -> bool:
    """Every nonzero entry lies in [2^-T, 2^T]: squares and fourth powers stay normal and
    finite, so the unscaled formulas of :mod:`rfverify.jordan` apply as they stand.

    Checked on the float64 image of the data, which costs a fifth of longdouble arithmetic.
    For longdouble (T = 2048) that is conservative above (values beyond float64's range are
    declined) and, below, lets through only nonzero entries under 5e-324 (flushed to 0 by the
    cast); their fourth powers are still normal longdouble numbers down to about 1e-1233.
    """
    for a in arrays:
        if a.size == 0:
            continue
        hi, lo = _bounds(a.dtype)
        with np.errstate(over="ignore"):
            mag = np.abs(a.astype(np.float64, copy=False))
        top = mag.max()
        if not (top <= hi and top < np.inf):  # also catches NaN
            return False
        if lo > 0 and np.min(mag, initial=np.inf, where=mag > 0) < lo:
            return False
    return True


def cols(x, n3):
    """(x0, x1, x2) strided views of the L3 part and the L1 tail of a flat cone vector."""
    return x[0:3 * n3:3], x[1:3 * n3:3], x[2:3 * n3:3], x[3 * n3:]


def _interleave(c0, c1, c2, tail, dtype):
    n3 = c0.shape[0]
    out = np.empty(3 * n3 + tail.shape[0], dtype=dtype)
    out[0:3 * n3:3] = c0
    out[1:3 * n3:3] = c1
    out[2:3 * n3:3] = c2
    out[3 * n3:] = tail
    return out


def _spectral(x0, x1, x2):
    """(λ1, λ2) = x0 ± ‖x̄‖ per L3 cone, ‖x̄‖ by hypot as in :mod:`rfverify.jordan`."""
    nb = np.hypot(x1, x2)
    return x0 + nb, x0 - nb


def _finite(*arrays) -> bool:
    return all(bool(np.isfinite(a).all()) for a in arrays)


def product(x, y, n3):
    """x∘y cone by cone, or None (see the module contract)."""
    if not moderate(x, y):
        return None
    x0, x1, x2, xt = cols(x, n3)
    y0, y1, y2, yt = cols(y, n3)
    dtype = np.result_type(x, y)
    out = _interleave(x0 * y0 + x1 * y1 + x2 * y2, x0 * y1 + y0 * x1, x0 * y2 + y0 * x2, xt * yt, dtype)
    return out if _finite(out) else None


def arrow_solve(x, y, n3):
    """d with x∘d = y, or None.  Same route as :func:`rfverify.jordan.arrow_solve`:
    d0 = (x0 y0 − x̄ᵀȳ)/λ1/λ2 (det never formed), d̄ = (ȳ − d0 x̄)/x0."""
    if not moderate(x, y):
        return None
    x0, x1, x2, xt = cols(x, n3)
    y0, y1, y2, yt = cols(y, n3)
    with np.errstate(all="ignore"):
        l1, l2 = _spectral(x0, x1, x2)
        if not (np.all(l1 != 0) and np.all(l2 != 0) and np.all(x0 != 0) and np.all(xt != 0)):
            return None
        d0 = ((x0 * y0 - (x1 * y1 + x2 * y2)) / l1) / l2
        out = _interleave(d0, (y1 - d0 * x1) / x0, (y2 - d0 * x2) / x0, yt / xt, np.result_type(x, y))
    return out if _finite(out) else None


def lambda2(x, n3):
    """λ2 = x0 − ‖x̄‖ per cone (L1: x itself), in the order of the cones, or None."""
    if not moderate(x):
        return None
    x0, x1, x2, xt = cols(x, n3)
    out = np.concatenate((x0 - np.hypot(x1, x2), xt))
    return out if _finite(out) else None


class StepPoint:
    """Step lengths from one interior point x to the cone boundary along several directions.

    The route of :func:`rfverify.jordan.step_to_boundary`: x + α dx ∈ L iff e + α y ∈ L with
    y = Q_{x^{-1/2}} dx, so the largest step is α = −1/λ2(y) when λ2(y) < 0 (L1: α = −x/dx
    when dx < 0).  x^{-1/2} depends on x only, and the predictor and the corrector both
    measure their steps from the same iterate, so it is computed once here.
    Build with :func:`step_point`, which returns None where the kernels decline.
    """

    def __init__(self, x, n3, w, det_w, xt):
        self.x, self.n3 = x, n3
        self._w, self._det_w, self._xt = w, det_w, xt

    def min_step(self, dx):
        """min over cones of the largest α with x + α dx in the cone (∞ if none), or None."""
        if not moderate(dx):
            return None
        w0, w1, w2 = self._w
        det_w = self._det_w
        d0, d1, d2, dt = cols(dx, self.n3)
        with np.errstate(all="ignore"):
            wd2 = 2 * (w0 * d0 + w1 * d1 + w2 * d2)
            y0 = wd2 * w0 - det_w * d0
            y1 = wd2 * w1 + det_w * d1
            y2 = wd2 * w2 + det_w * d2
            # α = −1/λ2(y) is decreasing in −λ2(y): the smallest step belongs to the most
            # negative λ2, so one reduction replaces a division per cone.
            lo = min(np.min(y0 - np.hypot(y1, y2), initial=np.inf), np.min(dt / self._xt, initial=np.inf))
            if not np.isfinite(lo) and not lo == np.inf:
                return None  # NaN or −inf: let the careful route name it
            if lo >= 0:
                return np.inf
            alpha = -1 / lo
        # An overflowing step (subnormal λ2): the careful route clips it to the largest float.
        return float(alpha) if np.isfinite(alpha) else None


def step_point(x, n3):
    """A :class:`StepPoint` for the interior point x, or None (see the module contract)."""
    if not moderate(x):
        return None
    x0, x1, x2, xt = cols(x, n3)
    with np.errstate(all="ignore"):
        l1, l2 = _spectral(x0, x1, x2)
        if not (np.all(l2 > 0) and np.all(xt > 0)):
            return None
        r1, r2 = np.sqrt(l1), np.sqrt(l2)
        t = r1 + r2
        rr = r1 * r2
        # w = x^{-1/2} = R x^{1/2} / √det x, x^{1/2} = ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)).
        w0 = (t / 2) / rr
        w1 = -(x1 / t) / rr
        w2 = -(x2 / t) / rr
        det_w = np.multiply(*_spectral(w0, w1, w2))
    if not _finite(w0, w1, w2, det_w):
        return None
    return StepPoint(x, n3, (w0, w1, w2), det_w, xt)


def det3(p, n3):
    """det p = (p0 + ‖p̄‖)(p0 − ‖p̄‖) per L3 cone (the factored form of
    :func:`rfverify.jordan.det`), for p already vetted by :func:`moderate`."""
    return np.multiply(*_spectral(*cols(p, n3)[:3]))


def quad_blocks(p, n3):
    """Entries of the block-diagonal Q_p = 2ppᵀ − det(p) R, cone by cone, row-major, or None."""
    if not moderate(p):
        return None
    p3 = p[:3 * n3].reshape(n3, 3)
    pt = p[3 * n3:]
    with np.errstate(all="ignore"):
        det = det3(p, n3)
        q = 2 * p3[:, :, None] * p3[:, None, :]
        q[:, 0, 0] -= det
        q[:, 1, 1] += det
        q[:, 2, 2] += det
        out = np.concatenate((q.ravel(), pt * pt)).astype(np.float64, copy=False)
    return out if _finite(out) else None


class NT:
    """Nesterov–Todd scaling of an interior pair (z, s), flat: fields p, p_inv, lam, cond."""

    __slots__ = ("p", "p_inv", "lam", "cond")


def nt_scaling(z, s, n3):
    """The cancellation-free construction of :func:`rfverify.jordan.nt_scaling`, or None."""
    if not moderate(z, s):
        return None
    z0, z1, z2, zt = cols(z, n3)
    s0, s1, s2, st = cols(s, n3)
    dtype = np.result_type(z, s)
    with np.errstate(all="ignore"):
        l1z, l2z = _spectral(z0, z1, z2)
        l1s, l2s = _spectral(s0, s1, s2)
        if not (np.all(l2z > 0) and np.all(l2s > 0) and np.all(zt > 0) and np.all(st > 0)):
            return None
        rz = np.sqrt(l1z) * np.sqrt(l2z)
        rs = np.sqrt(l1s) * np.sqrt(l2s)
        zb0, zb1, zb2 = z0 / rz, z1 / rz, z2 / rz
        sb0, sb1, sb2 = s0 / rs, s1 / rs, s2 / rs
        g = np.sqrt((1 + (zb0 * sb0 + zb1 * sb1 + zb2 * sb2)) / 2)
        g2 = 2 * g
        wb0 = (sb0 + zb0) / g2
        den = np.sqrt(2 * (wb0 + 1))
        v0 = (wb0 + 1) / den
        v1 = ((sb1 - zb1) / g2) / den
        v2 = ((sb2 - zb2) / g2) / den
        q = np.sqrt(np.sqrt(rs / rz))
        d = g2 + zb0 + sb0
        cz, cs = (g + zb0) / d, (g + sb0) / d
        root = np.sqrt(rs * rz)
        # L1: p = (s/z)^{1/4}... the k = 1 case of the same construction, where z̄ = s̄ = v = 1.
        qt = np.sqrt(np.sqrt(st / zt))
        out = NT()
        out.p = _interleave(q * v0, q * v1, q * v2, qt, dtype)
        out.p_inv = _interleave(v0 / q, -v1 / q, -v2 / q, 1 / qt, dtype)
        out.lam = _interleave(g * root, (cz * sb1 + cs * zb1) * root, (cz * sb2 + cs * zb2) * root,
                              np.sqrt(st * zt), dtype)
        l1v = v0 + np.hypot(v1, v2)
        l1v2 = l1v * l1v
        out.cond = np.concatenate((l1v2 * l1v2, np.ones(zt.shape[0], dtype=dtype))).astype(np.float64)
    if not _finite(out.p, out.p_inv, out.lam):
        return None
    return out


def quad_apply(p, det_p, sq_tail, y, n3):
    """Q_p y = 2(pᵀy)p − det(p) R y given det(p) per L3 cone and p² per L1 cone, unchecked:
    the caller (:class:`rfverify.solver.cones.QuadOperator`) has vetted p and det_p."""
    p0, p1, p2, _ = cols(p, n3)
    y0, y1, y2, yt = cols(y, n3)
    out = np.empty(y.shape[0], dtype=np.result_type(p, y))
    h = 2 * (p0 * y0 + p1 * y1 + p2 * y2)
    out[0:3 * n3:3] = h * p0 - det_p * y0
    out[1:3 * n3:3] = h * p1 + det_p * y1
    out[2:3 * n3:3] = h * p2 + det_p * y2
    out[3 * n3:] = sq_tail * yt
    return out
