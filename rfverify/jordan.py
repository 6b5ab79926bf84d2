r"""Jordan algebra of Lorentz (second-order) cones, vectorised over batches of cones.

The Lorentz cone of dimension ``k`` is ``L^k = {x = (x0; x̄) : x0 >= ‖x̄‖}``.  Its Jordan algebra
(DESIGN.md §3) has the product ``x∘y = (xᵀy; x0 ȳ + y0 x̄)``, identity ``e = (1; 0)``, the
reflection ``R = diag(1, -I)``, spectral values ``λ1,2 = x0 ± ‖x̄‖`` with frames
``c1,2 = ½(1; ±x̄/‖x̄‖)``, ``det x = λ1 λ2``, ``trace x = λ1 + λ2 = 2 x0``, ``x⁻¹ = R x / det x``,
``x^p = λ1^p c1 + λ2^p c2`` and the quadratic representation ``Q_x = 2xxᵀ - det(x) R``.

Conventions shared by every function
------------------------------------
Shapes
    An argument is either one cone, shape ``(k,)``, or a batch of ``N`` cones of equal dimension,
    shape ``(N, k)``; the last axis holds the cone coordinates ``(x0, x̄)``.  Results of a
    single-cone call have the single-cone shape (a vector ``(k,)`` or a numpy scalar); results of
    a batch call have a leading axis ``N``.  In binary operations a ``(k,)`` argument broadcasts
    against an ``(N, k)`` one.  ``N = 0`` is allowed.
dtype
    The working dtype is ``np.result_type(*args, np.float64)``: ``float64`` stays ``float64``,
    ``numpy.longdouble`` (80-bit extended on x86-64) stays ``longdouble``, integers and
    ``float32`` are promoted to ``float64``, and a mix of ``float64`` and ``longdouble`` is
    computed in ``longdouble``.  Every intermediate is kept in the working dtype (no
    ``np.linalg``, which has no ``longdouble`` support), so extended precision is real.
Domain errors
    Inputs containing NaN or ±Inf, and arguments outside an operation's domain (e.g. the square
    root of a point outside the cone), raise :class:`rfverify.errors.ConeDomainError` naming the
    operation, the first offending cone (``None`` for a single-cone call) and the offending
    quantity.  No function returns a NaN silently; results whose true value exceeds the range of
    the dtype overflow to ±inf (``det`` of a point of size 1e160 in float64, for instance).
Dimension ``k = 1``
    ``L^1`` is the non-negative ray (``x̄`` is empty).  The same formulas are used, which makes
    ``x`` an element with the double spectral value ``λ1 = λ2 = x0``: ``x∘y = x0 y0``,
    ``det x = x0²`` (the square of the rank-one determinant; this keeps
    ``det(Q_x y) = det(x)² det(y)`` and ``Q_x = det(x)`` consistent), ``x⁻¹ = 1/x0``,
    ``x^p = x0^p``, ``Q_x y = x0² y0`` and ``cond(Q_x) = 1``.  Both frames are ``(½,)``; the
    decomposition ``x = λ1 c1 + λ2 c2`` holds but the frame identities ``c1∘c2 = 0`` do not
    (the algebra has rank one).

Structure: one copy of every formula
------------------------------------
* *Kernels* (``_product``, ``_quad``, ``_nt`` …) evaluate the formulas on 2-D arrays whose rows
  need no rescaling; they check nothing.
* *Row operations* (``product_rows``, ``quad_rows``, ``power_rows`` …, not in ``__all__``) take
  2-D arrays ``(N, k)`` of one dtype, rescale the rows that need it by a power of two, check
  finiteness and the domain, call the kernels and refuse a NaN result.  They are the whole
  computation: the public functions below add argument parsing (shapes, dtypes, broadcasting,
  single cones), and :class:`rfverify.solver.cones.ProductCone` applies them to the two
  families of its flat L3/L1 vectors (views, no copies).  One cheap test of the whole flat
  vector (:func:`moderate`) lets ordinary data skip the per-row magnitude test and the NaN
  check (``scale=False``), so the solver's hot path is the formulas and a few passes over the
  data, with the same results bit for bit.

Numerical design
----------------
* ``‖x̄‖`` is computed as ``m·sqrt(Σ (x̄_i/m)²)`` with ``m = max|x̄_i|`` (as ``hypot`` does), so it
  neither overflows for ``x̄ ~ 1e200`` nor loses digits for subnormal ``x̄``.
* Points of extreme magnitude (outside ``2^±(maxexp/8)``, about ``1e±38`` in float64) are scaled
  by an exact power of two (a multiple of 4 in the exponent, so square and fourth roots of the
  scale are exact too) before squaring-type operations and scaled back with ``ldexp``.  Hence
  ``det``, ``Q_x y``, ``x⁻¹``, ``sqrt`` etc. overflow or underflow only when their *true* value is
  not representable.  Points of ordinary size are never rescaled, so the results there are exactly
  what the plain formulas give.
* ``det x`` is formed as ``(x0 - ‖x̄‖)(x0 + ‖x̄‖)``, never as ``x0² - ‖x̄‖²``: the squares round
  with an absolute error ``eps·x0²`` which swamps a determinant near the boundary (the difference
  can come out 0 or hugely wrong), and ``x0²`` overflows long before ``det x`` does.
* ``λ2 = x0 - ‖x̄‖`` has relative accuracy ``≈ k·eps·λ1/λ2``.  ``λ1/λ2`` is the condition number
  of ``λ2`` under componentwise relative perturbations of ``x``, so this is what a backward-stable
  evaluation delivers: the error is of the size that rounding the entries of ``x`` themselves
  causes.  (Doing better near the boundary is what the longdouble mode is for.)  Every other
  formula here is arranged so that it loses no more than the conditioning of its result implies:
  no cancellation in ``sqrt``, ``power``, ``nt_scaling``, no division by ``‖x̄‖``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .errors import ConeDomainError

__all__ = [
    "NTScaling", "arrow", "arrow_solve", "cond_quad", "det", "identity", "inverse",
    "jordan_product", "max_step", "min_lambda2", "nt_scaling", "power", "quad_apply",
    "quad_matrix", "reflect", "spectral_frames", "spectral_values", "sqrt", "step_to_boundary",
    "trace",
]


# --------------------------------------------------------------------------------------------
# argument checks and power-of-two scaling
# --------------------------------------------------------------------------------------------


def _prepare(op, names, *args):
    """Validate and convert the arguments of a public function: returns (single, [2-D arrays
    of the common dtype]).  Non-finite entries raise ConeDomainError(op) here."""
    arrs = []
    for name, a in zip(names, args):
        a = np.asarray(a)
        if a.dtype.kind not in "biuf":
            raise TypeError(
                f"{op}: argument '{name}' must be a real numeric array, got dtype {a.dtype}"
            )
        if a.ndim not in (1, 2) or a.shape[-1] < 1:
            raise ValueError(
                f"{op}: argument '{name}' must have shape (k,) or (N, k) with k >= 1, "
                f"got shape {a.shape}"
            )
        arrs.append(a)
    dtype = np.result_type(*arrs, np.float64)
    ks = {a.shape[-1] for a in arrs}
    if len(ks) > 1:
        raise ValueError(
            f"{op}: arguments have different cone dimensions "
            + ", ".join(f"{n}: k={a.shape[-1]}" for n, a in zip(names, arrs))
        )
    single = all(a.ndim == 1 for a in arrs)
    out = []
    for name, a in zip(names, arrs):
        a2 = np.asarray(a, dtype=dtype).reshape(-1, a.shape[-1])
        _require_finite(op, name, a2, a.ndim == 1)
        out.append(a2)
    if len(out) > 1:
        try:
            out = list(np.broadcast_arrays(*out))
        except ValueError:
            raise ValueError(
                f"{op}: batch sizes do not match: "
                + ", ".join(f"{n}: {np.shape(a)}" for n, a in zip(names, arrs))
            ) from None
    return single, out


def _require_finite(op, name, x, single):
    if np.isfinite(x).all():
        return
    i = int(np.argmin(np.isfinite(x).all(axis=1)))
    val = x[i][~np.isfinite(x[i])][0]
    raise ConeDomainError(
        op,
        f"argument '{name}' contains a non-finite entry ({val}); the operation is undefined — "
        "check where the NaN/Inf was produced upstream",
        cone=_cone_index(i, single),
        value=float(val),
    )


def _out(a, single):
    return a[0] if single else a


def _cone_index(i, single):
    return None if single else int(i)


def _raise_first(op, bad, single, describe):
    """ConeDomainError(op) at the first row where ``bad`` holds; ``describe(i)`` returns the
    message and the offending value for row i."""
    if bad.any():
        i = int(np.argmax(bad))
        text, value = describe(i)
        raise ConeDomainError(op, text, cone=_cone_index(i, single), value=value)


def _check_nan_free(op, out, single, scale=True):
    """out, or ConeDomainError(op) at the first row holding a NaN.  With ``scale=False`` the
    inputs were shown moderate() and passed the domain checks, so every intermediate of the
    kernels is finite and there is nothing to look for."""
    if not scale:
        return out
    bad = np.isnan(out)
    if bad.any():
        i = int(np.argmax(bad.reshape(bad.shape[0], -1).any(axis=1)))
        raise ConeDomainError(
            op,
            "the result is not representable in this dtype (intermediate overflow); "
            "rescale the data",
            cone=_cone_index(i, single),
            value=float("nan"),
        )
    return out


_BOUNDS = {}


def _bounds(dtype):
    """(T, 2^T, 2^-T) with T = maxexp/8 of the dtype; the powers as float64 numbers (inf and 0
    where float64 cannot hold them)."""
    b = _BOUNDS.get(dtype)
    if b is None:
        t = np.finfo(dtype).maxexp // 8
        b = _BOUNDS[dtype] = (t, np.ldexp(1.0, t) if t < 1024 else np.inf,
                              np.ldexp(1.0, -t) if t < 1074 else 0.0)
    return b


def moderate(*arrays) -> bool:
    """True when provably no row of the arrays needs rescaling: every nonzero |entry| lies in
    [2^-T, 2^T], hence so does every row's maximum (the criterion of :func:`_scaled`), and
    every entry is finite.  Row operations may then be called with ``scale=False``: products
    of up to four such numbers stay finite and normal, so once the domain checks pass no
    kernel can produce a NaN.

    Checked on the float64 image, which costs a fifth of longdouble arithmetic; False where
    that image cannot tell (NaN, Inf, entries beyond float64's range or flushed to 0 by the
    cast), and the row operations then look row by row.
    """
    for x in arrays:
        if x.size == 0:
            continue
        _, hi, lo = _bounds(x.dtype)
        if x.dtype == np.float64:
            mag = np.abs(x)
        else:
            with np.errstate(over="ignore"):
                mag = np.abs(x.astype(np.float64))
        top = mag.max()
        if not (top <= hi and top < np.inf):  # also catches NaN
            return False
        if lo > 0:
            small = mag < lo
            if small.any() and (small & (mag > 0)).any():
                return False
        elif mag.min() == 0 and x[mag == 0].any():
            return False  # longdouble entries below float64's range, flushed to 0 by the cast
    return True


def _scale_exponents(x):
    """Per-row exponent e (a multiple of 4) with x·2^-e of moderate size.

    Rows whose largest entry lies in [2^-T, 2^T] are left alone (e = 0): there products of up
    to four numbers of the row's magnitude (det·y, Q_x y, ...) can neither overflow nor reach
    the subnormal range, and leaving such rows untouched keeps ordinary results bit-for-bit
    equal to the textbook formulas.  Other rows are brought to max|x̂_i| in [2^-4, 1).  A
    multiple of 4 makes 2^(e/2) and 2^(e/4) exact, which sqrt and the NT scaling need.
    """
    m = np.max(np.abs(x), axis=-1)
    t = _bounds(x.dtype)[0]
    _, e = np.frexp(m)
    e = -((-e.astype(np.int64)) // 4) * 4
    extreme = (m > 0) & ((m > np.ldexp(np.ones_like(m), t)) | (m < np.ldexp(np.ones_like(m), -t)))
    return np.where(extreme, e, 0)


def _scaled(x, op, name, single, scale=True):
    """(x̂, e) with x = x̂·2^e row by row; e = 0 (a scalar) when no row needs rescaling, which
    ``scale=False`` asserts (the caller has checked :func:`moderate`).  Non-finite entries
    raise ConeDomainError(op) naming the argument."""
    if not scale or moderate(x):
        return x, 0
    _require_finite(op, name, x, single)
    e = _scale_exponents(x)
    if not e.any():
        return x, 0
    return np.ldexp(x, -e[:, None]), e


def _shift(a, e):
    """a·2^e row by row (exact barring over/underflow); e = 0 (no row rescaled) leaves a
    untouched."""
    if not isinstance(e, np.ndarray):
        return a
    return np.ldexp(a, e.reshape(e.shape + (1,) * (a.ndim - 1)))


def _take(e, rows):
    return e[rows] if isinstance(e, np.ndarray) else e


def _at(a, e, i):
    """a[i]·2^e[i] as a Python float (the unscaled value, for messages)."""
    return float(np.ldexp(a[i], _take(e, i)))


# --------------------------------------------------------------------------------------------
# kernels: the formulas on 2-D arrays (N, k) whose rows need no rescaling; no checks
# --------------------------------------------------------------------------------------------


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
    r1, r2 = np.sqrt(l1), np.sqrt(l2)
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
    rz = np.sqrt(l1z) * np.sqrt(l2z)  # √det ẑ, no overflow: ẑ is O(1)
    rs = np.sqrt(l1s) * np.sqrt(l2s)
    z0, s0 = zs[:, 0] / rz, ss[:, 0] / rs
    zb = [c / rz for c in _bar(zs)]
    sb = [c / rs for c in _bar(ss)]
    # z̄ᵀs̄ >= 1 for unit-det interior points, so γ >= 1 and w̄0 >= 1: no cancellation in γ,
    # in w̄0 + 1 or in the denominator d below.
    dot = z0 * s0
    for a, b in zip(zb, sb):
        dot = dot + a * b
    g = np.sqrt((1 + dot) / 2)
    g2 = 2 * g
    wb0 = (s0 + z0) / g2
    den = np.sqrt(2 * (wb0 + 1))
    v0 = (wb0 + 1) / den
    vb = [((b - a) / g2) / den for a, b in zip(zb, sb)]
    q = np.sqrt(np.sqrt(rs / rz))
    d = g2 + z0 + s0
    cz, cs = (g + z0) / d, (g + s0) / d
    root = np.sqrt(rs * rz)
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


# --------------------------------------------------------------------------------------------
# row operations: 2-D arrays (N, k) of one floating dtype; rescaling, domain checks, kernels.
# Errors name `op` and the row (None when `single`); scale=False skips the per-row magnitude
# test where the caller has shown moderate() of the arguments.
# --------------------------------------------------------------------------------------------


def product_rows(x, y, *, op="jordan_product", single=False, scale=True):
    """x∘y row by row (also x² for y = x)."""
    xs, ex = _scaled(x, op, "x", single, scale)
    ys, ey = _scaled(y, op, "y", single, scale)
    out = _shift(_product(xs, ys), ex + ey)
    return _check_nan_free(op, out, single, scale)


def spectral_rows(x, *, op="spectral_values", single=False, scale=True):
    """(λ1, λ2) row by row."""
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    return _shift(l1, e), _shift(l2, e)


class QuadRows(NamedTuple):
    """x prepared for repeated Q_x y: x = xs·2^e row by row, det = det(xs)."""

    xs: np.ndarray
    det: np.ndarray
    e: object


def quad_rows(x, *, op="quad_apply", single=False, scale=True) -> QuadRows:
    """Prepare Q_x (det x computed once in the cancellation-free form) for :func:`quad_apply_rows`."""
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    return QuadRows(xs, l1 * l2, e)


def quad_apply_rows(qx: QuadRows, y, *, op="quad_apply", single=False, scale=True, out=None):
    """Q_x y row by row (into ``out`` if given); y is scaled by a power of two too, so that the
    two terms stay finite and the result over/underflows only when its true value does (no
    inf − inf)."""
    ys, ey = _scaled(y, op, "y", single, scale)
    q = _quad(qx.xs, ys, qx.det, out)
    e = 2 * qx.e + ey
    if isinstance(e, np.ndarray):
        np.ldexp(q, e[:, None], out=q)
    return _check_nan_free(op, q, single, scale)


def _invertible(x, op, single, scale):
    """(x̂, e, λ1, λ2) of rows with det x != 0, else ConeDomainError at the first other row."""
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    _raise_first(op, l1 * l2 == 0, single, lambda i: (
        f"det x = 0 (λ1 = {_at(l1, e, i)}, λ2 = {_at(l2, e, i)}): x lies on the boundary of L "
        "or of -L, where x⁻¹ does not exist", 0.0))
    return xs, e, l1, l2


def inverse_rows(x, *, op="inverse", single=False, scale=True):
    xs, e, l1, l2 = _invertible(x, op, single, scale)
    return _check_nan_free(op, _shift(_inverse(xs, l1, l2), -e), single, scale)


def inverse_square_rows(x, *, op="power", single=False, scale=True):
    """x⁻² = R x²/det(x)² row by row, wherever det x != 0."""
    xs, e, l1, l2 = _invertible(x, op, single, scale)
    return _check_nan_free(op, _shift(_inverse_square(xs, l1, l2), -2 * e), single, scale)


def arrow_solve_rows(x, y, *, op="arrow_solve", single=False, scale=True):
    xs, ex = _scaled(x, op, "x", single, scale)
    ys, ey = _scaled(y, op, "y", single, scale)
    l1, l2, _ = _spec(xs)
    x0 = xs[:, 0]
    _raise_first(op, (l1 == 0) | (l2 == 0) | (x0 == 0), single, lambda i: (
        f"Arw(x) is singular (x0 = {_at(x0, ex, i)}, λ2 = {_at(l2, ex, i)}): x∘d = y has no "
        "unique solution", 0.0))
    return _check_nan_free(op, _shift(_arrow_solve(xs, ys, l1, l2), ey - ex), single, scale)


def sqrt_rows(x, *, op="sqrt", single=False, scale=True):
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    _raise_first(op, l2 < 0, single, lambda i: (
        f"x is outside the cone (λ2 = {_at(l2, e, i)} < 0); the square root exists only on L",
        _at(l2, e, i)))
    return _check_nan_free(op, _shift(_sqrt(xs, np.sqrt(l1), np.sqrt(l2)), e // 2), single, scale)


def power_rows(x, p, *, op="power", single=False, scale=True):
    """x^p row by row for a finite real p (see :func:`power` for the domain)."""
    p = x.dtype.type(p)
    if p == 0:
        out = np.zeros_like(x)
        out[:, 0] = 1
        return out
    if p == 1:
        return x.copy()
    if p == -1:
        return inverse_rows(x, op=op, single=single, scale=scale)
    if p == 0.5:
        return sqrt_rows(x, op=op, single=single, scale=scale)
    if p == 2:  # closed form (‖x‖²; 2 x0 x̄) for every x
        return product_rows(x, x, op=op, single=single, scale=scale)
    if p == -2:
        return inverse_square_rows(x, op=op, single=single, scale=scale)
    is_int = bool(p == np.floor(p))
    xs, e = _scaled(x, op, "x", single, scale)
    l1s, l2s, ns = _spec(xs)
    interior = l2s > 0
    if is_int and p < 0:
        _raise_first(op, (l1s * l2s) == 0, single, lambda i: (
            f"negative integer power p = {float(p)} needs det x != 0 (x off the boundaries of "
            f"L and -L), got λ1 = {_at(l1s, e, i)}, λ2 = {_at(l2s, e, i)}", 0.0))
    if not is_int:
        need = "λ2 >= 0 (x in L)" if p > 0 else "λ2 > 0 (x in int L)"
        _raise_first(op, (l2s < 0) if p > 0 else ~interior, single, lambda i: (
            f"non-integer power p = {float(p)} needs {need}, got λ2 = {_at(l2s, e, i)}",
            _at(l2s, e, i)))
    out = np.empty_like(x)
    if interior.any():
        m = interior
        out[m] = _power_interior(xs[m], _take(e, m), l1s[m], l2s[m], ns[m], p)
    rest = ~interior
    if rest.any():
        if is_int:
            out[rest] = _power_integer(op, x[rest], p, single)
        else:
            out[rest] = _power_boundary(xs[rest], _take(e, rest), l1s[rest], p)
    return _check_nan_free(op, out, single)


def _power_integer(op, x, p, single):
    """x^p for integer p by binary powering (power-associativity), valid for any x with
    det x != 0 when p < 0; used off the interior, where the spectral formula would need
    logarithms of non-positive numbers or would cancel (λ1 ≈ -λ2)."""
    base = inverse_rows(x, op=op, single=single) if p < 0 else x
    m = abs(int(p))
    result = np.zeros_like(x)
    result[:, 0] = 1
    while m:
        if m & 1:
            result = product_rows(result, base, op=op, single=single)
        m >>= 1
        if m:
            base = product_rows(base, base, op=op, single=single)
    return result


def quad_matrix_rows(x, *, op="quad_matrix", single=False, scale=True):
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    return _check_nan_free(op, _shift(_quad_matrix(xs, l1 * l2), 2 * e), single, scale)


def arrow_rows(x, *, op="arrow", single=False, scale=True):
    if scale:  # nothing to rescale; only the finiteness that moderate() would have shown
        _require_finite(op, "x", x, single)
    return _arrow(x)


class NTScaling(NamedTuple):
    """Nesterov–Todd scaling of an interior pair ``(z, s)``; see :func:`nt_scaling`.

    Attributes
    ----------
    p : ndarray, shape of the inputs
        NT point, ``p ∈ int L``, with ``Q_p z = Q_{p⁻¹} s``.  ``w = p²`` satisfies ``Q_w z = s``.
    p_inv : ndarray
        ``p⁻¹`` (computed from the unit-determinant direction, not by inverting ``p``).
    lam : ndarray
        Scaled point ``λ = Q_p z = Q_{p⁻¹} s`` (cancellation-free closed form).
    v : ndarray
        Unit-determinant direction (``det v = 1``), ``p = √β v``.
    beta : ndarray or scalar
        ``det p = β = (det s / det z)^{1/4}``, computed from the spectral values of ``z``, ``s``.
    cond : ndarray or scalar
        ``cond(Q_p) = λ1(v)⁴`` (``λ2(v) = 1/λ1(v)``), without the cancellation in ``λ2(p)``.
    """

    p: np.ndarray
    p_inv: np.ndarray
    lam: np.ndarray
    v: np.ndarray
    beta: np.ndarray
    cond: np.ndarray


def nt_rows(z, s, *, op="nt_scaling", single=False, scale=True) -> NTScaling:
    zs, ez = _scaled(z, op, "z", single, scale)
    ss, es = _scaled(s, op, "s", single, scale)
    l1z, l2z, _ = _spec(zs)
    l1s, l2s, _ = _spec(ss)
    for name, l2v, ev in (("z", l2z, ez), ("s", l2s, es)):
        _raise_first(op, ~(l2v > 0), single, lambda i: (
            f"argument '{name}' is not strictly inside the cone (λ2 = {_at(l2v, ev, i)} <= 0); "
            "the NT scaling needs an interior pair", _at(l2v, ev, i)))
    q, p, p_inv, lam, v, cond = _nt(zs, ss, l1z, l2z, l1s, l2s)
    sh = (es - ez) // 4  # es, ez are multiples of 4
    p, p_inv, lam = _shift(p, sh), _shift(p_inv, -sh), _shift(lam, (es + ez) // 2)
    for arr in (p, p_inv, lam):
        _check_nan_free(op, arr, single, scale)
    return NTScaling(p=p, p_inv=p_inv, lam=lam, v=v, beta=_shift(q * q, 2 * sh), cond=cond)


def step_point_rows(x, *, op="step_to_boundary", single=False, scale=True) -> QuadRows:
    """Q_{x^{-1/2}} of an interior x, prepared for the step lengths along many directions
    (the route of :func:`step_to_boundary`): x^{-1/2} = x̂^{-1/2}·2^(-e/2) for x = x̂·2^e."""
    xs, e = _scaled(x, op, "x", single, scale)
    l1, l2, _ = _spec(xs)
    _raise_first(op, ~(l2 > 0), single, lambda i: (
        f"x is not strictly inside the cone (λ2 = {_at(l2, e, i)} <= 0); the step length is "
        "measured from an interior point", _at(l2, e, i)))
    w = _inverse_sqrt(xs, l1, l2)
    lw1, lw2, _ = _spec(w)
    return QuadRows(w, lw1 * lw2, -e // 2)


def ray_lambda2_rows(point: QuadRows, dx, *, op="step_to_boundary", single=False, scale=True):
    """λ2(Q_{x^{-1/2}} dx) row by row for ``point = step_point_rows(x)``: x + α dx ∈ L iff
    1 + α·λ2 >= 0."""
    ds, ed = _scaled(dx, op, "dx", single, scale)
    head, bars = _quad_cols(point.xs, ds, point.det)
    l2 = _shift(head - _norm(bars, head.shape[0], head.dtype), 2 * point.e + ed)
    _check_nan_free(op, l2[:, None], single, scale)
    return l2


def step_from_lambda2(l2y):
    """Step to the boundary from λ2(y) of y = Q_{x^{-1/2}} dx: −1/λ2(y) if λ2(y) < 0, else inf.

    -1/λ2(y) overflows when the true step exceeds the dtype's range (e.g. a subnormal dx
    pointing out of the cone); inf would claim "never leaves the cone", which is false, so the
    largest representable step is returned instead (x + max·dx is still in L)."""
    neg = l2y < 0
    alpha = np.where(neg, -1 / np.where(neg, l2y, -1), np.inf)
    return np.where(neg & np.isinf(alpha), np.finfo(alpha.dtype).max, alpha)


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def identity(k, n=None, dtype=np.float64):
    """Identity element ``e = (1; 0)`` of the Jordan algebra of ``L^k`` (``k >= 1``), shape
    ``(k,)`` if ``n is None`` else ``(n, k)``, in the floating ``dtype`` (``np.longdouble`` for
    extended precision)."""
    k = int(k)
    if k < 1:
        raise ValueError(f"identity: cone dimension k must be >= 1, got {k}")
    dtype = np.dtype(dtype)
    if dtype.kind != "f":
        raise TypeError(f"identity: dtype must be a floating dtype, got {dtype}")
    shape = (k,) if n is None else (int(n), k)
    e = np.zeros(shape, dtype=dtype)
    e[..., 0] = 1
    return e


def _public(op, rows, names, *args, **kw):
    """A row operation behind the conventions of the module (see its docstring)."""
    single, arrs = _prepare(op, names, *args)
    with np.errstate(all="ignore"):
        out = rows(*arrs, op=op, single=single, **kw)
    return _out(out, single)


def jordan_product(x, y):
    """Jordan product ``x∘y = (xᵀy; x0 ȳ + y0 x̄)`` of any finite vectors (not restricted to the
    cone), commutative bit for bit.  Raises ConeDomainError only for non-finite input."""
    return _public("jordan_product", product_rows, ("x", "y"), x, y)


def arrow(x):
    """Arrow matrix ``Arw(x) = [[x0, x̄ᵀ], [x̄, x0 I]]``, i.e. ``Arw(x) y = x∘y``, shape ``(k, k)``
    or ``(N, k, k)``.  Diagnostics and tests only: the solver applies ``x∘·`` directly."""
    return _public("arrow", arrow_rows, ("x",), x)


def reflect(x):
    """Reflection ``R x = (x0; -x̄)`` with ``R = diag(1, -I)``."""
    single, (x,) = _prepare("reflect", ("x",), x)
    return _out(_reflect(x), single)


def spectral_values(x):
    """Spectral values ``λ1 = x0 + ‖x̄‖ >= λ2 = x0 - ‖x̄‖`` (each of shape ``(N,)``, scalars for
    one cone; ``λ1 = λ2 = x0`` for ``k = 1``).

    ``‖x̄‖`` is computed hypot-style (scaled by ``max|x̄_i|``), so it is accurate for subnormal
    ``x̄`` and does not overflow for ``|x̄| ~ 1e300``.  ``λ1`` overflows to inf only if
    ``x0 + ‖x̄‖`` exceeds the dtype's range.  ``x ∈ L`` iff ``λ2 >= 0``, ``x ∈ int L`` iff
    ``λ2 > 0``.  ``λ2`` has relative accuracy ``≈ k·eps·λ1/|λ2|`` (its condition number).
    """
    single, (x,) = _prepare("spectral_values", ("x",), x)
    with np.errstate(all="ignore"):
        l1, l2 = spectral_rows(x, single=single)
    return _out(l1, single), _out(l2, single)


def spectral_frames(x):
    """Jordan frame ``c1,2 = ½(1; ±x̄/‖x̄‖)`` of ``x``, so that ``x = λ1 c1 + λ2 c2``; each the
    shape of ``x``, with ``c1∘c2 = 0``, ``ci∘ci = ci`` and ``c1 + c2 = e`` for ``k >= 2``.

    When ``x̄ = 0`` the frame is not unique (``x`` is a multiple of ``e``); this function then
    deliberately returns the frame along the first unit axis, ``c1,2 = ½(1; ±1, 0, …, 0)``, for
    which the decomposition still holds (``λ1 = λ2 = x0``).  A subnormal ``x̄`` is normalised
    without underflow (divided by ``max|x̄_i|`` first).  For ``k = 1`` both frames are ``(½,)``:
    the decomposition ``x0 = x0·½ + x0·½`` holds, the idempotent relations do not (rank one).
    """
    single, (x,) = _prepare("spectral_frames", ("x",), x)
    u = _unit_bar(x[:, 1:])
    half = np.full((x.shape[0], 1), 0.5, dtype=x.dtype)
    c1 = np.concatenate([half, u / 2], axis=1)
    c2 = np.concatenate([half, -u / 2], axis=1)
    return _out(c1, single), _out(c2, single)


def det(x):
    """Determinant ``det x = λ1 λ2``, computed as ``(x0 - ‖x̄‖)(x0 + ‖x̄‖)``; shape ``(N,)`` (a
    scalar for one cone), ``< 0`` outside ``L ∪ -L``, ``x0²`` for ``k = 1``.

    Never as ``x0² - ‖x̄‖²``: near the boundary the two squares agree in most of their digits
    and each carries a rounding error ``≈ eps·x0²``, so their difference can be 0, of the wrong
    sign, or wrong in every digit, whereas the factored form inherits only the (unavoidable)
    error of ``λ2``.  It also avoids overflow: ``x0²`` overflows at ``x0 ~ 1.3e154`` in float64
    while ``λ1 λ2`` stays finite near the boundary.  Extreme magnitudes are handled by exact
    power-of-two scaling, so ``det`` overflows to inf (or underflows to 0) only when the true
    determinant is not representable.
    """
    single, (x,) = _prepare("det", ("x",), x)
    with np.errstate(all="ignore"):
        xs, e = _scaled(x, "det", "x", single)
        l1, l2, _ = _spec(xs)
        d = _shift(l1 * l2, 2 * e)
    return _out(d, single)


def trace(x):
    """Trace ``trace x = λ1 + λ2 = 2 x0``, shape ``(N,)`` (a scalar for one cone)."""
    single, (x,) = _prepare("trace", ("x",), x)
    with np.errstate(over="ignore"):
        return _out(2 * x[:, 0], single)


def inverse(x):
    """Jordan inverse ``x⁻¹ = R x / det x``, so that ``x∘x⁻¹ = e``.

    Defined whenever ``det x != 0``: inside ``int L`` (then ``x⁻¹ ∈ int L``), inside ``-int L``,
    and outside ``L ∪ -L`` (``det < 0``).  Computed as ``((R x)/λ1)/λ2`` on power-of-two-scaled
    data, so it does not fail when ``det x`` itself would under/overflow but ``x⁻¹`` is
    representable.  Relative accuracy ``≈ k·eps·λ1/|λ2|``, inherited from ``λ2``.
    Raises ConeDomainError (``value = 0.0``) at the first cone with computed ``det x = 0``
    (``λ2 = 0``: on the boundary of ``L``, or ``λ1 = 0``: on the boundary of ``-L``).
    """
    return _public("inverse", inverse_rows, ("x",), x)


def power(x, p):
    """Real power ``x^p = λ1^p c1 + λ2^p c2``.

    Domain (the first offending cone is reported):

    ============================  ===========================  ====================
    exponent ``p``                requirement                  ``value`` on error
    ============================  ===========================  ====================
    ``p = 0``                     none; ``x^0 = e``            —
    integer ``p > 0``             none (any finite ``x``)      —
    integer ``p < 0``             ``det x != 0`` (as inverse)  ``det x`` (= 0.0)
    non-integer ``p > 0``         ``λ2 >= 0`` (closed cone)    ``λ2``
    non-integer ``p < 0``         ``λ2 > 0`` (interior)        ``λ2``
    ============================  ===========================  ====================

    On the interior the spectral formula is evaluated without cancellation (divided difference
    ``(λ1^p - λ2^p)/(λ1 - λ2)`` via ``expm1``/``log1p``, no division by ``‖x̄‖``); relative error
    ``≈ |p|·k·eps·λ1/λ2`` in the ``c2`` component, ``≈ |p|·eps`` in the ``c1`` component.  Integer
    powers of non-interior points are computed by binary powering with Jordan products (the
    algebra is power-associative), because there ``λ2^p`` with ``λ2 <= 0`` has no logarithm and
    ``λ1^p - λ2^p`` cancels when ``λ1 ≈ -λ2``.  Closed forms, bit-identical to the functions
    named: ``p = 1`` returns a copy of ``x``, ``p = -1`` is :func:`inverse`, ``p = ½`` is
    :func:`sqrt`, ``p = 2`` is ``x∘x = (‖x‖²; 2 x0 x̄)``; ``p = -2`` is ``R x²/det(x)²`` (no
    cancellation; for every ``x`` in the domain).

    ``p`` is a real scalar, converted to the working dtype of ``x`` (pass ``np.longdouble(1)/3``
    for an extended-precision exponent).  The result overflows to inf when the true one does.
    """
    single, (x,) = _prepare("power", ("x",), x)
    pa = np.asarray(p)
    if pa.ndim != 0 or pa.dtype.kind not in "biuf":
        raise TypeError(f"power: exponent p must be a real scalar, got {p!r}")
    pp = pa.astype(x.dtype)[()]
    if not np.isfinite(pp):
        raise ConeDomainError("power", f"exponent p = {p!r} is not finite", value=float(pp))
    with np.errstate(all="ignore"):
        return _out(power_rows(x, pp, single=single), single)


def sqrt(x):
    """Jordan square root ``x^{1/2} = √λ1 c1 + √λ2 c2``, the unique ``s ∈ L`` with ``s∘s = x``.

    Defined on the closed cone (``λ2 >= 0``; on the boundary ``√λ2 = 0``); raises
    ConeDomainError (``value = λ2``) at the first cone with ``λ2 < 0``, e.g. a point that left
    the cone by rounding.  Evaluated in the cancellation-free closed form
    ``((√λ1 + √λ2)/2 ; x̄/(√λ1 + √λ2))``, which needs no frame and is valid for ``x̄ = 0`` and
    ``x = 0``.  Backward stable: ``sqrt(x)∘sqrt(x) = x`` up to ``O(k·eps·λ1)`` whatever
    ``λ2/λ1`` is.
    """
    return _public("sqrt", sqrt_rows, ("x",), x)


def arrow_solve(x, y):
    """Jordan division: the ``d`` with ``x∘d = y``, i.e. ``d = Arw(x)⁻¹ y``.

    ``d0 = (x0 y0 − x̄ᵀȳ)/det x`` and ``d̄ = (ȳ − d0 x̄)/x0``; used for the scaled
    complementarity right-hand side ``λ \\ ξ`` of the interior-point method.  Relative error
    ``≈ k·eps·λ1/λ2`` (the condition number of ``Arw(x)``).  For ``k = 1``, ``d = y/x``.
    Raises ConeDomainError at the first cone where ``Arw(x)`` is singular (``det x = 0`` or
    ``x0 = 0``).
    """
    return _public("arrow_solve", arrow_solve_rows, ("x", "y"), x, y)


def _quad_apply_rows(x, y, *, op, single):
    return quad_apply_rows(quad_rows(x, op=op, single=single), y, op=op, single=single)


def quad_apply(x, y):
    """Quadratic representation applied to a vector: ``Q_x y = 2(xᵀy) x - det(x) R y``.

    Never forms ``Q_x`` (``O(k)`` work per cone).  Equals ``(2 Arw(x)² - Arw(x²)) y``;
    ``Q_x`` is an automorphism of ``int L`` for ``x ∈ int L``.  Power-of-two scaling makes the
    result overflow only when its true value does (no ``inf - inf``).  Any finite vectors.
    """
    return _public("quad_apply", _quad_apply_rows, ("x", "y"), x, y)


def quad_matrix(x):
    """Explicit ``Q_x = 2 x xᵀ - det(x) R``, shape ``(k, k)`` or ``(N, k, k)`` (diagnostics and
    tests only; use :func:`quad_apply`).  Its eigenvalues are ``λ1²``, ``λ2²`` and ``λ1 λ2``
    (multiplicity ``k - 2``)."""
    return _public("quad_matrix", quad_matrix_rows, ("x",), x)


def cond_quad(x):
    """Spectral condition number of ``Q_x``: ``cond(Q_x) = (λ1/λ2)²`` for ``x ∈ L``.

    Shape ``(N,)`` (a scalar for one cone); ``inf`` where ``λ2 = 0`` (boundary, ``Q_x``
    singular; including ``x = 0``), ``1`` for ``k = 1``.  Raises ConeDomainError
    (``value = λ2``) at the first cone with ``λ2 < 0`` (outside ``L``, where ``λ1/λ2`` is not a
    condition number).
    """
    single, (x,) = _prepare("cond_quad", ("x",), x)
    with np.errstate(all="ignore"):
        xs, e = _scaled(x, "cond_quad", "x", single)
        l1, l2, _ = _spec(xs)
        _raise_first("cond_quad", l2 < 0, single, lambda i: (
            f"x is outside the cone (λ2 = {_at(l2, e, i)} < 0)", _at(l2, e, i)))
        ratio = np.where(l2 > 0, l1 / np.where(l2 > 0, l2, 1), np.inf)
        c = ratio * ratio
    return _out(c.astype(x.dtype, copy=False), single)


def nt_scaling(z, s):
    """Nesterov–Todd scaling point ``p`` of an interior pair: ``Q_p z = Q_{p⁻¹} s = λ``.

    Cancellation-free construction (CVXOPT's):
    ``z̄ = z/√det z``, ``s̄ = s/√det s`` (unit determinant),
    ``γ = √((1 + z̄ᵀs̄)/2)`` (``>= 1``), ``w̄ = (s̄ + R z̄)/(2γ)`` (unit det, ``w̄0 >= 1``),
    ``v = (w̄ + e)/√(2(w̄0 + 1)) = w̄^{1/2}`` (unit det), ``β = (det s/det z)^{1/4}``,
    ``p = √β v``, ``p⁻¹ = R v/√β``.  Then ``Q_p = β Q_v`` is CVXOPT's ``W = β(2vvᵀ - R)`` and
    ``W z = W⁻¹ s``.  The scaled point is
    ``λ = (det z det s)^{1/4} (γ ; ((γ + z̄0) s̄₁ + (γ + s̄0) z̄₁)/(2γ + z̄0 + s̄0))``.
    All determinant-related quantities come from the spectral values of ``z`` and ``s`` (never
    from ``p``), and ``√det`` is taken as ``√λ1·√λ2`` on power-of-two-scaled data, so nothing
    under/overflows unless ``p`` or ``λ`` does.

    ``z, s`` must be strictly interior (``λ2 > 0``); ConeDomainError names the first cone where
    ``z`` (checked first) or ``s`` is not, and the argument, with ``value = λ2``.  Returns an
    :class:`NTScaling` whose ``p, p_inv, lam, v`` have the broadcast shape of the inputs and
    ``beta, cond`` shape ``(N,)`` (scalars for one cone).
    """
    single, (z, s) = _prepare("nt_scaling", ("z", "s"), z, s)
    with np.errstate(all="ignore"):
        r = nt_rows(z, s, single=single)
    return NTScaling(*(_out(a, single) for a in r))


def step_to_boundary(x, dx):
    """Largest ``α >= 0`` with ``x + α dx ∈ L``, per cone (``inf`` if the ray never leaves ``L``).

    Route: with ``y = Q_{x^{-1/2}} dx`` we have ``x + α dx = Q_{x^{1/2}}(e + α y)`` because
    ``Q_{x^{1/2}} e = x`` and ``Q_{x^{1/2}} Q_{x^{-1/2}} = I``.  ``Q_{x^{1/2}}`` maps ``L`` onto
    ``L`` for interior ``x``, so ``x + α dx ∈ L`` iff ``e + α y ∈ L`` iff
    ``λ2(e + α y) = 1 + α λ2(y) >= 0`` (``e + αy`` has the frame of ``y``).  Hence
    ``α = -1/λ2(y)`` if ``λ2(y) < 0`` and ``α = inf`` otherwise (then ``dx ∈ L``).  This needs no
    quadratic-equation root (whose textbook form cancels), and the work is scale-free:
    ``α(x, dx) = α(c x, c dx)``.

    ``x`` must be strictly interior (ConeDomainError with ``value = λ2`` at the first cone that
    is not); ``dx`` is any finite direction.  Returns ``α`` of shape ``(N,)`` (a scalar for one
    cone), ``> 0``; ``inf`` exactly when ``dx ∈ L`` (as computed: ``λ2(y) >= 0``); the dtype's
    largest finite number when the ray leaves the cone only beyond that (tiny ``dx``).
    """
    single, (x, dx) = _prepare("step_to_boundary", ("x", "dx"), x, dx)
    with np.errstate(all="ignore"):
        alpha = _step("step_to_boundary", x, dx, single)
    return _out(alpha, single)


def _step(op, x, dx, single):
    point = step_point_rows(x, op=op, single=single)
    return step_from_lambda2(ray_lambda2_rows(point, dx, op=op, single=single))


def max_step(x, dx, alpha_max=1.0):
    """Common step length ``min(alpha_max, min_i step_to_boundary(x_i, dx_i))``, a scalar in the
    working dtype; ``alpha_max`` (``>= 0``, may be ``inf``) for an empty batch.  Errors as
    :func:`step_to_boundary`, with ``operation="max_step"``."""
    single, (x, dx) = _prepare("max_step", ("x", "dx"), x, dx)
    am = np.asarray(alpha_max, dtype=x.dtype)[()]
    if np.isnan(am) or am < 0:
        raise ValueError(f"max_step: alpha_max must be >= 0, got {alpha_max!r}")
    with np.errstate(all="ignore"):
        alpha = _step("max_step", x, dx, single)
    if alpha.size == 0:
        return am
    return np.minimum(am, np.min(alpha))


def min_lambda2(x):
    """Smallest ``λ2`` over a batch of cones and where it occurs (diagnostics): ``(value,
    index)`` with the value in the dtype of ``x`` (``+inf`` for an empty batch) and the index of
    the first cone attaining it (``None`` for a single cone or an empty batch)."""
    single, (x,) = _prepare("min_lambda2", ("x",), x)
    if x.shape[0] == 0:
        return x.dtype.type(np.inf), None
    with np.errstate(all="ignore"):
        _, l2 = spectral_rows(x, op="min_lambda2", single=single)
    i = int(np.argmin(l2))
    return l2[i], (None if single else i)
