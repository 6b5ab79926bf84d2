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

import numpy as np

from ..errors import ConeDomainError
from ._checks import _at, _out, _prepare, _raise_first, _scaled, _shift, moderate
from ._formulas import _reflect, _spec, _unit_bar
from ._rows import (NTScaling, QuadRows, arrow_rows, arrow_solve_rows, inverse_rows, inverse_square_rows, nt_rows,
                    power_rows, product_rows, quad_apply_rows, quad_matrix_rows, quad_rows, ray_lambda2_rows,
                    spectral_rows, sqrt_rows, step_from_lambda2, step_point_rows)

ROW_API = (moderate, QuadRows, NTScaling, product_rows, spectral_rows, quad_rows, quad_apply_rows, inverse_rows,
           inverse_square_rows, arrow_solve_rows, sqrt_rows, power_rows, quad_matrix_rows, arrow_rows, nt_rows,
           step_point_rows, ray_lambda2_rows, step_from_lambda2)
"""The row operations (not in ``__all__``) that :class:`rfverify.solver.cones.ProductCone` applies
to its flat vectors: the whole computation, without the public functions' argument parsing."""

__all__ = [
    "NTScaling", "arrow", "arrow_solve", "cond_quad", "det", "identity", "inverse",
    "jordan_product", "max_step", "min_lambda2", "nt_scaling", "power", "quad_apply",
    "quad_matrix", "reflect", "spectral_frames", "spectral_values", "sqrt", "step_to_boundary",
    "trace",
]


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
