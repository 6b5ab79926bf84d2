"""Property-based tests of DESIGN.md §3 for both implementations of the Jordan algebra of Lorentz
cones: :mod:`rfverify.jordan` in float64 and longdouble, and :mod:`reference.jordan` in mpmath
(50 digits, some also 30).

Each identity is written once and runs against every implementation through the adapters of
tests/jordan_impls.py, which also explains how the tolerances are built (``u`` the unit of the
arithmetic under test, ``S`` the scale and ``κ = λ1/λ2`` the conditioning of a cone vector;
checks in 140-digit arithmetic; an underflow floor for the numpy dtypes).  The docstring of each
test states its bound and the forward-error argument; one constant serves every implementation
(the larger where their calibrations differed).  Calibration (``ci`` profile,
``JORDAN_RATIOS=1 pytest -s``): the worst error/bound of any check was 0.43 (the reference's
correctly rounded xᵀx and x∘y, bound u), 0.25 for the production code (longdouble det with an
exact ‖x̄‖), typically 0.005–0.1.  Then come explicit cases
for both implementations (domain errors, non-finite input, k = 1, frames at x̄ = 0) and tests
of what only the production code has (batches, dtypes, extreme magnitudes, longdouble being
really extended).  Agreement between the two implementations is in
tests/test_reference_jordan.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from reference import jordan as R
from rfverify import jordan as J
from rfverify.errors import ConeDomainError

try:
    from jordan_impls import (ABS300, BOUNDARY, F64, HI, HUGE, IMPLS, K1, KS_FRAME, LD, LDBL, MIX5,
                              NEAR12, NEAR12_K5, NEAR12_TINY, NEAREPS, OUT, REF50, SUBN, SUBN_TINY,
                              TINY, XBAR0, XBAR0_K2, H, cases, cast, check, cones, diff,
                              expect_domain, eye, families, gen_partner, kappa, matmul, matvec,
                              maxabs, mdiff, o_det, o_inverse, o_lams, o_norm, o_product,
                              o_quad_matrix, other, over_impls, over_impls_and_ref30, pinned,
                              reference_only, report_worst_ratios, scale, unit)
except ImportError:  # tests/ made a package
    from tests.jordan_impls import (ABS300, BOUNDARY, F64, HI, HUGE, IMPLS, K1, KS_FRAME, LD, LDBL,
                                    MIX5, NEAR12, NEAR12_K5, NEAR12_TINY, NEAREPS, OUT, REF50, SUBN,
                                    SUBN_TINY, TINY, XBAR0, XBAR0_K2, H, cases, cast, check, cones,
                                    diff, expect_domain, eye, families, gen_partner, kappa, matmul,
                                    matvec, maxabs, mdiff, o_det, o_inverse, o_lams,
                                    o_norm, o_product, o_quad_matrix, other, over_impls,
                                    over_impls_and_ref30, pinned, reference_only,
                                    report_worst_ratios, scale, unit)

assert report_worst_ratios  # an autouse fixture: imported to take effect in this module


def _k(batch):
    return len(batch[0])


# ==========================================================================================
# DESIGN §3 identities, each against every implementation
# ==========================================================================================


@over_impls
@given(case=cases("gg"))
@pinned((HUGE, TINY), (SUBN, gen_partner(SUBN)), (K1, gen_partner(K1)), (K1[:1], [[-3.0]]))
def test_product_is_commutative_and_accurate(impl, case):
    """x∘y = y∘x exactly, and each entry against the exact product.

    Commutativity, bound 0: the production forms the same products in the same order for both
    argument orders (IEEE + and × are commutative); the reference rounds once the exact value
    of a sum that is symmetric in (x, y).  Accuracy: the reference rounds every entry correctly
    (≤ u·|entry|: ``ctx.fdot`` sums exact products exactly; u rather than u/2 because mpmath's
    exact sum may drop terms more than 2·prec bits below the result); the production's entries
    are k-term sums of products, ≤ 4(k+2)·u·S(x)S(y)."""
    X, Y = impl.inputs(case)
    XY = impl.product(X, Y)
    assert impl.out(XY) == impl.out(impl.product(Y, X))
    for x, y, got in cones(impl, X, Y, XY):
        k = len(x)
        for g, want in zip(got, o_product(x, y)):
            bound = (4 * (k + 2) * impl.u * scale(x) * scale(y) if impl.production
                     else impl.u * abs(want))
            check(impl, abs(g - want), bound, "x∘y vs exact")


@over_impls
@given(case=cases("g"))
@pinned((NEAR12,), (HUGE,), (TINY,), (SUBN,), (K1,))
def test_identity_is_neutral(impl, case):
    """x∘e = e∘x = x, Q_e x = x, x⁰ = e and x¹ = x exactly (bound 0): x0·1 + Σx̄_i·0 = x0 and
    x0·0 + 1·x̄_i = x̄_i are exact, so are det e = 1 and 2(eᵀx)e − Rx = (x0; x̄), and the only
    other operation, the power-of-two rescaling of extreme inputs, is exact too."""
    (X,) = impl.inputs(case)
    E = impl.identity(_k(X), len(X))
    x = impl.out(X)
    assert impl.out(impl.product(X, E)) == x and impl.out(impl.product(E, X)) == x
    assert impl.out(impl.quad_apply(E, X)) == x
    assert impl.out(impl.power(X, 0)) == impl.out(E) and impl.out(impl.power(X, 1)) == x


@over_impls
@given(case=cases("ig"))
@pinned((NEAR12, gen_partner(NEAR12)), (HUGE, TINY), (TINY, HUGE), (XBAR0, gen_partner(XBAR0)),
        (K1, gen_partner(K1)), (K1[:1], [[-2.0]]), (XBAR0_K2, [[1.0, -1.0]]))
def test_arrow_solve(impl, case):
    """d = x \\ y solves x∘d = y: residual ‖x∘d − y‖∞ ≤ 8(k+2)·u·κ²·S(y); against the exact
    solution Arw(x)⁻¹y (Cramer-type formula in HI) ≤ 8(k+2)·u·κ·S(y)/λ2; x \\ e = x⁻¹ to
    8(k+2)·u·κ·S(x⁻¹).

    Arw(x) has eigenvalues λ1, x0, λ2, so ‖Arw(x)⁻¹‖ = 1/λ2 and its condition number is κ: d0
    carries the relative error O(k u κ) of det x, so |Δd| = O(k u κ S(y)/λ2) (forward), and
    multiplying back by Arw(x) (norm ≈ λ1) gives O(k u κ² S(y)).  d may underflow into the
    subnormal range, which x∘d magnifies by S(x): 4·S(x) subnormal quanta more."""
    X, Y = impl.inputs(case)
    D = impl.arrow_solve(X, Y)
    DE = impl.arrow_solve(X, impl.identity(_k(X), len(X)))
    for x, y, d, de, xi in cones(impl, X, Y, D, DE, impl.inverse(X)):
        k, u, kap = len(x), impl.u, kappa(x)
        check(impl, diff(o_product(x, d), y), 8 * (k + 2) * u * kap**2 * scale(y) + 4 * scale(x) * impl.subnormal,
              "x∘d − y")
        if k == 1:
            exact = [y[0] / x[0]]
        else:
            d0 = HI.fdot([(x[0], y[0])] + [(-a, b) for a, b in zip(x[1:], y[1:])]) / o_det(x)
            exact = [d0] + [(b - d0 * a) / x[0] for a, b in zip(x[1:], y[1:])]
        check(impl, diff(d, exact), 8 * (k + 2) * u * kap * scale(y) / o_lams(x)[1], "x \\ y vs exact")
        check(impl, diff(de, xi), 8 * (k + 2) * u * kap * scale(xi), "x \\ e − x⁻¹")


@over_impls_and_ref30
@given(case=cases("i"))
@pinned((NEAR12,), (NEAR12_K5,), (NEAREPS,), (ABS300,), (HUGE,), (TINY,), (SUBN,), (SUBN_TINY,),
        (XBAR0,), (K1,))
def test_inverse(impl, case):
    """x∘x⁻¹ = x⁻¹∘x = e to 4(k+2)·u·κ; x⁻¹ against the exact R x/(x0² − ‖x̄‖²) to
    4(k+2)·u·κ·S(x⁻¹); (x⁻¹)⁻¹ = x to 4(k+2)·u·κ·S(x); x⁻¹ ∈ int L; x^(−1) is x⁻¹ exactly.

    x⁻¹ = R x/(λ1λ2) inherits the relative error O(k u κ) of λ2 as a common factor (the forward
    bound, S(x⁻¹) = 1/λ2); the head of x∘x⁻¹ = (x0² − ‖x̄‖²)/det is a k-term dot product with
    terms ≤ λ1²/det = κ, so it adds k u κ; the bar part x0(−x̄)/det + (x0/det)x̄ cancels up to
    u κ.  (x⁻¹)⁻¹ has the same κ."""
    (X,) = impl.inputs(case)
    XI = impl.inverse(X)
    assert impl.out(impl.power(X, -1)) == impl.out(XI)
    for x, xi, p1, p2, xii in cones(impl, X, XI, impl.product(X, XI), impl.product(XI, X), impl.inverse(XI)):
        k, u, kap = len(x), impl.u, kappa(x)
        check(impl, diff(p1, unit(k)), 4 * (k + 2) * u * kap, "x∘x⁻¹ − e")
        check(impl, diff(p2, unit(k)), 4 * (k + 2) * u * kap, "x⁻¹∘x − e")
        exact = o_inverse(x)
        check(impl, diff(xi, exact), 4 * (k + 2) * u * kap * scale(exact), "x⁻¹ vs exact Rx/det")
        check(impl, diff(xii, x), 4 * (k + 2) * u * kap * scale(x), "(x⁻¹)⁻¹ − x")
        assert o_lams(xi)[1] > 0


@over_impls_and_ref30
@given(case=cases("i"))
@pinned((NEAR12,), (NEAREPS,), (ABS300,), (NEAR12_TINY,), (HUGE,), (TINY,), (SUBN,), (XBAR0,), (K1,),
        ([[1.0, 1.0, 0.0], [2.0, 0.0, -2.0], [0.0, 0.0, 0.0]],), ([BOUNDARY],))  # boundary, x = 0
def test_sqrt_squared(impl, case):
    """(x^{1/2})² = x to 4(k+2)·u·S(x) whatever κ, also on the boundary and at x = 0, squared
    exactly and with the implementation's own product; x^{1/2} ∈ L (exact λ2 ≥ −2(k+2)·u·S(√x):
    on ∂L its rounded entries may step out by that much; the production's own λ2 of it is ≥ 0,
    the reference's may round to −u·S there); x^½ is sqrt(x) exactly.

    Backward stability of the closed form ((√λ1+√λ2)/2 ; x̄/(√λ1+√λ2)): an error δ in √λ2 only
    changes the c2-coefficient, and squaring turns it into 2√λ2·δ = Δλ2 = O(k u λ1); everything
    else is O(k u) relative rounding of O(S) terms."""
    (X,) = impl.inputs(case)
    RT = impl.sqrt(X)
    assert impl.out(impl.power(X, 0.5)) == impl.out(RT)
    for x, r, rr, own_l2 in cones(impl, X, RT, impl.product(RT, RT), impl.spectral_values(RT)[1]):
        k, u, S = len(x), impl.u, scale(x)
        assert o_lams(r)[1] >= -2 * (k + 2) * u * scale(r)
        assert own_l2 >= 0 or not impl.production
        check(impl, diff(o_product(r, r), x), 4 * (k + 2) * u * S, "(√x)² − x")
        check(impl, diff(rr, x), 4 * (k + 2) * u * S, "√x∘√x − x (own product)")


@over_impls
@given(case=cases("g"))
@pinned((NEAR12,), (HUGE,), (TINY,), (SUBN,), (K1,))
def test_quad_of_identity_is_square(impl, case):
    """Q_x e = x∘x to 4(k+2)·u·S(x)² for any x.

    Q_x e = (2x0² − λ1λ2 ; 2x0x̄) against the exact (‖x‖² ; 2x0x̄): the error is the rounding of
    det x = λ1λ2, absolute λ1·Δλ2 + λ2·Δλ1 = O(k u S²), plus one rounding per entry."""
    (X,) = impl.inputs(case)
    for x, q in cones(impl, X, impl.quad_apply(X, impl.identity(_k(X), len(X)))):
        k = len(x)
        check(impl, diff(q, o_product(x, x)), 4 * (k + 2) * impl.u * scale(x) ** 2, "Q_x e − x²")


@over_impls
@given(case=cases("gg"))
@pinned((NEAR12, gen_partner(NEAR12)), (HUGE, TINY), (TINY, HUGE), (SUBN, gen_partner(SUBN)),
        (K1, gen_partner(K1)), (K1[:1], [[-2.0]]))
def test_quad_equals_arrow_form(impl, case):
    """Q_x y = (2Arw(x)² − Arw(x²)) y to 4(k+2)²·u·S(x)²·S(y); quad_matrix(x) equals that matrix
    entrywise to 4(k+2)²·u·S(x)²; Arw(x) y = x∘y (Arw is exact).

    The oracle matrix is formed exactly from the textbook arrow form; 2(xᵀy)x − det(x)Ry differs
    by the error of det (absolute O(k u S²), times |y|) and the rounding of a k-term dot product,
    quad_matrix by the same det error per diagonal entry and one rounding elsewhere."""
    X, Y = impl.inputs(case)
    for x, y, q, m, a in cones(impl, X, Y, impl.quad_apply(X, Y), impl.quad_matrix(X), impl.arrow(X)):
        k, u, sx2 = len(x), impl.u, scale(x) ** 2
        oracle = o_quad_matrix(x)
        check(impl, diff(q, matvec(oracle, y)), 4 * (k + 2) ** 2 * u * sx2 * scale(y),
              "Q_x y − (2Arw² − Arw(x²))y")
        check(impl, mdiff(m, oracle), 4 * (k + 2) ** 2 * u * sx2, "quad_matrix − arrow form")
        check(impl, diff(matvec(a, y), o_product(x, y)), HI.eps * scale(x) * scale(y), "Arw(x)y − x∘y")


@over_impls
@given(case=cases("i"))
@pinned((NEAR12,), (HUGE,), (TINY,), (SUBN,), (XBAR0,), (K1,))
def test_quad_of_inverse_is_inverse_of_quad(impl, case):
    """Q_{x⁻¹} Q_x = I (as matrices) to (k+2)²·u·κ² (max entry).

    Q̃_x = Q_x + E with |E| = O(k u S²), Q̃_{x⁻¹} = (1+θ)²Q_{x⁻¹} + E' with θ = O(k u κ) (the
    common factor of x⁻¹) and |E'| = O(k u/λ2²); the product is I + 2θI + Q_{x⁻¹}E + E'Q_x, and
    ‖Q_{x⁻¹}‖ = 1/λ2², ‖Q_x‖ = λ1² give O(k² u κ²): κ² = cond(Q_x) is the honest amplification
    (the pinned 1e-12 cases therefore only check finiteness and consistency)."""
    (X,) = impl.inputs(case)
    for x, qi, q in cones(impl, X, impl.quad_matrix(impl.inverse(X)), impl.quad_matrix(X)):
        k = len(x)
        check(impl, mdiff(matmul(qi, q), eye(k)), (k + 2) ** 2 * impl.u * kappa(x) ** 2, "Q_{x⁻¹}Q_x − I")


@over_impls
@given(case=cases("i"), t=st.integers(-2, 3))
@pinned((families(HUGE * 1e-100, HUGE),), t=3)
@pinned((families(TINY * 1e75, TINY),), t=-2)
@pinned((XBAR0,), t=2)
@pinned((K1[:2],), t=-2)
@pinned((K1,), t=3)
@pinned((NEAR12,), t=2)
@pinned((NEAR12,), t=-2)
def test_quad_of_integer_power(impl, case, t):
    """Q_{x^t} = (Q_x)^t for integer t ∈ {−2, …, 3}, against (Q_x)^t formed exactly from the
    oracle Q_x ((Q_x)^{−|t|} as (Q_{x⁻¹})^{|t|} from the exact inverse; Q_{x⁻¹} = Q_x⁻¹ is tested
    above); max entry.

    t ≥ 0: bound (t+1)(k+2)²·u·S(x)^{2t}: the c1-part of x^t has relative error O(t k u), the
    c2-part absolute error t·λ2^{t−1}·Δλ2 = O(t k u λ1^t) (κ-free for t ≥ 1); Q of it adds
    O(k² u S^{2t}).  t < 0: bound (|t|+1)(k+2)²·u·κ·λ2^{−2|t|}: x^t carries relative error
    O(|t| k u κ) in its dominant λ2^t-component."""
    (X,) = impl.inputs(case)
    for x, lhs in cones(impl, X, impl.quad_matrix(impl.power(X, t))):
        k, u = len(x), impl.u
        base = o_quad_matrix(x if t >= 0 else o_inverse(x))
        rhs = eye(k)
        for _ in range(abs(t)):
            rhs = matmul(rhs, base)
        if t >= 0:
            bound = (t + 1) * (k + 2) ** 2 * u * scale(x) ** (2 * t)
        else:
            bound = (-t + 1) * (k + 2) ** 2 * u * kappa(x) * o_lams(x)[1] ** (2 * t)
        check(impl, mdiff(lhs, rhs), bound, f"Q_(x^{t}) − (Q_x)^{t}")


@over_impls
@given(case=cases("gg"))
@pinned((NEAR12, NEAR12[:, [0, 2, 1]]), (HUGE, TINY), (SUBN, gen_partner(SUBN)), (K1, gen_partner(K1)),
        (K1[:1], [[-3.0]]))
def test_det_of_quad(impl, case):
    """det(Q_x y) = det(x)² det(y) to 8(k+2)²·u·S(x)⁴·S(y)² absolute (right side exact).

    w = Q_x y has absolute error O(k u S(x)²S(y)) and S(w) ≤ 2S(x)²S(y), so det(w) = λ1(w)λ2(w)
    has absolute error O(S(w)·k u S(x)²S(y)) = O(k u S(x)⁴S(y)²)."""
    X, Y = impl.inputs(case)
    for x, y, d in cones(impl, X, Y, impl.det(impl.quad_apply(X, Y))):
        k = len(x)
        bound = 8 * (k + 2) ** 2 * impl.u * scale(x) ** 4 * scale(y) ** 2
        check(impl, abs(d - o_det(x) ** 2 * o_det(y)), bound, "det(Q_x y)")


@over_impls
@given(case=cases("gg"))
@pinned((NEAR12, gen_partner(NEAR12)), (families(HUGE * 1e-75, HUGE), families(TINY * 1e75, TINY)),
        (SUBN, gen_partner(SUBN)), (K1, gen_partner(K1)), (K1[:1], [[-3.0]]))
def test_quad_of_quad(impl, case):
    """Q_{Q_x y} = Q_x Q_y Q_x (matrices, right side exact from the oracle) to
    2(k+2)³·u·S(x)⁴·S(y)² (max entry): w = Q_x y has absolute error O(k u S(x)²S(y)) and
    S(w) ≤ 2S(x)²S(y), so Q_w = 2wwᵀ − det(w)R has error O(S(w)·k u S(x)²S(y)), and forming
    it rounds k-term sums of entries bounded by S(x)⁴S(y)²."""
    X, Y = impl.inputs(case)
    for x, y, lhs in cones(impl, X, Y, impl.quad_matrix(impl.quad_apply(X, Y))):
        k = len(x)
        qx = o_quad_matrix(x)
        rhs = matmul(matmul(qx, o_quad_matrix(y)), qx)
        check(impl, mdiff(lhs, rhs), 2 * (k + 2) ** 3 * impl.u * scale(x) ** 4 * scale(y) ** 2,
              "Q_{Q_x y} − Q_xQ_yQ_x")


@over_impls
@given(case=cases("iii", production={"log_rho": (-3.0, 0.0)}))
@pinned((HUGE, TINY, HUGE), (SUBN, XBAR0[:1].repeat(2, 0), SUBN), (K1, K1[::-1], K1),
        (K1[:1], [[3.0]], [[1e-100]]),
        (reference_only(NEAR12.reference), reference_only(NEAR12.reference), reference_only(NEAR12.reference)))
def test_quad_maps_interior_onto_interior(impl, case):
    """Q_x (int L) = int L for x ∈ int L.

    Into: λ2(Q_x y) ≥ λ2(x)²·λ2(y) exactly (y − λ2(y)e ∈ L ⇒ Q_x y ⪰ λ2(y)x², and λ2 is
    superadditive); the computed Q_x y has absolute error ≤ 4(k+2)²·u·S(x)²S(y), so
    λ2(Q_x y) ≥ λ2(x)²λ2(y) − that is asserted, and > 0 — a real check where the lower bound is
    far above the rounding term (the production draws λ2/λ1 ≥ 1e-3 for it, the reference
    ≥ 1e-12 in 50 digits; the 1e-12 triple is pinned for the reference only).
    Onto: for interior t the preimage Q_{x⁻¹} t is interior and Q_x(Q_{x⁻¹} t) = t up to
    4(k+2)²·u·κ(x)²·S(t) (Q_{x⁻¹} errors of size k u S(t)/λ2² amplified by ‖Q_x‖ = λ1²)."""
    X, Y, T = impl.inputs(case)
    PRE = impl.quad_apply(impl.inverse(X), T)
    for x, y, t, w, pre, back in cones(impl, X, Y, T, impl.quad_apply(X, Y), PRE, impl.quad_apply(X, PRE)):
        k, u = len(x), impl.u
        l2w = o_lams(w)[1]
        assert l2w > 0
        assert l2w >= o_lams(x)[1] ** 2 * o_lams(y)[1] - 4 * (k + 2) ** 2 * u * scale(x) ** 2 * scale(y)
        assert o_lams(pre)[1] > 0
        check(impl, diff(back, t), 4 * (k + 2) ** 2 * u * kappa(x) ** 2 * scale(t), "Q_x Q_{x⁻¹} t − t")


@over_impls_and_ref30
@given(case=cases("ii"))
@pinned((NEAR12, XBAR0[:1].repeat(2, 0)), (NEAR12, NEAR12[:, [0, 2, 1]]),
        (NEAR12[:1], [[1.0, -(1.0 - 1e-12), 0.0]]), (HUGE, TINY), (TINY, HUGE), (SUBN, other(SUBN)),
        (XBAR0, XBAR0[::-1]), (K1, K1[::-1]), (K1[:1], [[3e-100]]), (ABS300, other(ABS300)),
        (MIX5, other(MIX5)))
def test_nt_scaling(impl, case):
    """NT point: Q_p z = Q_{p⁻¹} s = λ, Arw(Q_p z) = Arw(Q_{p⁻¹} s), Q_{p²} z = s, p∘p⁻¹ = e,
    p, λ ∈ int L, det p = (det s/det z)^{1/4}, det λ = √(det z det s); the production's β and
    cond fields are det p and cond(Q_p).

    Vector identities (‖·‖∞): 2(k+2)²·u·[(κ(z)+κ(s))·S(λ) + S(p)²S(z) + S(p⁻¹)²S(s)].
    √det z = √λ1√λ2 and √det s carry relative errors O(k u κ), which move the common scale √β
    of p, and so Q_p z and Q_{p⁻¹}s in opposite directions, by O(k u (κ(z)+κ(s))) relative to λ;
    applying Q_p (Q_{p⁻¹}) adds O(k u ‖p‖² S(z)) (O(k u ‖p⁻¹‖² S(s))).  For Q_{p²} z = s the
    same argument with p² gives 4(k+2)²·u·[(κ(z)+κ(s))·S(s) + S(p)⁴S(z)].  p∘p⁻¹ = e to
    8(k+2)·u·κ(p) (as x∘x⁻¹).  The determinant identities are relative, to
    2(k+2)·u·(κ(z)+κ(s)+κ(λ)+κ(p)): each det involved has relative error O(k u κ) of its
    argument; cond additionally inherits the relative error of λ2(p) (times κ(p))."""
    Z, S = impl.inputs(case)
    nt = impl.nt_scaling(Z, S)
    A, B = impl.quad_apply(nt.p, Z), impl.quad_apply(nt.p_inv, S)
    QS = impl.quad_apply(impl.product(nt.p, nt.p), Z)
    rows = cones(impl, Z, S, nt.p, nt.p_inv, nt.lam, A, B, impl.arrow(A), impl.arrow(B), QS,
                 impl.product(nt.p, nt.p_inv))
    rels = []
    for z, s, p, p_inv, lam, a, b, arw_a, arw_b, qs, pp in rows:
        k, u = len(z), impl.u
        kz, ks, kp = kappa(z), kappa(s), kappa(p)
        bound = 2 * (k + 2) ** 2 * u * ((kz + ks) * scale(lam) + scale(p) ** 2 * scale(z)
                                        + scale(p_inv) ** 2 * scale(s))
        check(impl, diff(a, b), bound, "Q_p z − Q_{p⁻¹} s")
        check(impl, diff(a, lam), bound, "Q_p z − λ")
        check(impl, diff(b, lam), bound, "Q_{p⁻¹} s − λ")
        check(impl, mdiff(arw_a, arw_b), bound, "Arw(Q_p z) − Arw(Q_{p⁻¹} s)")
        check(impl, diff(qs, s), 4 * (k + 2) ** 2 * u * ((kz + ks) * scale(s) + scale(p) ** 4 * scale(z)),
              "Q_{p²} z − s")
        assert o_lams(p)[1] > 0 and o_lams(lam)[1] > 0
        check(impl, diff(pp, unit(k)), 8 * (k + 2) * u * kp, "p∘p⁻¹ − e")
        rel = 2 * (k + 2) * u * (kz + ks + kappa(lam) + kp)
        dz, ds = o_det(z), o_det(s)
        check(impl, abs(o_det(p) / HI.root(ds / dz, 4) - 1), rel, "det p vs (det s/det z)^¼")
        check(impl, abs(o_det(lam) / HI.sqrt(dz * ds) - 1), rel, "det λ vs √(det z det s)")
        rels.append((rel, kp, o_det(p), HI.root(ds / dz, 4)))
    if impl.production:
        for (rel, kp, det_p, beta_true), beta, cond, cq in zip(rels, H(nt.beta), H(nt.cond),
                                                               H(J.cond_quad(nt.p))):
            check(impl, abs(beta / beta_true - 1), rel, "β vs (det s/det z)^¼")
            check(impl, abs(det_p / beta - 1), rel, "det p vs β")
            check(impl, abs(cond / cq - 1), rel * kp, "cond field vs cond_quad(p)")


@over_impls
@given(case=cases("i"))
@pinned((NEAR12,), (NEAREPS,), (HUGE,), (TINY,), (SUBN,), (XBAR0,), (K1,), (MIX5,),
        (MIX5 * [[1, 1, 1, 1, 0.1], [1, 1, 1, 1, 1]],))
def test_cond_quad(impl, case):
    """cond(Q_x) = (λ1/λ2)².

    (a) Against the exact spectral values: relative error ≤ 8(k+2)·u·κ (the relative error of
    λ2, doubled by the square).
    (b) Against the extreme eigenvalues of the implementation's own quad_matrix(x), computed in
    HI: its entries have absolute error O(k u S²), which moves the smallest eigenvalue λ2² by that
    much (Weyl), i.e. relative (k+2)·u·κ²; the ratio is asserted to 8(k+2)·u·κ² where that is
    < 0.1 (where the conditioning allows the comparison at all)."""
    (X,) = impl.inputs(case)
    for x, c, q in cones(impl, X, impl.cond_quad(X), impl.quad_matrix(X)):
        k, u, kap = len(x), impl.u, kappa(x)
        check(impl, abs(c / kap**2 - 1), 8 * (k + 2) * u * kap, "cond vs exact (λ1/λ2)²")
        rel_eig = 8 * (k + 2) * u * kap**2
        if rel_eig < 0.1:
            ev = HI.eigsy(HI.matrix(q), eigvals_only=True)
            ev = sorted(ev[i] for i in range(k))
            check(impl, abs((ev[-1] / ev[0]) / c - 1), rel_eig, "cond vs eigenvalues of quad_matrix")


@over_impls
@given(case=cases("g"))
@pinned((NEAR12,), (NEAREPS,), (HUGE,), (TINY,), (SUBN,), (SUBN_TINY,), (ABS300,), (XBAR0,),
        (XBAR0_K2,), (K1,), ([[1.5 + 2.0**-52, -1.5], [1e155 * (1 + 2.0**-52), 1e155]],))
def test_spectral_decomposition_and_det(impl, case):
    """Spectral values against the exact ones to 4(k+2)·u·S(x) (absolute; λ2 relative O(k u κ)
    is its condition number), λ1 ≥ λ2; x = λ1c1 + λ2c2 to 4(k+2)·u·S(x); c1 + c2 = e exactly;
    for k ≥ 2 a Jordan frame (c1∘c2 = 0, ci∘ci = ci to (k+2)·u: x̄/‖x̄‖ has norm 1 ± O(k u)),
    for k = 1 both frames are ½; trace = 2x0 exactly.
    det x = λ1λ2 against the exact x0² − ‖x̄‖² to 8(k+2)·u·S(x)² absolute (λ1Δλ2 + λ2Δλ1), and
    to 4u relative when x̄ has at most one non-zero entry (always for k = 2): then ‖x̄‖ = |x_i|
    is exact, x0 ∓ |x_i| are single roundings (exact by Sterbenz near the boundary) and the
    factored det has relative error ≤ 3u + O(u²) whatever κ is — what x0² − ‖x̄‖² cannot do.
    A det beyond the dtype's range overflows to inf (never NaN).  The reference's ‖x̄‖ and xᵀx
    are correctly rounded (≤ 2u and u relative)."""
    (X,) = impl.inputs(case)
    n, k = len(X), _k(X)
    l1s, l2s = impl.spectral_values(X)
    c1s, c2s = impl.spectral_frames(X)
    e = impl.out(impl.identity(k, n))
    assert [[a + b for a, b in zip(c1, c2)] for c1, c2 in zip(impl.out(c1s), impl.out(c2s))] == e
    for x, l1, l2, c1, c2, d, t in cones(impl, X, l1s, l2s, c1s, c2s, impl.det(X), impl.trace(X)):
        u, S = impl.u, scale(x)
        m1, m2 = o_lams(x)
        assert l1 >= l2
        check(impl, max(abs(l1 - m1), abs(l2 - m2)), 4 * (k + 2) * u * S, "spectral values")
        check(impl, diff([l1 * a + l2 * b for a, b in zip(c1, c2)], x), 4 * (k + 2) * u * S, "λ1c1 + λ2c2 − x")
        if k > 1:
            check(impl, maxabs(o_product(c1, c2)), (k + 2) * u, "c1∘c2")
            check(impl, diff(o_product(c1, c1), c1), (k + 2) * u, "c1∘c1 − c1")
            check(impl, diff(o_product(c2, c2), c2), (k + 2) * u, "c2∘c2 − c2")
        else:
            assert c1 == c2 == [0.5]
        assert t == 2 * x[0]
        truth = o_det(x)
        if abs(truth) > impl.max:
            assert HI.isinf(d)
            continue
        check(impl, abs(d - truth), 8 * (k + 2) * u * S**2, "det vs x0² − ‖x̄‖²")
        if sum(1 for v in x[1:] if v) <= 1:
            check(impl, abs(d - truth), 4 * u * abs(truth), "det relative (exact ‖x̄‖)")
    if not impl.production:  # helpers only the reference has
        for x in X:
            xh = H(x)
            check(impl, abs(H(R.bar_norm(x)) - o_norm(xh)), 2 * impl.u * o_norm(xh), "‖x̄‖")
            check(impl, abs(H(R.dot(x, x)) - HI.fsum(xh, squared=True)), impl.u * HI.fsum(xh, squared=True),
                  "xᵀx")


@over_impls
@given(case=cases("i", production={"log_rho": (-4.0, 0.0)}),
       p=st.sampled_from([2, 3, -1, -2, 0.5, 1.5, -0.5]))
@pinned((NEAR12,), p=0.5)
@pinned((NEAR12,), p=-1)
@pinned((XBAR0,), p=-0.5)
@pinned((K1[:2],), p=3)
@pinned((HUGE * 1e-75,), p=1.5)
def test_det_of_powers(impl, case, p):
    """det(x^p) = det(x)^p (incl. det(x∘x) = det(x)², det(x⁻¹) = 1/det x) against the exact
    right side, relative error ≤ 2(k+2)·u·(κ(x^p) + (|p|+1)κ(x)): the left side is λ1λ2 of x^p
    (relative error O(k u κ(x^p)), κ(x^p) = κ^|p|) of an x^p whose own error is O(|p| k u κ)."""
    (X,) = impl.inputs(case)
    XP = impl.power(X, p)
    squares = [impl.det(impl.product(X, X))] if p == 2 else []
    for x, xp, d, *sq in cones(impl, X, XP, impl.det(XP), *squares):
        k = len(x)
        bound = 2 * (k + 2) * impl.u * (kappa(xp) + (abs(p) + 1) * kappa(x))
        rhs = o_det(x) ** HI.mpf(p)
        check(impl, abs(d / rhs - 1), bound, f"det(x^{p}) / det(x)^{p}")
        for d2 in sq:
            check(impl, abs(d2 / rhs - 1), bound, "det(x∘x) / det(x)²")


@over_impls
@given(case=cases("ig"))
@pinned((NEAR12, gen_partner(NEAR12)), (HUGE, -HUGE[::-1]), (TINY, gen_partner(TINY)), (SUBN, gen_partner(SUBN)),
        (XBAR0, -XBAR0[:, [0, 2, 1]] - [[0, 1, 0], [0, 0, 1]]), (XBAR0[:1], [[-1.0, 0.0, 0.0]]),
        (K1, -K1[::-1]), (K1[:1], [[-0.7]]),
        ([[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]),  # boundary reached at α = 1
        ([[1.0, 0.0, 0.0]], [[1.0, 1.0, 0.0]]),  # dx on ∂L: never leaves (α = inf)
        ([[1.0, 0.0, 0.0]], [[2.2250738585e-311] * 3]),  # α ≈ 1.1e311 > max (float64)
        ([[1e-3, 0.0]], [[2.2250738585e-311] * 2]), ([[1e-3, 0.0]], [[5e-324, 5e-324]]))  # tangent, subnormal dx
def test_step_to_boundary(impl, case):
    """α = step_to_boundary(x, dx): x + α dx ∈ ∂L and x + 0.99α dx ∈ int L; α = inf iff dx ∈ L.

    Boundary: |λ2(x + α dx)| ≤ 2(k+2)·u·(S(x) + α S(dx))·(κ(x) + α S(dx)/λ2(x)), evaluated
    exactly.  The relative error of α is O(k u (κ + α S(dx)/λ2(x))): x^{-1/2} carries a common
    relative error O(k u κ), y = Q_{x^{-1/2}} dx an absolute error O(k u S(dx)/λ2(x)) against
    |λ2(y)| = 1/α; λ2 along the ray moves by at most 2S(dx) per unit of α.
    inf: then λ2(dx) ≥ −8(k+2)·u·κ·S(dx) (dx ∈ L up to the rounding of y).  α equal to the
    dtype's largest number: the ray leaves L only beyond the dtype's range, x + α dx ∈ L and
    λ2(dx) ≤ 8(k+2)·u·κ·S(dx) (a tangent dx, λ2(dx) = 0, may round either way).  The
    production's max_step is min(α_max, min α) exactly."""
    X, DX = impl.inputs(case)
    AL = impl.step_to_boundary(X, DX)
    for x, dx, a in cones(impl, X, DX, AL):
        k, u = len(x), impl.u
        assert a > 0
        kap, sdx = kappa(x), scale(dx)
        if HI.isinf(a):
            assert o_lams(dx)[1] >= -8 * (k + 2) * u * kap * sdx, "α = inf but dx ∉ L"
            continue
        if a == impl.max:
            assert o_lams(dx)[1] <= 8 * (k + 2) * u * kap * sdx, "α = max but dx ∈ int L"
            assert o_lams([p + a * q for p, q in zip(x, dx)])[1] >= 0
            continue
        l2b = o_lams([p + a * q for p, q in zip(x, dx)])[1]
        bound = 2 * (k + 2) * u * (scale(x) + a * sdx) * (kap + a * sdx / o_lams(x)[1])
        check(impl, abs(l2b), bound, "λ2(x + α dx)")
        a99 = a * HI.mpf("0.99")
        assert o_lams([p + a99 * q for p, q in zip(x, dx)])[1] > 0, "x + 0.99α dx left the cone"
    if impl.production:
        for amax in (1.0, np.inf):
            ms = J.max_step(X, DX, alpha_max=amax)
            assert ms.dtype == impl.dtype and ms == min(impl.dtype(amax), np.min(AL))


