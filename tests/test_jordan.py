"""Property-based tests of :mod:`rfverify.jordan` (DESIGN.md §3), in float64 and longdouble.

How the tolerances are built
----------------------------
``u = np.finfo(dtype).eps`` of the dtype under test; ``k`` the cone dimension; for a vector ``x``
``S(x) = |x0| + ‖x̄‖ = max |λi(x)|`` is its scale and, for ``x ∈ int L``, ``κ(x) = λ1/λ2`` its
conditioning (``cond(Q_x) = κ²``).  Every bound has the form ``C · (k+2)^j · u · (conditioning) ·
(scale)`` and the docstring of each test states it and gives the forward-error argument.  The
basic facts used throughout:

* ``‖x̄‖`` (hypot-style) has relative error ``≤ (k/2+2)u``, so ``λ1`` has relative error ``O(k u)``
  and ``λ2 = x0 - ‖x̄‖`` absolute error ``O(k u S)``, i.e. relative error ``O(k u κ)`` — ``κ`` is
  the condition number of ``λ2`` itself, so this is what a backward-stable code delivers.
* a sum of ``k`` products of entries bounded by ``a`` and ``b`` has error ``≤ k u a b``.
* results below the subnormal range underflow: ``check`` adds an absolute floor of 16 subnormal
  quanta of the dtype; reference sides that could underflow in float64 are evaluated in
  longdouble.

The constants ``C`` are small (1–8).  They were calibrated against the observed error ratios:
in instrumented runs (~2 700 examples per test) the worst ratio error/bound of any check was
0.17, typically 0.02–0.1; 40 further random seeds and one 1500-examples-per-test run passed.

Checking arithmetic is done in longdouble (for float64 runs it is then exact for our purposes;
for longdouble runs it adds O(u) noise, covered by C) or in mpmath where an oracle is needed, and
longdouble runs must reach longdouble accuracy: the inputs carry bits below float64 precision
(``_cast`` jitters them at the 2^-60 level), the bounds use ``eps(longdouble)`` and
``test_longdouble_is_really_extended`` asserts errors far below ``eps(float64)``.

The input generators are bounded in conditioning (``λ2/λ1 >= 1e-6`` by default) so that the
bounds mean something; the known-hard cases (``λ2 → 0`` at relative distance 1e-12 and ``eps``,
``λ2 ~ 1e-300``, ``x̄ = 0``, scales 1e±150, subnormal ``x̄``) are pinned with ``@example``.
"""

from __future__ import annotations

import math

import mpmath
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from rfverify import jordan as J
from rfverify.errors import ConeDomainError

LD = np.longdouble
DTYPES = [np.float64, np.longdouble]
DTYPE_IDS = ["float64", "longdouble"]
KS_ALL = (1, 2, 3, 5)
KS_FRAME = (2, 3, 5)

dtypes = pytest.mark.parametrize("dtype", DTYPES, ids=DTYPE_IDS)


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------


def eps(dtype) -> float:
    return float(np.finfo(dtype).eps)


def L(a):
    """Checking arithmetic in longdouble (exact conversion from float64)."""
    return np.asarray(a, dtype=LD)


def _cast(a, dtype):
    """float64 test data → dtype.  For longdouble, jitter every entry at the 2^-60 level so the
    inputs have bits below float64 precision (a silent float64 computation then shows up).
    The head is only ever enlarged and |x̄_i| by at most the same factor, so λ2 can only grow:
    interior points stay interior."""
    a = np.asarray(a, dtype=np.float64)
    if dtype is np.float64:
        return a.copy()
    x = a.astype(LD)
    h = (np.arange(x.size).reshape(x.shape) * 7919 % 997) / LD(997)
    jit = np.ldexp(LD(1), -60)
    x[..., 0] *= 1 + jit * (1 + h[..., 0])
    x[..., 1:] *= 1 + jit * (2 * h[..., 1:] - 1)
    return x


def ref_lams(x):
    """(λ1, λ2) computed independently in longdouble (plain sqrt of the sum of squares, which
    cannot overflow or underflow in longdouble for float64-range data)."""
    x = L(x)
    n = np.sqrt(np.sum(x[..., 1:] ** 2, axis=-1))
    return x[..., 0] + n, x[..., 0] - n


def ref_det(x):
    """det via ref_lams, in longdouble (no under/overflow for float64-range data)."""
    l1, l2 = ref_lams(x)
    return l1 * l2


def scale(x):
    """S(x) = |x0| + ‖x̄‖ = max|λi|."""
    x = L(x)
    return np.abs(x[..., 0]) + np.sqrt(np.sum(x[..., 1:] ** 2, axis=-1))


def kappa(x):
    """λ1/λ2 (inf on the boundary: only a few pinned examples get there)."""
    l1, l2 = ref_lams(x)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(l2 > 0, l1 / np.where(l2 > 0, l2, 1), LD(np.inf))


def maxabs(a, axis=-1):
    return np.max(np.abs(L(a)), axis=axis)


def check(dtype, err, bound, what):
    """Assert err <= bound + floor elementwise (in longdouble); report the worst ratio.

    floor = 16 × the smallest subnormal of the dtype under test: results whose true value is
    below the subnormal range underflow (gradually) and that absolute error is not covered by
    relative bounds (e.g. Q_x y = x0²y0 ~ 5e-451 for x0 ~ 1e-150 in float64)."""
    err = L(err)
    bound = L(bound) + 16 * LD(np.finfo(dtype).smallest_subnormal)
    assert np.all(np.isfinite(err)), f"{what}: non-finite error {err}"
    ok = err <= bound
    if not np.all(ok):
        ratio = np.max(err / np.where(bound > 0, bound, LD(np.finfo(LD).tiny)))
        pytest.fail(f"{what}: error {err} exceeds bound {bound} (worst ratio {float(ratio):.3g})")


def ref_quad_matrix(x):
    """Q_x = 2Arw(x)² - Arw(x²) in the dtype of x (arrow-form, independent of quad_matrix)."""
    a = J.arrow(x)
    a2 = J.arrow(J.jordan_product(x, x))
    return 2 * np.matmul(a, a) - a2


# ---- mpmath oracles (independent high-precision evaluation on the exact input values) ------

MP_PREC = 240  # bits: exact for products of float64/longdouble inputs, ample for sqrt


@pytest.fixture(autouse=True)
def _mp_precision():
    """Run every test of this module with a high mpmath precision, restored afterwards."""
    with mpmath.workprec(MP_PREC):
        yield


def to_mp(a):
    a = np.asarray(a)
    flat = []
    for v in a.reshape(-1):
        num, den = (LD(v) if a.dtype == LD else float(v)).as_integer_ratio()
        flat.append(mpmath.mpf(num) / den)
    return np.array(flat, dtype=object).reshape(a.shape)


def mp_norm_bar(xm):
    return mpmath.sqrt(mpmath.fsum(v * v for v in xm[1:]))


def mp_lams(xm):
    n = mp_norm_bar(xm)
    return xm[0] + n, xm[0] - n


def mp_product(xm, ym):
    head = mpmath.fsum(a * b for a, b in zip(xm, ym))
    return np.array([head] + [xm[0] * b + ym[0] * a for a, b in zip(xm[1:], ym[1:])], dtype=object)


def mp_quad(xm, ym):
    l1, l2 = mp_lams(xm)
    d = mpmath.fsum(a * b for a, b in zip(xm, ym))
    ry = np.array([ym[0]] + [-v for v in ym[1:]], dtype=object)
    return np.array([2 * d * a - l1 * l2 * b for a, b in zip(xm, ry)], dtype=object)


def mp_maxabs_diff(am, bm):
    return max(abs(a - b) for a, b in zip(am, bm))


# ------------------------------------------------------------------------------------------
# strategies (all produce float64 arrays; tests cast them to the dtype under test)
# ------------------------------------------------------------------------------------------


def _build_interior(k, log_s, log_rho, dirs):
    lam1 = 10.0 ** log_s
    lam2 = lam1 * 10.0 ** log_rho
    x = np.zeros((len(log_s), k))
    x[:, 0] = (lam1 + lam2) / 2
    if k > 1:
        m = np.max(np.abs(dirs), axis=1)
        safe = np.where(m > 0, m, 1.0)
        r = dirs / safe[:, None]
        nr = np.sqrt(np.sum(r * r, axis=1))
        unit = r / np.where(nr > 0, nr, 1.0)[:, None]
        x[:, 1:] = ((lam1 - lam2) / 2)[:, None] * unit
    return x


def interior_arrays(k, n, log_rho=(-6.0, 0.0), log_scale=(-3.0, 3.0)):
    """n points of int L^k with λ1 = 10^s, λ2/λ1 = 10^r (r in log_rho), random direction
    (an all-zero direction gives x̄ = 0)."""
    return st.tuples(
        arrays(np.float64, n, elements=st.floats(*log_scale)),
        arrays(np.float64, n, elements=st.floats(*log_rho)),
        arrays(np.float64, (n, k - 1), elements=st.floats(-1.0, 1.0)),
    ).map(lambda t: _build_interior(k, *t))


