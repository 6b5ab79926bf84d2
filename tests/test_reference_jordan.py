r"""Tests of :mod:`reference.jordan` that concern the reference alone, and the agreement of the two
implementations of DESIGN.md §3 (DESIGN.md §5).

The identities of §3 themselves run against both implementations in tests/test_jordan.py
(with the adapters, tolerance conventions and pinned cases of tests/jordan_impls.py).  Here:

1. **Agreement between implementations**: every public function of :mod:`rfverify.jordan`
   (float64 and ``numpy.longdouble``) against the reference at 50 digits on the same (exactly
   converted) inputs, to the accuracy the inputs allow; plus a deterministic check that the
   longdouble results are really better than the float64 ones.  (Both refuse the same
   out-of-domain points naming the same operation: tests/test_jordan.py::test_domain_errors.)
2. **The reference's own interface**: argument checks, exact conversion into a context, the
   context of mixed inputs.
3. **Precision hygiene**: no reference function touches ``mpmath.mp``'s precision, and results
   computed in a 30-digit context carry 30 digits (no more, no fewer).

Inputs of the agreement tests: the reference's ranges narrowed to scales 1e±40 with entries 0 or
≥ 2^-60 relative, so that no intermediate of the float64/longdouble computation reaches the
subnormal range (underflow is a range limit of the dtype, tested in tests/test_jordan.py, not an
accuracy question).
"""

from __future__ import annotations

import os
from fractions import Fraction

import mpmath
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from reference import jordan as R
from rfverify import jordan as J

try:
    from jordan_impls import (F64, HI, HUGE, K1, LD, LDBL, MIX5, NEAR12, NEAREPS, REF50, SUBN, TINY,
                              XBAR0, H, cases, cast, check, cones, diff, gen_partner, kappa, matvec,
                              maxabs, mdiff, o_det, o_lams, o_product, o_quad_matrix, other, pinned,
                              report_worst_ratios, scale)
except ImportError:  # tests/ made a package
    from tests.jordan_impls import (F64, HI, HUGE, K1, LD, LDBL, MIX5, NEAR12, NEAREPS, REF50, SUBN,
                                    TINY, XBAR0, H, cases, cast, check, cones, diff, gen_partner,
                                    kappa, matvec, maxabs, mdiff, o_det, o_lams, o_product,
                                    o_quad_matrix, other, pinned, report_worst_ratios, scale)

assert report_worst_ratios  # an autouse fixture: imported to take effect in this module

over_dtypes = pytest.mark.parametrize("impl", [F64, LDBL], ids=lambda i: i.name)
NARROW = {"log_scale": (-40.0, 40.0)}  # the agreement tests' range, see the module docstring


def _same_inputs(impl, case):
    """The case's reference rows in the dtype under test (longdouble jittered below float64
    precision), and exactly the same numbers in the 50-digit reference."""
    prod = tuple(cast(v.rows("reference"), impl.dtype) for v in case)
    return prod, tuple(REF50.convert(a) for a in prod)


def _np_scalar(v):
    return np.asarray(v)[()]


def _E(l1, l2, p):
    """Error scale of x^p: (|p|+2)(λ1^p + λ2^p) + |p|·λ1·λ2^{p−1} (see test_power_additive)."""
    p = HI.mpf(p)
    return (abs(p) + 2) * (l1**p + l2**p) + abs(p) * l1 * l2 ** (p - 1)


# ==========================================================================================
# 1. agreement between implementations
# ==========================================================================================

POWERS = [-3, -2, -1.5, -1, -0.5, 1.0 / 3.0, 0.5, 1.5, 2, 3]
# production functions covered by the agreement tests below
AGREEMENT_COVERED = {
    "identity", "jordan_product", "arrow", "reflect", "spectral_values", "spectral_frames",
    "det", "trace", "inverse", "power", "sqrt", "quad_apply", "quad_matrix", "arrow_solve",
    "cond_quad", "nt_scaling", "step_to_boundary", "max_step", "min_lambda2",
}


def test_agreement_covers_every_production_function():
    assert AGREEMENT_COVERED | {"NTScaling"} == set(J.__all__)


