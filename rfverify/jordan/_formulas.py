"""The closed forms of the Jordan-algebra operations on 2-D arrays ``(N, k)`` whose rows need
no rescaling; they check nothing (see :mod:`rfverify.jordan`).

They are written once for every numpy precision: float64 and longdouble arrays, and object
arrays of gmpy2 ``mpfr`` numbers (the multiple-precision tail, :mod:`rfverify.extended.wide`),
for which :func:`_root` and the two-column norm take the element's own correctly rounded
operations.  The compiled kernels (:mod:`rfverify.solver.kernels` in float64,
:mod:`rfverify.extended.cones` in double-double) are transcriptions tested against them."""

from __future__ import annotations

import numpy as np

from ._checks import _shift

# --------------------------------------------------------------------------------------------
# kernels: the formulas on 2-D arrays (N, k) whose rows need no rescaling; no checks
# --------------------------------------------------------------------------------------------


def _root(x):
    """√x elementwise; on object arrays gmpy2's correctly rounded square root (numpy's object
    loop would call ``elem.sqrt()``, which mpfr lacks, and ``x ** 0.5``, the same number, costs
    several times more: 2.7 s of a 21 s tail on a 474-contact Lattice)."""
    return _object_sqrt(x) if x.dtype == object else np.sqrt(x)


def _object_sqrt(x):
    import gmpy2  # only the multiple-precision tail passes object arrays

    return np.frompyfunc(gmpy2.sqrt, 1, 1)(x)


def _bar_norm(xb):
    """‖x̄‖ per row of the bar block x̄ (N, k-1); see :func:`_norm`."""
    return _norm([xb[:, j] for j in range(xb.shape[1])], xb.shape[0], xb.dtype)


def _norm(cols, n, dtype):
    """Euclidean norm of rows given as columns, hypot-style: scaled by the largest entry so
    that neither the squares overflow (x̄ ~ 1e200) nor underflow (subnormal x̄)."""
    if not cols:
        return np.zeros(n, dtype=dtype)
    if len(cols) == 1:
        return np.abs(cols[0])
    if len(cols) == 2:
        # L3, the hot case: libm's hypot is already overflow/underflow-safe and correctly
        # rounded to within an ulp, at a fraction of the cost of the scaled sum below.
        if cols[0].dtype == object:  # mpfr: the exponent range makes hypot's scaling unnecessary
            return _root(cols[0] * cols[0] + cols[1] * cols[1])
        return np.hypot(cols[0], cols[1])
    xb = np.stack(cols, axis=1)
    m = np.max(np.abs(xb), axis=-1)
    safe = np.where(m > 0, m, 1)
    r = xb / safe[..., None]
    return m * np.sqrt(np.sum(r * r, axis=-1))


def _unit_bar(xb):
    """x̄/‖x̄‖ per row; the first unit axis where x̄ = 0 (deliberate choice of frame)."""
    if xb.shape[-1] == 0:
        return xb.copy()
    m = np.max(np.abs(xb), axis=-1)
    nz = m > 0
    safe = np.where(nz, m, 1)
    # Divide by m first: r has max|r_i| = 1, so r·r neither underflows for subnormal x̄ nor
    # overflows for huge x̄, and the normalisation keeps full relative accuracy.
    r = xb / safe[..., None]
    nr = np.sqrt(np.sum(r * r, axis=-1))
    u = r / np.where(nz, nr, 1)[..., None]
    axis0 = np.zeros_like(u)
    axis0[..., 0] = 1
    return np.where(nz[..., None], u, axis0)


def _spec(x):
    """(λ1, λ2, ‖x̄‖) per row."""
    n = _bar_norm(x[:, 1:])
    x0 = x[:, 0]
    return x0 + n, x0 - n, n


def _reflect(x):
    return _rows(x[:, 0], [-c for c in _bar(x)])


def _dot(x, y):
    """xᵀy per row.  numpy's reduction over a short last axis is slow: einsum is fastest in
    longdouble, a sum of column products in float64 (measured on L3 batches)."""
    if x.dtype == np.longdouble or y.dtype == np.longdouble or not x.shape[1]:
        return np.einsum("ij,ij->i", x, y)
    s = x[:, 0] * y[:, 0]
    for j in range(1, x.shape[1]):
        s += x[:, j] * y[:, j]
    return s


def _bar(x):
    """The bar columns x[:, 1], …, x[:, k-1] (views)."""
    return [x[:, j] for j in range(1, x.shape[1])]