def general_arrays(k, n, log_scale=(-3.0, 3.0)):
    """n arbitrary vectors (inside, outside or on the boundary of the cone)."""
    return st.tuples(
        arrays(np.float64, n, elements=st.floats(*log_scale)),
        arrays(np.float64, (n, k), elements=st.floats(-1.0, 1.0)),
    ).map(lambda t: t[1] * (10.0 ** t[0])[:, None])


@st.composite
def cases(draw, kinds, ks=KS_ALL, log_rho=(-6.0, 0.0), log_scale=(-3.0, 3.0), n_max=4):
    """A tuple of arrays of common (n, k): kind "i" = interior, "g" = general."""
    k = draw(st.sampled_from(ks))
    n = draw(st.integers(1, n_max))
    out = []
    for kind in kinds:
        if kind == "i":
            out.append(draw(interior_arrays(k, n, log_rho, log_scale)))
        else:
            out.append(draw(general_arrays(k, n, log_scale)))
    return tuple(out)


# ---- pinned hard cases (float64 values; in longdouble runs they are cast + jittered) ------

A = np.array
NEAR12 = A([[1.0, 1.0 - 1e-12, 0.0], [1.0, 0.0, -(1.0 - 1e-12)]])  # λ2/λ1 ≈ 5e-13
NEAR12_K5 = A([[2.0, 1.2 * (1 - 1e-12), 0.0, -1.6 * (1 - 1e-12), 0.0]])
NEAREPS = A([[1.0 + 2.0**-52, 1.0], [1.5 + 2.0**-52, -1.5]])  # λ2 = ulp: closest to ∂L
ABS300 = A([[1e-300, 5e-301, 0.0], [2e-300, 0.0, 1.999999e-300]])  # λ2 ~ 1e-300 absolute
NEAR12_TINY = A([[1e-300, 1e-300 * (1 - 1e-12), 0.0]])
XBAR0 = A([[2.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
XBAR0_K2 = A([[1.5, 0.0]])
K1 = A([[0.7], [3.0], [1e-150]])
HUGE = A([[1e150, 3e149, 4e149], [2e150, 0.0, 1.99e150]])
TINY = HUGE * 1e-300
SUBN = A([[1.0, 1e-310, 0.0], [2.0, 5e-324, -5e-324]])  # subnormal x̄
SUBN_TINY = A([[1e-300, 1e-310, 2e-310]])
MIX5 = A([[3.0, 0.5, -1.0, 0.25, 2.0], [1.0, 0.0, 0.0, 0.0, 0.0]])


def other(x, seed=0):
    """A well-separated interior partner of the same shape (for pair examples)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.zeros_like(x)
    y[:, 0] = 1.0 + 0.25 * seed
    if x.shape[1] > 1:
        y[:, 1] = 0.5
    return y * np.max(np.abs(x), axis=1, keepdims=True)


def gen_partner(x):
    """An arbitrary (non-cone) partner vector of the same shape and scale."""
    x = np.asarray(x, dtype=np.float64)
    y = np.ones_like(x) * np.max(np.abs(x), axis=1, keepdims=True)
    y[:, 0] *= -0.5
    return y


# ------------------------------------------------------------------------------------------
# algebraic identities
# ------------------------------------------------------------------------------------------


@dtypes
@given(case=cases("gg"))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, gen_partner(K1)))
def test_product_is_commutative(dtype, case):
    """x∘y = y∘x exactly: the implementation forms the same products in the same order for
    both argument orders, and IEEE + and × are commutative, so the bound is 0."""
    x, y = (_cast(a, dtype) for a in case)
    a = J.jordan_product(x, y)
    b = J.jordan_product(y, x)
    assert a.dtype == dtype
    assert np.array_equal(a, b)


@dtypes
@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(K1,))
def test_identity_is_neutral(dtype, case):
    """x∘e = x exactly: x0·1 + Σ x̄_i·0 = x0 and x0·0 + 1·x̄ = x̄ are exact, and the only other
    operation, the power-of-two rescaling of extreme inputs, is exact too.  Bound 0."""
    (x,) = (_cast(a, dtype) for a in case)
    e = J.identity(x.shape[1], x.shape[0], dtype)
    assert np.array_equal(J.jordan_product(x, e), x)
    assert np.array_equal(J.jordan_product(e, x), x)
    assert np.array_equal(J.quad_apply(e, x), x)  # Q_e = I exactly as well


@dtypes
@given(case=cases("ig"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, TINY))
@example(case=(TINY, HUGE))
@example(case=(XBAR0, gen_partner(XBAR0)))
@example(case=(K1, gen_partner(K1)))
def test_arrow_solve(dtype, case):
    """d = x \\ y solves x∘d = y with ‖x∘d − y‖∞ ≤ 8(k+2)·u·κ²·S(y) (+ underflow floor).

    Arw(x) has eigenvalues λ1, x0, λ2, so ‖Arw(x)⁻¹‖ = 1/λ2 and ‖d‖ ≲ S(y)/λ2; d0 carries the
    relative error O(k u κ) of det x, and multiplying back by Arw(x) (norm ≈ λ1) gives
    k u κ · λ1 · S(y)/λ2 = k u κ² S(y).  Also x \\ (x∘y) = y for the same reason, and
    x \\ e = x⁻¹ (the inverse is the solution of x∘d = e).
    """
    x, y = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    kap = kappa(x)
    d = J.arrow_solve(x, y)
    assert d.dtype == dtype
    # d may underflow into the subnormal range (absolute error ≤ one subnormal spacing), which
    # multiplying back by x magnifies by S(x).
    floor = 4 * scale(x) * np.finfo(dtype).smallest_subnormal
    check(dtype, maxabs(L(J.jordan_product(x, d)) - L(y)), 8 * (k + 2) * u * kap**2 * scale(y) + floor,
          "x∘d - y")
    e = J.identity(k, x.shape[0], dtype)
    check(dtype, maxabs(L(J.arrow_solve(x, e)) - L(J.inverse(x))),
          8 * (k + 2) * u * kap * scale(J.inverse(x)), "x \\ e - x⁻¹")


def test_arrow_solve_domain():
    x = np.array([[2.0, 0.5, 0.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])  # cone 1: det = 0
    y = np.ones((3, 3))
    with pytest.raises(ConeDomainError) as ei:
        J.arrow_solve(x, y)
    assert ei.value.operation == "arrow_solve" and ei.value.cone == 1


@dtypes
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(NEAR12_K5,))
@example(case=(NEAREPS,))
@example(case=(ABS300,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(SUBN_TINY,))
@example(case=(XBAR0,))
@example(case=(K1,))
def test_inverse(dtype, case):
    """x∘x⁻¹ = e (and x⁻¹∘x = e) with ‖x∘x⁻¹ - e‖∞ ≤ 4(k+2)·u·κ.

    x⁻¹ = R x/(λ1λ2) inherits the relative error O(k u κ) of λ2 as a common factor; the head
    of x∘x⁻¹ = (x0² - ‖x̄‖²)/det is a k-term dot product with terms ≤ λ1²/det = κ, so it adds
    k u κ; the bar part x0(-x̄)/det + (x0/det)x̄ cancels up to u κ.
    Also: x⁻¹ is interior and (x⁻¹)⁻¹ = x up to 4(k+2)·u·κ·S(x).
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    kap = kappa(x)
    xi = J.inverse(x)
    assert xi.dtype == dtype
    e = J.identity(k, x.shape[0], dtype)
    check(dtype, maxabs(J.jordan_product(x, xi) - e), 4 * (k + 2) * u * kap, "x∘x⁻¹ - e")
    check(dtype, maxabs(J.jordan_product(xi, x) - e), 4 * (k + 2) * u * kap, "x⁻¹∘x - e")
    assert np.all(J.spectral_values(xi)[1] > 0)
    check(dtype, maxabs(L(J.inverse(xi)) - L(x)), 4 * (k + 2) * u * kap * scale(x), "(x⁻¹)⁻¹ - x")


@dtypes
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(ABS300,))
@example(case=(NEAR12_TINY,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
@example(case=(A([[1.0, 1.0, 0.0], [2.0, 0.0, -2.0], [0.0, 0.0, 0.0]]),))  # boundary and x = 0
def test_sqrt_squared(dtype, case):
    """(x^{1/2})² = x with ‖·‖∞ error ≤ 4(k+2)·u·S(x), independent of κ; x^{1/2} ∈ L.

    Backward stability of the closed form ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)): an error δ in √λ2 is
    an error in the c2-coefficient only, and squaring maps it to 2√λ2·δ = O(k u λ1) because
    δ = Δλ2/(2√λ2) with Δλ2 = O(k u λ1); the rest is O(k u) relative rounding of O(S) terms.
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    r = J.sqrt(x)
    assert r.dtype == dtype
    assert np.all(J.spectral_values(r)[1] >= 0)
    check(dtype, maxabs(L(J.jordan_product(r, r)) - L(x)), 4 * (k + 2) * u * scale(x), "(√x)² - x")
    assert np.array_equal(J.power(x, 0.5), r)


@dtypes
@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(K1,))
def test_quad_of_identity_is_square(dtype, case):
    """Q_x e = x∘x with ‖·‖∞ ≤ 4(k+2)·u·S(x)², for any x.

    Q_x e = (2x0² - λ1λ2 ; 2x0x̄) and x∘x = (‖x‖² ; 2x0x̄): the bar parts are the same exact
    products; the heads differ by the rounding of k squares and of λ1λ2, whose absolute error
    is λ1·Δλ2 + λ2·Δλ1 = O(k u S²) (the absolute error of λ2 is O(k u S)).
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    e = J.identity(k, x.shape[0], dtype)
    err = maxabs(L(J.quad_apply(x, e)) - L(J.jordan_product(x, x)))
    check(dtype, err, 4 * (k + 2) * u * scale(x) ** 2, "Q_x e - x²")


@dtypes
@given(case=cases("gg"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, TINY))
@example(case=(TINY, HUGE))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, gen_partner(K1)))
def test_quad_equals_arrow_form(dtype, case):
    """Q_x y = (2Arw(x)² - Arw(x²)) y with ‖·‖∞ ≤ 4(k+2)²·u·S(x)²·S(y).

    Also quad_matrix(x) equals that matrix entrywise to (k+2)²·u·S(x)² (two k-term rounded
    sums per entry, each ≤ k u S²/2 or so).  The matrix route
    rounds k-term sums of products bounded by S(x)² (then by S(x)²S(y)), the direct route a
    k-term dot product and det(x)·Ry with det error O(k u S(x)²): both are O(k² u S² S(y)).
    """
    x, y = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    assert ref_quad_matrix(x).dtype == dtype
    # Reference side in longdouble: in float64, Arw(x∘x) of x ~ 1e-163 would underflow.
    m = ref_quad_matrix(L(x))
    direct = J.quad_apply(x, y)
    via_matrix = np.einsum("nij,nj->ni", m, L(y))
    bound = 4 * (k + 2) ** 2 * u * scale(x) ** 2 * scale(y)
    check(dtype, maxabs(L(direct) - via_matrix), bound, "Q_x y - (2Arw² - Arw(x²))y")
    qm = J.quad_matrix(x)
    check(dtype, 
        np.max(np.abs(L(qm) - L(m)), axis=(1, 2)),
        (k + 2) ** 2 * u * scale(x) ** 2,
        "quad_matrix - arrow form",
    )


@dtypes
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
def test_quad_of_inverse_is_inverse_of_quad(dtype, case):
    """Q_{x⁻¹} Q_x = I (as matrices) with max-entry error ≤ (k+2)²·u·κ².

    Q̃_x = Q_x + E with |E| = O(k u S²) and Q̃_{x⁻¹} = (1+θ)²Q_{x⁻¹} + E' with θ = O(k u κ)
    (common factor of x⁻¹) and |E'| = O(k u/λ2²); the product is I + 2θI + Q_{x⁻¹}E + E'Q_x,
    and ‖Q_{x⁻¹}‖ = 1/λ2², ‖Q_x‖ = λ1² give O(k² u κ²).  (κ² = cond(Q_x) is the honest
    amplification here; the pinned 1e-12 case therefore only checks finiteness/consistency.)
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    prod = np.matmul(L(J.quad_matrix(J.inverse(x))), L(J.quad_matrix(x)))
    err = np.max(np.abs(prod - np.eye(k, dtype=LD)), axis=(1, 2))
    check(dtype, err, (k + 2) ** 2 * u * kappa(x) ** 2, "Q_{x⁻¹}Q_x - I")


@dtypes
@given(case=cases("i"), t=st.integers(-2, 3))
@example(case=(HUGE * 1e-100,), t=3)
@example(case=(TINY * 1e75,), t=-2)
@example(case=(XBAR0,), t=2)
@example(case=(K1[:2],), t=-2)
@example(case=(K1,), t=3)
@example(case=(NEAR12,), t=2)
def test_quad_of_integer_power(dtype, case, t):
    """Q_{x^t} = (Q_x)^t for integer t ∈ {-2,…,3}.

    t >= 0: (Q_x)^t by repeated matmul; max-entry error ≤ (t+1)(k+2)²·u·S(x)^{2t}.  The
    c1-part of x^t has relative error O(t k u), the c2-part absolute error
    t·λ2^{t-1}·Δλ2 = O(t k u λ1^t) (κ-free for t >= 1); Q of it and the t-1 matmuls add
    O(t k² u S^{2t}).
    t < 0: (Q_x)^t := (Q_x⁻¹)^{|t|} = (Q_{x⁻¹})^{|t|} (identity Q_{x⁻¹} = Q_x⁻¹, tested above),
    max-entry error ≤ (|t|+1)(k+2)²·u·κ·λ2^{-2|t|}: x^t and x⁻¹ carry relative errors
    O(|t| k u κ) in their dominant λ2^t-component.
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    lhs = L(J.quad_matrix(J.power(x, t)))
    base = L(J.quad_matrix(x if t >= 0 else J.inverse(x)))
    rhs = np.broadcast_to(np.eye(k, dtype=LD), base.shape).copy()
    for _ in range(abs(t)):
        rhs = np.matmul(rhs, base)
    err = np.max(np.abs(lhs - rhs), axis=(1, 2))
    if t >= 0:
        bound = (t + 1) * (k + 2) ** 2 * u * scale(x) ** (2 * t)
    else:
        _, l2 = ref_lams(x)
        bound = (-t + 1) * (k + 2) ** 2 * u * kappa(x) * l2 ** (2 * t)
    check(dtype, err, bound, f"Q_(x^{t}) - (Q_x)^{t}")


@dtypes
@given(case=cases("gg"))
@example(case=(NEAR12, NEAR12[:, [0, 2, 1]]))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, gen_partner(K1)))
def test_det_of_quad(dtype, case):
    """det(Q_x y) = det(x)² det(y) with absolute error ≤ 8(k+2)²·u·S(x)⁴·S(y)².

    w = Q_x y has absolute error O(k u S(x)²S(y)), so det(w) = λ1(w)λ2(w) has absolute error
    O(S(w)·k u S(x)²S(y)) ≤ O(k u S(x)⁴S(y)²); on the right det(x)² has relative error
    O(k u κ) and det(x)²·k u κ ≤ k u S(x)⁴/κ·… ≤ k u S(x)⁴, det(y) absolute O(k u S(y)²).
    (Evaluated in longdouble so det(x)² of a 1e150-point does not overflow in the check.)
    """
    x, y = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    lhs = L(J.det(J.quad_apply(x, y)))
    # Reference side in longdouble (det y of y ~ 1e-163 underflows in float64, det(Q_x y)
    # need not).
    dx = ref_det(x)
    rhs = dx * dx * ref_det(y)
    bound = 8 * (k + 2) ** 2 * u * scale(x) ** 4 * scale(y) ** 2
    check(dtype, np.abs(lhs - rhs), bound, "det(Q_x y)")