@over_impls
@given(case=cases("i", production={"log_scale": (-2.0, 2.0)},
                  reference={"log_rho": (-8.0, 0.0), "log_scale": (-30.0, 30.0)}),
       p=st.integers(-3072, 3072), q=st.integers(-3072, 3072))
@pinned((NEAR12,), p=1024, q=-512)
@pinned((XBAR0,), p=333, q=-1000)
@pinned((SUBN,), p=-1536, q=3072)
@pinned((K1,), p=-2048, q=100)
@pinned((HUGE,), p=-1536, q=512)
@pinned((TINY,), p=512, q=-1536)
def test_power_additive(impl, case, p, q):
    """x^a ∘ x^b = x^{a+b} for a = p/1024, b = q/1024 ∈ [−3, 3] (a + b exact), x ∈ int L.

    With M(a) = max(λ1^a, λ2^a) and E(a) = (|a|+2)(λ1^a + λ2^a) + |a|·λ1·λ2^{a−1} (the computed
    x^a has absolute error ≤ c·k·u·E(a): λ1^a has relative error O(|a| k u), the c2-coefficient
    λ2^a absolute error |a|λ2^{a−1}·Δλ2 = O(|a| k u λ1 λ2^{a−1}), the frame or divided
    difference O(k u)), the product has error ≤ 2(k+2)·u·[E(a)M(b) + M(a)E(b) + E(a+b)] (E already
    carries the k of the spectral values; the product's k-term dot product is absorbed because
    E ≥ |x^a| termwise)."""
    (X,) = impl.inputs(case)
    a_, b_ = p / 1024, q / 1024
    lhs = impl.product(impl.power(X, a_), impl.power(X, b_))
    for x, got, want in cones(impl, X, lhs, impl.power(X, a_ + b_)):
        k = len(x)
        l1, l2 = o_lams(x)

        def E(t):
            t = HI.mpf(t)
            return (abs(t) + 2) * (l1**t + l2**t) + abs(t) * l1 * l2 ** (t - 1)

        def M(t):
            return max(l1 ** HI.mpf(t), l2 ** HI.mpf(t))

        bound = 2 * (k + 2) * impl.u * (E(a_) * M(b_) + M(a_) * E(b_) + E(a_ + b_))
        check(impl, diff(got, want), bound, "x^a∘x^b − x^(a+b)")


