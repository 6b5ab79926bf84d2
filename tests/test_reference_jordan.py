r"""Tests of :mod:`reference.jordan`, the mpmath Jordan algebra (DESIGN.md §3, §5).

Three groups:

1. **Properties of the reference** (hypothesis): every identity of DESIGN §3, at ``dps = 50``
   (some also at ``dps = 30``), on float64-generated inputs converted *exactly* into the
   working context.
2. **Agreement between implementations**: every public function of :mod:`rfverify.jordan`
   (float64 and ``numpy.longdouble``) against the reference at 50 digits on the same
   (exactly converted) inputs, to the accuracy the inputs allow; plus a deterministic check
   that the longdouble results are really better than the float64 ones.
3. **Precision hygiene**: no reference function touches ``mpmath.mp``'s precision, and results
   computed in a 30-digit context carry 30 digits (no more, no fewer).

How the tolerances are built
----------------------------
``u`` is the unit of the arithmetic under test: ``ctx.eps = 2^(1-prec)`` of the working context
for the reference (``2.7e-51`` at ``dps = 50``, ``2.0e-30`` at ``dps = 30`` — i.e.
``u ≈ 10^-dps`` up to a factor < 10), ``numpy.finfo(dtype).eps`` for the production code.
``k`` is the cone dimension; for a vector ``x``, ``S(x) = |x0| + ‖x̄‖ = max|λi(x)|`` is its
scale and, for ``x ∈ int L``, ``κ(x) = λ1/λ2`` its conditioning (``cond(Q_x) = κ²``).  Every
bound has the form ``C·(k+2)^j·u·(conditioning)·(scale)``; the docstring of each test states it
and gives the forward-error argument.  The facts used throughout:

* ``‖x̄‖`` is correctly rounded up to ``1.5u`` relative (exact sum of exact squares, one
  rounding, then a correctly rounded sqrt), so ``λ2 = x0 - ‖x̄‖`` has absolute error
  ``O(u·S)``, i.e. relative error ``O(u·κ)`` — ``κ`` is the condition number of ``λ2`` itself.
* ``ctx.fdot`` sums exact products exactly and rounds once, so each entry of ``x∘y``,
  ``xᵀy``, ``Q_x y`` costs one rounding of the exact value of its (rounded) inputs.

**Checking arithmetic** is done in a separate context ``HI`` with 140 digits, into which every
50-digit value converts exactly; residuals and oracles (textbook formulas: the exact
``x0² - ‖x̄‖²``, ``2Arw(x)² - Arw(x²)``, matrix products) are evaluated there, so the checking
side adds nothing measurable (``1e-140``) to the errors being bounded.  Oracles needing even
more digits (divided differences with ``‖x̄‖/x0 ~ 1e-300``) use a 500-digit context.

**Inputs**: float64 vectors with ``k ∈ {1, 2, 3, 5}``, scales ``λ1 = 10^s``,
``s ∈ [-100, 100]``, conditioning ``λ2/λ1 = 10^r``, ``r ∈ [-12, 0]``, random directions (an
all-zero direction gives ``x̄ = 0``; hypothesis also produces subnormal components), converted
exactly with :func:`reference.jordan.to_ctx`.  Hard cases are pinned with ``@example``.

The constants ``C`` (1–8) were calibrated on instrumented runs (set ``REFERENCE_JORDAN_RATIOS=1``
and run with ``-s`` to print the worst ``error/bound`` of every check): in the ``ci`` run, 12
further random seeds and one run with 1500 examples per test, the worst ratio of any check
was 0.48 (xᵀx and x∘y, whose bound u is twice the correct-rounding error u/2), otherwise
≤ 0.25, typically 0.005–0.1, and no check that can be non-zero stayed below 1e-3 — the bounds
are neither violated nor vacuous.  A formula error shows up as an O(1) relative error, i.e. ~40
orders of magnitude above these bounds (checked by deliberate mutations of the reference).

Runtime: the ``ci`` profile (300 examples per test) runs this file in about 30 s on two cores;
no test lowers ``max_examples``.
"""

from __future__ import annotations

import math
import os
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from reference import jordan as R
from rfverify import jordan as J
from rfverify.errors import ConeDomainError

LD = np.longdouble
KS = (1, 2, 3, 5)
DPS = 50
CTX = {50: R.context(50), 30: R.context(30)}
HI = R.context(140)  # checking arithmetic: every 50-digit value converts exactly
dps_both = pytest.mark.parametrize("dps", [50, 30])
dtypes = pytest.mark.parametrize("dtype", [np.float64, LD], ids=["float64", "longdouble"])


# ------------------------------------------------------------------------------------------
# checking helpers (all in HI)
# ------------------------------------------------------------------------------------------

_WORST: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def _report_worst_ratios():
    """With REFERENCE_JORDAN_RATIOS=1 (and -s), print the worst error/bound of every check."""
    yield
    if os.environ.get("REFERENCE_JORDAN_RATIOS"):
        print("\nworst error/bound ratios:")
        for what, r in sorted(_WORST.items(), key=lambda t: -t[1]):
            print(f"  {r:9.3g}  {what}")


def H(v):
    """To the checking context (exact for every value of a context of <= 140 digits);
    ±inf (α = inf, cond = inf) maps to ±HI.inf."""
    if isinstance(v, (list, tuple, np.ndarray)):
        return [H(t) for t in v]
    if (hasattr(v, "_mpf_") and mpmath.isinf(v)) or (
        isinstance(v, (float, np.floating)) and np.isinf(v)
    ):
        return HI.inf if v > 0 else -HI.inf
    return R.to_ctx(HI, v)


def mp_u(ctx):
    return H(ctx.eps)


def np_u(dtype):
    return H(np.finfo(dtype).eps)


def o_norm(x):
    x = H(x)
    return HI.sqrt(HI.fsum(x[1:], squared=True)) if len(x) > 1 else HI.zero


def o_lams(x):
    x = H(x)
    n = o_norm(x)
    return x[0] + n, x[0] - n


def o_det(x):
    """Exact x0² − ‖x̄‖² (for k = 1: x0²): exact squares, exact sum, one rounding in HI."""
    x = H(x)
    if len(x) == 1:
        return x[0] * x[0]
    return HI.fsum([x[0] * x[0]] + [-(v * v) for v in x[1:]])


def scale(x):
    x = H(x)
    return abs(x[0]) + o_norm(x)


def kappa(x):
    l1, l2 = o_lams(x)
    return l1 / l2 if l2 > 0 else HI.inf


def o_product(x, y):
    x, y = H(x), H(y)
    return [HI.fdot(x, y)] + [HI.fdot(((x[0], b), (y[0], a))) for a, b in zip(x[1:], y[1:])]


def o_arrow(x):
    x = H(x)
    k = len(x)
    rows = [list(x)]
    for i in range(1, k):
        row = [HI.zero] * k
        row[0], row[i] = x[i], x[0]
        rows.append(row)
    return rows


def matmul(a, b):
    a, b = H(a), H(b)
    cols = list(zip(*b))
    return [[HI.fdot(r, c) for c in cols] for r in a]


def matvec(a, v):
    a, v = H(a), H(v)
    return [HI.fdot(r, v) for r in a]


def o_quad_matrix(x):
    """Textbook Q_x = 2Arw(x)² − Arw(x∘x), independent of the 2xxᵀ − det(x)R formula."""
    a = o_arrow(x)
    a2 = o_arrow(o_product(x, x))
    return [[2 * p - q for p, q in zip(r1, r2)] for r1, r2 in zip(matmul(a, a), a2)]


def maxabs(v):
    return max(abs(t) for t in H(v))


def diff(a, b):
    return max(abs(p - q) for p, q in zip(H(a), H(b)))


def mdiff(a, b):
    return max(diff(r, s) for r, s in zip(a, b))


def eye(k):
    return [[HI.mpf(1) if i == j else HI.zero for j in range(k)] for i in range(k)]


def check(err, bound, what):
    """Assert err <= bound (HI numbers); record the worst ratio per check."""
    err, bound = H(err), H(bound)
    ratio = float(err / bound) if bound else (0.0 if not err else math.inf)
    if ratio > _WORST.get(what, -1.0):
        _WORST[what] = ratio
    if not err <= bound:
        pytest.fail(
            f"{what}: error {HI.nstr(err, 5)} exceeds bound {HI.nstr(bound, 5)} "
            f"(ratio {ratio:.3g})"
        )


# ------------------------------------------------------------------------------------------
# input strategies (float64 values; tests convert them exactly)
# ------------------------------------------------------------------------------------------


def _build_interior(k, log_s, log_rho, dirs):
    lam1 = 10.0**log_s
    lam2 = lam1 * 10.0**log_rho
    if k == 1:
        return [lam1]
    d = np.asarray(dirs, dtype=np.float64)
    m = np.max(np.abs(d))
    bar = np.zeros(k - 1)
    if m > 0:
        r = d / m
        bar = (lam1 - lam2) / 2 * (r / np.sqrt(np.sum(r * r)))
    return [(lam1 + lam2) / 2] + bar.tolist()


def _unit_floats(no_tiny):
    """Floats in [-1, 1]; with no_tiny, values below 2^-60 in magnitude become exact zeros."""
    f = st.floats(-1.0, 1.0)
    return f.map(lambda v: v if abs(v) >= 2.0**-60 else 0.0) if no_tiny else f