@dtypes
@given(case=cases("gg"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE * 1e-75, TINY * 1e75))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, gen_partner(K1)))
def test_quad_of_quad(dtype, case):
    """Q_{Q_x y} = Q_x Q_y Q_x (matrices) with max-entry error ≤ 2(k+2)³·u·S(x)⁴·S(y)².

    w = Q_x y has absolute error O(k u S(x)²S(y)) and S(w) ≤ 2S(x)²S(y), so Q_w has error
    O(S(w)·k u S(x)²S(y)); the triple product rounds k-term sums of entries bounded by
    S(x)⁴S(y)², twice.
    """
    x, y = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    lhs = L(J.quad_matrix(J.quad_apply(x, y)))
    # Reference side: arrow-form Q in longdouble (Q_y ~ y² may underflow in float64 while
    # Q_{Q_x y} does not).
    qx = ref_quad_matrix(L(x))
    qy = ref_quad_matrix(L(y))
    rhs = np.matmul(np.matmul(qx, qy), qx)
    err = np.max(np.abs(lhs - rhs), axis=(1, 2))
    bound = 2 * (k + 2) ** 3 * u * scale(x) ** 4 * scale(y) ** 2
    check(dtype, err, bound, "Q_{Q_x y} - Q_xQ_yQ_x")


@dtypes
@given(case=cases("iii", log_rho=(-3.0, 0.0)))
@example(case=(HUGE, TINY, HUGE))
@example(case=(SUBN, XBAR0[:1].repeat(2, 0), SUBN))
@example(case=(K1, K1[::-1], K1))
def test_quad_maps_interior_onto_interior(dtype, case):
    """Q_x (int L) = int L for x ∈ int L.

    Into: λ2(Q_x y) >= λ2(x)²·λ2(y) exactly (y - λ2(y)e ∈ L ⇒ Q_x y ⪰ λ2(y)x², and λ2 is
    superadditive); computed Q_x y has absolute error ≤ 4(k+2)²·u·S(x)²S(y), so we assert
    λ2(Q_x y) >= λ2(x)²λ2(y) - that, and > 0 — with λ2/λ1 >= 1e-3 the lower bound is
    >= 1e-9·S(x)²S(y), far above the rounding term, so interiority is a real check.
    Onto: for interior t the preimage Q_{x⁻¹} t is interior and Q_x(Q_{x⁻¹} t) = t up to
    4(k+2)²·u·κ(x)²·S(t) (Q_{x⁻¹} errors of size k u S(t)/λ2² amplified by ‖Q_x‖ = λ1²).
    """
    x, y, t = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    w = J.quad_apply(x, y)
    _, l2w = J.spectral_values(w)
    _, l2x = ref_lams(x)
    _, l2y = ref_lams(y)
    assert np.all(l2w > 0)
    slack = 4 * (k + 2) ** 2 * u * scale(x) ** 2 * scale(y)
    assert np.all(L(l2w) >= l2x**2 * l2y - slack)
    pre = J.quad_apply(J.inverse(x), t)
    assert np.all(J.spectral_values(pre)[1] > 0)
    back = J.quad_apply(x, pre)
    bound = 4 * (k + 2) ** 2 * u * kappa(x) ** 2 * scale(t)
    check(dtype, maxabs(L(back) - L(t)), bound, "Q_x Q_x⁻¹ t")


