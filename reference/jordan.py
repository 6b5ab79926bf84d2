r"""Jordan algebra of Lorentz cones in arbitrary precision (mpmath), one cone at a time.

This is the reference implementation of DESIGN.md §3 used by the reference interior-point
method (DESIGN.md §5).  It is written independently of :mod:`rfverify.jordan` (it imports
nothing from ``rfverify``): agreement between the two is evidence for both.

Cone vectors
------------
A cone vector is a Python ``list`` of ``k >= 1`` mpmath ``mpf`` numbers, ``x = [x0, x1, …]``
with head ``x0`` and bar part ``x̄ = x[1:]``.  The Lorentz cone is
``L^k = {x : x0 >= ‖x̄‖}``.  Every function returns new lists (inputs are never modified);
tuples and other sequences are accepted as input.  The algebra (DESIGN.md §3):

* product ``x∘y = (xᵀy ; x0 ȳ + y0 x̄)``, identity ``e = (1 ; 0)``, ``Arw(x) y = x∘y``;
* reflection ``R = diag(1, -I)``;
* spectral values ``λ1,2 = x0 ± ‖x̄‖`` (``λ1 >= λ2``), frames ``c1,2 = ½(1 ; ±x̄/‖x̄‖)``;
* ``det x = λ1 λ2`` computed as ``(x0 - ‖x̄‖)(x0 + ‖x̄‖)`` (never ``x0² - ‖x̄‖²``),
  ``x⁻¹ = R x / det x``, ``x^p = λ1^p c1 + λ2^p c2``;
* quadratic representation ``Q_x y = 2(xᵀy) x - det(x) R y``, ``cond(Q_x) = (λ1/λ2)²``.

``k = 1`` is the non-negative ray ``R_+`` with the conventions of :mod:`rfverify.jordan`: the
element has the double spectral value ``λ1 = λ2 = x0``, so ``det x = x0²``, ``x⁻¹ = 1/x0``,
``x^p = x0^p``, ``Q_x y = x0² y0`` and ``cond(Q_x) = 1`` (``inf`` at ``x0 = 0``).

Precision: never global
-----------------------
Every function works in the mpmath *context of its inputs*: ``ctx = x[0].context`` (the first
argument's first entry; if that is a plain int/float, the first mpf found among the arguments).
All arithmetic uses that context's numbers and functions (``ctx.sqrt``, ``ctx.fsum``,
``ctx.fdot``, …) at its current precision ``ctx.prec``.  No function reads, assigns or
temporarily changes ``mpmath.mp.prec``/``mpmath.mp.dps`` or any other context's precision.
The intended use is a private context::

    ctx = reference.jordan.context(50)          # mpmath.MPContext() with dps = 50
    x = reference.jordan.to_ctx(ctx, [2.0, 0.5, -0.25])
    r = reference.jordan.sqrt(x)                # 50-digit arithmetic, mpmath.mp untouched

Code that works with the global context inside ``mpmath.mp.workdps(d)`` gets ``d`` digits,
because then ``ctx`` is ``mpmath.mp`` with its (temporarily set) precision.

Secondary arguments and entries that are plain Python/numpy ints or binary floats are converted
*exactly* into ``ctx``; mpf numbers of another context are rounded to ``ctx.prec`` (see
:func:`to_ctx`).  Results are mpf numbers of ``ctx``.

Accuracy: each elementary operation rounds to ``ctx.prec`` bits (``ctx.eps = 2^(1-prec)``,
about ``10^-dps``).  The formulas are the cancellation-free ones of :mod:`rfverify.jordan`
(factored ``det``, closed-form ``sqrt``, divided-difference ``power``, CVXOPT-style NT scaling,
``step_to_boundary`` via ``Q_{x^{-1/2}}``), so every result is accurate to a small multiple
of ``ctx.eps`` times the condition number of the quantity computed (``λ1/λ2`` for ``λ2``,
``det``, ``x⁻¹``; ``(λ1/λ2)²`` for ``Q_x⁻¹``) times its scale.  mpmath has no overflow or
underflow in practice (exponents are unbounded), so no rescaling is needed.

Domain errors
-------------
Non-finite input (NaN, ±inf, in any argument or exponent) and arguments outside an operation's
domain (``λ2 < 0`` where the closed cone is required, ``λ2 <= 0`` where the interior is
required, ``det x = 0`` for an inverse) raise :class:`ReferenceDomainError` (a ``ValueError``)
with attributes ``operation`` (the function name) and ``value`` (the offending quantity, an
mpf, e.g. ``λ2``), and a message naming the operation.  No function returns NaN.  Wrong types
or shapes (not a sequence of reals, ``k = 0``, dimension mismatch) raise ``TypeError`` /
``ValueError``.
"""

from __future__ import annotations

import numbers
from typing import NamedTuple

import mpmath
from mpmath import libmp

