"""Row operations of the Jordan algebra: 2-D arrays ``(N, k)`` of one floating dtype, rescaled
where needed, checked, and evaluated by the closed forms (see :mod:`rfverify.jordan`).  The
solver's :class:`~rfverify.solver.cones.ProductCone` calls them on its flat vectors."""

from __future__ import annotations

import numpy as np

from typing import NamedTuple

from ._checks import _at, _check_nan_free, _raise_first, _require_finite, _scaled, _shift, _take
from ._formulas import (_arrow, _arrow_solve, _inverse, _inverse_sqrt, _inverse_square, _norm, _nt, _power_boundary,
                        _power_interior, _product, _quad, _quad_cols, _quad_matrix, _spec, _sqrt)

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