def interior(k, log_rho=(-12.0, 0.0), log_scale=(-100.0, 100.0), no_tiny=False):
    """A point of int L^k with λ1 = 10^s, λ2/λ1 = 10^r (up to the rounding of the floats)."""
    return st.tuples(
        st.floats(*log_scale),
        st.floats(*log_rho),
        st.lists(_unit_floats(no_tiny), min_size=k - 1, max_size=k - 1),
    ).map(lambda t: _build_interior(k, *t))


def general(k, log_scale=(-100.0, 100.0), no_tiny=False):
    """An arbitrary vector (inside, outside or on the boundary of the cone) of size 10^s."""
    return st.tuples(
        st.floats(*log_scale), st.lists(_unit_floats(no_tiny), min_size=k, max_size=k)
    ).map(lambda t: [v * 10.0 ** t[0] for v in t[1]])


@st.composite
def cases(draw, kinds, ks=KS, log_rho=(-12.0, 0.0), log_scale=(-100.0, 100.0), no_tiny=False):
    """A tuple of float lists of one common k: kind "i" = interior, "g" = general."""
    k = draw(st.sampled_from(ks))
    return tuple(
        draw(
            interior(k, log_rho, log_scale, no_tiny)
            if kind == "i"
            else general(k, log_scale, no_tiny)
        )
        for kind in kinds
    )


def agreement_cases(kinds):
    """Inputs for the agreement tests: scales 1e±40 and entries 0 or >= 2^-60 relative, so
    that no intermediate of the float64/longdouble computation reaches the subnormal range
    (underflow is a range limit of the dtype, tested in tests/test_jordan.py, not an
    accuracy question; the reference itself is tested on subnormal inputs above)."""
    return cases(kinds, log_scale=(-40.0, 40.0), no_tiny=True)


# pinned hard cases (single cones, float64 values)
NEAR12 = [1.0, 1.0 - 1e-12, 0.0]  # λ2/λ1 ≈ 5e-13
NEAR12_K5 = [2.0, 1.2 * (1 - 1e-12), 0.0, -1.6 * (1 - 1e-12), 0.0]
NEAREPS = [1.0 + 2.0**-52, 1.0]  # λ2 = one ulp of float64: κ ≈ 9e15
XBAR0 = [2.0, 0.0, 0.0]
XBAR0_K2 = [1.5, 0.0]
K1 = [0.7]
HUGE = [1e100, 3e99, 4e99]
TINY = [1e-100, 3e-101, -4e-101]
SUBN = [1.0, 1e-310, 0.0]  # subnormal x̄
MIX5 = [3.0, 0.5, -1.0, 0.25, 2.0]
OUT = [1.0, 2.0, 0.0]  # λ2 = −1
BOUNDARY = [5.0, 3.0, 4.0]  # λ2 = 0 exactly


def partner(x, c=1.0):
    """A well-separated interior partner of the same k and scale."""
    m = max(abs(v) for v in x)
    y = [c * m] + [0.0] * (len(x) - 1)
    if len(x) > 1:
        y[1] = 0.5 * m
    return y


def gen_partner(x):
    """An arbitrary (non-cone) partner of the same k and scale."""
    m = max(abs(v) for v in x)
    return [-0.5 * m] + [m] * (len(x) - 1)


def cv(values, dps=DPS):
    """Float values → exact mpf list of the dps-digit working context."""
    return R.to_ctx(CTX[dps], values)


# ==========================================================================================
# 1. properties of the reference
# ==========================================================================================


@given(case=cases("gg"))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, [-3.0]))
def test_product_commutative_and_correctly_rounded(case):
    """x∘y = y∘x exactly, and every entry is the correctly rounded exact value (≤ u·|entry|).

    Each entry is one ``ctx.fdot`` of exact products: the exact value is symmetric in
    (x, y) and is rounded once, so the two orders agree bit for bit (bound 0), and the
    rounding error is ≤ u/2 relative (u allowed: mpmath's exact sum may drop terms more than
    2·prec bits below the result, which changes it by < 2^-2prec relative)."""
    x, y = (cv(a) for a in case)
    u = mp_u(CTX[DPS])
    a, b = R.product(x, y), R.product(y, x)
    assert a == b
    assert all(v.context is CTX[DPS] for v in a)
    for got, want in zip(a, o_product(x, y)):
        check(abs(H(got) - want), u * abs(want), "x∘y correctly rounded")


@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(SUBN,))
@example(case=(K1,))
def test_identity_is_neutral(case):
    """x∘e = e∘x = x and Q_e x = x exactly (bound 0): x0·1 + Σx̄_i·0 = x0, x0·0 + 1·x̄_i = x̄_i
    and, for Q_e, det e = 1, 2(eᵀx)e − Rx = (2x0 − x0 ; x̄) are exact, and x has at most
    53 significant bits, so rounding to the 50-digit context is exact too."""
    (x,) = (cv(a) for a in case)
    e = R.identity(CTX[DPS], len(x))
    assert R.product(x, e) == x and R.product(e, x) == x
    assert R.quad_apply(e, x) == x
    assert R.power(x, 0) == e and R.power(x, 1) == x


@dps_both
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(NEAR12_K5,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
def test_inverse(dps, case):
    """x∘x⁻¹ = e to 4(k+2)·u·κ; x⁻¹ against the exact R x/(x0² − ‖x̄‖²) to 4(k+2)·u·κ·S(x⁻¹);
    (x⁻¹)⁻¹ = x to 4(k+2)·u·κ·S(x); x⁻¹ ∈ int L.

    x⁻¹ = R x/(λ1λ2) carries the relative error O(u κ) of λ2 as a common factor (forward
    bound, S(x⁻¹) = 1/λ2); x∘x⁻¹ has head (x0² − ‖x̄‖²)/det with terms ≤ λ1²/det = κ, so
    the exact-sum fdot adds only u; the bar part cancels up to u κ.  (x⁻¹)⁻¹ has the same κ."""
    (x,) = (cv(a, dps) for a in case)
    ctx = CTX[dps]
    k = len(x)
    u = mp_u(ctx)
    kap = kappa(x)
    xi = R.inverse(x)
    e = R.identity(ctx, k)
    check(diff(R.product(x, xi), e), 4 * (k + 2) * u * kap, "x∘x⁻¹ − e")
    exact = [v / o_det(x) for v in H(R.reflect(x))] if k > 1 else [1 / H(x[0])]
    check(diff(xi, exact), 4 * (k + 2) * u * kap * scale(exact), "x⁻¹ vs exact Rx/det")
    check(diff(R.inverse(xi), x), 4 * (k + 2) * u * kap * scale(x), "(x⁻¹)⁻¹ − x")
    assert o_lams(xi)[1] > 0
    assert R.power(x, -1) == xi


@dps_both
@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
@example(case=(BOUNDARY,))
@example(case=([0.0, 0.0, 0.0],))
@example(case=([2.0, 0.0, -2.0],))
def test_sqrt_squared(dps, case):
    """(x^{1/2})² = x to 4(k+2)·u·S(x), whatever κ (also on the boundary and at x = 0);
    x^{1/2} ∈ L (λ2 >= −2(k+2)·u·S: on ∂L the rounded entries may step out by that much);
    power(x, ½) is sqrt(x).

    Backward stability of ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)): an error δ in √λ2 only changes the
    c2-coefficient, and squaring turns it into 2√λ2·δ = Δλ2 = O(u λ1); everything else is
    O(u) relative rounding of O(S) terms."""
    (x,) = (cv(a, dps) for a in case)
    k = len(x)
    u = mp_u(CTX[dps])
    r = R.sqrt(x)
    # in L up to the final rounding of its entries (exactly on ∂L when x is)
    assert o_lams(r)[1] >= -2 * (k + 2) * u * scale(r)
    check(diff(o_product(r, r), x), 4 * (k + 2) * u * scale(x), "(√x)² − x")
    check(diff(R.product(r, r), x), 4 * (k + 2) * u * scale(x), "(√x)∘(√x) − x (reference ∘)")
    assert R.power(x, 0.5) == r


@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(SUBN,))
@example(case=(K1,))
def test_quad_of_identity_is_square(case):
    """Q_x e = x∘x to 4(k+2)·u·S(x)² for any x.

    Q_x e = (2x0² − λ1λ2 ; 2x0x̄) against the exact (‖x‖² ; 2x0x̄): the only error is the
    rounding of det x = λ1λ2, absolute λ1Δλ2 + λ2Δλ1 = O(u S²), plus one rounding per entry."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    e = R.identity(CTX[DPS], k)
    check(diff(R.quad_apply(x, e), o_product(x, x)), 4 * (k + 2) * u * scale(x) ** 2, "Q_x e − x²")


@given(case=cases("gg"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, [-2.0]))
def test_quad_equals_arrow_form(case):
    """Q_x y = (2Arw(x)² − Arw(x²)) y to 4(k+2)·u·S(x)²·S(y); quad_matrix(x) equals that
    matrix entrywise to 4(k+2)·u·S(x)²; Arw(x) y = x∘y.

    The oracle matrix is formed exactly (HI) from the textbook arrow form; the reference's
    2(xᵀy)x − det(x)Ry differs by the error of det (absolute O(u S²), times |y|) and one
    rounding per term, and quad_matrix by the same det error per diagonal entry."""
    x, y = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    m = o_quad_matrix(x)
    sx2 = scale(x) ** 2
    check(diff(R.quad_apply(x, y), matvec(m, y)), 4 * (k + 2) * u * sx2 * scale(y),
          "Q_x y − (2Arw² − Arw(x²))y")
    check(mdiff(R.quad_matrix(x), m), 4 * (k + 2) * u * sx2, "quad_matrix − arrow form")
    check(diff(matvec(R.arrow(x), y), o_product(x, y)), HI.eps * scale(x) * scale(y),
          "Arw(x)y − x∘y")


@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
def test_quad_of_inverse_is_inverse_of_quad(case):
    """Q_{x⁻¹} Q_x = I (matrices) to (k+2)²·u·κ² (max entry).

    Q̃_x = Q_x + E, |E| = O(u S²); Q̃_{x⁻¹} = (1+θ)²Q_{x⁻¹} + E' with θ = O(u κ) (the common
    factor of x⁻¹) and |E'| = O(u/λ2²); so the product is I + O(u κ) + ‖Q_{x⁻¹}‖·|E| +
    |E'|·‖Q_x‖ = I + O(k² u κ²) (‖Q_x‖ = λ1², ‖Q_{x⁻¹}‖ = 1/λ2²): κ² = cond(Q_x) is the
    honest amplification."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    prod = matmul(R.quad_matrix(R.inverse(x)), R.quad_matrix(x))
    check(mdiff(prod, eye(k)), (k + 2) ** 2 * u * kappa(x) ** 2, "Q_{x⁻¹}Q_x − I")