__all__ = [
    "NTScaling",
    "ReferenceDomainError",
    "arrow",
    "arrow_solve",
    "bar_norm",
    "cond_quad",
    "context",
    "det",
    "dot",
    "identity",
    "inverse",
    "nt_scaling",
    "power",
    "product",
    "quad_apply",
    "quad_matrix",
    "reflect",
    "spectral_frames",
    "spectral_values",
    "sqrt",
    "step_to_boundary",
    "to_ctx",
    "trace",
]


class ReferenceDomainError(ValueError):
    """An argument lies outside the domain of a reference Jordan-algebra operation.

    Attributes
    ----------
    operation : str
        Name of the function (``"sqrt"``, ``"inverse"``, ``"nt_scaling"``, ``"to_ctx"``, …).
    value : mpf or None
        The offending quantity (``λ2``, ``det x``, the non-finite entry, …), in the working
        context of the call.
    problem : str
        The explanation (the message without the operation prefix).
    """

    def __init__(self, operation: str, problem: str, value=None):
        self.operation = operation
        self.value = value
        self.problem = problem
        super().__init__(f"{operation}: {problem}")


# --------------------------------------------------------------------------------------------
# contexts and conversion
# --------------------------------------------------------------------------------------------


def context(dps):
    """A fresh private ``mpmath.MPContext()`` with ``dps`` significant decimal digits.

    Its precision is independent of ``mpmath.mp`` (and of every other context): setting or
    using it never changes the global precision.

    Parameters
    ----------
    dps : int
        Decimal digits, ``>= 1`` (``ctx.prec`` becomes about ``3.32·dps + 3`` bits).

    Returns
    -------
    mpmath.MPContext
    """
    if isinstance(dps, bool) or not isinstance(dps, numbers.Integral) or int(dps) < 1:
        raise ValueError(f"context: dps must be an integer >= 1, got {dps!r}")
    ctx = mpmath.MPContext()
    ctx.dps = int(dps)
    return ctx


_NONFINITE = (libmp.fnan, libmp.finf, libmp.fninf)


def _scalar(ctx, v, op, what):
    """One real value → mpf of ctx (exact for ints and binary floats, see to_ctx)."""
    if type(v) is ctx.mpf:
        out = v
    elif isinstance(v, bool):
        raise TypeError(f"{op}: {what} must be a real number, got the bool {v!r}")
    elif isinstance(v, numbers.Integral):
        out = ctx.make_mpf(libmp.from_int(int(v)))
    elif hasattr(v, "_mpf_"):  # mpf of another context: round to ctx's precision
        out = ctx.mpf(v)
    elif isinstance(v, str):
        try:
            out = ctx.mpf(v)
        except (ValueError, TypeError):
            raise TypeError(f"{op}: {what} = {v!r} is not a number") from None
    elif isinstance(v, numbers.Rational):  # fractions.Fraction: rounded like a string
        out = ctx.make_mpf(libmp.from_rational(int(v.numerator), int(v.denominator),
                                               ctx.prec, ctx.rounding))
    elif isinstance(v, numbers.Real) and hasattr(v, "as_integer_ratio"):
        # float, numpy float16/32/64 and longdouble: the exact binary value num/2^j.
        try:
            num, den = v.as_integer_ratio()
        except (OverflowError, ValueError):  # ±inf, nan
            raise ReferenceDomainError(
                op, f"{what} is not finite ({v}); the operation is undefined",
                value=ctx.mpf(float(v)),
            ) from None
        if den & (den - 1):  # not a binary fraction (an unusual Real type): round
            out = ctx.make_mpf(libmp.from_rational(num, den, ctx.prec, ctx.rounding))
        else:
            out = ctx.make_mpf(libmp.from_man_exp(num, 1 - den.bit_length()))
    elif hasattr(v, "_mpc_") or isinstance(v, numbers.Complex) and not isinstance(
        v, numbers.Real
    ):
        raise TypeError(f"{op}: {what} must be real, got the complex value {v!r}")
    else:
        try:
            out = ctx.mpf(v)
        except (TypeError, ValueError):
            raise TypeError(
                f"{op}: {what} must be a real number (int, float, str or mpf), got "
                f"{type(v).__name__}"
            ) from None
    if out._mpf_ in _NONFINITE:
        raise ReferenceDomainError(
            op, f"{what} is not finite ({out}); the operation is undefined", value=out
        )
    return out


def to_ctx(ctx, values):
    """Convert numbers into mpf numbers of the context ``ctx``.

    * Python and numpy ints and binary floats (``float``, ``numpy.float64``, ``numpy.float32``,
      ``numpy.longdouble``, …) are converted **exactly**, at any precision of ``ctx`` (a
      binary float is ``m·2^e`` and becomes exactly that mpf).
    * mpf numbers of any context (including ``ctx`` itself) and decimal strings are rounded
      to ``ctx.prec`` (round-to-nearest); ``fractions.Fraction`` likewise.
    * NaN and ±inf raise :class:`ReferenceDomainError` (``operation="to_ctx"``); complex
      numbers and non-numbers raise ``TypeError``.

    Parameters
    ----------
    ctx : mpmath context (e.g. from :func:`context`, or ``mpmath.mp``)
    values : number, or (nested) sequence / numpy array of numbers

    Returns
    -------
    mpf or list
        One mpf for a scalar; otherwise lists of the same nesting (a 2-D array becomes a
        list of rows).
    """
    return _convert(ctx, values, "to_ctx", "value")