BIG = R.context(500)  # the divided differences below need ~1100 bits more than the inputs


def _near_axis(x, small):
    """x with x̄ rescaled to ‖x̄‖ ≈ 10^small · x0 by a power of two (x̄ = 0 stays 0), in the
    numbers of x."""
    x = x.copy()
    m = np.max(np.abs(x[:, 1:]), axis=1, keepdims=True)
    shift = int(np.floor(small * math.log2(10)))
    x[:, 1:] = np.ldexp(x[:, 1:] / np.where(m > 0, m, 1), shift) * x[:, :1]
    return x


@over_impls
@given(case=cases("i", ks=KS_FRAME, production={"log_rho": (-1.0, -0.01), "log_scale": (-2.0, 2.0)},
                  reference={"log_rho": (-1.0, -0.01), "log_scale": (-20.0, 20.0)}),
       small=st.floats(-320.0, -1.0), p=st.sampled_from([-2.0, -0.5, 1.0 / 3.0, 1.5, 3.0, 1e-3, 7.0]))
@pinned((SUBN,), small=-1.0, p=1.5)
@pinned((XBAR0,), small=-1.0, p=-2.0)
def test_power_bar_is_accurate_componentwise(impl, case, small, p):
    """Near the axis (‖x̄‖/x0 = 10^small down to 1e-320) the bar part of x^p is D·x̄ with the
    divided difference D = (λ1^p − λ2^p)/(λ1 − λ2); the textbook λ1^p − λ2^p cancels completely
    there.  The expm1/log1p form keeps D to relative accuracy O(|p| k u) (κ ≈ 1 here), so each
    component satisfies |bar_i − D*·x̄_i| ≤ 8(|p|+2)(k+2)·u·|D*·x̄_i| (+ the underflow floor),
    with D* from a 500-digit oracle; the head (λ1^p + λ2^p)/2 has no cancellation
    (4(|p|+2)·u·|head|).  Same for sqrt (p = ½, bar = x̄/(√λ1+√λ2)).  The rescaling is done
    in the implementation's input numbers (longdouble keeps its wider exponent range)."""
    rows = cast(case[0].rows(impl.family), impl.input_dtype)
    X = impl.convert(_near_axis(rows, small))
    for fn, pp in ((lambda v: impl.power(v, p), p), (impl.sqrt, 0.5)):
        for x, r in cones(impl, X, fn(X)):
            k, u = len(x), impl.u
            xb = R.to_ctx(BIG, x)
            n = BIG.sqrt(BIG.fsum(xb[1:], squared=True))
            l1, l2 = xb[0] + n, xb[0] - n
            if l1 == l2:  # x̄ = 0
                assert all(v == 0 for v in r[1:])
                continue
            ppb = R.to_ctx(BIG, pp)
            dstar = (l1**ppb - l2**ppb) / (l1 - l2)
            head = (l1**ppb + l2**ppb) / 2
            check(impl, abs(R.to_ctx(BIG, r[0]) - head), 4 * (abs(pp) + 2) * u * abs(head), f"head of x^{pp}")
            for j in range(1, k):
                want = dstar * xb[j]
                check(impl, abs(R.to_ctx(BIG, r[j]) - want), 8 * (abs(pp) + 2) * (k + 2) * u * abs(want),
                      f"bar of x^p (p={pp})")