@dtypes
@given(case=cases("ii"))
@example(case=(NEAR12, XBAR0[:1].repeat(2, 0)))
@example(case=(NEAR12, NEAR12[:, [0, 2, 1]]))
@example(case=(HUGE, TINY))
@example(case=(TINY, HUGE))
@example(case=(SUBN, other(SUBN)))
@example(case=(XBAR0, XBAR0[::-1]))
@example(case=(K1, K1[::-1]))
@example(case=(ABS300, other(ABS300)))
def test_nt_scaling(dtype, case):
    """NT point: Q_p z = Q_{p⁻¹} s = λ, Arw(Q_p z) = Arw(Q_{p⁻¹} s), p, λ ∈ int L,
    p∘p_inv = e, det p = β = (det s/det z)^{1/4}, det λ = √(det z det s).

    Bound for the vector identities (‖·‖∞):
    2(k+2)²·u·[(κ(z)+κ(s))·S(λ) + S(p)²S(z) + S(p⁻¹)²S(s)].  √det z = √λ1√λ2 and √det s
    carry relative errors O(k u κ), which perturb the common scale √β of p and so Q_p z and
    Q_{p⁻¹}s in opposite directions by O(k u (κ(z)+κ(s))) relative to λ; applying Q_p
    (resp. Q_{p⁻¹}) to z (resp. s) adds O(k u ‖p‖² S(z)) (resp. O(k u ‖p⁻¹‖² S(s))).
    p∘p⁻¹ = e to 8(k+2)·u·κ(p) (as x∘x⁻¹).  The determinant identities are checked in
    relative terms, 2(k+2)·u·(κ(z)+κ(s)+κ(λ)+κ(p)): each det or spectral value involved has
    relative error O(k u κ) of its argument.
    """
    z, s = (_cast(a, dtype) for a in case)
    k = z.shape[1]
    u = eps(dtype)
    nt = J.nt_scaling(z, s)
    for f in nt:
        assert f.dtype == dtype
    a = J.quad_apply(nt.p, z)
    b = J.quad_apply(nt.p_inv, s)
    bound = (
        2
        * (k + 2) ** 2
        * u
        * (
            (kappa(z) + kappa(s)) * scale(nt.lam)
            + scale(nt.p) ** 2 * scale(z)
            + scale(nt.p_inv) ** 2 * scale(s)
        )
    )
    check(dtype, maxabs(L(a) - L(b)), bound, "Q_p z - Q_{p⁻¹} s")
    check(dtype, maxabs(L(a) - L(nt.lam)), bound, "Q_p z - λ")
    check(dtype, maxabs(L(b) - L(nt.lam)), bound, "Q_{p⁻¹} s - λ")
    arw = np.max(np.abs(L(J.arrow(a)) - L(J.arrow(b))), axis=(1, 2))
    check(dtype, arw, bound, "Arw(Q_p z) - Arw(Q_{p⁻¹} s)")
    assert np.all(J.spectral_values(nt.p)[1] > 0)
    assert np.all(J.spectral_values(nt.lam)[1] > 0)
    e = J.identity(k, z.shape[0], dtype)
    kap_p = kappa(nt.p)
    err = maxabs(L(J.jordan_product(nt.p, nt.p_inv)) - L(e))
    check(dtype, err, 8 * (k + 2) * u * kap_p, "p∘p⁻¹ - e")
    kz, ks, kl = kappa(z), kappa(s), kappa(nt.lam)
    rel = 2 * (k + 2) * u * (kz + ks + kl + kap_p)
    # Reference determinants in longdouble: det of a 1e-300 point underflows in float64.
    dz, ds = ref_det(z), ref_det(s)
    beta_true = np.sqrt(np.sqrt(ds / dz))
    check(dtype, np.abs(L(nt.beta) / beta_true - 1), rel, "β vs (det s/det z)^¼")
    check(dtype, np.abs(ref_det(nt.p) / L(nt.beta) - 1), rel, "det p vs β")
    check(dtype, np.abs(ref_det(nt.lam) / np.sqrt(dz * ds) - 1), rel, "det λ vs √(det z det s)")
    err = np.abs(L(nt.cond) / L(J.cond_quad(nt.p)) - 1)
    check(dtype, err, rel * kap_p, "cond field vs cond_quad(p)")


@dtypes
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
@example(case=(MIX5 * [[1, 1, 1, 1, 0.1], [1, 1, 1, 1, 1]],))
def test_cond_quad(dtype, case):
    """cond(Q_x) = (λ1/λ2)².

    (a) Against the eigenvalues of quad_matrix(x), computed by np.linalg.eigvalsh in float64
    (longdouble runs cast the matrix: np.linalg has no longdouble): the smallest eigenvalue
    λ2² has absolute error O(k u₆₄ S²) (Weyl), so the ratio has relative error
    ≤ 8(k+2)·u₆₄·κ² — asserted where that is < 0.1 (the conditioning allows the comparison).
    (b) Against an mpmath oracle on the exact input: relative error ≤ 8(k+2)·u·κ
    (the relative error of λ2, doubled by the square), in the dtype under test.
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    c = J.cond_quad(x)
    assert c.dtype == dtype
    kap = kappa(x)
    u64 = eps(np.float64)
    q = np.asarray(J.quad_matrix(x), dtype=np.float64)
    # Normalise each matrix to unit max-entry first: the eigen-ratio is scale-free and this
    # keeps eigvalsh away from overflow for the 1e150 examples.
    q = q / np.max(np.abs(q), axis=(1, 2), keepdims=True)
    ev = np.linalg.eigvalsh(q)
    rel_eig = 8 * (k + 2) * u64 * kap**2
    meaningful = rel_eig < 0.1
    # where not meaningful λ_min may come out as 0 or negative: mask before dividing
    ratio = L(ev[:, -1]) / np.where(meaningful, L(ev[:, 0]), 1)
    check(dtype, np.where(meaningful, np.abs(ratio / L(c) - 1), 0), rel_eig, "cond vs eigvalsh")
    for i in range(x.shape[0]):
        l1, l2 = mp_lams(to_mp(x[i]))
        truth = (l1 / l2) ** 2
        err = abs(mpmath.mpf(to_mp(np.asarray(c[i]))[()]) / truth - 1)
        check(dtype, LD(float(err)), 8 * (k + 2) * u * kap[i], "cond vs mpmath")


@dtypes
@given(case=cases("g", ks=KS_ALL))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(SUBN_TINY,))
@example(case=(XBAR0,))
@example(case=(XBAR0_K2,))
@example(case=(K1,))
def test_spectral_decomposition(dtype, case):
    """x = λ1c1 + λ2c2 (‖·‖∞ ≤ 4(k+2)·u·S(x)); for k >= 2 the frame is a Jordan frame:
    c1∘c2 = 0, ci∘ci = ci (≤ (k+2)·u — the unit vector x̄/‖x̄‖ has norm 1 ± O(k u) and
    c1∘c2 = (¼(1 - ‖x̄/‖x̄‖‖²); 0)),
    c1 + c2 = e exactly.  Spectral values agree with an mpmath oracle to 4(k+2)·u·S(x)
    (absolute; λ2 relative O(k u κ) is its condition number).  For k = 1 both frames are ½.
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    l1, l2 = J.spectral_values(x)
    c1, c2 = J.spectral_frames(x)
    assert l1.dtype == dtype and c1.dtype == dtype
    assert np.all(l1 >= l2)
    S = scale(x)
    recon = L(l1)[:, None] * L(c1) + L(l2)[:, None] * L(c2)
    check(dtype, maxabs(recon - L(x)), 4 * (k + 2) * u * S, "λ1c1 + λ2c2 - x")
    e = J.identity(k, x.shape[0], dtype)
    assert np.array_equal(c1 + c2, e)
    if k > 1:
        tol = (k + 2) * u
        check(dtype, maxabs(J.jordan_product(c1, c2)), tol, "c1∘c2")
        check(dtype, maxabs(L(J.jordan_product(c1, c1)) - L(c1)), tol, "c1∘c1 - c1")
        check(dtype, maxabs(L(J.jordan_product(c2, c2)) - L(c2)), tol, "c2∘c2 - c2")
    for i in range(x.shape[0]):
        m1, m2 = mp_lams(to_mp(x[i]))
        err = max(abs(to_mp(np.asarray(l1[i]))[()] - m1), abs(to_mp(np.asarray(l2[i]))[()] - m2))
        check(dtype, LD(float(err)), 4 * (k + 2) * u * S[i], "spectral values vs mpmath")