def _convert(ctx, values, op, what):
    if isinstance(values, str) or not hasattr(values, "__iter__"):
        return _scalar(ctx, values, op, what)
    if getattr(values, "ndim", None) == 0:  # numpy 0-d array
        return _scalar(ctx, values[()], op, what)
    return [_convert(ctx, v, op, what) for v in values]


def _find_ctx(op, args):
    for a in args:
        for v in a:
            c = getattr(v, "context", None)
            if c is not None and hasattr(v, "_mpf_"):
                return c
    raise TypeError(
        f"{op}: no mpmath number among the arguments, so there is no working precision; "
        "convert the data first with reference.jordan.to_ctx(ctx, values)"
    )


def _vectors(op, names, *args):
    """Validate arguments: returns (ctx, [lists of mpf of ctx]).

    ctx = the context of the first argument's first entry (else of the first mpf found).
    Non-finite entries raise ReferenceDomainError(op) here, once."""
    seqs = []
    for name, a in zip(names, args):
        if isinstance(a, (str, bytes)) or not hasattr(a, "__len__"):
            raise TypeError(
                f"{op}: argument '{name}' must be a sequence of k >= 1 real numbers (a cone "
                f"vector), got {type(a).__name__}"
            )
        if len(a) < 1:
            raise ValueError(f"{op}: argument '{name}' is empty; cone vectors have k >= 1")
        seqs.append(a)
    if len({len(a) for a in seqs}) > 1:
        raise ValueError(
            f"{op}: arguments have different cone dimensions "
            + ", ".join(f"{n}: k={len(a)}" for n, a in zip(names, seqs))
        )
    first = seqs[0][0]
    ctx = first.context if hasattr(first, "_mpf_") and hasattr(first, "context") else None
    if ctx is None:
        ctx = _find_ctx(op, seqs)
    out = []
    for name, a in zip(names, seqs):
        mpf_t = ctx.mpf
        vec = []
        for i, v in enumerate(a):
            if type(v) is mpf_t and v._mpf_ not in _NONFINITE:
                vec.append(v)
            else:
                vec.append(_scalar(ctx, v, op, f"argument '{name}' entry {i}"))
        out.append(vec)
    return ctx, out


# --------------------------------------------------------------------------------------------
# internal kernels (validated lists of mpf of ctx)
# --------------------------------------------------------------------------------------------


def _norm(ctx, xb):
    """‖x̄‖: exact sum of exact squares, one rounding, then a correctly rounded sqrt."""
    if not xb:
        return ctx.zero
    if len(xb) == 1:
        return abs(xb[0])
    return ctx.sqrt(ctx.fsum(xb, squared=True))


def _lams(ctx, x):
    n = _norm(ctx, x[1:])
    return x[0] + n, x[0] - n, n


def _reflect(x):
    return [x[0]] + [-v for v in x[1:]]


def _product(ctx, x, y):
    x0, y0 = x[0], y[0]
    head = ctx.fdot(x, y)
    # one rounding per entry; the two terms enter symmetrically, so x∘y = y∘x bit for bit
    return [head] + [ctx.fdot(((x0, b), (y0, a))) for a, b in zip(x[1:], y[1:])]


def _quad(ctx, x, y):
    """Q_x y = 2(xᵀy) x - det(x) R y, without forming Q_x."""
    l1, l2, _ = _lams(ctx, x)
    d = l1 * l2
    s2 = 2 * ctx.fdot(x, y)
    out = [ctx.fdot(((s2, x[0]), (-d, y[0])))]
    out += [ctx.fdot(((s2, a), (d, b))) for a, b in zip(x[1:], y[1:])]
    return out


def _inverse(ctx, x, op):
    l1, l2, _ = _lams(ctx, x)
    d = l1 * l2
    if not d:
        raise ReferenceDomainError(
            op,
            f"det x = 0 (λ1 = {ctx.nstr(l1, 8)}, λ2 = {ctx.nstr(l2, 8)}): x lies on the "
            "boundary of L or of -L, where x⁻¹ does not exist",
            value=d,
        )
    if len(x) == 1:
        return [1 / x[0]]
    return [x[0] / d] + [-v / d for v in x[1:]]


def _sqrt_parts(ctx, x, op):
    l1, l2, _ = _lams(ctx, x)
    if l2 < 0:
        raise ReferenceDomainError(
            op,
            f"x is outside the cone (λ2 = {ctx.nstr(l2, 8)} < 0); the square root exists "
            "only on L",
            value=l2,
        )
    return ctx.sqrt(l1), ctx.sqrt(l2)