# ==========================================================================================
# explicit cases, both implementations
# ==========================================================================================

GOOD = [2.0, 0.5, -0.5]


def _good(k):
    return (GOOD + [0.0] * k)[:k]


def _bad_inputs(impl, point, index=3):
    """The bad point alone and, for the production (which works on batches), in a batch of good
    cones at ``index``: pairs (input, cone index the error must name)."""
    single = impl.convert([point])[0]
    if not impl.production:
        return [(single, None)]
    batch = np.tile(_good(len(point)), (5, 1))
    batch[index] = point
    return [(impl.convert(batch), index), (single, None)]


DOMAIN = [  # (operation, call on (module, x, a good partner of the same shape), bad point, λ2 or det)
    ("sqrt", lambda m, x, g: m.sqrt(x), OUT, -1),
    ("inverse", lambda m, x, g: m.inverse(x), BOUNDARY, 0),
    ("inverse", lambda m, x, g: m.inverse(x), [-5.0, 3.0, 4.0], 0),  # ∂(−L): λ1 = 0
    ("inverse", lambda m, x, g: m.inverse(x), [0.0], 0),
    *[("power", lambda m, x, g, p=p: m.power(x, p), OUT, -1) for p in (0.5, 1.5, -0.5, -1.5, 1 / 3)],
    *[("power", lambda m, x, g, p=p: m.power(x, p), BOUNDARY, None) for p in (-0.5, -2, -1)],
    ("cond_quad", lambda m, x, g: m.cond_quad(x), OUT, -1),
    ("nt_scaling", lambda m, x, g: m.nt_scaling(x, g), BOUNDARY, 0),
    ("nt_scaling", lambda m, x, g: m.nt_scaling(g, x), OUT, -1),
    ("step_to_boundary", lambda m, x, g: m.step_to_boundary(x, g), BOUNDARY, 0),
    ("arrow_solve", lambda m, x, g: m.arrow_solve(x, g), BOUNDARY, 0),
    ("arrow_solve", lambda m, x, g: m.arrow_solve(x, g), [1.0, 1.0, 0.0], 0),
    ("arrow_solve", lambda m, x, g: m.arrow_solve(x, g), [0.0, 1.0, 1.0], None),
]