@over_dtypes
@given(case=cases("i", no_tiny=True, reference=NARROW), p=st.sampled_from(POWERS))
@pinned((NEAR12,), p=-0.5)
@pinned((NEAREPS,), p=1.5)
@pinned((HUGE,), p=-1)
@pinned((SUBN,), p=1.0 / 3.0)
@pinned((XBAR0,), p=3)
@pinned((K1,), p=-1.5)
@pinned((MIX5,), p=2)
def test_agreement_unary(impl, case, p):
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
    (xd,), (x_ref,) = _same_inputs(impl, case)
    k, u = xd.shape[1], impl.u
    assert impl.out(J.identity(k, dtype=impl.dtype)) == REF50.out(R.identity(REF50.ctx, k))
    for name in ("arrow", "reflect", "trace"):
        assert impl.out(getattr(impl, name)(xd)) == REF50.out(getattr(REF50, name)(x_ref))
    got = cones(impl, xd, *impl.spectral_values(xd), impl.det(xd), *impl.spectral_frames(xd), impl.quad_matrix(xd),
                impl.inverse(xd), impl.sqrt(xd), impl.power(xd, p), impl.cond_quad(xd))
    want = cones(REF50, x_ref, *REF50.spectral_values(x_ref), REF50.det(x_ref), *REF50.spectral_frames(x_ref),
                 REF50.quad_matrix(x_ref), REF50.inverse(x_ref), REF50.sqrt(x_ref), REF50.power(x_ref, p),
                 REF50.cond_quad(x_ref))
    for i, ((x, l1, l2, d, c1, c2, qm, inv, sq, pw, cq), (_, r1, r2, rd, q1, q2, rqm, rinv, rsq, rpw, rcq)) in \
            enumerate(zip(got, want)):
        S, kap = scale(x), kappa(x)
        l1h, l2h = o_lams(x)
        check(impl, max(abs(l1 - r1), abs(l2 - r2)), 4 * (k + 2) * u * S, "spectral_values")
        check(impl, abs(H(impl.min_lambda2(xd[i:i + 1])) - r2), 4 * (k + 2) * u * S, "min_lambda2")
        check(impl, abs(d - rd), 8 * (k + 2) * u * S**2, "det")
        check(impl, max(diff(c1, q1), diff(c2, q2)), 4 * (k + 2) * u, "spectral_frames")
        check(impl, mdiff(qm, rqm), 4 * (k + 2) * u * S**2, "quad_matrix")
        check(impl, diff(inv, rinv), 4 * (k + 2) * u * kap * scale(rinv), "inverse")
        check(impl, diff(sq, rsq), 4 * (k + 2) * u * HI.sqrt(kap) * scale(rsq), "sqrt")
        check(impl, diff(pw, rpw), 4 * (k + 2) * u * _E(l1h, l2h, p), "power")
        check(impl, abs(cq / rcq - 1), 8 * (k + 2) * u * kap, "cond_quad")