def _sqrt_closed(ctx, x, r1, r2):
    # √x = √λ1 c1 + √λ2 c2 = ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)), since (√λ1-√λ2)/(2‖x̄‖) =
    # (λ1-λ2)/(2‖x̄‖(√λ1+√λ2)) = 1/(√λ1+√λ2): no subtraction, no division by ‖x̄‖.
    t = r1 + r2
    if not t:  # x = 0 (the only point of L with λ1 = 0)
        return [ctx.zero] * len(x)
    return [t / 2] + [v / t for v in x[1:]]


def _require_interior(ctx, op, name, l2):
    if not l2 > 0:
        raise ReferenceDomainError(
            op,
            f"argument '{name}' is not strictly inside the cone (λ2 = {ctx.nstr(l2, 8)} <= 0); "
            f"{op} needs an interior point",
            value=l2,
        )


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------


def identity(ctx, k):
    """Identity element ``e = (1 ; 0, …, 0)`` of the Jordan algebra of ``L^k``, in ``ctx``.

    Parameters
    ----------
    ctx : mpmath context
        Context of the result (this is the only function that takes the context explicitly).
    k : int
        Cone dimension, ``k >= 1``.

    Returns
    -------
    list of mpf, length ``k``.
    """
    if isinstance(k, bool) or not isinstance(k, numbers.Integral) or int(k) < 1:
        raise ValueError(f"identity: cone dimension k must be an integer >= 1, got {k!r}")
    return [ctx.mpf(1)] + [ctx.mpf(0)] * (int(k) - 1)


def product(x, y):
    """Jordan product ``x∘y = (xᵀy ; x0 ȳ + y0 x̄)`` (``x0 y0`` for ``k = 1``).

    Any finite vectors.  Each entry is a dot product evaluated by ``ctx.fdot`` (exact products,
    exact sum, one rounding to ``ctx.prec``), so every entry is correctly rounded and the product
    is commutative bit for bit.

    Returns
    -------
    list of mpf, length ``k``, in the context of ``x``.

    Raises
    ------
    ReferenceDomainError
        ``operation="product"`` for non-finite input.
    """
    ctx, (x, y) = _vectors("product", ("x", "y"), x, y)
    return _product(ctx, x, y)


def arrow(x):
    """Arrow matrix ``Arw(x) = [[x0, x̄ᵀ], [x̄, x0 I]]`` as a list of ``k`` rows (exact).

    ``Arw(x) y = x∘y``; eigenvalues ``λ1, λ2`` and ``x0`` (multiplicity ``k - 2``).  Tests and
    diagnostics only.

    Raises
    ------
    ReferenceDomainError
        ``operation="arrow"`` for non-finite input.
    """
    ctx, (x,) = _vectors("arrow", ("x",), x)
    k = len(x)
    rows = [list(x)]
    for i in range(1, k):
        row = [ctx.zero] * k
        row[0] = x[i]
        row[i] = x[0]
        rows.append(row)
    return rows


def reflect(x):
    """Reflection ``R x = (x0 ; -x̄)`` with ``R = diag(1, -I)`` (exact).

    Raises
    ------
    ReferenceDomainError
        ``operation="reflect"`` for non-finite input.
    """
    _, (x,) = _vectors("reflect", ("x",), x)
    return _reflect(x)


def dot(x, y):
    """Euclidean inner product ``xᵀy`` by ``ctx.fdot`` (correctly rounded to ``ctx.prec``).

    Raises
    ------
    ReferenceDomainError
        ``operation="dot"`` for non-finite input.
    """
    ctx, (x, y) = _vectors("dot", ("x", "y"), x, y)
    return ctx.fdot(x, y)


def bar_norm(x):
    """``‖x̄‖`` (``0`` for ``k = 1``): exact sum of exact squares, one rounding, then sqrt.

    Relative error ``<= 1.5·ctx.eps``.  No scaling is needed: mpmath exponents do not overflow.

    Raises
    ------
    ReferenceDomainError
        ``operation="bar_norm"`` for non-finite input.
    """
    ctx, (x,) = _vectors("bar_norm", ("x",), x)
    return _norm(ctx, x[1:])


def trace(x):
    """``trace x = λ1 + λ2 = 2 x0`` (exact).

    Raises
    ------
    ReferenceDomainError
        ``operation="trace"`` for non-finite input.
    """
    _, (x,) = _vectors("trace", ("x",), x)
    return 2 * x[0]