@over_impls
@pytest.mark.parametrize("op, call, point, value", DOMAIN,
                         ids=[f"{t[0]}-{i}" for i, t in enumerate(DOMAIN)])
def test_domain_errors(impl, op, call, point, value):
    """A point outside an operation's domain — outside L where the closed cone is required,
    on ∂L where the interior is, det = 0 for an inverse, a NaN exponent — is refused by both
    implementations with their domain error naming the operation and the offending λ2 or det
    (so both refuse the same points for the same reason); the production names the cone of a
    batch (None for a single vector), and for nt_scaling which argument."""
    for x, cone in _bad_inputs(impl, point):
        batch = impl.production and np.ndim(x) == 2
        good_row = _good(len(point))
        good = impl.convert(np.tile(good_row, (len(x), 1))) if batch else impl.convert([good_row])[0]
        err = expect_domain(impl, op, lambda: call(impl.module, x, good), cone=cone)
        if value is not None:
            assert float(err.value) == pytest.approx(value, abs=1e-12)
        if op == "nt_scaling":
            assert ("'z'" if point is BOUNDARY else "'s'") in str(err)


@over_impls
def test_closed_cone_and_outside_semantics(impl):
    """What is allowed: sqrt and non-integer p > 0 on ∂L (x^p = λ1^p c1) and at 0; the inverse
    outside L ∪ −L and inside −L; integer powers of any point (binary powering: y³ = y∘(y∘y),
    y⁻² = y⁻¹∘y⁻¹, y⁰ = e, y¹ = y), but not a NaN exponent; cond(Q_x) = inf on ∂L and 1 at e
    and for k = 1; the simple steps (e → −e: α = 1 exactly, α = inf along e and 0, k = 1:
    α = 0.5).  Tolerances: small multiples of u times the scale of the result."""
    m, u = impl.module, impl.u

    def one(v):
        return impl.convert([v])[0]

    def close(a, b, tol):
        assert diff(a, b) <= tol * u, (a, b)

    bnd, zero = one(BOUNDARY), one([0.0, 0.0, 0.0])
    r = m.sqrt(bnd)
    assert o_lams(H(r))[1] >= -8 * u * scale(H(r))
    close(o_product(r, r), BOUNDARY, 16 * 5 * 10)
    assert H(m.sqrt(zero)) == [0, 0, 0] and H(m.power(zero, 0.7)) == [0, 0, 0]
    assert H(m.sqrt(one([2.0, 0.0, 2.0])))[0] > 0
    ten = HI.mpf(10)
    close(m.power(bnd, 1.5), [ten**1.5 / 2, ten**1.5 * 3 / 10, ten**1.5 * 4 / 10], 16 * 32)
    for v in ([1.0, 2.0, 0.0], [-3.0, 1.0, 1.0]):
        y = one(v)
        yi = m.inverse(y)
        close(o_product(y, yi), unit(3), 64 * 4)
    y = one([0.5, 2.0, -1.0])
    yy = o_product(y, y)
    close(m.power(y, 3), o_product(y, yy), 64 * 30)
    yi = H(m.inverse(y))
    close(m.power(y, -2), o_product(yi, yi), 64 * 30)
    assert H(m.power(y, 0)) == unit(3) and H(m.power(y, 1)) == H(y)
    expect_domain(impl, "power", lambda: m.power(one(GOOD), float("nan")))
    assert HI.isinf(H(m.cond_quad(bnd))) and HI.isinf(H(m.cond_quad(zero)))
    assert H(m.cond_quad(one([1.0, 0.0, 0.0]))) == 1 and H(m.cond_quad(one([4.0]))) == 1
    e = one([1.0, 0.0, 0.0])
    minus_e = one([-1.0, 0.0, 0.0])
    assert H(m.step_to_boundary(e, minus_e)) == 1
    assert HI.isinf(H(m.step_to_boundary(e, e))) and HI.isinf(H(m.step_to_boundary(e, zero)))
    assert abs(H(m.step_to_boundary(one([2.0]), one([-4.0]))) - HI.mpf("0.5")) <= 4 * u
    x0_zero = lambda: m.arrow_solve(one([0.0, 1.0]), one([2.0, 3.0]))  # noqa: E731 (Arw invertible)
    if impl.production:  # its closed form divides by x0: refused, never a wrong answer
        expect_domain(impl, "arrow_solve", x0_zero)
    else:
        assert H(x0_zero()) == [3, 2]