@over_dtypes
@given(case=cases("ig", no_tiny=True, reference=NARROW))
@pinned((NEAR12, gen_partner(NEAR12)), (HUGE, -HUGE), (SUBN, gen_partner(SUBN)),
        (XBAR0[:1], [[-1.0, 0.5, 0.0]]), (K1[:1], [[-0.7]]), ([[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
def test_agreement_binary(impl, case):
    """Two-argument functions, x ∈ int L, y arbitrary (u = eps(dtype)):

    * jordan_product: 4(k+2)·u·S(x)S(y) (each entry a k-term sum of products);
    * quad_apply: 4(k+2)²·u·S(x)²S(y) (det error times |y|, plus the k-term dot product);
    * arrow_solve: 8(k+2)·u·κ·S(y)/λ2(x) (forward error, cond(Arw(x)) = κ, ‖Arw⁻¹‖ = 1/λ2);
    * step_to_boundary, max_step (α_max = 1): relative 4(k+2)·u·(κ + α S(y)/λ2(x)) (see
      test_step_to_boundary); if either side says "never leaves" (inf) or the float side
      saturates at the dtype's largest number, the other side's λ2(Q_{x^{-1/2}} y) must be
      within that error of 0, i.e. 1/α ≤ 4(k+2)·u·S(y)/λ2(x)·κ.
    """
    (xd, yd), (x_ref, y_ref) = _same_inputs(impl, case)
    k, u = xd.shape[1], impl.u
    got = cones(impl, xd, yd, impl.product(xd, yd), impl.quad_apply(xd, yd), impl.arrow_solve(xd, yd),
                impl.step_to_boundary(xd, yd))
    want = cones(REF50, x_ref, y_ref, REF50.product(x_ref, y_ref), REF50.quad_apply(x_ref, y_ref),
                 REF50.arrow_solve(x_ref, y_ref), REF50.step_to_boundary(x_ref, y_ref))
    for i, ((x, y, pr, qa, sol, a_prod), (_, _, rpr, rqa, rsol, a_ref)) in enumerate(zip(got, want)):
        kap, l2x = kappa(x), o_lams(x)[1]
        check(impl, diff(pr, rpr), 4 * (k + 2) * u * scale(x) * scale(y), "jordan_product")
        check(impl, diff(qa, rqa), 4 * (k + 2) ** 2 * u * scale(x) ** 2 * scale(y), "quad_apply")
        check(impl, diff(sol, rsol), 8 * (k + 2) * u * kap * scale(y) / l2x, "arrow_solve")
        sat = a_prod == impl.max
        small = 4 * (k + 2) * u * kap * scale(y) / l2x  # error in λ2(y) = −1/α
        if HI.isinf(a_ref) or HI.isinf(a_prod) or sat:
            for a in (a_ref, a_prod):
                if not HI.isinf(a) and a != impl.max:
                    assert 1 / a <= small, f"step: one side inf, other α = {a}"
            continue
        rel = 4 * (k + 2) * u * (kap + a_ref * scale(y) / l2x)
        check(impl, abs(a_prod / a_ref - 1), rel, "step_to_boundary")
        ms = H(_np_scalar(impl.max_step(xd[i:i + 1], yd[i:i + 1])))
        one = min(a_ref, HI.mpf(1))
        check(impl, abs(ms - one), rel * one, "max_step")


@over_dtypes
@given(case=cases("ii", no_tiny=True, reference=NARROW))
@pinned((NEAR12, XBAR0[:1].repeat(2, 0)), (NEAR12, NEAR12[:, [0, 2, 1]]), (HUGE, TINY), (SUBN, other(SUBN)),
        (K1[:1], [[3e-50]]), (MIX5, other(MIX5)))
def test_agreement_nt_scaling(impl, case):
    """rfverify.jordan.nt_scaling against the reference (u = eps(dtype), K = κ(z) + κ(s)):
    p, p⁻¹, λ each to 4(k+2)²·u·K·S(field); β (= det p) relative 4(k+2)·u·K; v = p/√β to
    4(k+2)²·u·K·S(v); cond (= κ(p)², computed by the production as λ1(v)⁴) relative
    8(k+2)·u·K·κ(p).

    The NT quantities depend on (z, s) through z̄ = z/√det z and s̄ = s/√det s and the scalar
    (det s/det z)^{1/8}; √det z = √λ1√λ2 carries relative error O(k u κ(z)) (likewise for s),
    the unit-determinant construction (γ ≥ 1, w̄0 ≥ 1, denominators ≥ 4) adds only O(k u)
    relative to the scale of each field, so the forward error is O(k² u K) times the scale.
    cond = κ(p)² additionally inherits the relative error of λ2(p) (conditioning κ(p))."""
    (zd, sd), (z_ref, s_ref) = _same_inputs(impl, case)
    k, u = zd.shape[1], impl.u
    got = J.nt_scaling(zd, sd)
    ref = REF50.nt_scaling(z_ref, s_ref)
    for z, s, p, p_inv, lam, beta, v, cond, rp, rpi, rl in zip(
            *(impl.out(a) for a in (zd, sd, got.p, got.p_inv, got.lam, got.beta, got.v, got.cond)),
            *(REF50.out(a) for a in ref)):
        kk = kappa(z) + kappa(s)
        for name, a, b in (("p", p, rp), ("p_inv", p_inv, rpi), ("lam", lam, rl)):
            check(impl, diff(a, b), 4 * (k + 2) ** 2 * u * kk * scale(b), f"nt_scaling.{name}")
        det_p = o_det(rp)
        check(impl, abs(beta / det_p - 1), 4 * (k + 2) * u * kk, "nt_scaling.beta")
        want_v = [t / HI.sqrt(det_p) for t in rp]
        check(impl, diff(v, want_v), 4 * (k + 2) ** 2 * u * kk * scale(want_v), "nt_scaling.v")
        kp = kappa(rp)
        check(impl, abs(cond / kp**2 - 1), 8 * (k + 2) * u * kk * kp, "nt_scaling.cond")


# The functions compared in the deterministic longdouble test below, on (x, s, y) of either
# implementation (exact functions — identity, arrow, reflect, trace — are excluded).
COMPARED = {
    "jordan_product": lambda i, x, s, y: i.product(x, y),
    "spectral_values": lambda i, x, s, y: list(i.spectral_values(x)),
    "spectral_frames": lambda i, x, s, y: i.spectral_frames(x)[0],
    "det": lambda i, x, s, y: i.det(x),
    "inverse": lambda i, x, s, y: i.inverse(x),
    "power": lambda i, x, s, y: i.power(x, 1.0 / 3.0),
    "sqrt": lambda i, x, s, y: i.sqrt(x),
    "quad_apply": lambda i, x, s, y: i.quad_apply(x, y),
    "quad_matrix": lambda i, x, s, y: i.quad_matrix(x),
    "arrow_solve": lambda i, x, s, y: i.arrow_solve(x, y),
    "cond_quad": lambda i, x, s, y: i.cond_quad(x),
    "nt_scaling": lambda i, x, s, y: list(i.nt_scaling(x, s)[:3]),
    "step_to_boundary": lambda i, x, s, y: i.step_to_boundary(x, y),
    "max_step": lambda i, x, s, y: [i.max_step(x, y)],
    "min_lambda2": lambda i, x, s, y: [i.min_lambda2(x)],
}


def _flat(v):
    v = H(v)
    return [t for item in v for t in _flat(item)] if isinstance(v, list) else [v]


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
    fail both."""
    rng = np.random.default_rng(20240611)
    err = {F64.name: {}, LDBL.name: {}}
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
        refs = {name: _flat(fn(REF50, *(REF50.convert([a]) for a in (xf, sf, yf))))
                for name, fn in COMPARED.items()}
        x, s, y = (H(a) for a in (xf, sf, yf))
        # relative to the size of the result and to the conditioning of the data (for the
        # step: κ + α S(y)/λ2(x), see test_step_to_boundary)
        cond = kappa(x) * kappa(s) * (k + 2)
        alpha = refs["step_to_boundary"][0]
        cond_step = (kappa(x) + alpha * scale(y) / o_lams(x)[1]) * (k + 2)
        for impl in (F64, LDBL):
            args = [np.asarray([a], dtype=impl.dtype) for a in (xf, sf, yf)]
            for name, fn in COMPARED.items():
                c = cond_step if name in ("step_to_boundary", "max_step") else cond
                e = diff(_flat(fn(impl, *args)), refs[name]) / (maxabs(refs[name]) * c)
                err[impl.name][name] = max(err[impl.name].get(name, HI.zero), e)
    tol_ld = 4 * LDBL.u
    assert set(err[LDBL.name]) | {"identity", "arrow", "reflect", "trace", "NTScaling"} == set(J.__all__)
    assert tol_ld < F64.u / 2
    for name in err[LDBL.name]:
        e64, eld = err[F64.name][name], err[LDBL.name][name]
        if os.environ.get("JORDAN_RATIOS"):
            print(name, float(e64 / F64.u), float(eld / LDBL.u))
        assert eld <= tol_ld, f"{name}: longdouble error {HI.nstr(eld, 3)} is not extended"
        assert 16 * eld < e64, (
            f"{name}: longdouble error {HI.nstr(eld, 3)} not clearly below float64 "
            f"{HI.nstr(e64, 3)}"
        )


# ==========================================================================================
# 2. the reference's own interface
# ==========================================================================================

CTX = REF50.ctx
REF_PUBLIC = REF50.PUBLIC
BINARY = REF50.BINARY
X3 = [2.0, 0.5, -0.5]
D3 = [0.1, -0.3, 0.2]


def cv(values):
    """Float values → exact mpf list of the 50-digit working context."""
    return R.to_ctx(CTX, values)


def _expect_domain(fn, op):
    with pytest.raises(R.ReferenceDomainError) as ei:
        fn()
    assert ei.value.operation == op and str(ei.value).startswith(op + ":")


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