@dtypes
@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(ABS300,))
@example(case=(K1,))
@example(case=(A([[1.5 + 2.0**-52, -1.5], [1e155 * (1 + 2.0**-52), 1e155]]),))
def test_det_against_oracle(dtype, case):
    """det x = λ1λ2 against the exact x0² - ‖x̄‖² (mpmath) to 8(k+2)·u·S(x)² absolute
    (λ1·Δλ2 + λ2·Δλ1 with absolute errors O(k u S) of the spectral values), and trace = 2x0
    exactly.  Results that are not representable (|det| beyond the dtype's range) must
    overflow to inf / underflow to 0 rather than be NaN.

    When x̄ has at most one non-zero entry (always for k = 2) ‖x̄‖ = |x_i| is exact, so
    x0 ∓ |x_i| are single roundings (exact by Sterbenz near the boundary) and the factored
    det has relative error ≤ 3u + O(u²) whatever κ is — asserted as 4u.  This is what
    distinguishes it from x0² - ‖x̄‖², whose relative error near the boundary is O(u κ).
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    d = J.det(x)
    assert d.dtype == dtype and not np.isnan(d).any()
    assert np.array_equal(J.trace(x), 2 * x[:, 0])
    S = scale(x)
    fmax = np.finfo(dtype).max
    for i in range(x.shape[0]):
        xm = to_mp(x[i])
        truth = xm[0] ** 2 - mpmath.fsum(v * v for v in xm[1:])
        if abs(truth) > fmax:
            assert np.isinf(d[i])
            continue
        err = abs(to_mp(np.asarray(d[i]))[()] - truth)
        # The bound itself may underflow (S² for S ~ 1e-300 in float64): allow the subnormal
        # quantum of the dtype on top.
        bound = 8 * (k + 2) * u * S[i] ** 2 + LD(np.finfo(dtype).smallest_subnormal)
        check(dtype, _mp_to_ld(err), bound, "det vs mpmath")
        if np.count_nonzero(x[i, 1:]) <= 1:
            rel = 4 * u * _mp_to_ld(abs(truth)) + LD(np.finfo(dtype).smallest_subnormal)
            check(dtype, _mp_to_ld(err), rel, "det vs mpmath, exact ‖x̄‖ (relative 4u)")


def _mp_to_ld(v):
    """mpf → longdouble without going through float64 (which would underflow/round)."""
    m, e = mpmath.frexp(v)
    hi = float(m)
    lo = float(m - hi)
    return np.ldexp(LD(hi) + LD(lo), int(e))


@dtypes
@given(case=cases("i", log_rho=(-4.0, 0.0)), p=st.sampled_from([2, 3, -1, -2, 0.5, 1.5, -0.5]))
@example(case=(NEAR12,), p=0.5)
@example(case=(NEAR12,), p=-1)
@example(case=(XBAR0,), p=-0.5)
@example(case=(K1[:2],), p=3)
@example(case=(HUGE * 1e-75,), p=1.5)
def test_det_of_powers(dtype, case, p):
    """det(x^p) = det(x)^p (incl. det(x∘x) = det(x)², det(x⁻¹) = 1/det x), relative error
    ≤ 2(k+2)·u·(κ(x^p) + (|p|+1)κ(x)): the left side is λ1λ2 of x^p (relative error
    O(k u κ(x^p)), κ(x^p) = κ^|p|), the right side det(x)^p (relative O(|p| k u κ))."""
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    xp = J.power(x, p)
    kap = kappa(x)
    bound = 2 * (k + 2) * u * (kappa(xp) + (abs(p) + 1) * kap)
    lhs = L(J.det(xp))
    rhs = L(J.det(x)) ** LD(p)
    check(dtype, np.abs(lhs / rhs - 1), bound, f"det(x^{p}) / det(x)^{p}")
    if p == 2:
        check(dtype, np.abs(L(J.det(J.jordan_product(x, x))) / rhs - 1), bound, "det(x∘x)/det(x)²")


@dtypes
@given(case=cases("ig"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, -HUGE[::-1]))
@example(case=(TINY, gen_partner(TINY)))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(XBAR0, -XBAR0[:, [0, 2, 1]] - [[0, 1, 0], [0, 0, 1]]))
@example(case=(K1, -K1[::-1]))
@example(case=(A([[1.0, 0.0, 0.0]]), A([[0.0, 1.0, 0.0]])))  # boundary reached at α = 1
@example(case=(A([[1.0, 0.0, 0.0]]), A([[2.2250738585e-311] * 3])))  # α ≈ 1.1e311 > max (f64)
@example(case=(A([[1e-3, 0.0]]), A([[2.2250738585e-311] * 2])))  # tangent, subnormal dx
def test_step_to_boundary(dtype, case):
    """α = step_to_boundary(x, dx): x + α dx ∈ ∂L and x + 0.99α dx ∈ int L; α = inf iff dx ∈ L.

    Boundary: |λ2(x + α dx)| ≤ 2(k+2)·u·(S(x) + α S(dx))·(κ(x) + α S(dx)/λ2(x)).  The
    relative error of α is O(k u (κ + α S(dx)/λ2(x))): x^{-1/2} carries a common relative
    error O(k u κ), and y = Q_{x^{-1/2}} dx an absolute error O(k u S(dx)/λ2(x)) against
    |λ2(y)| = 1/α; λ2 of the trial point moves by at most 2S(dx) per unit of α, and its
    evaluation adds O(k u (S(x) + α S(dx))).
    Interior: λ2 is concave along the ray, so λ2(x + 0.99α dx) >= 0.01λ2(x) - 0.99·(bound);
    asserted directly as > 0.  max_step = min(alpha_max, min α) exactly.
    """
    x, dx = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    alpha = J.step_to_boundary(x, dx)
    assert alpha.dtype == dtype
    assert np.all(alpha > 0)
    kap = kappa(x)
    sdx = scale(dx)
    # α = finfo.max: the ray leaves L only beyond the dtype's range (dx tiny): x + max·dx ∈ L
    # and dx ∉ int L up to rounding (a tangent dx, λ2(dx) = 0, may round either way).
    # Checked separately; the boundary identity applies to the other cones.
    huge = alpha == np.finfo(dtype).max
    if huge.any():
        slack = 8 * (k + 2) * u * kap * sdx
        assert np.all(ref_lams(dx)[1][huge] <= slack[huge]), "α = max but dx ∈ int L"
        _, l2h = ref_lams(L(x) + L(np.where(huge, alpha, 0))[:, None] * L(dx))
        assert np.all(l2h[huge] >= 0)
    fin = np.isfinite(alpha) & ~huge
    a = L(np.where(fin, alpha, 0))
    _, l2x = ref_lams(x)
    if fin.any():
        _, l2b = ref_lams(L(x) + a[:, None] * L(dx))
        bound = 2 * (k + 2) * u * (scale(x) + a * sdx) * (kap + a * sdx / l2x)
        check(dtype, np.where(fin, np.abs(l2b), 0), bound, "λ2(x + α dx)")
        _, l2i = ref_lams(L(x) + (LD("0.99") * a)[:, None] * L(dx))
        assert np.all(l2i[fin] > 0), "x + 0.99α dx left the cone"
    never = np.isinf(alpha)
    if never.any():
        _, l2d = ref_lams(dx)
        slack = 8 * (k + 2) * u * kap * sdx
        assert np.all(l2d[never] >= -slack[never]), "α = inf but dx ∉ L"
    for amax in (1.0, np.inf):
        ms = J.max_step(x, dx, alpha_max=amax)
        assert ms.dtype == dtype
        assert ms == min(dtype(amax), np.min(alpha))


@dtypes
@given(
    case=cases("i", log_rho=(-6.0, 0.0), log_scale=(-2.0, 2.0)),
    p=st.integers(-3072, 3072),
    q=st.integers(-3072, 3072),
)
@example(case=(NEAR12,), p=1024, q=-512)
@example(case=(XBAR0,), p=333, q=-1000)
@example(case=(SUBN,), p=-1536, q=3072)
@example(case=(K1,), p=-2048, q=100)
@example(case=(HUGE,), p=-1536, q=512)
@example(case=(TINY,), p=512, q=-1536)
def test_power_additive(dtype, case, p, q):
    """x^a ∘ x^b = x^{a+b} for a = p/1024, b = q/1024 ∈ [-3, 3] (a + b exact), x ∈ int L.

    With M(a) = max(λ1^a, λ2^a) and
    E(a) = (|a|+2)(λ1^a + λ2^a) + |a|·λ1·λ2^{a-1}  (computed x^a has absolute error ≤ c·k·u·E(a):
    λ1^a has relative error O(|a| k u), the c2-coefficient λ2^a absolute error
    |a|λ2^{a-1}·Δλ2 = O(|a| k u λ1 λ2^{a-1}), the frame O(k u)), the product has error
    ≤ 2(k+2)·u·[E(a)M(b) + M(a)E(b) + E(a+b)] (E already carries the k of the spectral
    values; the product's k-term dot product is absorbed because E >= |x^a| termwise).
    """
    (x,) = (_cast(a, dtype) for a in case)
    k = x.shape[1]
    u = eps(dtype)
    a_, b_ = p / 1024, q / 1024
    l1, l2 = ref_lams(x)

    def E(t):
        return (abs(t) + 2) * (l1**t + l2**t) + abs(t) * l1 * l2 ** (t - 1)

    def M(t):
        return np.maximum(l1**t, l2**t)

    xa, xb, xab = J.power(x, a_), J.power(x, b_), J.power(x, a_ + b_)
    assert xa.dtype == dtype
    lhs = L(J.jordan_product(xa, xb))
    bound = 2 * (k + 2) * u * (E(a_) * M(b_) + M(a_) * E(b_) + E(a_ + b_))
    check(dtype, maxabs(lhs - L(xab)), bound, f"x^{a_}∘x^{b_} - x^{a_ + b_}")


@dtypes
@given(
    case=cases("i", ks=KS_FRAME, log_rho=(-1.0, -0.01), log_scale=(-2.0, 2.0)),
    small=st.floats(-320.0, -1.0),
    p=st.sampled_from([-2.0, -0.5, 1.0 / 3.0, 1.5, 3.0, 1e-3]),
)
@example(case=(SUBN,), small=-1.0, p=1.5)
@example(case=(XBAR0,), small=-1.0, p=-2.0)
def test_power_bar_is_accurate_componentwise(dtype, case, small, p):
    """Near the axis (x̄ small, here ‖x̄‖/x0 = 10^small down to subnormal) the bar part of x^p
    is D·x̄ with D = (λ1^p - λ2^p)/(λ1 - λ2); the naive difference λ1^p - λ2^p cancels and
    would lose all digits.  The expm1/log1p form keeps D to relative accuracy O(|p| k u) here
    (κ ≈ 1), so each component satisfies
    |bar_i - D*·x̄_i| ≤ 8(|p|+2)(k+2)·u·|D*·x̄_i| + 16·(smallest subnormal).
    The same holds for sqrt's closed form (p = ½, bar = x̄/(√λ1+√λ2))."""
    (x,) = (_cast(a, dtype) for a in case)
    x = x.copy()
    m = np.max(np.abs(x[:, 1:]), axis=1, keepdims=True)
    # shrink x̄ to ‖x̄‖ ≈ 10^small · x0 (exactly representable scaling by a power of two)
    shift = np.floor(small * math.log2(10))
    x[:, 1:] = np.ldexp(x[:, 1:] / np.where(m > 0, m, 1), int(shift)) * x[:, :1]
    k = x.shape[1]
    u = eps(dtype)
    floor = 16 * np.finfo(dtype).smallest_subnormal
    for fn, pp in ((lambda v: J.power(v, p), p), (J.sqrt, 0.5)):
        r = fn(x)
        # λ1 - λ2 = 2‖x̄‖ with ‖x̄‖/x0 down to 1e-320: the oracle needs ~1100 bits more.
        with mpmath.workprec(1500):
            _check_bar(r, x, pp, k, u, floor)


def _check_bar(r, x, pp, k, u, floor):
    """Componentwise check of the bar part of r = x^pp against D*·x̄ (see the caller)."""
    for i in range(x.shape[0]):
        xm = to_mp(x[i])
        l1, l2 = mp_lams(xm)
        if l1 == l2:  # x̄ = 0
            assert np.all(r[i, 1:] == 0)
            continue
        dstar = (l1**pp - l2**pp) / (l1 - l2)
        rm = to_mp(r[i])
        for j in range(1, k):
            want = dstar * xm[j]
            err = abs(rm[j] - want)
            bound = 8 * (abs(pp) + 2) * (k + 2) * u * abs(want) + floor
            assert err <= bound, (f"bar[{j}] of x^{pp}", float(err), float(bound))


# ------------------------------------------------------------------------------------------
# longdouble really is extended precision
# ------------------------------------------------------------------------------------------


@given(case=cases("ii", log_rho=(-0.5, 0.0), log_scale=(-1.0, 1.0)))
@example(case=(MIX5 * [[1, 0.1, 0.1, 0.1, 0.1], [1, 1, 1, 1, 1]], other(MIX5)))
def test_longdouble_is_really_extended(case):
    """On well-conditioned data (κ <= ~3.2, scale 0.1…10) every longdouble result must be
    accurate to 64·(k+2)·eps(longdouble) relative to the scale — about 5e-17·(k+2)/7, far
    below eps(float64) = 2.2e-16; a computation that silently went through float64 would be
    off by ~1e-16.  Residuals are evaluated in mpmath on the exact longdouble values."""
    x, y = (_cast(a, LD) for a in case)
    k = x.shape[1]
    tol = 64 * (k + 2) * eps(LD)
    assert tol < eps(np.float64) / 2
    res = {
        "inverse": J.inverse(x),
        "sqrt": J.sqrt(x),
        "power": J.power(x, LD(1) / 3),
        "quad": J.quad_apply(x, y),
        "prod": J.jordan_product(x, y),
        "l": J.spectral_values(x),
        "det": J.det(x),
        "nt": J.nt_scaling(x, y),
        "step": J.step_to_boundary(x, y - 2 * x),
    }
    for i in range(x.shape[0]):
        xm, ym = to_mp(x[i]), to_mp(y[i])
        S = max(abs(v) for v in xm)
        e = np.array([mpmath.mpf(1)] + [mpmath.mpf(0)] * (k - 1), dtype=object)
        inv = to_mp(res["inverse"][i])
        assert mp_maxabs_diff(mp_product(xm, inv), e) < tol, "inverse"
        r = to_mp(res["sqrt"][i])
        assert mp_maxabs_diff(mp_product(r, r), xm) < tol * S, "sqrt"
        c = to_mp(res["power"][i])
        assert mp_maxabs_diff(mp_product(c, mp_product(c, c)), xm) < tol * S, "power 1/3"
        Sy = max(abs(v) for v in ym)
        assert mp_maxabs_diff(to_mp(res["quad"][i]), mp_quad(xm, ym)) < tol * S**2 * Sy * 4, "quad"
        assert mp_maxabs_diff(to_mp(res["prod"][i]), mp_product(xm, ym)) < tol * S * Sy * 4, "prod"
        m1, m2 = mp_lams(xm)
        assert abs(to_mp(np.asarray(res["l"][0][i]))[()] - m1) < tol * S, "λ1"
        assert abs(to_mp(np.asarray(res["l"][1][i]))[()] - m2) < tol * S, "λ2"
        assert abs(to_mp(np.asarray(res["det"][i]))[()] - m1 * m2) < tol * S**2, "det"
        nt = res["nt"]
        pm, pim = to_mp(nt.p[i]), to_mp(nt.p_inv[i])
        lam = to_mp(nt.lam[i])
        assert mp_maxabs_diff(mp_quad(pm, xm), mp_quad(pim, ym)) < tol * max(abs(v) for v in lam)
        assert mp_maxabs_diff(mp_quad(pm, xm), lam) < tol * max(abs(v) for v in lam)
        al = res["step"][i]
        if np.isfinite(al):
            am = to_mp(np.asarray(al))[()]
            dm = to_mp(y[i]) - 2 * xm
            _, b2 = mp_lams(xm + am * dm)
            assert abs(b2) < tol * S * (1 + am * max(abs(v) for v in dm)) * 4, "step"


# ------------------------------------------------------------------------------------------
# explicit tests: domain errors, NaN, dtype, cancellation, special cases
# ------------------------------------------------------------------------------------------


def _batch_with_bad_cone(bad, index=3, n=5, k=3):
    x = np.tile([2.0, 0.5, -0.5][:k] + [0.0] * max(0, k - 3), (n, 1))
    x[index] = bad
    return x


OUTSIDE = [1.0, 2.0, 0.0]  # λ2 = -1
BOUNDARY = [5.0, 3.0, 4.0]  # λ2 = 0 exactly: ‖(3, 4)‖ = 4·√(0.75² + 1) = 5 without rounding


def _exact(a, dtype):
    """No jitter: the domain tests need points exactly on the boundary."""
    return np.asarray(a, dtype=dtype)


@dtypes
def test_sqrt_outside_raises_with_cone_index(dtype):
    x = _exact(_batch_with_bad_cone(OUTSIDE, index=3), dtype)
    with pytest.raises(ConeDomainError) as ei:
        J.sqrt(x)
    assert ei.value.operation == "sqrt" and ei.value.cone == 3
    assert ei.value.value == pytest.approx(-1.0)
    with pytest.raises(ConeDomainError) as ei:
        J.sqrt(_exact(A(OUTSIDE), dtype))
    assert ei.value.cone is None  # single vector
    # A point that left the cone by one rounding error is refused, not silently NaN.
    with pytest.raises(ConeDomainError):
        J.sqrt(A([1.0, np.nextafter(1.0, 2.0), 0.0]))


@dtypes
def test_sqrt_on_boundary_is_allowed(dtype):
    x = _exact(A([BOUNDARY, [0.0, 0.0, 0.0], [2.0, 0.0, 2.0]]), dtype)
    r = J.sqrt(x)
    assert np.all(np.isfinite(r))
    assert np.all(J.spectral_values(r)[1] >= 0)
    assert np.max(np.abs(L(J.jordan_product(r, r)) - L(x))) < 16 * 5 * eps(dtype) * 10
    assert np.array_equal(r[1], np.zeros(3, dtype))


@dtypes
def test_inverse_domain(dtype):
    x = _exact(_batch_with_bad_cone(BOUNDARY, index=2), dtype)
    with pytest.raises(ConeDomainError) as ei:
        J.inverse(x)
    assert ei.value.operation == "inverse" and ei.value.cone == 2 and ei.value.value == 0.0
    with pytest.raises(ConeDomainError) as ei:  # boundary of -L: λ1 = 0
        J.inverse(_exact(A([[-5.0, 3.0, 4.0]]), dtype))
    assert ei.value.cone == 0
    # Outside L ∪ -L (det < 0) and inside -L the inverse exists.
    y = _exact(A([[1.0, 2.0, 0.0], [-3.0, 1.0, 1.0]]), dtype)
    e = J.identity(3, 2, dtype)
    assert np.max(np.abs(L(J.jordan_product(y, J.inverse(y))) - L(e))) < 64 * eps(dtype)


@dtypes
def test_power_domain(dtype):
    x = _exact(_batch_with_bad_cone(OUTSIDE, index=4), dtype)
    for p in (0.5, 1.5, -0.5, -1.5, 1 / 3):
        with pytest.raises(ConeDomainError) as ei:
            J.power(x, p)
        assert ei.value.operation == "power" and ei.value.cone == 4
        assert ei.value.value == pytest.approx(-1.0)
    b = _exact(_batch_with_bad_cone(BOUNDARY, index=1), dtype)
    for p in (-0.5, -2, -1):  # need the interior (non-integer) or det != 0 (integer)
        with pytest.raises(ConeDomainError) as ei:
            J.power(b, p)
        assert ei.value.operation == "power" and ei.value.cone == 1
    # Non-integer p > 0 on the boundary: λ1^p c1 (λ1 = 10).
    r = J.power(b, 1.5)[1]
    c1, _ = J.spectral_frames(b[1])
    assert np.max(np.abs(L(r) - L(10.0) ** LD(1.5) * L(c1))) < 16 * eps(dtype) * 10**1.5
    # Integer powers of points outside the cone: binary powering == repeated products.
    y = _exact(A([[0.5, 2.0, -1.0], [-1.0, 0.25, 0.5], [0.0, 1.0, 0.0]]), dtype)
    y2 = J.jordan_product(y, y)
    tol = 64 * eps(dtype)
    assert np.max(np.abs(L(J.power(y, 3)) - L(J.jordan_product(y, y2)))) < tol * 30
    yi = J.inverse(y)
    assert np.max(np.abs(L(J.power(y, -2)) - L(J.jordan_product(yi, yi)))) < tol * 30
    assert np.array_equal(J.power(y, 0), J.identity(3, 3, dtype))
    assert np.array_equal(J.power(y, 1), y)
    with pytest.raises(ConeDomainError):
        J.power(y, float("nan"))


@dtypes
def test_cond_quad_domain(dtype):
    x = _exact(_batch_with_bad_cone(OUTSIDE, index=0), dtype)
    with pytest.raises(ConeDomainError) as ei:
        J.cond_quad(x)
    assert ei.value.operation == "cond_quad" and ei.value.cone == 0
    c = J.cond_quad(_exact(A([BOUNDARY, [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), dtype))
    assert np.isinf(c[0]) and np.isinf(c[1]) and c[2] == 1
    assert J.cond_quad(_exact(A([[4.0]]), dtype))[0] == 1  # k = 1


@dtypes
def test_nt_scaling_domain_names_argument(dtype):
    good = _exact(np.tile([2.0, 0.5, 0.5], (4, 1)), dtype)
    badz = good.copy()
    badz[2] = BOUNDARY
    with pytest.raises(ConeDomainError) as ei:
        J.nt_scaling(badz, good)
    assert ei.value.operation == "nt_scaling" and ei.value.cone == 2 and "'z'" in str(ei.value)
    bads = good.copy()
    bads[1] = OUTSIDE
    with pytest.raises(ConeDomainError) as ei:
        J.nt_scaling(good, bads)
    assert ei.value.cone == 1 and "'s'" in str(ei.value) and ei.value.value == pytest.approx(-1)


@dtypes
def test_step_domain_and_simple_cases(dtype):
    x = _exact(_batch_with_bad_cone(BOUNDARY, index=3), dtype)
    dx = np.ones_like(x)
    for fn, name in ((J.step_to_boundary, "step_to_boundary"), (J.max_step, "max_step")):
        with pytest.raises(ConeDomainError) as ei:
            fn(x, dx)
        assert ei.value.operation == name and ei.value.cone == 3
    e = J.identity(3, dtype=dtype)
    assert J.step_to_boundary(e, -e) == 1  # exact: y = -e, λ2(y) = -1
    assert J.step_to_boundary(e, e) == np.inf
    assert J.step_to_boundary(e, np.zeros(3)) == np.inf
    a1 = J.step_to_boundary(_exact(A([2.0]), dtype), _exact(A([-4.0]), dtype))  # k = 1
    assert abs(L(a1) - LD(0.5)) <= 4 * eps(dtype)
    assert J.max_step(e, -e, alpha_max=0.5) == 0.5
    empty = np.zeros((0, 3), dtype)
    assert J.max_step(empty, empty, alpha_max=0.7) == dtype(0.7)


def test_min_lambda2():
    x = A([[2.0, 0.0, 1.0], [1.0, 0.0, 0.9], [3.0, 1.0, 1.0]])
    v, i = J.min_lambda2(x)
    assert i == 1 and v == pytest.approx(0.1)
    v, i = J.min_lambda2(x[0])
    assert i is None and v == pytest.approx(1.0)
    v, i = J.min_lambda2(np.zeros((0, 3), LD))
    assert i is None and v == np.inf and v.dtype == LD
    assert J.min_lambda2(L(x))[0].dtype == LD


# ---- every public function: non-finite input raises, dtype follows input -----------------

X3 = A([[2.0, 0.5, -0.5], [3.0, 1.0, 1.0], [1.0, 0.1, 0.2], [4.0, 0.0, 0.0]])
D3 = A([[0.1, -0.3, 0.2], [-1.0, 0.5, 0.5], [0.0, 1.0, 0.0], [0.2, 0.2, 0.2]])

PUBLIC = {
    "jordan_product": lambda x, y: J.jordan_product(x, y),
    "arrow": lambda x, y: J.arrow(x),
    "reflect": lambda x, y: J.reflect(x),
    "spectral_values": lambda x, y: J.spectral_values(x),
    "spectral_frames": lambda x, y: J.spectral_frames(x),
    "det": lambda x, y: J.det(x),
    "trace": lambda x, y: J.trace(x),
    "inverse": lambda x, y: J.inverse(x),
    "power": lambda x, y: J.power(x, -1.5),
    "sqrt": lambda x, y: J.sqrt(x),
    "quad_apply": lambda x, y: J.quad_apply(x, y),
    "arrow_solve": lambda x, y: J.arrow_solve(x, y),
    "quad_matrix": lambda x, y: J.quad_matrix(x),
    "cond_quad": lambda x, y: J.cond_quad(x),
    "nt_scaling": lambda x, y: J.nt_scaling(x, 2 * x),
    "step_to_boundary": lambda x, y: J.step_to_boundary(x, y),
    "max_step": lambda x, y: J.max_step(x, y),
    "min_lambda2": lambda x, y: J.min_lambda2(x),
}


def _leaves(r):
    if isinstance(r, tuple):
        return [leaf for item in r for leaf in _leaves(item)]
    return [r]


def test_public_api_is_covered():
    assert set(PUBLIC) | {"identity", "NTScaling"} == set(J.__all__)


@pytest.mark.parametrize("name", sorted(PUBLIC))
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_input_raises(name, bad):
    x = X3.copy()
    x[2, 1] = bad
    with pytest.raises(ConeDomainError) as ei:
        PUBLIC[name](x, D3)
    assert ei.value.operation == name and ei.value.cone == 2
    if name in ("jordan_product", "quad_apply", "arrow_solve", "step_to_boundary", "max_step"):
        y = D3.copy()
        y[1, 0] = bad
        with pytest.raises(ConeDomainError) as ei:
            PUBLIC[name](X3, y)
        assert ei.value.operation == name and ei.value.cone == 1
    with pytest.raises(ConeDomainError) as ei:  # single vector: cone is None
        PUBLIC[name](x[2], D3[2])
    assert ei.value.cone is None


@pytest.mark.parametrize("name", sorted(PUBLIC))
@pytest.mark.parametrize(
    "in_dtypes, out_dtype",
    [
        ((np.float64, np.float64), np.float64),
        ((LD, LD), LD),
        ((np.float32, np.float32), np.float64),
        ((np.int64, np.int64), np.float64),
        ((np.float64, LD), LD),
        ((LD, np.float64), LD),
    ],
    ids=["f64", "ld", "f32", "int", "f64+ld", "ld+f64"],
)
def test_dtype_follows_input(name, in_dtypes, out_dtype):
    xi = (X3 * 10).astype(np.int64) if in_dtypes[0] is np.int64 else X3
    yi = (D3 * 10).astype(np.int64) if in_dtypes[1] is np.int64 else D3
    x = xi.astype(in_dtypes[0])
    y = yi.astype(in_dtypes[1])
    if name in ("jordan_product", "quad_apply", "arrow_solve", "step_to_boundary", "max_step"):
        expected = out_dtype
    else:  # single-argument functions follow x only
        expected = np.result_type(x, np.float64)
    for leaf in _leaves(PUBLIC[name](x, y)):
        if leaf is None or isinstance(leaf, int):
            continue  # min_lambda2's index
        assert np.asarray(leaf).dtype == expected, f"{name}: {np.asarray(leaf).dtype}"
    # single-cone call keeps single-cone shapes
    for leaf in _leaves(PUBLIC[name](x[0], y[0])):
        if leaf is None or isinstance(leaf, int):
            continue
        assert np.ndim(leaf) in (0, 1, 2) and (np.ndim(leaf) == 0 or np.shape(leaf)[0] == 3)


def test_identity_dtype_and_shape():
    assert J.identity(3).tolist() == [1.0, 0.0, 0.0]
    e = J.identity(5, 4, LD)
    assert e.dtype == LD and e.shape == (4, 5) and np.all(e[:, 0] == 1) and np.all(e[:, 1:] == 0)
    assert J.identity(1, 2).tolist() == [[1.0], [1.0]]


def test_broadcast_single_against_batch():
    y = X3
    x = X3[1]
    assert np.array_equal(J.quad_apply(x, y), J.quad_apply(np.tile(x, (4, 1)), y))
    assert np.array_equal(J.jordan_product(y, x), J.jordan_product(y, np.tile(x, (4, 1))))
    with pytest.raises(ValueError):
        J.jordan_product(X3, X3[:, :2])
    with pytest.raises(ValueError):
        J.jordan_product(X3, X3[:3])


# ---- cancellation-free determinant ---------------------------------------------------------


def test_det_is_cancellation_free():
    """The factored det (x0-‖x̄‖)(x0+‖x̄‖) is right where x0² - ‖x̄‖² in float64 is not."""
    # (a) k=2, one ulp inside the boundary: exact det = 3·2^-52 + 2^-104.  The squares round
    # (x0² to 1.5 ulp off), so the naive difference is 2^-50 (33% too large).
    x = A([1.5 + 2.0**-52, 1.5])
    truth = mpmath.mpf(x[0]) ** 2 - mpmath.mpf(x[1]) ** 2
    naive = x[0] * x[0] - x[1] * x[1]
    assert abs(naive / truth - 1) > 0.3
    assert abs(J.det(x) / truth - 1) < 2 * eps(np.float64)
    # (b) k=3, one ulp inside: naive gives exactly 0 (claims the boundary), factored is
    # positive and has the right order of magnitude.
    x = A([1.6395410951735119, 1.2940638143982073, 1.0067243153057943])
    xm = to_mp(x)
    truth = xm[0] ** 2 - xm[1] ** 2 - xm[2] ** 2
    assert truth > 0
    naive = x[0] * x[0] - (x[1] * x[1] + x[2] * x[2])
    assert naive == 0.0
    assert J.det(x) > 0 and abs(J.det(x) / truth - 1) < 1
    # (c) magnitude: x0² overflows (inf - inf = NaN) while det x ≈ 4.8e294 is representable.
    x = A([1e155 * (1 + 2.0**-52), 1e155])
    with np.errstate(over="ignore", invalid="ignore"):
        naive = x[0] * x[0] - x[1] * x[1]
    assert np.isnan(naive)
    truth = mpmath.mpf(x[0]) ** 2 - mpmath.mpf(x[1]) ** 2
    assert np.isfinite(J.det(x)) and abs(J.det(x) / truth - 1) < 4 * eps(np.float64)


def test_extreme_magnitudes():
    """Where the true result is representable it is returned; where not, ±inf/0, never NaN."""
    big = A([1e160, 3e159, 4e159])  # λ = 1.5e160, 5e159; det = 7.5e319: not representable
    l1, l2 = J.spectral_values(big)
    assert l1 == pytest.approx(1.5e160) and l2 == pytest.approx(5e159)
    assert np.isinf(J.det(big))
    assert abs(J.det(big.astype(LD)) / LD("7.5e319") - 1) < 1e-15  # fine in longdouble
    inv = J.inverse(big)  # ~1e-160, representable although det overflows
    assert np.all(np.isfinite(inv)) and inv[0] > 0
    e = J.identity(3)
    assert np.max(np.abs(J.jordan_product(big, inv) - e)) < 1e-14
    tiny = A([1e-200, 0.0, 5e-201])  # det = 7.5e-401 underflows, x⁻¹ ~ 1.3e200 does not
    assert J.det(tiny) == 0.0
    ti = J.inverse(tiny)
    assert np.max(np.abs(J.jordan_product(tiny, ti) - e)) < 1e-15
    # Q_x y with |x| ~ 1e160, |y| ~ 1e-160: 2(xᵀy)x - det(x)Ry = (1.25e160, 6e159, 8e159)
    # although det x overflows.
    q = J.quad_apply(big, A([1e-160, 0.0, 0.0]))
    assert q == pytest.approx([1.25e160, 6e159, 8e159], rel=1e-14)
    qq = J.quad_apply(big, big)  # ~1e480: overflows, but to inf, not inf - inf = NaN
    assert np.isinf(qq).any() and not np.isnan(qq).any()
    # NT scaling of a 1e150 point against a 1e-150 point, sqrt/power at 1e±300.
    nt = J.nt_scaling(A([1e150, 0.0, 5e149]), A([1e-150, 5e-151, 0.0]))
    assert all(np.all(np.isfinite(f)) for f in nt)
    assert J.sqrt(A([1e300, 0.0, 5e299])) == pytest.approx(J.sqrt(A([1.0, 0.0, 0.5])) * 1e150)
    assert J.power(A([1e-300, 5e-301, 0.0]), -1) == pytest.approx(
        J.power(A([1.0, 0.5, 0.0]), -1) * 1e300
    )


def test_zero_bar_and_subnormal_frames():
    c1, c2 = J.spectral_frames(A([[3.0, 0.0, 0.0], [1.0, 5e-324, 0.0], [1.0, -5e-324, 5e-324]]))
    assert c1[0].tolist() == [0.5, 0.5, 0.0] and c2[0].tolist() == [0.5, -0.5, 0.0]
    assert c1[1].tolist() == [0.5, 0.5, 0.0]
    assert c1[2, 1] == pytest.approx(-0.5 / math.sqrt(2)) and c1[2, 2] == pytest.approx(
        0.5 / math.sqrt(2)
    )
    # k = 1: both frames are (½,), decomposition holds.
    c1, c2 = J.spectral_frames(A([4.0]))
    assert c1.tolist() == [0.5] and c2.tolist() == [0.5]


def test_k1_semantics():
    """L^1 = R_+: λ1 = λ2 = x0, det = x0², x⁻¹ = 1/x0, x^p = x0^p, Q_x y = x0² y0, cond = 1."""
    x = A([[2.0], [0.5]])
    y = A([[3.0], [-1.0]])
    assert J.jordan_product(x, y).tolist() == [[6.0], [-0.5]]
    assert J.det(x).tolist() == [4.0, 0.25]
    assert J.inverse(x).tolist() == [[0.5], [2.0]]
    assert np.allclose(J.power(x, 1.5), x**1.5, rtol=4e-16, atol=0)
    assert np.allclose(J.power(x, -2.5), x**-2.5, rtol=4e-16, atol=0)
    assert J.sqrt(A([[4.0]])).tolist() == [[2.0]]
    assert J.quad_apply(x, y).tolist() == [[12.0], [-0.25]]
    assert J.cond_quad(x).tolist() == [1.0, 1.0]
    assert J.step_to_boundary(x, -x) == pytest.approx([1.0, 1.0], rel=4e-16)
    nt = J.nt_scaling(A([[2.0]]), A([[8.0]]))
    assert nt.p[0, 0] == pytest.approx(math.sqrt(2.0)) and nt.lam[0, 0] == pytest.approx(4.0)


def test_batch_equals_single_calls():
    """The vectorised batch path gives, cone by cone, exactly the single-cone results."""
    rng = np.random.default_rng(0)
    z = rng.normal(size=(50, 4))
    z[:, 0] = np.linalg.norm(z[:, 1:], axis=1) + 0.5
    s = rng.normal(size=(50, 4))
    s[:, 0] = np.linalg.norm(s[:, 1:], axis=1) + 0.1
    d = rng.normal(size=(50, 4))
    nt = J.nt_scaling(z, s)
    alpha = J.step_to_boundary(z, d)
    pw = J.power(z, -0.7)
    for i in range(0, 50, 7):
        one = J.nt_scaling(z[i], s[i])
        assert all(np.array_equal(a[i], b) for a, b in zip(nt, one))
        assert alpha[i] == J.step_to_boundary(z[i], d[i])
        assert np.array_equal(pw[i], J.power(z[i], -0.7))