@over_impls
def test_k1_semantics(impl):
    """L^1 = R_+: λ1 = λ2 = x0, det = x0², x⁻¹ = 1/x0, x^p = x0^p, Q_x y = x0² y0, cond = 1
    (inf at 0), x \\ y = y0/x0, Arw(x) = [[x0]], frames ½; NT: p = (s/z)^{1/4}, λ = √(zs)."""
    x, y = impl.convert([[2.0], [0.5]]), impl.convert([[3.0], [-1.0]])
    u = impl.u
    out = impl.out
    assert out(impl.product(x, y)) == [[6], [-0.5]]
    assert out(impl.det(x)) == [4, 0.25] and out(impl.inverse(x)) == [[0.5], [2]]
    assert out(impl.spectral_values(x)) == [[2, 0.5], [2, 0.5]]
    assert out(impl.spectral_frames(x)) == [[[0.5], [0.5]], [[0.5], [0.5]]]
    for p in (1.5, -2.5):
        for got, x0 in zip(out(impl.power(x, p)), (2, 0.5)):
            want = HI.mpf(x0) ** HI.mpf(p)
            assert abs(got[0] / want - 1) <= 4 * u
    assert out(impl.sqrt(impl.convert([[4.0]]))) == [[2]]
    assert out(impl.quad_apply(x, y)) == [[12], [-0.25]]
    assert out(impl.arrow_solve(x, y)) == [[1.5], [-2]]
    assert out(impl.cond_quad(x)) == [1, 1] and HI.isinf(out(impl.cond_quad(impl.convert([[0.0]])))[0])
    assert all(abs(a - 1) <= 4 * u for a in out(impl.step_to_boundary(x, impl.convert([[-2.0], [-0.5]]))))
    assert HI.isinf(out(impl.step_to_boundary(x[:1], y[:1]))[0])
    assert out(impl.identity(1, 1)) == [[1]] and out(impl.reflect(x)) == out(x)
    assert out(impl.arrow(x)) == [[[2]], [[0.5]]]
    nt = impl.nt_scaling(impl.convert([[2.0]]), impl.convert([[8.0]]))
    (p,), (p_inv,), (lam,) = out(nt.p), out(nt.p_inv), out(nt.lam)
    assert abs(p[0] - HI.sqrt(2)) <= 2 * u * 2 and abs(lam[0] - 4) <= 4 * u * 4
    assert abs(p[0] * p_inv[0] - 1) <= 2 * u
    if not impl.production:  # a helper only the reference has
        assert R.bar_norm(x[0]) == 0