@given(case=cases("i"), t=st.integers(-2, 3))
@example(case=(HUGE,), t=3)
@example(case=(TINY,), t=-2)
@example(case=(XBAR0,), t=2)
@example(case=(K1,), t=-2)
@example(case=(NEAR12,), t=2)
@example(case=(NEAR12,), t=-2)
def test_quad_of_integer_power(case, t):
    """Q_{x^t} = (Q_x)^t for integer t ∈ {−2, …, 3} (max entry; (Q_x)^t formed exactly from
    the oracle Q_x, (Q_x)^{−|t|} as (Q_{x⁻¹})^{|t|} from the exact inverse).

    t >= 0: bound (t+1)(k+2)²·u·S(x)^{2t}: x^t has c1-part relative error O(t u) and c2-part
    absolute error t·λ2^{t−1}·Δλ2 = O(t u λ1^t); Q of it adds O(k u S^{2t}).
    t < 0: bound (|t|+1)(k+2)²·u·κ·λ2^{−2|t|}: x^t carries relative error O(|t| u κ) in its
    dominant λ2^t-component."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    lhs = R.quad_matrix(R.power(x, t))
    if t >= 0:
        base = o_quad_matrix(x)
    else:
        xi = [v / o_det(x) for v in H(R.reflect(x))] if k > 1 else [1 / H(x[0])]
        base = o_quad_matrix(xi)
    rhs = eye(k)
    for _ in range(abs(t)):
        rhs = matmul(rhs, base)
    if t >= 0:
        bound = (t + 1) * (k + 2) ** 2 * u * scale(x) ** (2 * t)
    else:
        bound = (-t + 1) * (k + 2) ** 2 * u * kappa(x) * o_lams(x)[1] ** (2 * t)
    check(mdiff(lhs, rhs), bound, f"Q_(x^{t}) − (Q_x)^{t}")


@given(case=cases("gg"))
@example(case=(NEAR12, [1.0, 0.0, 1.0 - 1e-12]))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, [-3.0]))
def test_det_of_quad(case):
    """det(Q_x y) = det(x)² det(y) to 8(k+2)²·u·S(x)⁴·S(y)² absolute (right side exact).

    w = Q_x y has absolute error O(k u S(x)²S(y)) and S(w) ≤ 2S(x)²S(y); det(w) = λ1(w)λ2(w)
    then has absolute error O(S(w)·k u S(x)²S(y)) = O(k u S(x)⁴S(y)²)."""
    x, y = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    lhs = R.det(R.quad_apply(x, y))
    rhs = o_det(x) ** 2 * o_det(y)
    check(abs(H(lhs) - rhs), 8 * (k + 2) ** 2 * u * scale(x) ** 4 * scale(y) ** 2, "det(Q_x y)")


@given(case=cases("gg"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, TINY))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(K1, [-3.0]))
def test_quad_of_quad(case):
    """Q_{Q_x y} = Q_x Q_y Q_x (matrices, right side exact from the oracle) to
    2(k+2)³·u·S(x)⁴·S(y)² (max entry): w = Q_x y has absolute error O(k u S(x)²S(y)) and
    S(w) ≤ 2S(x)²S(y), so Q_w = 2wwᵀ − det(w)R has error O(S(w)·k u S(x)²S(y))."""
    x, y = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    lhs = R.quad_matrix(R.quad_apply(x, y))
    qx = o_quad_matrix(x)
    rhs = matmul(matmul(qx, o_quad_matrix(y)), qx)
    check(mdiff(lhs, rhs), 2 * (k + 2) ** 3 * u * scale(x) ** 4 * scale(y) ** 2,
          "Q_{Q_x y} − Q_xQ_yQ_x")


@given(case=cases("iii"))
@example(case=(HUGE, TINY, HUGE))
@example(case=(NEAR12, NEAR12, NEAR12))
@example(case=(SUBN, XBAR0, SUBN))
@example(case=(K1, [3.0], [1e-100]))
def test_quad_maps_interior_onto_interior(case):
    """Q_x (int L) = int L for x ∈ int L.

    Into: λ2(Q_x y) >= λ2(x)²·λ2(y) exactly (Q_x y ⪰ λ2(y) x² and λ2(x²) = λ2(x)²); the
    computed Q_x y has absolute error ≤ 4(k+2)·u·S(x)²S(y), so λ2(Q_x y) >= λ2(x)²λ2(y) − that
    is asserted, and > 0 — with λ2/λ1 >= 1e-12 the lower bound is >= 1e-36·S(x)²S(y), far
    above the rounding term, so interiority is a real check.
    Onto: for interior t the preimage Q_{x⁻¹} t is interior and Q_x(Q_{x⁻¹} t) = t up to
    4(k+2)²·u·κ(x)²·S(t) (errors of size u S(t)/λ2² amplified by ‖Q_x‖ = λ1²)."""
    x, y, t = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    w = R.quad_apply(x, y)
    l2w = o_lams(w)[1]
    assert l2w > 0
    slack = 4 * (k + 2) * u * scale(x) ** 2 * scale(y)
    assert l2w >= o_lams(x)[1] ** 2 * o_lams(y)[1] - slack
    pre = R.quad_apply(R.inverse(x), t)
    assert o_lams(pre)[1] > 0
    check(diff(R.quad_apply(x, pre), t), 4 * (k + 2) ** 2 * u * kappa(x) ** 2 * scale(t),
          "Q_x Q_{x⁻¹} t − t")


@dps_both
@given(case=cases("ii"))
@example(case=(NEAR12, XBAR0))
@example(case=(NEAR12, [1.0, 0.0, 1.0 - 1e-12]))
@example(case=(NEAR12, [1.0, -(1.0 - 1e-12), 0.0]))
@example(case=(HUGE, TINY))
@example(case=(TINY, HUGE))
@example(case=(SUBN, partner(SUBN)))
@example(case=(XBAR0, [0.5, 0.0, 0.0]))
@example(case=(K1, [3e-100]))
@example(case=(MIX5, partner(MIX5)))
def test_nt_scaling(dps, case):
    """NT point: Q_p z = Q_{p⁻¹} s = λ, Q_{p²} z = s, p∘p⁻¹ = e, p, λ ∈ int L,
    det p = (det s/det z)^{1/4}, det λ = √(det z det s).

    Vector identities (‖·‖∞): 2(k+2)²·u·[(κ(z)+κ(s))·S(λ) + S(p)²S(z) + S(p⁻¹)²S(s)].
    √det z = √λ1√λ2 and √det s carry relative errors O(u κ), which move the common scale √β
    of p, and so Q_p z and Q_{p⁻¹}s in opposite directions, by O(u(κ(z)+κ(s))) relative to λ;
    applying Q_p (Q_{p⁻¹}) adds O(k u ‖p‖² S(z)) (O(k u ‖p⁻¹‖² S(s))).  For Q_{p²} z = s the
    same argument with p² gives 4(k+2)²·u·[(κ(z)+κ(s))·S(s) + S(p)⁴S(z)].
    p∘p⁻¹ = e to 8(k+2)·u·κ(p) (as x∘x⁻¹).  The determinant identities are relative, to
    2(k+2)·u·(κ(z)+κ(s)+κ(λ)+κ(p)): each det involved has relative error O(u κ)."""
    z, s = (cv(a, dps) for a in case)
    ctx = CTX[dps]
    k = len(z)
    u = mp_u(ctx)
    p, p_inv, lam = R.nt_scaling(z, s)
    a = R.quad_apply(p, z)
    b = R.quad_apply(p_inv, s)
    kz, ks = kappa(z), kappa(s)
    bound = 2 * (k + 2) ** 2 * u * (
        (kz + ks) * scale(lam) + scale(p) ** 2 * scale(z) + scale(p_inv) ** 2 * scale(s)
    )
    check(diff(a, b), bound, "Q_p z − Q_{p⁻¹} s")
    check(diff(a, lam), bound, "Q_p z − λ")
    check(diff(b, lam), bound, "Q_{p⁻¹} s − λ")
    w = R.product(p, p)
    check(diff(R.quad_apply(w, z), s),
          4 * (k + 2) ** 2 * u * ((kz + ks) * scale(s) + scale(p) ** 4 * scale(z)), "Q_{p²} z − s")
    assert o_lams(p)[1] > 0 and o_lams(lam)[1] > 0
    kp = kappa(p)
    check(diff(R.product(p, p_inv), R.identity(ctx, k)), 8 * (k + 2) * u * kp, "p∘p⁻¹ − e")
    rel = 2 * (k + 2) * u * (kz + ks + kappa(lam) + kp)
    dz, ds = o_det(z), o_det(s)
    check(abs(o_det(p) / HI.root(ds / dz, 4) - 1), rel, "det p vs (det s/det z)^¼")
    check(abs(o_det(lam) / HI.sqrt(dz * ds) - 1), rel, "det λ vs √(det z det s)")


@given(case=cases("i"))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(K1,))
@example(case=(MIX5,))
def test_cond_quad(case):
    """cond(Q_x) = (λ1/λ2)².

    (a) Against the exact spectral values (HI): relative error ≤ 8(k+2)·u·κ (the relative
    error of λ2, doubled by the square).
    (b) Against the extreme eigenvalues of the reference's own quad_matrix(x), computed by
    mpmath's eigsy in HI: the matrix entries have absolute error O(k u S²), which moves the
    smallest eigenvalue λ2² by that much (Weyl), i.e. relative (k+2)·u·κ²; the ratio is
    asserted to 8(k+2)·u·κ² (κ ≤ 1e12 and u ≈ 1e-50, so this is always meaningful)."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    kap = kappa(x)
    c = R.cond_quad(x)
    check(abs(H(c) / kap**2 - 1), 8 * (k + 2) * u * kap, "cond vs exact (λ1/λ2)²")
    ev = HI.eigsy(HI.matrix(H(R.quad_matrix(x))), eigvals_only=True)
    ev = sorted(ev[i] for i in range(k))
    check(abs((ev[-1] / ev[0]) / H(c) - 1), 8 * (k + 2) * u * kap**2, "cond vs eigenvalues")


