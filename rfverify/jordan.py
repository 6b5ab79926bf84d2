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
    "NTScaling",
    "arrow",
    "arrow_solve",
    "cond_quad",
    "det",
    "identity",
    "inverse",
    "jordan_product",
    "max_step",
    "min_lambda2",
    "nt_scaling",
    "power",
    "quad_apply",
    "quad_matrix",
    "reflect",
    "spectral_frames",
    "spectral_values",
    "sqrt",
    "step_to_boundary",
    "trace",
]


# --------------------------------------------------------------------------------------------
# internal helpers (all work on 2-D arrays (N, k) of one floating dtype)
# --------------------------------------------------------------------------------------------


def _prepare(op, names, *args):
    """Validate and convert arguments: returns (single, [2-D arrays of the common dtype]).

    Non-finite entries raise ConeDomainError(op) here, once, so no later step can manufacture
    a NaN from them.
    """
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
        fin = np.isfinite(a2).all(axis=1)
        if not fin.all():
            i = int(np.argmin(fin))
            row = a2[i]
            val = row[~np.isfinite(row)][0]
            raise ConeDomainError(
                op,
                f"argument '{name}' contains a non-finite entry ({val}); the operation is "
                "undefined — check where the NaN/Inf was produced upstream",
                cone=None if a.ndim == 1 else i,
                value=float(val),
            )
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


def _out(a, single):
    return a[0] if single else a


def _cone_index(i, single):
    return None if single else int(i)


def _bar_norm(xb):
    """‖x̄‖ per row, hypot-style: scaled by max|x̄_i| so that neither the squares overflow
    (x̄ ~ 1e200) nor underflow (subnormal x̄)."""
    n_bar = xb.shape[-1]
    if n_bar == 0:
        return np.zeros(xb.shape[:-1], dtype=xb.dtype)
    if n_bar == 1:
        return np.abs(xb[..., 0])
    if n_bar == 2:
        # L3, the hot case: libm's hypot is already overflow/underflow-safe and correctly
        # rounded to within an ulp, at a fraction of the cost of the scaled sum below.
        return np.hypot(xb[..., 0], xb[..., 1])
    m = np.max(np.abs(xb), axis=-1)
    safe = np.where(m > 0, m, 1)
    r = xb / safe[..., None]
    return m * np.sqrt(np.sum(r * r, axis=-1))


def _unit_bar(xb):
    """x̄/‖x̄‖ per row; the first unit axis where x̄ = 0 (deliberate choice of frame)."""
    n_bar = xb.shape[-1]
    if n_bar == 0:
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