def _rows(head, bars, out=None):
    """The (N, k) array with these columns (written into ``out`` if given).  Kernels work column
    by column: numpy's whole-row broadcasts and in-place updates of 2-D slices cost several
    times more for L3 batches."""
    if out is None:
        out = np.empty((head.shape[0], 1 + len(bars)), dtype=np.result_type(head, *bars))
    out[:, 0] = head
    for j, c in enumerate(bars, 1):
        out[:, j] = c
    return out


def _product(x, y):
    """x∘y = (xᵀy; x0 ȳ + y0 x̄); x² = (‖x‖²; 2 x0 x̄) is the cancellation-free square."""
    x0, y0 = x[:, 0], y[:, 0]
    return _rows(_dot(x, y), [x0 * yj + y0 * xj for xj, yj in zip(_bar(x), _bar(y))])


def _quad(x, y, det, out=None):
    """Q_x y = 2(xᵀy) x − det(x) R y, with det(x) = λ1 λ2 given (reused across many y)."""
    return _rows(*_quad_cols(x, y, det), out=out)


def _quad_cols(x, y, det):
    h = _dot(x, y)
    h *= 2
    return h * x[:, 0] - det * y[:, 0], [h * xj + det * yj for xj, yj in zip(_bar(x), _bar(y))]


def _inverse(x, l1, l2):
    # (Rx/λ1)/λ2 instead of Rx/(λ1 λ2): dividing twice avoids forming det, which may not be
    # representable although x⁻¹ is.
    return _rows((x[:, 0] / l1) / l2, [(-xj / l1) / l2 for xj in _bar(x)])


def _inverse_square(x, l1, l2):
    """x⁻² = R x²/det(x)² = (‖x‖² r²; −2 x0 r² x̄) with r = 1/det x taken as (1/λ1)/λ2.  The
    scalar factors come first, so x̄ is multiplied once and a subnormal x̄ keeps its digits
    (squaring x⁻¹ would round a subnormal x̄/det twice)."""
    r = (1 / l1) / l2
    r2 = r * r
    return _rows(_dot(x, x) * r2, _times_bar(-(2 * x[:, 0]) * r2, x))


def _arrow_solve(x, y, l1, l2):
    # d0 = (x0 y0 − x̄ᵀȳ)/det x, divided by λ1 then λ2 (det may not be representable);
    # d̄ = (ȳ − d0 x̄)/x0 from the vector part of x∘d = y.
    x0 = x[:, 0]
    d0 = ((x0 * y[:, 0] - _dot(x[:, 1:], y[:, 1:])) / l1) / l2
    return _rows(d0, [(yj - d0 * xj) / x0 for xj, yj in zip(_bar(x), _bar(y))])


def _sqrt(x, r1, r2):
    # √x = √λ1 c1 + √λ2 c2 = ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)) because (√λ1-√λ2)/2 · x̄/‖x̄‖ =
    # (λ1-λ2)/(2(√λ1+√λ2)) · x̄/‖x̄‖ and λ1-λ2 = 2‖x̄‖.  No subtraction, no division by ‖x̄‖:
    # accurate for x̄ → 0 and on the boundary (λ2 = 0) alike.  r1, r2 = √λ1, √λ2.
    t = r1 + r2
    safe = np.where(t > 0, t, 1)  # t = 0 only for x = 0, where x̄/1 = 0 is the right answer
    return _rows(t / 2, [xj / safe for xj in _bar(x)])


def _inverse_sqrt(x, l1, l2):
    """x^{-1/2} = R x^{1/2} / √det x for interior x, with x^{1/2} in the closed form above."""
    r1, r2 = _root(l1), _root(l2)
    half = _sqrt(x, r1, r2)
    rr = r1 * r2
    return _rows(half[:, 0] / rr, [-hj / rr for hj in _bar(half)])


def _times_bar(dd, xs):
    """dd·x̄ columns, with exact zeros kept where x̄_i = 0 (an overflowed dd must not make
    inf·0 = NaN)."""
    return [np.where(xj == 0, xj, dd * xj) for xj in _bar(xs)]