@over_impls
def test_frames_at_zero_and_subnormal_bar(impl):
    """x̄ = 0 takes the first axis as the frame direction (c1 = (½, ½, 0), c2 = (½, −½, 0)), as
    does a subnormal x̄ along it; a subnormal x̄ in another direction is normalised correctly;
    k = 1 frames are ½; (4; 0, 0)^(−1.5) = (1/8; 0, 0)."""
    x = impl.convert([[3.0, 0.0, 0.0], [1.0, 5e-324, 0.0], [1.0, -5e-324, 5e-324]])
    c1, c2 = (impl.out(c) for c in impl.spectral_frames(x))
    assert c1[0] == [0.5, 0.5, 0] and c2[0] == [0.5, -0.5, 0] and c1[1] == [0.5, 0.5, 0]
    w = HI.mpf(0.5) / HI.sqrt(2)
    assert abs(c1[2][1] + w) <= 4 * impl.u and abs(c1[2][2] - w) <= 4 * impl.u
    c1, c2 = (impl.out(c) for c in impl.spectral_frames(impl.convert([[4.0]])))
    assert c1 == c2 == [[0.5]]
    (r,) = impl.out(impl.power(impl.convert([[4.0, 0.0, 0.0]]), -1.5))
    assert abs(r[0] - HI.mpf("0.125")) <= 2 * impl.u * HI.mpf("0.125") and r[1:] == [0, 0]


X3 = [[2.0, 0.5, -0.5], [3.0, 1.0, 1.0], [1.0, 0.1, 0.2], [4.0, 0.0, 0.0]]
D3 = [[0.1, -0.3, 0.2], [-1.0, 0.5, 0.5], [0.0, 1.0, 0.0], [0.2, 0.2, 0.2]]


@pytest.mark.parametrize("impl, name", [(i, n) for i in (F64, REF50) for n in sorted(i.PUBLIC)],
                         ids=[f"{i.name}-{n}" for i in (F64, REF50) for n in sorted(i.PUBLIC)])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_input_raises(impl, name, bad):
    """NaN or ±inf in any argument of any public function (every name the module exports) is
    refused with the domain error naming the function (the production: and the cone of a batch, None for a single vector;
    the reference: saying "not finite", also for a plain float among mpf arguments)."""
    fn = impl.PUBLIC[name]
    x, y = impl.convert(X3), impl.convert(D3)
    bad_x = impl.convert(X3)
    bad_x[2][1] = bad if impl.production else impl.ctx.mpf(bad)
    if impl.production:
        expect_domain(impl, name, lambda: fn(bad_x, y), cone=2)
    err = expect_domain(impl, name, lambda: fn(bad_x[2], y[2]))
    if not impl.production:
        assert "not finite" in str(err)
    if name in impl.BINARY:
        bad_y = impl.convert(D3)
        bad_y[1][0] = bad if impl.production else impl.ctx.mpf(bad)
        if impl.production:
            expect_domain(impl, name, lambda: fn(x, bad_y), cone=1)
        expect_domain(impl, name, lambda: fn(x[1], bad_y[1]))
        if not impl.production:
            expect_domain(impl, name, lambda: fn(x[1], [float(bad), 0.5, 0.5]))


# ==========================================================================================
# production only: batches, dtypes, extreme magnitudes, longdouble
# ==========================================================================================


def test_min_lambda2():
    x = np.array([[2.0, 0.0, 1.0], [1.0, 0.0, 0.9], [3.0, 1.0, 1.0]])
    v, i = J.min_lambda2(x)
    assert i == 1 and v == pytest.approx(0.1)
    v, i = J.min_lambda2(x[0])
    assert i is None and v == pytest.approx(1.0)
    v, i = J.min_lambda2(np.zeros((0, 3), LD))
    assert i is None and v == np.inf and v.dtype == LD
    assert J.min_lambda2(x.astype(LD))[0].dtype == LD


@pytest.mark.parametrize("impl", [F64, LDBL], ids=lambda i: i.name)
def test_max_step(impl):
    """max_step = min(α_max, min α), α_max on an empty batch, in the dtype; its domain error
    names max_step and the cone."""
    e = J.identity(3, dtype=impl.dtype)
    assert J.max_step(e, -e, alpha_max=0.5) == 0.5
    empty = np.zeros((0, 3), impl.dtype)
    assert J.max_step(empty, empty, alpha_max=0.7) == impl.dtype(0.7)
    x = np.tile(np.asarray(GOOD, dtype=impl.dtype), (5, 1))
    x[3] = BOUNDARY
    expect_domain(impl, "max_step", lambda: J.max_step(x, np.ones_like(x)), cone=3)


@pytest.mark.parametrize("name", sorted(F64.PUBLIC))
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
    X3a, D3a = np.array(X3), np.array(D3)
    xi = (X3a * 10).astype(np.int64) if in_dtypes[0] is np.int64 else X3a
    yi = (D3a * 10).astype(np.int64) if in_dtypes[1] is np.int64 else D3a
    x = xi.astype(in_dtypes[0])
    y = yi.astype(in_dtypes[1])
    if name in F64.BINARY:
        expected = out_dtype
    else:  # single-argument functions follow x only
        expected = np.result_type(x, np.float64)
    for leaf in _leaves(F64.PUBLIC[name](x, y)):
        if leaf is None or isinstance(leaf, int):
            continue  # min_lambda2's index
        assert np.asarray(leaf).dtype == expected, f"{name}: {np.asarray(leaf).dtype}"
    # single-cone call keeps single-cone shapes
    for leaf in _leaves(F64.PUBLIC[name](x[0], y[0])):
        if leaf is None or isinstance(leaf, int):
            continue
        assert np.ndim(leaf) in (0, 1, 2) and (np.ndim(leaf) == 0 or np.shape(leaf)[0] == 3)