def spectral_values(x):
    """Spectral values ``(λ1, λ2) = (x0 + ‖x̄‖, x0 - ‖x̄‖)``, ``λ1 >= λ2``.

    ``x ∈ L`` iff ``λ2 >= 0``, ``x ∈ int L`` iff ``λ2 > 0``.  Absolute error
    ``O(ctx.eps·(|x0| + ‖x̄‖))``; so ``λ2`` has relative error ``O(ctx.eps·λ1/λ2)``, its
    condition number.  For ``k = 1``: ``λ1 = λ2 = x0``.

    Returns
    -------
    (mpf, mpf)

    Raises
    ------
    ReferenceDomainError
        ``operation="spectral_values"`` for non-finite input.
    """
    ctx, (x,) = _vectors("spectral_values", ("x",), x)
    l1, l2, _ = _lams(ctx, x)
    return l1, l2


def spectral_frames(x):
    """Jordan frame ``c1,2 = ½(1 ; ±x̄/‖x̄‖)``, so that ``x = λ1 c1 + λ2 c2``.

    For ``x̄ = 0`` the frame is not unique; the frame along the first axis,
    ``c1,2 = ½(1 ; ±1, 0, …, 0)``, is returned (the decomposition still holds because then
    ``λ1 = λ2``).  For ``k = 1`` both frames are ``[½]``.

    Returns
    -------
    (list of mpf, list of mpf)

    Raises
    ------
    ReferenceDomainError
        ``operation="spectral_frames"`` for non-finite input.
    """
    ctx, (x,) = _vectors("spectral_frames", ("x",), x)
    half = ctx.mpf(1) / 2
    if len(x) == 1:
        return [half], [half]
    n = _norm(ctx, x[1:])
    if n:
        u = [v / n for v in x[1:]]
    else:
        u = [ctx.mpf(1)] + [ctx.zero] * (len(x) - 2)
    return [half] + [v / 2 for v in u], [half] + [-v / 2 for v in u]


def det(x):
    """``det x = λ1 λ2``, computed as ``(x0 - ‖x̄‖)(x0 + ‖x̄‖)`` (``x0²`` for ``k = 1``).

    Never as ``x0² - ‖x̄‖²``: the factored form inherits only the error of ``λ2`` (relative
    ``O(ctx.eps·λ1/λ2)``, absolute ``O(ctx.eps·λ1²)``).  Any finite ``x``; ``det < 0`` outside
    ``L ∪ -L``.

    Raises
    ------
    ReferenceDomainError
        ``operation="det"`` for non-finite input.
    """
    ctx, (x,) = _vectors("det", ("x",), x)
    l1, l2, _ = _lams(ctx, x)
    return l1 * l2


def inverse(x):
    """Jordan inverse ``x⁻¹ = R x / det x`` (``1/x0`` for ``k = 1``), so that ``x∘x⁻¹ = e``.

    Defined whenever ``det x ≠ 0`` (inside ``int L``, inside ``-int L``, or outside
    ``L ∪ -L``).  Relative error ``O(ctx.eps·λ1/|λ2|)``, inherited from ``det``.

    Raises
    ------
    ReferenceDomainError
        ``operation="inverse"``, ``value = det x = 0``, when ``x`` is on the boundary of ``L``
        or ``-L``; also for non-finite input.
    """
    ctx, (x,) = _vectors("inverse", ("x",), x)
    return _inverse(ctx, x, "inverse")


def sqrt(x):
    """Jordan square root, the unique ``r ∈ L`` with ``r∘r = x``, for ``x ∈ L`` (``λ2 >= 0``).

    Closed form ``((√λ1 + √λ2)/2 ; x̄/(√λ1 + √λ2))``: no subtraction and no division by
    ``‖x̄‖``, valid on the boundary (``λ2 = 0``), for ``x̄ = 0`` and for ``x = 0``.  Backward
    stable: ``sqrt(x)∘sqrt(x) = x`` up to ``O(k·ctx.eps·λ1)`` whatever ``λ2/λ1`` is.

    Raises
    ------
    ReferenceDomainError
        ``operation="sqrt"``, ``value = λ2``, for ``λ2 < 0``; also for non-finite input.
    """
    ctx, (x,) = _vectors("sqrt", ("x",), x)
    r1, r2 = _sqrt_parts(ctx, x, "sqrt")
    return _sqrt_closed(ctx, x, r1, r2)


def _power_spectral(ctx, x, p, l1, l2, n):
    """λ1^p c1 + λ2^p c2 for λ2 > 0, any real p, with a cancellation-free bar part.

    x^p = ((a + b)/2 ; D x̄), a = λ1^p, b = λ2^p, D = (a - b)/(λ1 - λ2) (divided difference;
    λ1 - λ2 = 2‖x̄‖).  With δ = 2‖x̄‖/λ2 and t = p·log1p(δ) = log(a/b):
      t > 1 : D = a·(1 - e^-t)/(2‖x̄‖), a and b differ by more than a factor e: no cancellation;
      t <= 1: D = b·(e^t - 1)/(λ1 - λ2) = b·p·E(t)·L(δ)/λ2 with E(t) = expm1(t)/t and
              L(δ) = log1p(δ)/δ (both -> 1 as the argument -> 0): no subtraction of close
              numbers and no division by ‖x̄‖, so x̄ -> 0 (down to any exponent) keeps full
              relative accuracy.
    """
    a = l1**p
    b = l2**p
    head = (a + b) / 2
    if not n:  # x̄ = 0: first-axis frame, (a - b)/2 = 0, so the bar part is exactly 0
        return [head] + [ctx.zero] * (len(x) - 1)
    delta = 2 * n / l2
    lg = ctx.log1p(delta)
    t = p * lg
    if t > 1:
        dd = a * -ctx.expm1(-t) / (2 * n)
    else:
        e_t = ctx.expm1(t) / t if t else ctx.mpf(1)
        dd = b * p * e_t * (lg / delta) / l2
    return [head] + [dd * v for v in x[1:]]