@given(case=cases("ig"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, TINY))
@example(case=(TINY, HUGE))
@example(case=(XBAR0, gen_partner(XBAR0)))
@example(case=(K1, [-2.0]))
@example(case=(XBAR0_K2, [1.0, -1.0]))
def test_arrow_solve(case):
    """d = x \\ y: x∘d = y to 8(k+2)·u·κ²·S(y) (residual) and d against the exact solution
    Arw(x)⁻¹y (oracle: exact Cramer-type formula in HI) to 8(k+2)·u·κ·S(y)/λ2 (forward);
    x \\ e = x⁻¹.

    Arw(x) has eigenvalues λ1, x0, λ2, so ‖Arw(x)⁻¹‖ = 1/λ2 and the condition number is κ:
    d0 carries the relative error O(u κ) of det x, the numerator O(u S(x)S(y)), so
    |Δd| = O(u κ S(y)/λ2) (forward); multiplying back by Arw(x) (norm λ1) gives O(u κ² S(y))."""
    x, y = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    kap = kappa(x)
    d = R.arrow_solve(x, y)
    check(diff(o_product(x, d), y), 8 * (k + 2) * u * kap**2 * scale(y), "x∘d − y")
    xh, yh = H(x), H(y)
    if k == 1:
        exact = [yh[0] / xh[0]]
    else:
        d0 = HI.fdot([(xh[0], yh[0])] + [(-a, b) for a, b in zip(xh[1:], yh[1:])]) / o_det(x)
        exact = [d0] + [(b - d0 * a) / xh[0] for a, b in zip(xh[1:], yh[1:])]
    l2 = o_lams(x)[1]
    check(diff(d, exact), 8 * (k + 2) * u * kap * scale(y) / l2, "x \\ y vs exact")
    e = R.identity(CTX[DPS], k)
    xi = R.inverse(x)
    check(diff(R.arrow_solve(x, e), xi), 8 * (k + 2) * u * kap * scale(xi), "x \\ e − x⁻¹")