def _leaves(r):
    if isinstance(r, tuple):
        return [leaf for item in r for leaf in _leaves(item)]
    return [r]


def test_identity_dtype_and_shape():
    assert J.identity(3).tolist() == [1.0, 0.0, 0.0]
    e = J.identity(5, 4, LD)
    assert e.dtype == LD and e.shape == (4, 5) and np.all(e[:, 0] == 1) and np.all(e[:, 1:] == 0)
    assert J.identity(1, 2).tolist() == [[1.0], [1.0]]


def test_broadcast_single_against_batch():
    y = np.array(X3)
    x = y[1]
    assert np.array_equal(J.quad_apply(x, y), J.quad_apply(np.tile(x, (4, 1)), y))
    assert np.array_equal(J.jordan_product(y, x), J.jordan_product(y, np.tile(x, (4, 1))))
    with pytest.raises(ValueError):
        J.jordan_product(y, y[:, :2])
    with pytest.raises(ValueError):
        J.jordan_product(y, y[:3])


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


def test_det_is_cancellation_free():
    """The factored det (x0−‖x̄‖)(x0+‖x̄‖) is right where x0² − ‖x̄‖² in float64 is not."""
    eps = np.finfo(np.float64).eps
    # (a) k=2, one ulp inside the boundary: exact det = 3·2^-52 + 2^-104.  The squares round
    # (x0² to 1.5 ulp off), so the naive difference is 2^-50 (33% too large).
    x = np.array([1.5 + 2.0**-52, 1.5])
    truth = o_det(x)
    naive = x[0] * x[0] - x[1] * x[1]
    assert abs(naive / truth - 1) > 0.3
    assert abs(H(J.det(x)) / truth - 1) < 2 * eps
    # (b) k=3, one ulp inside: naive gives exactly 0 (claims the boundary), factored is
    # positive and has the right order of magnitude.
    x = np.array([1.6395410951735119, 1.2940638143982073, 1.0067243153057943])
    truth = o_det(x)
    assert truth > 0
    assert x[0] * x[0] - (x[1] * x[1] + x[2] * x[2]) == 0.0
    assert J.det(x) > 0 and abs(H(J.det(x)) / truth - 1) < 1
    # (c) magnitude: x0² overflows (inf − inf = NaN) while det x ≈ 4.8e294 is representable.
    x = np.array([1e155 * (1 + 2.0**-52), 1e155])
    with np.errstate(over="ignore", invalid="ignore"):
        naive = x[0] * x[0] - x[1] * x[1]
    assert np.isnan(naive)
    assert np.isfinite(J.det(x)) and abs(H(J.det(x)) / o_det(x) - 1) < 4 * eps


def test_extreme_magnitudes():
    """Where the true result is representable it is returned; where not, ±inf/0, never NaN."""
    big = np.array([1e160, 3e159, 4e159])  # λ = 1.5e160, 5e159; det = 7.5e319: not representable
    l1, l2 = J.spectral_values(big)
    assert l1 == pytest.approx(1.5e160) and l2 == pytest.approx(5e159)
    assert np.isinf(J.det(big))
    assert abs(J.det(big.astype(LD)) / LD("7.5e319") - 1) < 1e-15  # fine in longdouble
    inv = J.inverse(big)  # ~1e-160, representable although det overflows
    assert np.all(np.isfinite(inv)) and inv[0] > 0
    e = J.identity(3)
    assert np.max(np.abs(J.jordan_product(big, inv) - e)) < 1e-14
    tiny = np.array([1e-200, 0.0, 5e-201])  # det = 7.5e-401 underflows, x⁻¹ ~ 1.3e200 does not
    assert J.det(tiny) == 0.0
    ti = J.inverse(tiny)
    assert np.max(np.abs(J.jordan_product(tiny, ti) - e)) < 1e-15
    # Q_x y with |x| ~ 1e160, |y| ~ 1e-160: 2(xᵀy)x − det(x)Ry = (1.25e160, 6e159, 8e159)
    # although det x overflows.
    q = J.quad_apply(big, np.array([1e-160, 0.0, 0.0]))
    assert q == pytest.approx([1.25e160, 6e159, 8e159], rel=1e-14)
    with np.errstate(over="ignore"):
        qq = J.quad_apply(big, big)  # ~1e480: overflows, but to inf, not inf − inf = NaN
    assert np.isinf(qq).any() and not np.isnan(qq).any()
    # NT scaling of a 1e150 point against a 1e-150 point, sqrt/power at 1e±300.
    nt = J.nt_scaling(np.array([1e150, 0.0, 5e149]), np.array([1e-150, 5e-151, 0.0]))
    assert all(np.all(np.isfinite(f)) for f in nt)
    assert J.sqrt(np.array([1e300, 0.0, 5e299])) == pytest.approx(J.sqrt(np.array([1.0, 0.0, 0.5])) * 1e150)
    assert J.power(np.array([1e-300, 5e-301, 0.0]), -1) == pytest.approx(
        J.power(np.array([1.0, 0.5, 0.0]), -1) * 1e300
    )


@given(case=cases("ii", production={"log_rho": (-0.5, 0.0), "log_scale": (-1.0, 1.0)}))
@pinned((MIX5 * [[1, 0.1, 0.1, 0.1, 0.1], [1, 1, 1, 1, 1]], other(MIX5)))
def test_longdouble_is_really_extended(case):
    """On well-conditioned data (κ ≤ ~3.2, scale 0.1…10) every longdouble result must be
    accurate to 64·(k+2)·eps(longdouble) relative to the scale — about 5e-17·(k+2)/7, far below
    eps(float64) = 2.2e-16; a computation that silently went through float64 would be off by
    ~1e-16.  Residuals are evaluated exactly (HI) on the exact longdouble values."""
    X, Y = LDBL.inputs(case)
    k = X.shape[1]
    tol = 64 * (k + 2) * LDBL.u
    assert tol < F64.u / 2
    nt = J.nt_scaling(X, Y)
    res = cones(LDBL, X, Y, J.inverse(X), J.sqrt(X), J.power(X, LD(1) / 3), J.quad_apply(X, Y),
                J.jordan_product(X, Y), *J.spectral_values(X), J.det(X), nt.p, nt.p_inv, nt.lam,
                J.step_to_boundary(X, Y - 2 * X))
    for x, y, inv, sq, cube_root, quad, prod, l1, l2, det, p, p_inv, lam, al in res:
        S, Sy, Sl = maxabs(x), maxabs(y), maxabs(lam)
        assert diff(o_product(x, inv), unit(k)) < tol, "inverse"
        assert diff(o_product(sq, sq), x) < tol * S, "sqrt"
        assert diff(o_product(cube_root, o_product(cube_root, cube_root)), x) < tol * S, "power 1/3"
        assert diff(quad, matvec(o_quad_matrix(x), y)) < tol * S**2 * Sy * 4, "quad"
        assert diff(prod, o_product(x, y)) < tol * S * Sy * 4, "prod"
        m1, m2 = o_lams(x)
        assert abs(l1 - m1) < tol * S and abs(l2 - m2) < tol * S, "λ"
        assert abs(det - m1 * m2) < tol * S**2, "det"
        qpz = matvec(o_quad_matrix(p), x)
        assert diff(qpz, matvec(o_quad_matrix(p_inv), y)) < tol * Sl and diff(qpz, lam) < tol * Sl, "nt"
        if not HI.isinf(al):
            dm = [b - 2 * a for a, b in zip(x, y)]
            b2 = o_lams([a + al * d for a, d in zip(x, dm)])[1]
            assert abs(b2) < tol * S * (1 + al * maxabs(dm)) * 4, "step"


def test_arrow_solve_names_the_singular_cone():
    x = np.array([[2.0, 0.5, 0.0], [1.0, 1.0, 0.0], [3.0, 0.0, 1.0]])  # cone 1: det = 0
    expect_domain(F64, "arrow_solve", lambda: J.arrow_solve(x, np.ones((3, 3))), cone=1)