def _power_binary(ctx, x, m):
    """x^m for an integer m >= 0 by binary powering (the algebra is power-associative)."""
    result = identity(ctx, len(x))
    base = x
    while m:
        if m & 1:
            result = _product(ctx, result, base)
        m >>= 1
        if m:
            base = _product(ctx, base, base)
    return result


def power(x, p):
    """Real power ``x^p = λ1^p c1 + λ2^p c2``.

    Domain (the exponent ``p`` is converted exactly into the context of ``x``):

    ============================  ===========================  ====================
    exponent ``p``                requirement                  ``value`` on error
    ============================  ===========================  ====================
    ``p = 0``                     none; ``x^0 = e``            —
    integer ``p > 0``             none (any finite ``x``)      —
    integer ``p < 0``             ``det x ≠ 0``                ``det x``
    non-integer ``p > 0``         ``λ2 >= 0`` (closed cone)    ``λ2``
    non-integer ``p < 0``         ``λ2 > 0`` (interior)        ``λ2``
    ============================  ===========================  ====================

    Interior points (``λ2 > 0``, any ``p``) use the spectral formula with the divided
    difference ``(λ1^p - λ2^p)/(λ1 - λ2)`` evaluated via ``expm1``/``log1p`` (no cancellation,
    no division by ``‖x̄‖``; ``x̄ = 0`` uses the first-axis frame, giving a zero bar part).
    Boundary points with non-integer ``p > 0`` give ``λ1^p c1``.  Integer powers of
    non-interior points use binary powering by Jordan products (for ``p < 0`` of ``x⁻¹``).
    ``p = 1`` returns a copy, ``p = -1`` is :func:`inverse`, ``p = ½`` is :func:`sqrt`.
    Error: relative ``O(|p|·ctx.eps)`` in the ``c1`` component, ``O(|p|·ctx.eps·λ1/λ2)`` in
    the ``c2`` component.

    Raises
    ------
    ReferenceDomainError
        ``operation="power"`` outside the domain above or for non-finite ``x`` or ``p``.
    """
    ctx, (x,) = _vectors("power", ("x",), x)
    p = _scalar(ctx, p, "power", "exponent p")
    is_int = ctx.isint(p)
    if p == 0:
        return identity(ctx, len(x))
    if p == 1:
        return list(x)
    if p == -1:
        return _inverse(ctx, x, "power")
    if p == ctx.mpf(0.5):
        r1, r2 = _sqrt_parts(ctx, x, "power")
        return _sqrt_closed(ctx, x, r1, r2)
    l1, l2, n = _lams(ctx, x)
    if l2 > 0:
        return _power_spectral(ctx, x, p, l1, l2, n)
    if is_int:
        if p > 0:
            return _power_binary(ctx, x, int(p))
        return _power_binary(ctx, _inverse(ctx, x, "power"), int(-p))
    if p < 0 or l2 < 0:
        need = "λ2 >= 0 (x in L)" if p > 0 else "λ2 > 0 (x in int L)"
        raise ReferenceDomainError(
            "power",
            f"non-integer power p = {ctx.nstr(p, 8)} needs {need}, got λ2 = {ctx.nstr(l2, 8)}",
            value=l2,
        )
    # boundary (λ2 = 0), non-integer p > 0: λ1^p c1 = (a/2 ; (a/λ1) x̄)
    if not l1:
        return [ctx.zero] * len(x)
    a = l1**p
    return [a / 2] + [(a / l1) * v for v in x[1:]]


def quad_apply(x, y):
    """Quadratic representation applied to a vector: ``Q_x y = 2(xᵀy) x - det(x) R y``.

    Never forms ``Q_x``.  Equals ``(2 Arw(x)² - Arw(x²)) y``; for ``k = 1`` it is ``x0² y0``.
    Any finite vectors; absolute error ``O(k·ctx.eps·S(x)²·S(y))`` with
    ``S(x) = |x0| + ‖x̄‖``.

    Raises
    ------
    ReferenceDomainError
        ``operation="quad_apply"`` for non-finite input.
    """
    ctx, (x, y) = _vectors("quad_apply", ("x", "y"), x, y)
    return _quad(ctx, x, y)