@given(case=cases("ig"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, [-v for v in HUGE]))
@example(case=(TINY, gen_partner(TINY)))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(XBAR0, [-1.0, 0.0, 0.0]))
@example(case=(K1, [-0.7]))
@example(case=([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))  # boundary reached at α = 1
@example(case=([1.0, 0.0, 0.0], [1.0, 1.0, 0.0]))  # dx on ∂L: never leaves (α = inf)
@example(case=([1e-3, 0.0], [5e-324, 5e-324]))  # tangent subnormal dx
def test_step_to_boundary(case):
    """α = step_to_boundary(x, dx): x + α dx ∈ ∂L and x + 0.99α dx ∈ int L; α = inf iff dx ∈ L.

    Boundary: |λ2(x + α dx)| ≤ 2(k+2)·u·(S(x) + α S(dx))·(κ(x) + α S(dx)/λ2(x)), evaluated
    exactly.  The relative error of α is O(u (κ + α S(dx)/λ2(x))): x^{-1/2} carries a common
    relative error O(u κ), y = Q_{x^{-1/2}} dx an absolute error O(u S(dx)/λ2(x)) against
    |λ2(y)| = 1/α; λ2 along the ray moves by at most 2S(dx) per unit of α.
    inf: then λ2(dx) >= −8(k+2)·u·κ·S(dx) (dx ∈ L up to the rounding of y)."""
    x, dx = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    alpha = R.step_to_boundary(x, dx)
    assert alpha > 0
    kap = kappa(x)
    sdx = scale(dx)
    xh, dh = H(x), H(dx)
    if HI.isinf(H(alpha)):
        assert o_lams(dx)[1] >= -8 * (k + 2) * u * kap * sdx, "α = inf but dx ∉ L"
        return
    a = H(alpha)
    l2x = o_lams(x)[1]
    _, l2b = o_lams([p + a * q for p, q in zip(xh, dh)])
    bound = 2 * (k + 2) * u * (scale(x) + a * sdx) * (kap + a * sdx / l2x)
    check(abs(l2b), bound, "λ2(x + α dx)")
    a99 = a * HI.mpf("0.99")
    assert o_lams([p + a99 * q for p, q in zip(xh, dh)])[1] > 0, "x + 0.99α dx left the cone"


@given(
    case=cases("i", log_rho=(-8.0, 0.0), log_scale=(-30.0, 30.0)),
    p=st.integers(-3072, 3072),
    q=st.integers(-3072, 3072),
)
@example(case=(NEAR12,), p=1024, q=-512)
@example(case=(XBAR0,), p=333, q=-1000)
@example(case=(SUBN,), p=-1536, q=3072)
@example(case=(K1,), p=-2048, q=100)
@example(case=(HUGE,), p=-1536, q=512)
def test_power_additive(case, p, q):
    """x^a ∘ x^b = x^{a+b} for a = p/1024, b = q/1024 ∈ [−3, 3] (a + b exact), x ∈ int L.

    With M(a) = max(λ1^a, λ2^a) and E(a) = (|a|+2)(λ1^a + λ2^a) + |a|·λ1·λ2^{a−1} (the
    computed x^a has absolute error ≤ c·u·E(a): λ1^a relative O(|a| u), the c2-coefficient
    λ2^a absolute |a|λ2^{a−1}·Δλ2 = O(|a| u λ1 λ2^{a−1}), the divided difference O(|a| u)
    relative), the product has error ≤ 2(k+2)·u·[E(a)M(b) + M(a)E(b) + E(a+b)]."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    a_, b_ = p / 1024, q / 1024
    l1, l2 = o_lams(x)

    def E(t):
        t = HI.mpf(t)
        return (abs(t) + 2) * (l1**t + l2**t) + abs(t) * l1 * l2 ** (t - 1)

    def M(t):
        return max(l1**t, l2**t)

    lhs = R.product(R.power(x, a_), R.power(x, b_))
    bound = 2 * (k + 2) * u * (E(a_) * M(b_) + M(a_) * E(b_) + E(a_ + b_))
    check(diff(lhs, R.power(x, a_ + b_)), bound, "x^a∘x^b − x^(a+b)")


@given(
    case=cases("i", ks=(2, 3, 5), log_rho=(-1.0, -0.01), log_scale=(-20.0, 20.0)),
    small=st.floats(-320.0, -1.0),
    p=st.sampled_from([-2.0, -0.5, 1.0 / 3.0, 1.5, 3.0, 1e-3, 7.0]),
)
@example(case=(SUBN,), small=-1.0, p=1.5)
@example(case=(XBAR0,), small=-1.0, p=-2.0)
def test_power_bar_is_accurate_componentwise(case, small, p):
    """Near the axis (‖x̄‖/x0 = 10^small down to 1e-320) the bar part of x^p is D·x̄ with the
    divided difference D = (λ1^p − λ2^p)/(λ1 − λ2); the textbook λ1^p − λ2^p cancels
    completely there (λ1 = λ2 to 50 digits).  The expm1/log1p form keeps D to relative
    accuracy O(|p| u) (κ ≈ 1 here), so each component satisfies
    |bar_i − D*·x̄_i| ≤ 8(|p|+2)(k+2)·u·|D*·x̄_i|, with D* from a 500-digit oracle.  The head
    (λ1^p + λ2^p)/2 has no cancellation (bound 4(|p|+2)·u·|head|).  Same for sqrt (p = ½)."""
    (x,) = (list(a) for a in case)
    m = max(abs(v) for v in x[1:])
    if m == 0:
        x[1] = 1.0
        m = 1.0
    shift = math.floor(small * math.log2(10))
    x = [x[0]] + [math.ldexp(v / m, shift) * x[0] for v in x[1:]]  # exact power-of-two scaling
    xm = cv(x)
    k = len(x)
    u = mp_u(CTX[DPS])
    big = R.context(500)
    xb = R.to_ctx(big, xm)
    n = big.sqrt(big.fsum(xb[1:], squared=True))
    l1, l2 = xb[0] + n, xb[0] - n
    for fn, pp in ((lambda v: R.power(v, p), p), (R.sqrt, 0.5)):
        r = R.to_ctx(big, fn(xm))
        ppb = R.to_ctx(big, pp)
        if l1 == l2:
            assert all(v == 0 for v in r[1:])
            continue
        dstar = (l1**ppb - l2**ppb) / (l1 - l2)
        head = (l1**ppb + l2**ppb) / 2
        assert abs(r[0] - head) <= 4 * (abs(pp) + 2) * u * abs(head), f"head of x^{pp}"
        for j in range(1, k):
            want = dstar * xb[j]
            err = abs(r[j] - want)
            check(err, 8 * (abs(pp) + 2) * (k + 2) * u * abs(want), f"bar of x^p (p={pp})")


@given(case=cases("g"))
@example(case=(NEAR12,))
@example(case=(NEAREPS,))
@example(case=(HUGE,))
@example(case=(TINY,))
@example(case=(SUBN,))
@example(case=(XBAR0,))
@example(case=(XBAR0_K2,))
@example(case=(K1,))
@example(case=([1.5 + 2.0**-52, -1.5],))
def test_spectral_and_det(case):
    """Spectral values against the exact ones to 4(k+2)·u·S(x) (absolute); det against the
    exact x0² − ‖x̄‖² to 4(k+2)·u·S(x)² (absolute: λ1Δλ2 + λ2Δλ1), and to 4u relative when
    x̄ has at most one non-zero entry (then ‖x̄‖ = |x_i| is exact, λ1, λ2 are single roundings
    and det has relative error ≤ 3u + O(u²) whatever κ is — what x0² − ‖x̄‖² cannot do);
    x = λ1c1 + λ2c2 to 4(k+2)·u·S(x); for k >= 2 the frame is a Jordan frame (c1∘c2 = 0,
    ci∘ci = ci to (k+2)·u: x̄/‖x̄‖ has norm 1 ± O(u)); trace = 2x0 exactly."""
    (x,) = (cv(a) for a in case)
    k = len(x)
    u = mp_u(CTX[DPS])
    S = scale(x)
    l1, l2 = R.spectral_values(x)
    m1, m2 = o_lams(x)
    check(max(abs(H(l1) - m1), abs(H(l2) - m2)), 4 * (k + 2) * u * S, "spectral values")
    d = R.det(x)
    truth = o_det(x)
    check(abs(H(d) - truth), 4 * (k + 2) * u * S**2, "det vs x0² − ‖x̄‖²")
    if sum(1 for v in x[1:] if v) <= 1:
        check(abs(H(d) - truth), 4 * u * abs(truth), "det relative (exact ‖x̄‖)")
    assert R.trace(x) == 2 * x[0]
    c1, c2 = R.spectral_frames(x)
    recon = [H(l1) * a + H(l2) * b for a, b in zip(H(c1), H(c2))]
    check(diff(recon, x), 4 * (k + 2) * u * S, "λ1c1 + λ2c2 − x")
    if k > 1:
        check(maxabs(o_product(c1, c2)), (k + 2) * u, "c1∘c2")
        check(diff(o_product(c1, c1), c1), (k + 2) * u, "c1∘c1 − c1")
        check(diff(o_product(c2, c2), c2), (k + 2) * u, "c2∘c2 − c2")
        assert [a + b for a, b in zip(c1, c2)] == R.identity(CTX[DPS], k)
    check(abs(H(R.bar_norm(x)) - o_norm(x)), 2 * u * o_norm(x), "‖x̄‖")
    check(abs(H(R.dot(x, x)) - HI.fsum(H(x), squared=True)), u * HI.fsum(H(x), squared=True),
          "xᵀx")


# ---- explicit cases: domain errors, k = 1, conversion ------------------------------------


def test_k1_semantics():
    """L^1 = R_+: λ1 = λ2 = x0, det = x0², x⁻¹ = 1/x0, x^p = x0^p, Q_x y = x0² y0, cond = 1,
    NT: p = (s/z)^{1/4}, λ = √(zs)."""
    c = CTX[DPS]
    x, y = cv([2.0]), cv([3.0])
    assert R.product(x, y) == [6]
    assert R.spectral_values(x) == (2, 2)
    assert R.det(x) == 4 and R.inverse(x) == [0.5]
    assert R.quad_apply(x, y) == [12]
    assert R.cond_quad(x) == 1 and R.cond_quad(cv([0.0])) == c.inf
    assert abs(R.power(x, 1.5)[0] - c.mpf(2) ** 1.5) <= c.eps * 4
    assert R.sqrt(cv([4.0])) == [2]
    assert R.arrow_solve(x, y) == [1.5]
    assert abs(R.step_to_boundary(x, cv([-4.0])) - 0.5) <= 4 * c.eps
    assert R.step_to_boundary(x, y) == c.inf
    p, p_inv, lam = R.nt_scaling(cv([2.0]), cv([8.0]))
    assert abs(p[0] - c.sqrt(2)) <= 2 * c.eps and abs(lam[0] - 4) <= 4 * c.eps
    assert abs(p[0] * p_inv[0] - 1) <= 2 * c.eps
    assert R.identity(c, 1) == [1] and R.reflect(x) == x and R.arrow(x) == [[2]]
    assert R.spectral_frames(x) == ([0.5], [0.5]) and R.bar_norm(x) == 0


def test_x_bar_zero_uses_first_axis_frame():
    c1, c2 = R.spectral_frames(cv([3.0, 0.0, 0.0]))
    assert c1 == [0.5, 0.5, 0] and c2 == [0.5, -0.5, 0]
    r = R.power(cv([4.0, 0.0, 0.0]), -1.5)
    assert abs(r[0] - 0.125) <= 2 * CTX[DPS].eps and r[1:] == [0, 0]


def _expect_domain(fn, op, value=None):
    with pytest.raises(R.ReferenceDomainError) as ei:
        fn()
    err = ei.value
    assert isinstance(err, ValueError)
    assert err.operation == op and str(err).startswith(op + ":")
    if value is not None:
        assert err.value == value
    return err


def test_domain_errors():
    out, bnd, zero = cv(OUT), cv(BOUNDARY), cv([0.0, 0.0, 0.0])
    good = cv([2.0, 0.5, 0.5])
    _expect_domain(lambda: R.sqrt(out), "sqrt", -1)
    assert R.sqrt(bnd)[0] > 0 and R.sqrt(zero) == [0, 0, 0]  # closed cone allowed
    _expect_domain(lambda: R.inverse(bnd), "inverse", 0)
    _expect_domain(lambda: R.inverse(cv([-5.0, 3.0, 4.0])), "inverse", 0)  # ∂(−L)
    _expect_domain(lambda: R.inverse(cv([0.0])), "inverse", 0)
    # outside L ∪ −L and inside −L the inverse exists
    for v in ([1.0, 2.0, 0.0], [-3.0, 1.0, 1.0]):
        xv = cv(v)
        assert diff(R.product(xv, R.inverse(xv)), [1, 0, 0]) < 1e-48
    for p in (0.5, 1.5, -0.5, 1.0 / 3.0):
        _expect_domain(lambda: R.power(out, p), "power", -1)
    for p in (-0.5, -2, -1):
        _expect_domain(lambda: R.power(bnd, p), "power")
    r = R.power(bnd, 1.5)  # λ1^p c1 on the boundary, λ1 = 10
    c = CTX[DPS]
    want = [c.mpf(10) ** 1.5 / 2, c.mpf(10) ** 1.5 * 3 / 10, c.mpf(10) ** 1.5 * 4 / 10]
    assert diff(r, want) < 1e-48
    assert R.power(zero, 0.7) == [0, 0, 0]
    # integer powers outside the cone: binary powering
    y = cv([0.5, 2.0, -1.0])
    assert diff(R.power(y, 3), R.product(y, R.product(y, y))) < 1e-48
    assert diff(R.power(y, -2), R.product(R.inverse(y), R.inverse(y))) < 1e-48
    _expect_domain(lambda: R.power(good, float("nan")), "power")
    _expect_domain(lambda: R.cond_quad(out), "cond_quad", -1)
    assert R.cond_quad(bnd) == c.inf
    err = _expect_domain(lambda: R.nt_scaling(bnd, good), "nt_scaling", 0)
    assert "'z'" in str(err)
    err = _expect_domain(lambda: R.nt_scaling(good, out), "nt_scaling", -1)
    assert "'s'" in str(err)
    _expect_domain(lambda: R.step_to_boundary(bnd, good), "step_to_boundary", 0)
    _expect_domain(lambda: R.arrow_solve(bnd, good), "arrow_solve", 0)
    _expect_domain(lambda: R.arrow_solve(cv([0.0, 1.0, 1.0]), good), "arrow_solve")
    # k = 2, x0 = 0: Arw(x) = [[0, 1], [1, 0]] is invertible
    assert R.arrow_solve(cv([0.0, 1.0]), cv([2.0, 3.0])) == [3, 2]
    e = R.identity(c, 3)
    assert R.step_to_boundary(e, [-v for v in e]) == 1
    assert R.step_to_boundary(e, e) == c.inf and R.step_to_boundary(e, cv([0.0] * 3)) == c.inf


X3 = [2.0, 0.5, -0.5]
D3 = [0.1, -0.3, 0.2]

REF_PUBLIC = {
    "product": lambda x, y: R.product(x, y),
    "arrow": lambda x, y: R.arrow(x),
    "reflect": lambda x, y: R.reflect(x),
    "dot": lambda x, y: R.dot(x, y),
    "bar_norm": lambda x, y: R.bar_norm(x),
    "trace": lambda x, y: R.trace(x),
    "spectral_values": lambda x, y: R.spectral_values(x),
    "spectral_frames": lambda x, y: R.spectral_frames(x),
    "det": lambda x, y: R.det(x),
    "inverse": lambda x, y: R.inverse(x),
    "sqrt": lambda x, y: R.sqrt(x),
    "power": lambda x, y: R.power(x, -1.5),
    "quad_apply": lambda x, y: R.quad_apply(x, y),
    "quad_matrix": lambda x, y: R.quad_matrix(x),
    "arrow_solve": lambda x, y: R.arrow_solve(x, y),
    "nt_scaling": lambda x, y: R.nt_scaling(x, [2 * v for v in x]),
    "step_to_boundary": lambda x, y: R.step_to_boundary(x, y),
    "cond_quad": lambda x, y: R.cond_quad(x),
}
BINARY = ("product", "dot", "quad_apply", "arrow_solve", "step_to_boundary")


def test_reference_api_is_covered():
    assert set(REF_PUBLIC) | {"identity", "context", "to_ctx", "NTScaling",
                              "ReferenceDomainError"} == set(R.__all__)


@pytest.mark.parametrize("name", sorted(REF_PUBLIC))
@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_nonfinite_input_raises(name, bad):
    c = CTX[DPS]
    x = cv(X3)
    x[1] = c.mpf(bad)
    err = _expect_domain(lambda: REF_PUBLIC[name](x, cv(D3)), name)
    assert "not finite" in str(err)
    if name in BINARY:
        y = cv(D3)
        y[2] = c.mpf(bad)
        _expect_domain(lambda: REF_PUBLIC[name](cv(X3), y), name)
        _expect_domain(lambda: REF_PUBLIC[name](cv(X3), [0.1, float(bad), 0.2]), name)


@pytest.mark.parametrize("name", sorted(REF_PUBLIC))
def test_bad_arguments(name):
    with pytest.raises(TypeError, match="to_ctx"):  # no mpf: no working precision
        REF_PUBLIC[name](X3, D3)
    with pytest.raises(ValueError):
        REF_PUBLIC[name]([], [])
    if name in BINARY:
        with pytest.raises(ValueError, match="dimension"):
            REF_PUBLIC[name](cv(X3), cv(D3[:2]))


def test_to_ctx_and_context():
    c = R.context(20)
    assert c.dps == 20 and c is not mpmath.mp and R.context(20) is not c
    with pytest.raises(ValueError):
        R.context(0)
    # binary floats (any numpy width) and ints are exact even at 20 digits (67 bits)
    third = LD(1) / 3
    v = R.to_ctx(c, third)
    num, den = third.as_integer_ratio()
    assert v * den == num and v.context is c
    num, den = (0.1).as_integer_ratio()
    assert R.to_ctx(c, 0.1) * den == num
    assert R.to_ctx(c, np.float32(0.1)) == mpmath.mpf(float(np.float32(0.1)))
    assert R.to_ctx(c, 2**100 + 1) - 2**100 == 1
    assert R.to_ctx(c, np.int64(-7)) == -7
    # mpf of another context and strings are rounded to the target precision
    hi = R.context(60)
    w = R.to_ctx(c, hi.sqrt(2))
    assert w.context is c and w == c.sqrt(2)
    assert R.to_ctx(c, "0.1") == c.mpf("0.1")
    assert R.to_ctx(c, Fraction(1, 3)) == c.mpf(1) / 3
    assert R.to_ctx(c, [[1, 2.5], (3,)]) == [[1, 2.5], [3]]
    assert R.to_ctx(c, np.array([1.0, 2.0])) == [1, 2]
    for bad in (float("nan"), float("inf"), LD("-inf"), "nan", mpmath.mpf("inf")):
        _expect_domain(lambda: R.to_ctx(c, [1.0, bad]), "to_ctx")
    with pytest.raises(TypeError):
        R.to_ctx(c, 1 + 2j)
    with pytest.raises(TypeError):
        R.to_ctx(c, "abc")


def test_mixed_inputs_follow_first_argument():
    """The working context is that of the first argument; other mpf are rounded into it,
    plain floats converted exactly."""
    c30, c60 = R.context(30), R.context(60)
    x = R.to_ctx(c30, X3)
    y = [c60.sqrt(2), c60.mpf(0), c60.mpf(1) / 3]
    r = R.product(x, y)
    assert all(v.context is c30 for v in r)
    assert r == R.product(x, R.to_ctx(c30, y))
    assert R.product(x, D3) == R.product(x, R.to_ctx(c30, D3))
    r = R.product([2.0, 0.5, c60.mpf(1)], D3)  # first mpf found sets the context
    assert all(v.context is c60 for v in r)


# ==========================================================================================
# 2. agreement between implementations
# ==========================================================================================

REF = CTX[DPS]


def _cast(values, dtype):
    """float64 list → array of dtype.  For longdouble, jitter every entry at the 2^-60 level
    so the inputs have bits below float64 precision (a production path that silently drops to
    float64 then shows up); λ2 can only grow (head enlarged, |x̄_i| by at most that factor)."""
    a = np.asarray(values, dtype=np.float64)
    if dtype is np.float64:
        return a.copy()
    x = a.astype(LD)
    h = (np.arange(x.size) * 7919 % 997) / LD(997)
    jit = np.ldexp(LD(1), -60)
    x[0] *= 1 + jit * (1 + h[0])
    x[1:] *= 1 + jit * (2 * h[1:] - 1)
    return x


def _np_scalar(v):
    return np.asarray(v)[()]


def _E(l1, l2, p):
    """Error scale of x^p: (|p|+2)(λ1^p + λ2^p) + |p|·λ1·λ2^{p−1} (see test_power_additive)."""
    p = HI.mpf(p)
    return (abs(p) + 2) * (l1**p + l2**p) + abs(p) * l1 * l2 ** (p - 1)


POWERS = [-3, -2, -1.5, -1, -0.5, 1.0 / 3.0, 0.5, 1.5, 2, 3]
# production functions covered by the agreement tests below
AGREEMENT_COVERED = {
    "identity", "jordan_product", "arrow", "reflect", "spectral_values", "spectral_frames",
    "det", "trace", "inverse", "power", "sqrt", "quad_apply", "quad_matrix", "arrow_solve",
    "cond_quad", "nt_scaling", "step_to_boundary", "max_step", "min_lambda2",
}


def test_agreement_covers_every_production_function():
    assert AGREEMENT_COVERED | {"NTScaling"} == set(J.__all__)


@dtypes
@given(case=agreement_cases("i"), p=st.sampled_from(POWERS))
@example(case=(NEAR12,), p=-0.5)
@example(case=(NEAREPS,), p=1.5)
@example(case=(HUGE,), p=-1)
@example(case=(SUBN,), p=1.0 / 3.0)
@example(case=(XBAR0,), p=3)
@example(case=(K1,), p=-1.5)
@example(case=(MIX5,), p=2)
def test_agreement_unary(dtype, case, p):
    """rfverify.jordan (dtype) against the reference at 50 digits on the same inputs, for
    every one-argument function, x ∈ int L.  u = eps(dtype), bounds (forward errors of a
    backward-stable evaluation; the reference's own error, ~1e-50, is negligible):

    * identity, arrow, reflect, trace: exact (bound 0);
    * spectral_values, min_lambda2: 4(k+2)·u·S (absolute; ‖x̄‖ relative O(k u));
    * det: 8(k+2)·u·S² (λ1Δλ2 + λ2Δλ1);
    * spectral_frames: 4(k+2)·u (unit vector x̄/‖x̄‖; exact first-axis frame for x̄ = 0);
    * quad_matrix: 4(k+2)·u·S² (det error on the diagonal, one rounding elsewhere);
    * inverse: 4(k+2)·u·κ·S(x⁻¹) (common relative error O(k u κ) of det);
    * sqrt: 4(k+2)·u·√κ·S(√x) (√λ2 has absolute error Δλ2/(2√λ2) = O(k u λ1/√λ2));
    * power p: 4(k+2)·u·E(p) with E as in test_power_additive;
    * cond_quad: relative 8(k+2)·u·κ.
    """
    (xf,) = case
    xd = _cast(xf, dtype)
    x = R.to_ctx(REF, xd)  # the exact dtype values
    k = len(x)
    u = np_u(dtype)
    S = scale(x)
    kap = kappa(x)
    l1h, l2h = o_lams(x)
    what = f"[{np.dtype(dtype).name}]"
    assert H(J.identity(k, dtype=dtype).tolist()) == H(R.identity(REF, k))
    assert H(J.arrow(xd).tolist()) == H(R.arrow(x))
    assert H(J.reflect(xd).tolist()) == H(R.reflect(x))
    assert H(_np_scalar(J.trace(xd))) == H(R.trace(x))
    l1, l2 = J.spectral_values(xd)
    r1, r2 = R.spectral_values(x)
    check(max(abs(H(l1) - H(r1)), abs(H(l2) - H(r2))), 4 * (k + 2) * u * S,
          f"spectral_values {what}")
    check(abs(H(J.min_lambda2(xd)[0]) - H(r2)), 4 * (k + 2) * u * S, f"min_lambda2 {what}")
    check(abs(H(J.det(xd)) - H(R.det(x))), 8 * (k + 2) * u * S**2, f"det {what}")
    (c1, c2), (q1, q2) = J.spectral_frames(xd), R.spectral_frames(x)
    check(max(diff(c1, q1), diff(c2, q2)), 4 * (k + 2) * u, f"spectral_frames {what}")
    check(mdiff(J.quad_matrix(xd), R.quad_matrix(x)), 4 * (k + 2) * u * S**2,
          f"quad_matrix {what}")
    ri = R.inverse(x)
    check(diff(J.inverse(xd), ri), 4 * (k + 2) * u * kap * scale(ri), f"inverse {what}")
    rs = R.sqrt(x)
    check(diff(J.sqrt(xd), rs), 4 * (k + 2) * u * HI.sqrt(kap) * scale(rs), f"sqrt {what}")
    check(diff(J.power(xd, p), R.power(x, p)), 4 * (k + 2) * u * _E(l1h, l2h, p),
          f"power {what}")
    check(abs(H(J.cond_quad(xd)) / H(R.cond_quad(x)) - 1), 8 * (k + 2) * u * kap,
          f"cond_quad {what}")


@dtypes
@given(case=agreement_cases("ig"))
@example(case=(NEAR12, gen_partner(NEAR12)))
@example(case=(HUGE, [-v for v in HUGE]))
@example(case=(SUBN, gen_partner(SUBN)))
@example(case=(XBAR0, [-1.0, 0.5, 0.0]))
@example(case=(K1, [-0.7]))
@example(case=([1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
def test_agreement_binary(dtype, case):
    """Two-argument functions, x ∈ int L, y arbitrary (u = eps(dtype)):

    * jordan_product: 4(k+2)·u·S(x)S(y) (each entry a k-term sum of products);
    * quad_apply: 4(k+2)²·u·S(x)²S(y) (det error times |y|, plus the k-term dot product);
    * arrow_solve: 8(k+2)·u·κ·S(y)/λ2(x) (forward error, cond(Arw(x)) = κ, ‖Arw⁻¹‖ = 1/λ2);
    * step_to_boundary, max_step (α_max = 1): relative 4(k+2)·u·(κ + α S(y)/λ2(x)) (see
      test_step_to_boundary); if either side says "never leaves" (inf) or the float side
      saturates at the dtype's largest number, the other side's λ2(Q_{x^{-1/2}} y) must be
      within that error of 0, i.e. 1/α ≤ 4(k+2)·u·S(y)/λ2(x)·κ.
    """
    xf, yf = case
    xd, yd = _cast(xf, dtype), _cast(yf, dtype)
    x, y = R.to_ctx(REF, xd), R.to_ctx(REF, yd)
    k = len(x)
    u = np_u(dtype)
    kap = kappa(x)
    l2x = o_lams(x)[1]
    what = f"[{np.dtype(dtype).name}]"
    check(diff(J.jordan_product(xd, yd), R.product(x, y)), 4 * (k + 2) * u * scale(x) * scale(y),
          f"jordan_product {what}")
    check(diff(J.quad_apply(xd, yd), R.quad_apply(x, y)),
          4 * (k + 2) ** 2 * u * scale(x) ** 2 * scale(y), f"quad_apply {what}")
    check(diff(J.arrow_solve(xd, yd), R.arrow_solve(x, y)), 8 * (k + 2) * u * kap * scale(y) / l2x,
          f"arrow_solve {what}")
    a_prod = H(_np_scalar(J.step_to_boundary(xd, yd)))
    a_ref = H(R.step_to_boundary(x, y))
    sat = a_prod == H(np.finfo(dtype).max)
    small = 4 * (k + 2) * u * kap * scale(y) / l2x  # error in λ2(y) = −1/α
    if HI.isinf(a_ref) or HI.isinf(a_prod) or sat:
        finite = [a for a in (a_ref, a_prod) if not HI.isinf(a) and a != H(np.finfo(dtype).max)]
        for a in finite:
            assert 1 / a <= small, f"step: one side inf, other α = {a}"
    else:
        rel = 4 * (k + 2) * u * (kap + a_ref * scale(y) / l2x)
        check(abs(a_prod / a_ref - 1), rel, f"step_to_boundary {what}")
        ms = H(_np_scalar(J.max_step(xd, yd)))
        check(abs(ms - min(a_ref, HI.mpf(1))), rel * min(a_ref, HI.mpf(1)), f"max_step {what}")


@dtypes
@given(case=agreement_cases("ii"))
@example(case=(NEAR12, XBAR0))
@example(case=(NEAR12, [1.0, 0.0, 1.0 - 1e-12]))
@example(case=(HUGE, TINY))
@example(case=(SUBN, partner(SUBN)))
@example(case=(K1, [3e-50]))
@example(case=(MIX5, partner(MIX5)))
def test_agreement_nt_scaling(dtype, case):
    """rfverify.jordan.nt_scaling against the reference (u = eps(dtype), K = κ(z) + κ(s)):
    p, p⁻¹, λ each to 4(k+2)²·u·K·S(field); β (= det p) relative 4(k+2)·u·K; v = p/√β to
    4(k+2)²·u·K·S(v); cond (= κ(p)², computed by the production as λ1(v)⁴) relative
    8(k+2)·u·K·κ(p).

    The NT quantities depend on (z, s) through z̄ = z/√det z and s̄ = s/√det s and the scalar
    (det s/det z)^{1/8}; √det z = √λ1√λ2 carries relative error O(k u κ(z)) (likewise for s),
    the unit-determinant construction (γ >= 1, w̄0 >= 1, denominators >= 4) adds only O(k u)
    relative to the scale of each field, so the forward error is O(k² u K) times the scale.
    cond = κ(p)² additionally inherits the relative error of λ2(p) (conditioning κ(p))."""
    zf, sf = case
    zd, sd = _cast(zf, dtype), _cast(sf, dtype)
    z, s = R.to_ctx(REF, zd), R.to_ctx(REF, sd)
    k = len(z)
    u = np_u(dtype)
    kk = kappa(z) + kappa(s)
    what = f"[{np.dtype(dtype).name}]"
    got = J.nt_scaling(zd, sd)
    p, p_inv, lam = R.nt_scaling(z, s)
    for name, a, b in (("p", got.p, p), ("p_inv", got.p_inv, p_inv), ("lam", got.lam, lam)):
        check(diff(a, b), 4 * (k + 2) ** 2 * u * kk * scale(b), f"nt_scaling.{name} {what}")
    beta = o_det(p)
    check(abs(H(got.beta) / beta - 1), 4 * (k + 2) * u * kk, f"nt_scaling.beta {what}")
    v = [H(t) / HI.sqrt(beta) for t in p]
    check(diff(got.v, v), 4 * (k + 2) ** 2 * u * kk * scale(v), f"nt_scaling.v {what}")
    kp = kappa(p)
    check(abs(H(got.cond) / kp**2 - 1), 8 * (k + 2) * u * kk * kp, f"nt_scaling.cond {what}")


DOMAIN_PAIRS = [  # (production call, reference call, point outside the domain)
    ("sqrt", lambda x: J.sqrt(x), lambda x: R.sqrt(x), OUT),
    ("inverse", lambda x: J.inverse(x), lambda x: R.inverse(x), BOUNDARY),
    ("power", lambda x: J.power(x, -0.5), lambda x: R.power(x, -0.5), BOUNDARY),
    ("power", lambda x: J.power(x, 1.5), lambda x: R.power(x, 1.5), OUT),
    ("power", lambda x: J.power(x, -2), lambda x: R.power(x, -2), BOUNDARY),
    ("cond_quad", lambda x: J.cond_quad(x), lambda x: R.cond_quad(x), OUT),
    ("nt_scaling", lambda x: J.nt_scaling(x, X3), lambda x: R.nt_scaling(x, cv(X3)), BOUNDARY),
    ("nt_scaling", lambda x: J.nt_scaling(X3, x), lambda x: R.nt_scaling(cv(X3), x), OUT),
    ("step_to_boundary", lambda x: J.step_to_boundary(x, D3),
     lambda x: R.step_to_boundary(x, cv(D3)), BOUNDARY),
    ("arrow_solve", lambda x: J.arrow_solve(x, D3), lambda x: R.arrow_solve(x, cv(D3)), BOUNDARY),
]


@pytest.mark.parametrize("op, prod, ref, point", DOMAIN_PAIRS,
                         ids=[f"{t[0]}-{i}" for i, t in enumerate(DOMAIN_PAIRS)])
def test_domain_agreement(op, prod, ref, point):
    """Both implementations refuse the same out-of-domain point, naming the same operation
    (ConeDomainError in production, ReferenceDomainError in the reference)."""
    with pytest.raises(ConeDomainError) as ei:
        prod(np.asarray(point))
    assert ei.value.operation == op
    _expect_domain(lambda: ref(cv(point)), op)


def test_longdouble_agreement_is_strictly_better_than_float64():
    """On well-conditioned data (κ ≤ 10, scale 0.1…10, k ∈ {2, 3, 5}) every production
    function's longdouble result (computed from the *same* float64 inputs, cast exactly) must
    be closer to the 50-digit reference than the float64 result.  Errors are measured relative
    to the size of the result and divided by (k+2)·κ(x)·κ(s) (for the step by
    (k+2)·(κ(x) + α S(y)/λ2(x)), its conditioning, see test_step_to_boundary).  Per function,
    the worst longdouble error over 24 cases must be below 4·eps(longdouble) (observed: ≤ 0.17
    eps; 4·eps(longdouble) is 1/512 of eps(float64)) and at least 16× smaller than the worst
    float64 error (observed: float64 errors 0.02–0.12 eps(float64), i.e. ≥ 300× larger).  A
    longdouble path that silently went through float64 would have float64-size errors and
    fail both.  (Exact functions — identity, arrow, reflect, trace — are excluded.)"""
    rng = np.random.default_rng(20240611)
    err = {np.float64: {}, LD: {}}
    for i in range(24):
        k = (2, 3, 5)[i % 3]
        pts = []
        for _ in range(3):
            d = rng.normal(size=k - 1)
            d /= np.linalg.norm(d)
            l1 = 10.0 ** rng.uniform(-1, 1)
            l2 = l1 * 10.0 ** rng.uniform(-1, 0)
            pts.append(np.concatenate([[(l1 + l2) / 2], (l1 - l2) / 2 * d]))
        xf, sf, yf = pts
        yf = yf - 2 * xf  # direction leaving the cone
        x, s, y = (R.to_ctx(REF, a) for a in (xf, sf, yf))
        ref = {
            "jordan_product": R.product(x, y),
            "spectral_values": list(R.spectral_values(x)),
            "spectral_frames": R.spectral_frames(x)[0],
            "det": [R.det(x)],
            "inverse": R.inverse(x),
            "power": R.power(x, 1.0 / 3.0),
            "sqrt": R.sqrt(x),
            "quad_apply": R.quad_apply(x, y),
            "quad_matrix": [v for row in R.quad_matrix(x) for v in row],
            "arrow_solve": R.arrow_solve(x, y),
            "cond_quad": [R.cond_quad(x)],
            "nt_scaling": [v for f in R.nt_scaling(x, s) for v in f],
            "step_to_boundary": [R.step_to_boundary(x, y)],
            "max_step": [min(R.step_to_boundary(x, y), 1)],
            "min_lambda2": [R.spectral_values(x)[1]],
        }
        # relative to the size of the result and to the conditioning of the data (for the
        # step: κ + α S(y)/λ2(x), see test_step_to_boundary)
        cond = kappa(x) * kappa(s) * (k + 2)
        alpha = H(ref["step_to_boundary"][0])
        cond_step = (kappa(x) + alpha * scale(y) / o_lams(x)[1]) * (k + 2)
        for dtype in (np.float64, LD):
            xd, sd, yd = (a.astype(dtype) for a in (xf, sf, yf))
            got = {
                "jordan_product": J.jordan_product(xd, yd),
                "spectral_values": list(J.spectral_values(xd)),
                "spectral_frames": J.spectral_frames(xd)[0],
                "det": [J.det(xd)],
                "inverse": J.inverse(xd),
                "power": J.power(xd, 1.0 / 3.0),
                "sqrt": J.sqrt(xd),
                "quad_apply": J.quad_apply(xd, yd),
                "quad_matrix": J.quad_matrix(xd).ravel(),
                "arrow_solve": J.arrow_solve(xd, yd),
                "cond_quad": [J.cond_quad(xd)],
                "nt_scaling": np.concatenate(J.nt_scaling(xd, sd)[:3]),
                "step_to_boundary": [J.step_to_boundary(xd, yd)],
                "max_step": [J.max_step(xd, yd)],
                "min_lambda2": [J.min_lambda2(xd)[0]],
            }
            for name, want in ref.items():
                c = cond_step if name in ("step_to_boundary", "max_step") else cond
                e = diff([_np_scalar(v) for v in got[name]], want) / (maxabs(want) * c)
                err[dtype][name] = max(err[dtype].get(name, HI.zero), e)
    tol_ld = 4 * np_u(LD)
    assert set(err[LD]) | {"identity", "arrow", "reflect", "trace", "NTScaling"} == set(J.__all__)
    assert tol_ld < np_u(np.float64) / 2
    for name in err[LD]:
        e64, eld = err[np.float64][name], err[LD][name]
        if os.environ.get("REFERENCE_JORDAN_RATIOS"):
            print(name, float(e64 / np_u(np.float64)), float(eld / np_u(LD)))
        assert eld <= tol_ld, f"{name}: longdouble error {HI.nstr(eld, 3)} is not extended"
        assert 16 * eld < e64, (
            f"{name}: longdouble error {HI.nstr(eld, 3)} not clearly below float64 "
            f"{HI.nstr(e64, 3)}"
        )


# ==========================================================================================
# 3. precision hygiene
# ==========================================================================================


def _call_all(x, y):
    """Every reference function on (x, y); returns the flattened list of mpf results."""
    ctx = x[0].context
    out = [R.identity(ctx, len(x))]
    for name, fn in REF_PUBLIC.items():
        r = fn(x, y if name != "step_to_boundary" else [a - 2 * b for a, b in zip(y, x)])
        out.append(r)
    out.append(R.power(x, 3))
    out.append(R.power(x, 1.0 / 3.0))

    def flat(r):
        if isinstance(r, (list, tuple)):
            return [v for t in r for v in flat(t)]
        return [r]

    return flat(out)


@pytest.mark.parametrize("global_prec", [53, 300])
def test_reference_never_changes_global_precision(global_prec):
    """With mpmath.mp at 53 or 300 bits, every function computed in a private 30-digit
    context: mp.prec is unchanged afterwards, every result is an mpf of the private context
    rounded to its 103 bits, and the results do not depend on mp's precision at all."""
    c = R.context(30)
    x, y = R.to_ctx(c, [2.0, 0.7, -0.3, 0.2]), R.to_ctx(c, [1.5, 0.3, 0.2, -0.1])
    base = _call_all(x, y)
    with mpmath.workprec(global_prec):
        res = _call_all(x, y)
        assert mpmath.mp.prec == global_prec
    assert res == base
    assert all(v.context is c for v in res)
    assert all(v._mpf_[3] <= c.prec for v in res)  # mantissa bits
    assert c.prec == 103 and c.dps == 30


def test_thirty_digit_results_carry_thirty_digits():
    """Results of a 30-digit context are accurate to 30 digits — no more, no fewer.

    (a) √2 via sqrt((2; 0, 0)): within 10^-30·√2 of the true √2, but not within 10^-40.
    (b) Independent oracles (exact formulas in HI) on well-conditioned data (κ ≈ 4): det,
        x∘y, x⁻¹, (√x)², Q_x y, Q_p z = Q_{p⁻¹} s from the 30-digit results, each to
        64·10^-30 relative to the scale of the result.
    (c) Every function: the 30-digit results (global mp at 53 bits) agree with the 60-digit
        results (computed while the global mp is at 100 digits, so that a function leaking
        the global precision would show up as a mismatch) to 64·10^-30 relative, and differ
        from them by more than 10^-40 somewhere (the 30-digit results are not secretly more
        precise)."""
    c30, c60 = R.context(30), R.context(60)
    tol = 64 * HI.mpf(10) ** -30
    r30 = R.sqrt(R.to_ctx(c30, [2.0, 0.0, 0.0]))[0]
    assert r30.context is c30
    err = abs(H(r30) - HI.sqrt(2))
    assert HI.mpf(10) ** -40 < err <= HI.mpf(10) ** -30 * HI.sqrt(2)
    xs, ys = [2.0, 0.7, -0.3, 0.2], [1.5, 0.3, 0.2, -0.1]
    x, y = R.to_ctx(c30, xs), R.to_ctx(c30, ys)
    assert abs(H(R.det(x)) / o_det(x) - 1) <= tol
    assert diff(R.product(x, y), o_product(x, y)) <= tol * scale(x) * scale(y)
    xi = R.inverse(x)
    assert diff(o_product(x, xi), [1, 0, 0, 0]) <= tol
    r = R.sqrt(x)
    assert diff(o_product(r, r), x) <= tol * scale(x)
    assert diff(R.quad_apply(x, y), matvec(o_quad_matrix(x), y)) <= tol * scale(x) ** 2 * scale(y)
    s = [a + b for a, b in zip(x, R.to_ctx(c30, [1.0, 0.0, 0.0, 0.0]))]
    p, p_inv, lam = R.nt_scaling(x, s)
    qpz = matvec(o_quad_matrix(p), x)
    assert diff(qpz, matvec(o_quad_matrix(p_inv), s)) <= tol * scale(lam)
    assert diff(qpz, lam) <= tol * scale(lam)
    a = _call_all(x, y)
    with mpmath.workdps(100):
        b = _call_all(R.to_ctx(c60, xs), R.to_ctx(c60, ys))
    assert len(a) == len(b)
    worst = max(abs(H(p) - H(q)) / max(abs(H(q)), 1) for p, q in zip(a, b))
    assert worst <= tol
    assert worst > HI.mpf(10) ** -40


def test_global_context_inside_workdps():
    """Used with mpmath.mp inside workdps(d), the reference computes with d digits and
    leaves the (temporary) global precision alone."""
    with mpmath.workdps(40):
        x = [mpmath.mpf(2), mpmath.mpf(0), mpmath.mpf(0)]
        r = R.sqrt(x)[0]
        assert mpmath.mp.dps == 40
        assert r.context is mpmath.mp
        assert abs(H(r) - HI.sqrt(2)) <= HI.mpf(10) ** -40 * 2
        assert abs(H(r) - HI.sqrt(2)) > HI.mpf(10) ** -50
    assert mpmath.mp.prec == 53