def _power_interior(xs, e, l1s, l2s, ns, p):
    """x^p for rows with λ2 > 0 (any real p), cancellation-free; xs = x·2^-e.

    x^p = ((a + b)/2 ; D x̄) with a = λ1^p, b = λ2^p and the divided difference
    D = (a - b)/(λ1 - λ2).  With δ = 2‖x̄‖/λ2 and t = p log1p(δ) (= log(a/b)):
      t > 1 : a and b differ by more than a factor e, D = a(1 - e^-t)/(2‖x̄‖) has no
              cancellation (and stays inf rather than inf - inf if a overflows);
      t <= 1: D = b (e^t - 1)/(λ1 - λ2) = b·p·E(t)·L(δ)/λ2 with E(t) = expm1(t)/t and
              L(δ) = log1p(δ)/δ, both → 1 as their argument → 0, so neither λ1 ≈ λ2 nor a
              subnormal x̄ loses digits and nothing divides by ‖x̄‖.
    """
    a = np.power(_shift(l1s, e), p)
    b = np.power(_shift(l2s, e), p)
    # D x̄ is evaluated as (D 2^e) x̂ with the scaled denominators ‖x̂‖, λ̂2: D alone can
    # under/overflow (e.g. x ~ 1e150, p = -1.5: D ~ 1e-376) although D x̄ is representable.
    delta = (2 * ns) / l2s  # scale-free
    lg = np.log1p(delta)
    t = p * lg
    ratio_e = np.where(t == 0, 1, np.expm1(t) / np.where(t == 0, 1, t))
    ratio_l = np.where(delta == 0, 1, lg / np.where(delta == 0, 1, delta))
    d_small = b * p * ratio_e * ratio_l / l2s
    # a - b = a(1 - e^-t): written with expm1 it stays exact in relative terms and gives
    # D = inf (not inf - inf) when λ1^p overflows.
    d_big = a * -np.expm1(-t) / np.where(ns > 0, 2 * ns, 1)
    dd = np.where(t > 1, d_big, d_small)
    dd = np.where(ns > 0, dd, 0)  # x̄ = 0: the bar part is 0 whatever D is
    return _rows((a + b) / 2, _times_bar(dd, xs))


def _power_boundary(xs, e, l1s, p):
    """x^p for rows with λ2 = 0 and p > 0 (non-integer): λ1^p c1 (λ2^p = 0)."""
    a = np.power(_shift(l1s, e), p)
    # λ1^p c1 = (a/2 ; a x̄/λ1) = (a/2 ; (a/λ̂1) x̂), scaled as in _power_interior.
    dd = np.where(l1s > 0, a / np.where(l1s > 0, l1s, 1), 0)
    return _rows(a / 2, _times_bar(dd, xs))


def _nt(zs, ss, l1z, l2z, l1s, l2s):
    """NT scaling of interior rows in the units of zs, ss: (q, p̂, p̂⁻¹, λ̂, v, cond) with
    p = p̂·2^((es-ez)/4), p⁻¹ = p̂⁻¹·2^((ez-es)/4), λ = λ̂·2^((es+ez)/2), √β = q·2^((es-ez)/4)
    (see :func:`nt_scaling`)."""
    rz = _root(l1z) * _root(l2z)  # √det ẑ, no overflow: ẑ is O(1)
    rs = _root(l1s) * _root(l2s)
    z0, s0 = zs[:, 0] / rz, ss[:, 0] / rs
    zb = [c / rz for c in _bar(zs)]
    sb = [c / rs for c in _bar(ss)]
    # z̄ᵀs̄ >= 1 for unit-det interior points, so γ >= 1 and w̄0 >= 1: no cancellation in γ,
    # in w̄0 + 1 or in the denominator d below.
    dot = z0 * s0
    for a, b in zip(zb, sb):
        dot = dot + a * b
    g = _root((1 + dot) / 2)
    g2 = 2 * g
    wb0 = (s0 + z0) / g2
    den = _root(2 * (wb0 + 1))
    v0 = (wb0 + 1) / den
    vb = [((b - a) / g2) / den for a, b in zip(zb, sb)]
    q = _root(_root(rs / rz))
    d = g2 + z0 + s0
    cz, cs = (g + z0) / d, (g + s0) / d
    root = _root(rs * rz)
    lam = _rows(g * root, [(cz * b + cs * a) * root for a, b in zip(zb, sb)])
    v = _rows(v0, vb)
    l1v = v0 + _bar_norm(v[:, 1:])
    l1v2 = l1v * l1v
    p = _rows(q * v0, [q * c for c in vb])
    p_inv = _rows(v0 / q, [-c / q for c in vb])
    return q, p, p_inv, lam, v, l1v2 * l1v2


def _quad_matrix(x, det):
    q = 2 * x[:, :, None] * x[:, None, :]
    q[:, 0, 0] -= det
    for j in range(1, x.shape[1]):
        q[:, j, j] += det
    return q


def _arrow(x):
    a = x[:, 0, None, None] * np.eye(x.shape[1], dtype=x.dtype)[None]
    a[:, 0, :] = x
    a[:, :, 0] = x
    return a