def quad_matrix(x):
    """Explicit ``Q_x = 2 x xᵀ - det(x) R`` as a list of ``k`` rows (tests and diagnostics).

    Eigenvalues ``λ1²``, ``λ2²`` and ``λ1 λ2`` (multiplicity ``k - 2``); ``[[x0²]]`` for
    ``k = 1``.

    Raises
    ------
    ReferenceDomainError
        ``operation="quad_matrix"`` for non-finite input.
    """
    ctx, (x,) = _vectors("quad_matrix", ("x",), x)
    l1, l2, _ = _lams(ctx, x)
    d = l1 * l2
    k = len(x)
    rows = []
    for i in range(k):
        xi2 = 2 * x[i]
        row = []
        for j in range(k):
            if i != j:
                row.append(xi2 * x[j])
            else:
                row.append(ctx.fdot(((xi2, x[j]), (-d if i == 0 else d, 1))))
        rows.append(row)
    return rows


def arrow_solve(x, y):
    """Jordan division: the ``d`` with ``x∘d = y`` (``d = Arw(x)⁻¹ y``).

    ``d0 = (x0 y0 - x̄ᵀȳ)/det x``, ``d̄ = (ȳ - d0 x̄)/x0`` (``k = 2`` with ``x0 = 0`` uses the
    equivalent ``d1 = (x0 y1 - x1 y0)/det x``; ``k = 1``: ``y0/x0``).  Forward error
    ``O(k·ctx.eps·(λ1/λ2)·S(y)/λ2)`` for interior ``x`` (the condition number of ``Arw(x)`` is
    ``λ1/λ2``).

    Raises
    ------
    ReferenceDomainError
        ``operation="arrow_solve"`` when ``Arw(x)`` is singular (``det x = 0``, or ``x0 = 0``
        for ``k >= 3``), ``value`` = the vanishing quantity; also for non-finite input.
    """
    ctx, (x, y) = _vectors("arrow_solve", ("x", "y"), x, y)
    x0 = x[0]
    if len(x) == 1:
        if not x0:
            raise ReferenceDomainError("arrow_solve", "x0 = 0: Arw(x) = [x0] is singular",
                                       value=x0)
        return [y[0] / x0]
    l1, l2, _ = _lams(ctx, x)
    d = l1 * l2
    if not d or (not x0 and len(x) > 2):
        bad = d if not d else x0
        raise ReferenceDomainError(
            "arrow_solve",
            f"Arw(x) is singular (x0 = {ctx.nstr(x0, 8)}, λ1 = {ctx.nstr(l1, 8)}, "
            f"λ2 = {ctx.nstr(l2, 8)}): x∘d = y has no unique solution",
            value=bad,
        )
    d0 = ctx.fdot(((x0, y[0]), *((-a, b) for a, b in zip(x[1:], y[1:])))) / d
    if not x0:  # k = 2 only: Cramer's rule for [[x0, x1], [x1, x0]]
        return [d0, ctx.fdot(((x0, y[1]), (-x[1], y[0]))) / d]
    return [d0] + [ctx.fdot(((1, b), (-d0, a))) / x0 for a, b in zip(x[1:], y[1:])]


def cond_quad(x):
    """Spectral condition number of ``Q_x``: ``(λ1/λ2)²`` for ``x ∈ L``.

    ``ctx.inf`` on the boundary (``λ2 = 0``, ``Q_x`` singular, including ``x = 0``); ``1`` for
    ``k = 1`` and ``x0 > 0``.  Relative error ``O(ctx.eps·λ1/λ2)``.

    Raises
    ------
    ReferenceDomainError
        ``operation="cond_quad"``, ``value = λ2``, for ``λ2 < 0``; also for non-finite input.
    """
    ctx, (x,) = _vectors("cond_quad", ("x",), x)
    l1, l2, _ = _lams(ctx, x)
    if l2 < 0:
        raise ReferenceDomainError(
            "cond_quad", f"x is outside the cone (λ2 = {ctx.nstr(l2, 8)} < 0)", value=l2
        )
    if not l2:
        return ctx.inf
    r = l1 / l2
    return r * r


class NTScaling(NamedTuple):
    """Nesterov–Todd scaling of an interior pair (see :func:`nt_scaling`); unpacks as
    ``p, p_inv, lam = nt_scaling(z, s)``."""

    p: list
    p_inv: list
    lam: list