def _scale_exponents(x):
    """Per-row exponent e (a multiple of 4) with x·2^-e of moderate size.

    Rows whose largest entry lies in [2^-T, 2^T], T = maxexp/8, are left alone (e = 0): there
    products of up to four numbers of the row's magnitude (det·y, Q_x y, ...) can neither
    overflow nor reach the subnormal range, and leaving such rows untouched keeps ordinary
    results bit-for-bit equal to the textbook formulas.  Other rows are brought to max|x̂_i| in [2^-4, 1).  A multiple of 4 makes
    2^(e/2) and 2^(e/4) exact, which sqrt and the NT scaling need.
    """
    m = np.max(np.abs(x), axis=-1)
    t = np.finfo(x.dtype).maxexp // 8
    _, e = np.frexp(m)
    e = e.astype(np.int64)
    e = -((-e) // 4) * 4
    extreme = (m > 0) & ((m > np.ldexp(np.ones_like(m), t)) | (m < np.ldexp(np.ones_like(m), -t)))
    return np.where(extreme, e, 0)


def _scaled(x):
    # Fast path for the common case (every row of moderate size): one max over the array
    # instead of a per-row frexp/ldexp; the result is the same (e = 0 for such rows).
    a = np.abs(x)
    t = np.finfo(x.dtype).maxexp // 8
    if a.size and a.max() <= np.ldexp(1.0, t):
        # Column-wise maximum: numpy's reduction over a short last axis costs ~5× more.
        rowmax = a[:, 0].copy()
        for j in range(1, a.shape[1]):
            np.maximum(rowmax, a[:, j], out=rowmax)
        if np.all((rowmax >= np.ldexp(1.0, -t)) | (rowmax == 0)):
            return x, np.zeros(x.shape[0], dtype=np.int64)
    e = _scale_exponents(x)
    return np.ldexp(x, -e[:, None]), e


def _spec(xs):
    """(λ1, λ2, ‖x̄‖) of rows of xs, in the scale of xs."""
    n = _bar_norm(xs[:, 1:])
    x0 = xs[:, 0]
    return x0 + n, x0 - n, n


def _reflect(x):
    y = x.copy()
    y[..., 1:] *= -1
    return y


def _dot(x, y):
    # einsum avoids numpy's slow reduction over a short last axis (3× faster for L3 batches).
    return np.einsum("ij,ij->i", x, y)


def _product(x, y):
    """x∘y for 2-D arrays, scaled so that no intermediate overflows when the result does not."""
    xs, ex = _scaled(x)
    ys, ey = _scaled(y)
    head = _dot(xs, ys)
    bar = xs[:, :1] * ys[:, 1:] + ys[:, :1] * xs[:, 1:]
    out = np.concatenate([head[:, None], bar], axis=1)
    return np.ldexp(out, (ex + ey)[:, None])


def _quad(x, y):
    """Q_x y = 2(xᵀy)x - det(x) R y for 2-D arrays, without forming Q_x.

    x and y are scaled by exact powers of two so that the two terms stay finite; the result
    over/underflows only when its true value does (so no inf - inf = NaN).
    """
    xs, ex = _scaled(x)
    ys, ey = _scaled(y)
    l1, l2, _ = _spec(xs)
    q = 2 * _dot(xs, ys)[:, None] * xs - (l1 * l2)[:, None] * _reflect(ys)
    return np.ldexp(q, (2 * ex + ey)[:, None])


def _inverse(op, x, single):
    xs, e = _scaled(x)
    l1, l2, _ = _spec(xs)
    d = l1 * l2
    bad = d == 0
    if bad.any():
        i = int(np.argmax(bad))
        raise ConeDomainError(
            op,
            f"det x = 0 (λ1 = {float(np.ldexp(l1[i], e[i]))}, "
            f"λ2 = {float(np.ldexp(l2[i], e[i]))}): x lies on the boundary of L or of -L, "
            "where x⁻¹ does not exist",
            cone=_cone_index(i, single),
            value=0.0,
        )
    # (Rx / λ1) / λ2 instead of Rx / (λ1 λ2): the scaled λ's are O(1), and dividing twice
    # avoids forming det, which may not be representable although x⁻¹ is.
    inv = (_reflect(xs) / l1[:, None]) / l2[:, None]
    return np.ldexp(inv, -e[:, None])


def _arrow_solve(op, x, y, single):
    xs, ex = _scaled(x)
    ys, ey = _scaled(y)
    l1, l2, _ = _spec(xs)
    x0 = xs[:, 0]
    bad = (l1 == 0) | (l2 == 0) | (x0 == 0)
    if bad.any():
        i = int(np.argmax(bad))
        raise ConeDomainError(
            op,
            f"Arw(x) is singular (x0 = {float(np.ldexp(x0[i], ex[i]))}, "
            f"λ2 = {float(np.ldexp(l2[i], ex[i]))}): x∘d = y has no unique solution",
            cone=_cone_index(i, single),
            value=0.0,
        )
    # d0 = (x0 y0 − x̄ᵀȳ)/det x, divided by λ1 then λ2 (det may not be representable);
    # d̄ = (ȳ − d0 x̄)/x0 from the vector part of x∘d = y.
    d0 = ((x0 * ys[:, 0] - _dot(xs[:, 1:], ys[:, 1:])) / l1) / l2
    db = (ys[:, 1:] - d0[:, None] * xs[:, 1:]) / x0[:, None]
    out = np.concatenate([d0[:, None], db], axis=1)
    return np.ldexp(out, (ey - ex)[:, None])


def _sqrt(op, x, single):
    xs, e = _scaled(x)
    l1, l2, _ = _spec(xs)
    bad = l2 < 0
    if bad.any():
        i = int(np.argmax(bad))
        raise ConeDomainError(
            op,
            f"x is outside the cone (λ2 = {float(np.ldexp(l2[i], e[i]))} < 0); the square root "
            "exists only on L",
            cone=_cone_index(i, single),
            value=float(np.ldexp(l2[i], e[i])),
        )
    # √x = √λ1 c1 + √λ2 c2 = ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)) because (√λ1-√λ2)/2 · x̄/‖x̄‖ =
    # (λ1-λ2)/(2(√λ1+√λ2)) · x̄/‖x̄‖ and λ1-λ2 = 2‖x̄‖.  This form has no subtraction and no
    # division by ‖x̄‖, so it is accurate for x̄ → 0 and on the boundary (λ2 = 0) alike.
    r1 = np.sqrt(l1)
    r2 = np.sqrt(l2)
    t = r1 + r2
    safe = np.where(t > 0, t, 1)  # t = 0 only for x = 0, where x̄/1 = 0 is the right answer
    out = np.concatenate([(t / 2)[:, None], xs[:, 1:] / safe[:, None]], axis=1)
    return np.ldexp(out, (e // 2)[:, None])


def _power_interior(x, p):
    """x^p for rows with λ2 > 0 (any real p), cancellation-free.

    x^p = ((a + b)/2 ; D x̄) with a = λ1^p, b = λ2^p and the divided difference
    D = (a - b)/(λ1 - λ2).  With δ = 2‖x̄‖/λ2 and t = p log1p(δ) (= log(a/b)):
      t > 1 : a and b differ by more than a factor e, D = a(1 - e^-t)/(2‖x̄‖) has no
              cancellation (and stays inf rather than inf - inf if a overflows);
      t <= 1: D = b (e^t - 1)/(λ1 - λ2) = b·p·E(t)·L(δ)/λ2 with E(t) = expm1(t)/t and
              L(δ) = log1p(δ)/δ, both → 1 as their argument → 0, so neither λ1 ≈ λ2 nor a
              subnormal x̄ loses digits and nothing divides by ‖x̄‖.
    """
    dtype = x.dtype
    xs, e = _scaled(x)
    l1s, l2s, ns = _spec(xs)
    p = dtype.type(p)
    a = np.power(np.ldexp(l1s, e), p)
    b = np.power(np.ldexp(l2s, e), p)
    # D x̄ is evaluated as (D 2^e) x̂ with the scaled denominators ‖x̂‖, λ̂2: D alone can
    # under/overflow (e.g. x ~ 1e150, p = -1.5: D ~ 1e-376) although D x̄ is representable.
    delta = (2 * ns) / l2s  # scale-free
    lg = np.log1p(delta)
    t = p * lg
    big = t > 1
    ratio_e = np.where(t == 0, 1, np.expm1(t) / np.where(t == 0, 1, t))
    ratio_l = np.where(delta == 0, 1, lg / np.where(delta == 0, 1, delta))
    d_small = b * p * ratio_e * ratio_l / l2s
    # a - b = a(1 - e^-t): written with expm1 it stays exact in relative terms and gives
    # D = inf (not inf - inf) when λ1^p overflows.
    d_big = a * -np.expm1(-t) / np.where(ns > 0, 2 * ns, 1)
    dd = np.where(big, d_big, d_small)
    dd = np.where(ns > 0, dd, 0)  # x̄ = 0: the bar part is 0 whatever D is
    head = (a + b) / 2
    return np.concatenate([head[:, None], _times_bar(dd, xs)], axis=1)


def _times_bar(dd, xs):
    """dd·x̄ with exact zeros kept where x̄_i = 0 (an overflowed dd must not make inf·0 = NaN)."""
    xb = xs[:, 1:]
    return np.where(xb == 0, xb, dd[:, None] * xb)


def _power_boundary(x, p):
    """x^p for rows with λ2 = 0 and p > 0 (non-integer): λ1^p c1 (λ2^p = 0)."""
    dtype = x.dtype
    xs, e = _scaled(x)
    l1s, _, _ = _spec(xs)
    a = np.power(np.ldexp(l1s, e), dtype.type(p))
    # λ1^p c1 = (a/2 ; a x̄/λ1) = (a/2 ; (a/λ̂1) x̂), scaled as in _power_interior.
    dd = np.where(l1s > 0, a / np.where(l1s > 0, l1s, 1), 0)
    return np.concatenate([(a / 2)[:, None], _times_bar(dd, xs)], axis=1)


def _power_integer(op, x, p, single):
    """x^p for integer p by binary powering (power-associativity), valid for any x with
    det x != 0 when p < 0; used off the interior, where the spectral formula would need
    logarithms of non-positive numbers or would cancel (λ1 ≈ -λ2)."""
    base = _inverse(op, x, single) if p < 0 else x
    m = abs(int(p))
    result = np.zeros_like(x)
    result[:, 0] = 1
    while m:
        if m & 1:
            result = _product(result, base)
        m >>= 1
        if m:
            base = _product(base, base)
    return result


def _check_nan_free(op, out, single):
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


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def identity(k, n=None, dtype=np.float64):
    """Identity element ``e = (1; 0)`` of the Jordan algebra of ``L^k``.

    Parameters
    ----------
    k : int
        Cone dimension, ``k >= 1``.
    n : int or None
        Number of cones; ``None`` for a single cone.
    dtype : dtype, default float64
        Floating dtype of the result (``np.longdouble`` for extended precision).

    Returns
    -------
    ndarray
        Shape ``(k,)`` if ``n is None`` else ``(n, k)``.
    """
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


def jordan_product(x, y):
    """Jordan product ``x∘y = (xᵀy; x0 ȳ + y0 x̄)``.

    Parameters
    ----------
    x, y : array_like, shape ``(k,)`` or ``(N, k)``
        Any finite vectors (not restricted to the cone); ``(k,)`` broadcasts against ``(N, k)``.

    Returns
    -------
    ndarray
        Shape ``(k,)`` if both arguments are single cones, else ``(N, k)``; dtype
        ``result_type(x, y, float64)``.  The product is commutative bit for bit.

    Raises
    ------
    ConeDomainError
        ``operation="jordan_product"`` if an entry is NaN or infinite.
    """
    single, (x, y) = _prepare("jordan_product", ("x", "y"), x, y)
    with np.errstate(all="ignore"):
        out = _product(x, y)
    return _out(_check_nan_free("jordan_product", out, single), single)


def arrow(x):
    """Arrow matrix ``Arw(x) = [[x0, x̄ᵀ], [x̄, x0 I]]``, i.e. ``Arw(x) y = x∘y``.

    Diagnostics and tests only: the solver applies ``x∘·`` directly.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        Shape ``(k, k)`` or ``(N, k, k)``, dtype of ``x`` (promoted to at least float64).

    Raises
    ------
    ConeDomainError
        ``operation="arrow"`` for non-finite input.
    """
    single, (x,) = _prepare("arrow", ("x",), x)
    k = x.shape[1]
    a = x[:, 0, None, None] * np.eye(k, dtype=x.dtype)[None]
    a[:, 0, :] = x
    a[:, :, 0] = x
    return _out(a, single)


def reflect(x):
    """Reflection ``R x = (x0; -x̄)`` with ``R = diag(1, -I)``.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        Same shape as ``x``; dtype promoted to at least float64.

    Raises
    ------
    ConeDomainError
        ``operation="reflect"`` for non-finite input.
    """
    single, (x,) = _prepare("reflect", ("x",), x)
    return _out(_reflect(x), single)


def spectral_values(x):
    """Spectral values ``λ1 = x0 + ‖x̄‖ >= λ2 = x0 - ‖x̄‖``.

    ``‖x̄‖`` is computed hypot-style (scaled by ``max|x̄_i|``), so it is accurate for subnormal
    ``x̄`` and does not overflow for ``|x̄| ~ 1e300``.  ``λ1`` overflows to inf only if
    ``x0 + ‖x̄‖`` exceeds the dtype's range.  ``x ∈ L`` iff ``λ2 >= 0``, ``x ∈ int L`` iff
    ``λ2 > 0``.  ``λ2`` has relative accuracy ``≈ k·eps·λ1/|λ2|`` (its condition number).

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``
        For ``k = 1``: ``λ1 = λ2 = x0``.

    Returns
    -------
    lam1, lam2 : ndarray or numpy scalar
        Shape ``(N,)`` (or scalars for a single cone), dtype of ``x``.

    Raises
    ------
    ConeDomainError
        ``operation="spectral_values"`` for non-finite input.
    """
    single, (x,) = _prepare("spectral_values", ("x",), x)
    with np.errstate(all="ignore"):
        xs, e = _scaled(x)
        l1, l2, _ = _spec(xs)
        l1 = np.ldexp(l1, e)
        l2 = np.ldexp(l2, e)
    return _out(l1, single), _out(l2, single)


def spectral_frames(x):
    """Jordan frame ``c1,2 = ½(1; ±x̄/‖x̄‖)`` of ``x``, so that ``x = λ1 c1 + λ2 c2``.

    When ``x̄ = 0`` the frame is not unique (``x`` is a multiple of ``e``); this function then
    deliberately returns the frame along the first unit axis, ``c1,2 = ½(1; ±1, 0, …, 0)``, for
    which the decomposition still holds (``λ1 = λ2 = x0``).  A subnormal ``x̄`` is normalised
    without underflow (divided by ``max|x̄_i|`` first).

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``
        For ``k = 1`` both frames are ``(½,)``: the decomposition ``x0 = x0·½ + x0·½`` holds,
        the idempotent relations ``c∘c = c`` and ``c1∘c2 = 0`` do not (rank one).

    Returns
    -------
    c1, c2 : ndarray
        Same shape as ``x``, dtype of ``x``.  ``c1∘c2 = 0``, ``ci∘ci = ci``,
        ``c1 + c2 = e`` (for ``k >= 2``).

    Raises
    ------
    ConeDomainError
        ``operation="spectral_frames"`` for non-finite input.
    """
    single, (x,) = _prepare("spectral_frames", ("x",), x)
    u = _unit_bar(x[:, 1:])
    half = np.full((x.shape[0], 1), 0.5, dtype=x.dtype)
    c1 = np.concatenate([half, u / 2], axis=1)
    c2 = np.concatenate([half, -u / 2], axis=1)
    return _out(c1, single), _out(c2, single)


def det(x):
    """Determinant ``det x = λ1 λ2``, computed as ``(x0 - ‖x̄‖)(x0 + ‖x̄‖)``.

    Never as ``x0² - ‖x̄‖²``: near the boundary the two squares agree in most of their digits
    and each carries a rounding error ``≈ eps·x0²``, so their difference can be 0, of the wrong
    sign, or wrong in every digit, whereas the factored form inherits only the (unavoidable)
    error of ``λ2``.  It also avoids overflow: ``x0²`` overflows at ``x0 ~ 1.3e154`` in float64
    while ``λ1 λ2`` stays finite near the boundary.  Extreme magnitudes are handled by exact
    power-of-two scaling, so ``det`` overflows to inf (or underflows to 0) only when the true
    determinant is not representable.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``
        Any finite vector; ``det < 0`` outside ``L ∪ -L``.  For ``k = 1``, ``det x = x0²``.

    Returns
    -------
    ndarray or numpy scalar
        Shape ``(N,)`` (scalar for one cone), dtype of ``x``.

    Raises
    ------
    ConeDomainError
        ``operation="det"`` for non-finite input.
    """
    single, (x,) = _prepare("det", ("x",), x)
    with np.errstate(all="ignore"):
        xs, e = _scaled(x)
        l1, l2, _ = _spec(xs)
        d = np.ldexp(l1 * l2, 2 * e)
    return _out(d, single)


def trace(x):
    """Trace ``trace x = λ1 + λ2 = 2 x0``.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray or numpy scalar
        Shape ``(N,)`` (scalar for one cone), dtype of ``x``.

    Raises
    ------
    ConeDomainError
        ``operation="trace"`` for non-finite input.
    """
    single, (x,) = _prepare("trace", ("x",), x)
    with np.errstate(over="ignore"):
        return _out(2 * x[:, 0], single)


def inverse(x):
    """Jordan inverse ``x⁻¹ = R x / det x``, so that ``x∘x⁻¹ = e``.

    Defined whenever ``det x != 0``: inside ``int L`` (then ``x⁻¹ ∈ int L``), inside ``-int L``,
    and outside ``L ∪ -L`` (``det < 0``).  Computed as ``((R x)/λ1)/λ2`` on power-of-two-scaled
    data, so it does not fail when ``det x`` itself would under/overflow but ``x⁻¹`` is
    representable.  Relative accuracy ``≈ k·eps·λ1/|λ2|``, inherited from ``λ2``.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        Same shape as ``x``, dtype of ``x``.

    Raises
    ------
    ConeDomainError
        ``operation="inverse"``, ``cone`` = first cone with computed ``det x = 0`` (``λ2 = 0``:
        on the boundary of ``L``, or ``λ1 = 0``: on the boundary of ``-L``), ``value = 0.0``;
        also for non-finite input.
    """
    single, (x,) = _prepare("inverse", ("x",), x)
    with np.errstate(all="ignore"):
        out = _inverse("inverse", x, single)
    return _out(_check_nan_free("inverse", out, single), single)


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
    ``λ1^p - λ2^p`` cancels when ``λ1 ≈ -λ2``.  ``p = 1`` returns a copy of ``x``, ``p = -1`` is
    :func:`inverse`, ``p = ½`` is :func:`sqrt` (so both are bit-identical to those functions).

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``
    p : real scalar
        Converted to the working dtype of ``x`` (pass ``np.longdouble(1)/3`` for an extended
        precision exponent).

    Returns
    -------
    ndarray
        Same shape as ``x``, dtype of ``x``.  Overflows to inf when the true result does.

    Raises
    ------
    ConeDomainError
        ``operation="power"`` outside the domain above or for non-finite input.
    """
    single, (x,) = _prepare("power", ("x",), x)
    pa = np.asarray(p)
    if pa.ndim != 0 or pa.dtype.kind not in "biuf":
        raise TypeError(f"power: exponent p must be a real scalar, got {p!r}")
    pp = pa.astype(x.dtype)[()]
    if not np.isfinite(pp):
        raise ConeDomainError("power", f"exponent p = {p!r} is not finite", value=float(pp))
    is_int = bool(pp == np.floor(pp))
    with np.errstate(all="ignore"):
        if pp == 0:
            out = np.zeros_like(x)
            out[:, 0] = 1
            return _out(out, single)
        if pp == 1:
            return _out(x.copy(), single)
        if pp == -1:
            return _out(_check_nan_free("power", _inverse("power", x, single), single), single)
        if pp == 0.5:
            return _out(_check_nan_free("power", _sqrt("power", x, single), single), single)
        xs, e = _scaled(x)
        l1s, l2s, _ = _spec(xs)
        interior = l2s > 0
        if is_int and pp < 0:
            bad = (l1s * l2s) == 0
            if bad.any():
                i = int(np.argmax(bad))
                raise ConeDomainError(
                    "power",
                    f"negative integer power p = {float(pp)} needs det x != 0 (x off the "
                    f"boundaries of L and -L), got λ1 = {float(np.ldexp(l1s[i], e[i]))}, "
                    f"λ2 = {float(np.ldexp(l2s[i], e[i]))}",
                    cone=_cone_index(i, single),
                    value=0.0,
                )
        if not is_int:
            bad = (l2s < 0) if pp > 0 else ~interior
            if bad.any():
                i = int(np.argmax(bad))
                lam2 = float(np.ldexp(l2s[i], e[i]))
                need = "λ2 >= 0 (x in L)" if pp > 0 else "λ2 > 0 (x in int L)"
                raise ConeDomainError(
                    "power",
                    f"non-integer power p = {float(pp)} needs {need}, got λ2 = {lam2}",
                    cone=_cone_index(i, single),
                    value=lam2,
                )
        out = np.empty_like(x)
        if interior.any():
            out[interior] = _power_interior(x[interior], pp)
        rest = ~interior
        if rest.any():
            if is_int:
                out[rest] = _power_integer("power", x[rest], pp, single)
            else:
                out[rest] = _power_boundary(x[rest], pp)
    return _out(_check_nan_free("power", out, single), single)


def sqrt(x):
    """Jordan square root ``x^{1/2} = √λ1 c1 + √λ2 c2``, the unique ``s ∈ L`` with ``s∘s = x``.

    Defined on the closed cone (``λ2 >= 0``; on the boundary ``√λ2 = 0``).  Evaluated in the
    cancellation-free closed form ``((√λ1 + √λ2)/2 ; x̄/(√λ1 + √λ2))``, which needs no frame and
    is valid for ``x̄ = 0`` and ``x = 0``.  Backward stable: ``sqrt(x)∘sqrt(x) = x`` up to
    ``O(k·eps·λ1)`` whatever ``λ2/λ1`` is.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        Same shape as ``x``, dtype of ``x``; in ``L``.

    Raises
    ------
    ConeDomainError
        ``operation="sqrt"``, ``cone`` = first cone with ``λ2 < 0`` (outside ``L``, e.g. a point
        that left the cone by rounding), ``value = λ2``; also for non-finite input.
    """
    single, (x,) = _prepare("sqrt", ("x",), x)
    with np.errstate(all="ignore"):
        out = _sqrt("sqrt", x, single)
    return _out(_check_nan_free("sqrt", out, single), single)


def arrow_solve(x, y):
    """Jordan division: the ``d`` with ``x∘d = y``, i.e. ``d = Arw(x)⁻¹ y``.

    ``d0 = (x0 y0 − x̄ᵀȳ)/det x`` and ``d̄ = (ȳ − d0 x̄)/x0``; used for the scaled
    complementarity right-hand side ``λ \\ ξ`` of the interior-point method.  Relative error
    ``≈ k·eps·λ1/λ2`` (the condition number of ``Arw(x)``).  For ``k = 1``, ``d = y/x``.

    Parameters
    ----------
    x, y : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        ``(k,)`` if both are single cones, else ``(N, k)``; dtype ``result_type(x, y, float64)``.

    Raises
    ------
    ConeDomainError
        ``operation="arrow_solve"``, ``cone`` = first cone where ``Arw(x)`` is singular
        (``det x = 0`` or ``x0 = 0``); also for non-finite input.
    """
    single, (x, y) = _prepare("arrow_solve", ("x", "y"), x, y)
    with np.errstate(all="ignore"):
        out = _arrow_solve("arrow_solve", x, y, single)
    return _out(_check_nan_free("arrow_solve", out, single), single)


def quad_apply(x, y):
    """Quadratic representation applied to a vector: ``Q_x y = 2(xᵀy) x - det(x) R y``.

    Never forms ``Q_x`` (``O(k)`` work per cone).  Equals ``(2 Arw(x)² - Arw(x²)) y``;
    ``Q_x`` is an automorphism of ``int L`` for ``x ∈ int L``.  Power-of-two scaling makes the
    result overflow only when its true value does (no ``inf - inf``).

    Parameters
    ----------
    x, y : array_like, shape ``(k,)`` or ``(N, k)``
        Any finite vectors; ``(k,)`` broadcasts against ``(N, k)``.

    Returns
    -------
    ndarray
        ``(k,)`` if both are single cones, else ``(N, k)``; dtype ``result_type(x, y, float64)``.

    Raises
    ------
    ConeDomainError
        ``operation="quad_apply"`` for non-finite input.
    """
    single, (x, y) = _prepare("quad_apply", ("x", "y"), x, y)
    with np.errstate(all="ignore"):
        out = _quad(x, y)
    return _out(_check_nan_free("quad_apply", out, single), single)


def quad_matrix(x):
    """Explicit ``Q_x = 2 x xᵀ - det(x) R`` (diagnostics and tests only; use :func:`quad_apply`).

    Its eigenvalues are ``λ1²``, ``λ2²`` and ``λ1 λ2`` (multiplicity ``k - 2``).

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray
        Shape ``(k, k)`` or ``(N, k, k)``, dtype of ``x``.

    Raises
    ------
    ConeDomainError
        ``operation="quad_matrix"`` for non-finite input.
    """
    single, (x,) = _prepare("quad_matrix", ("x",), x)
    k = x.shape[1]
    with np.errstate(all="ignore"):
        xs, e = _scaled(x)
        l1, l2, _ = _spec(xs)
        r = np.ones(k, dtype=x.dtype)
        r[1:] = -1
        q = 2 * xs[:, :, None] * xs[:, None, :] - (l1 * l2)[:, None, None] * np.diag(r)[None]
        q = np.ldexp(q, (2 * e)[:, None, None])
    return _out(_check_nan_free("quad_matrix", q, single), single)


def cond_quad(x):
    """Spectral condition number of ``Q_x``: ``cond(Q_x) = (λ1/λ2)²`` for ``x ∈ L``.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    ndarray or numpy scalar
        Shape ``(N,)`` (scalar for one cone), dtype of ``x``.  ``inf`` where ``λ2 = 0``
        (boundary, ``Q_x`` singular; including ``x = 0``).  ``1`` for ``k = 1``.

    Raises
    ------
    ConeDomainError
        ``operation="cond_quad"``, first cone with ``λ2 < 0`` (outside ``L``, where ``λ1/λ2``
        is not a condition number), ``value = λ2``; also for non-finite input.
    """
    single, (x,) = _prepare("cond_quad", ("x",), x)
    with np.errstate(all="ignore"):
        xs, e = _scaled(x)
        l1, l2, _ = _spec(xs)
        bad = l2 < 0
        if bad.any():
            i = int(np.argmax(bad))
            lam2 = float(np.ldexp(l2[i], e[i]))
            raise ConeDomainError(
                "cond_quad",
                f"x is outside the cone (λ2 = {lam2} < 0)",
                cone=_cone_index(i, single),
                value=lam2,
            )
        ratio = np.where(l2 > 0, l1 / np.where(l2 > 0, l2, 1), np.inf)
        c = ratio * ratio
    return _out(c.astype(x.dtype, copy=False), single)


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

    Parameters
    ----------
    z, s : array_like, shape ``(k,)`` or ``(N, k)``
        Strictly interior points (``λ2 > 0``); ``(k,)`` broadcasts against ``(N, k)``.

    Returns
    -------
    NTScaling
        Fields ``p, p_inv, lam, v`` (shape of the broadcast inputs), ``beta, cond`` (``(N,)`` or
        scalars), all in ``result_type(z, s, float64)``.

    Raises
    ------
    ConeDomainError
        ``operation="nt_scaling"``, ``cone`` = first cone where ``z`` (checked first) or ``s``
        has ``λ2 <= 0``; the message names the argument, ``value = λ2``.  Also for non-finite
        input.
    """
    single, (z, s) = _prepare("nt_scaling", ("z", "s"), z, s)
    with np.errstate(all="ignore"):
        zs, ez = _scaled(z)
        ss, es = _scaled(s)
        l1z, l2z, _ = _spec(zs)
        l1s, l2s, _ = _spec(ss)
        for name, l2v, ev in (("z", l2z, ez), ("s", l2s, es)):
            bad = ~(l2v > 0)
            if bad.any():
                i = int(np.argmax(bad))
                lam2 = float(np.ldexp(l2v[i], ev[i]))
                raise ConeDomainError(
                    "nt_scaling",
                    f"argument '{name}' is not strictly inside the cone (λ2 = {lam2} <= 0); "
                    "the NT scaling needs an interior pair",
                    cone=_cone_index(i, single),
                    value=lam2,
                )
        rz = np.sqrt(l1z) * np.sqrt(l2z)  # √det ẑ, no overflow: ẑ is O(1)
        rs = np.sqrt(l1s) * np.sqrt(l2s)
        zb = zs / rz[:, None]
        sb = ss / rs[:, None]
        # z̄ᵀs̄ >= 1 for unit-det interior points, so γ >= 1 and w̄0 >= 1: no cancellation
        # in γ, in w̄0 + 1 or in the denominator d below.
        g = np.sqrt((1 + _dot(zb, sb)) / 2)
        wb = (sb + _reflect(zb)) / (2 * g)[:, None]
        v = wb.copy()
        v[:, 0] += 1
        v = v / np.sqrt(2 * (wb[:, 0] + 1))[:, None]
        # √β = (det s/det z)^{1/8} = (rs/rz)^{1/4} · 2^{(es - ez)/4}; es, ez are multiples of 4.
        q = np.sqrt(np.sqrt(rs / rz))
        sh = (es - ez) // 4
        p = np.ldexp(q[:, None] * v, sh[:, None])
        p_inv = np.ldexp(_reflect(v) / q[:, None], -sh[:, None])
        beta = np.ldexp(q * q, 2 * sh)
        d = 2 * g + zb[:, 0] + sb[:, 0]
        lam_bar = ((g + zb[:, 0]) / d)[:, None] * sb[:, 1:] + ((g + sb[:, 0]) / d)[:, None] * zb[
            :, 1:
        ]
        lam = np.concatenate([g[:, None], lam_bar], axis=1) * np.sqrt(rs * rz)[:, None]
        lam = np.ldexp(lam, ((es + ez) // 2)[:, None])
        l1v = v[:, 0] + _bar_norm(v[:, 1:])
        l1v2 = l1v * l1v
        cond = l1v2 * l1v2
    for arr in (p, p_inv, lam):
        _check_nan_free("nt_scaling", arr, single)
    return NTScaling(
        p=_out(p, single),
        p_inv=_out(p_inv, single),
        lam=_out(lam, single),
        v=_out(v, single),
        beta=_out(beta, single),
        cond=_out(cond, single),
    )


def step_to_boundary(x, dx):
    """Largest ``α >= 0`` with ``x + α dx ∈ L``, per cone (``inf`` if the ray never leaves ``L``).

    Route: with ``y = Q_{x^{-1/2}} dx`` we have ``x + α dx = Q_{x^{1/2}}(e + α y)`` because
    ``Q_{x^{1/2}} e = x`` and ``Q_{x^{1/2}} Q_{x^{-1/2}} = I``.  ``Q_{x^{1/2}}`` maps ``L`` onto
    ``L`` for interior ``x``, so ``x + α dx ∈ L`` iff ``e + α y ∈ L`` iff
    ``λ2(e + α y) = 1 + α λ2(y) >= 0`` (``e + αy`` has the frame of ``y``).  Hence
    ``α = -1/λ2(y)`` if ``λ2(y) < 0`` and ``α = inf`` otherwise (then ``dx ∈ L``).  This needs no
    quadratic-equation root (whose textbook form cancels), and the work is scale-free:
    ``α(x, dx) = α(c x, c dx)``.

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``
        Strictly interior points (``λ2 > 0``).
    dx : array_like, same cone dimension
        Any finite directions; ``(k,)`` broadcasts against ``(N, k)``.

    Returns
    -------
    ndarray or numpy scalar
        ``α``, shape ``(N,)`` (scalar for one cone), dtype ``result_type(x, dx, float64)``,
        ``> 0``; ``inf`` exactly when ``dx ∈ L`` (as computed: ``λ2(y) >= 0``); the dtype's
        largest finite number when the ray leaves the cone only beyond that (tiny ``dx``).

    Raises
    ------
    ConeDomainError
        ``operation="step_to_boundary"``, first cone with ``λ2(x) <= 0`` (``value = λ2``);
        also for non-finite input.
    """
    single, (x, dx) = _prepare("step_to_boundary", ("x", "dx"), x, dx)
    with np.errstate(all="ignore"):
        alpha = _step("step_to_boundary", x, dx, single)
    return _out(alpha, single)


def _step(op, x, dx, single):
    xs, e = _scaled(x)
    l1, l2, _ = _spec(xs)
    bad = ~(l2 > 0)
    if bad.any():
        i = int(np.argmax(bad))
        lam2 = float(np.ldexp(l2[i], e[i]))
        raise ConeDomainError(
            op,
            f"x is not strictly inside the cone (λ2 = {lam2} <= 0); the step length is measured "
            "from an interior point",
            cone=_cone_index(i, single),
            value=lam2,
        )
    dxs = np.ldexp(dx, -e[:, None])  # the same exact scaling of x and dx leaves α unchanged
    r1 = np.sqrt(l1)
    r2 = np.sqrt(l2)
    t = r1 + r2
    # x^{-1/2} = R x^{1/2} / √det x, with x^{1/2} in the closed form of sqrt().
    half = np.concatenate([(t / 2)[:, None], xs[:, 1:] / t[:, None]], axis=1)
    w = _reflect(half) / (r1 * r2)[:, None]
    y = _quad(w, dxs)
    ys, ey = _scaled(y)
    _, ly2, _ = _spec(ys)
    ly2 = np.ldexp(ly2, ey)
    neg = ly2 < 0
    alpha = np.where(neg, -1 / np.where(neg, ly2, -1), np.inf)
    # -1/λ2(y) overflows when the true step exceeds the dtype's range (e.g. a subnormal dx
    # pointing out of the cone).  inf would claim "never leaves the cone", which is false:
    # return the largest representable step instead (x + max·dx is still in L).
    alpha = np.where(neg & np.isinf(alpha), np.finfo(alpha.dtype).max, alpha)
    if np.isnan(alpha).any():
        _check_nan_free(op, alpha[:, None], single)
    return alpha


def max_step(x, dx, alpha_max=1.0):
    """Common step length ``min(alpha_max, min_i step_to_boundary(x_i, dx_i))``.

    Parameters
    ----------
    x, dx : array_like, shape ``(k,)`` or ``(N, k)``
        As in :func:`step_to_boundary` (``x`` strictly interior).
    alpha_max : float, default 1.0
        Upper bound on the step (``>= 0``; may be ``inf``).

    Returns
    -------
    numpy scalar
        In ``result_type(x, dx, float64)``; ``alpha_max`` for an empty batch.

    Raises
    ------
    ConeDomainError
        ``operation="max_step"`` if some ``x_i`` is not interior or input is non-finite.
    """
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
    """Smallest ``λ2`` over a batch of cones and where it occurs (diagnostics).

    Parameters
    ----------
    x : array_like, shape ``(k,)`` or ``(N, k)``

    Returns
    -------
    value : numpy scalar
        ``min_i λ2(x_i)`` in the dtype of ``x`` (``+inf`` for an empty batch).
    index : int or None
        Index of the first cone attaining it; ``None`` for a single cone or an empty batch.

    Raises
    ------
    ConeDomainError
        ``operation="min_lambda2"`` for non-finite input.
    """
    single, (x,) = _prepare("min_lambda2", ("x",), x)
    if x.shape[0] == 0:
        return x.dtype.type(np.inf), None
    with np.errstate(all="ignore"):
        xs, e = _scaled(x)
        _, l2, _ = _spec(xs)
        l2 = np.ldexp(l2, e)
    i = int(np.argmin(l2))
    return l2[i], (None if single else i)