def nt_scaling(z, s):
    """Nesterov–Todd point ``p`` of an interior pair: ``Q_p z = Q_{p⁻¹} s = lam``.

    CVXOPT-style construction, all quantities unit-determinant except the scalar factors:
    ``z̄ = z/√det z``, ``s̄ = s/√det s``; ``γ = √((1 + z̄ᵀs̄)/2)`` (``>= 1``);
    ``w̄ = (s̄ + R z̄)/(2γ)`` (``det w̄ = 1``, ``w̄0 >= 1``); ``v = (w̄ + e)/√(2(w̄0 + 1))``
    (``= w̄^{1/2}``, ``det v = 1``); ``β = (det s/det z)^{1/4}``; ``p = √β v`` and, because
    ``det v = 1``, ``p⁻¹ = R v/√β``.  Then ``Q_{p²} z = s`` (``p²`` is the NT scaling point
    ``w`` with ``Q_w z = s``).  The scaled point comes from the closed form
    ``lam = (det z det s)^{1/4} (γ ; ((γ + z̄0) s̄₁ + (γ + s̄0) z̄₁)/(2γ + z̄0 + s̄0))``
    (``₁`` = bar part), whose denominators are ``>= 4`` and whose head has no subtraction.
    ``√det`` is taken as ``√λ1·√λ2``.  For ``k = 1``: ``p = (s/z)^{1/4}``,
    ``p⁻¹ = (z/s)^{1/4}``, ``lam = √(z s)``.

    Parameters
    ----------
    z, s : sequences of length k
        Strictly interior points (``λ2 > 0``).

    Returns
    -------
    NTScaling
        ``(p, p_inv, lam)``, lists of mpf in the context of ``z``.

    Raises
    ------
    ReferenceDomainError
        ``operation="nt_scaling"``, ``value = λ2``, when ``z`` (checked first) or ``s`` has
        ``λ2 <= 0``; the message names the argument.  Also for non-finite input.
    """
    ctx, (z, s) = _vectors("nt_scaling", ("z", "s"), z, s)
    l1z, l2z, _ = _lams(ctx, z)
    _require_interior(ctx, "nt_scaling", "z", l2z)
    l1s, l2s, _ = _lams(ctx, s)
    _require_interior(ctx, "nt_scaling", "s", l2s)
    if len(z) == 1:
        q = ctx.sqrt(ctx.sqrt(s[0] / z[0]))
        return NTScaling([q], [1 / q], [ctx.sqrt(z[0] * s[0])])
    rz = ctx.sqrt(l1z) * ctx.sqrt(l2z)  # √det z
    rs = ctx.sqrt(l1s) * ctx.sqrt(l2s)  # √det s
    zb = [v / rz for v in z]
    sb = [v / rs for v in s]
    g = ctx.sqrt((1 + ctx.fdot(zb, sb)) / 2)
    g2 = 2 * g
    wb = [(sb[0] + zb[0]) / g2] + [(a - b) / g2 for a, b in zip(sb[1:], zb[1:])]
    c = ctx.sqrt(2 * (wb[0] + 1))
    v = [(wb[0] + 1) / c] + [a / c for a in wb[1:]]
    q = ctx.sqrt(ctx.sqrt(rs / rz))  # √β = (det s/det z)^{1/8}
    p = [q * a for a in v]
    p_inv = [v[0] / q] + [-a / q for a in v[1:]]
    m = ctx.sqrt(rs * rz)  # (det z det s)^{1/4}
    den = g2 + zb[0] + sb[0]
    cs = (g + zb[0]) / den
    cz = (g + sb[0]) / den
    lam = [m * g] + [m * ctx.fdot(((cs, a), (cz, b))) for a, b in zip(sb[1:], zb[1:])]
    return NTScaling(p, p_inv, lam)


def step_to_boundary(x, dx):
    """Largest ``α >= 0`` with ``x + α dx ∈ L``, for interior ``x``; ``ctx.inf`` if never.

    With ``y = Q_{x^{-1/2}} dx``: ``x + α dx = Q_{x^{1/2}}(e + α y)`` and ``Q_{x^{1/2}}`` maps
    ``L`` onto ``L``, so ``x + α dx ∈ L`` iff ``λ2(e + α y) = 1 + α λ2(y) >= 0``.  Hence
    ``α = -1/λ2(y)`` if ``λ2(y) < 0``, else ``ctx.inf`` (``dx ∈ L``).  ``x^{-1/2}`` is
    ``R x^{1/2}/√det x`` with the closed-form square root.  No quadratic-equation root, no
    cancellation beyond that of ``λ2(y)`` itself.  Relative error
    ``O(k·ctx.eps·(λ1/λ2 + α S(dx)/λ2(x)))``.

    Raises
    ------
    ReferenceDomainError
        ``operation="step_to_boundary"``, ``value = λ2(x)``, for ``λ2(x) <= 0``; also for
        non-finite input.
    """
    ctx, (x, dx) = _vectors("step_to_boundary", ("x", "dx"), x, dx)
    l1, l2, _ = _lams(ctx, x)
    _require_interior(ctx, "step_to_boundary", "x", l2)
    r1, r2 = ctx.sqrt(l1), ctx.sqrt(l2)
    half = _sqrt_closed(ctx, x, r1, r2)
    rdet = r1 * r2
    w = [half[0] / rdet] + [-v / rdet for v in half[1:]]  # x^{-1/2}
    y = _quad(ctx, w, dx)
    _, ly2, _ = _lams(ctx, y)
    if ly2 < 0:
        return -1 / ly2
    return ctx.inf
