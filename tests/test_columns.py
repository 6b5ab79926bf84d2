"""The solver's flat-vector cone operations (:class:`~rfverify.solver.cones.ProductCone`, the
L3^{n3} × L1^{n1} layout the interior-point method works on) against the validated public
functions of :mod:`rfverify.jordan`, in float64 and longdouble.

Both run the same row operations of :mod:`rfverify.jordan` (one copy of each formula), so on
every input — ordinary, near the boundary (λ2/λ1 down to 1e-8), or of extreme magnitude that
needs power-of-two rescaling — ProductCone must give, family by family, exactly the bits of
the public function: any difference means the flat layer (views, joins, dtypes) or a second
copy of a formula has crept in.  The accuracy of those shared formulas is what
``tests/test_jordan.py`` and ``tests/test_reference_jordan.py`` establish; the closed forms
p^±2, new on the solver's path, are checked here against mpmath.  Also pinned: the hot path
never rescales or re-validates ordinary data (the solver calls it a dozen times per
iteration), and errors name the operation and the *global* cone index.
"""

from __future__ import annotations

import mpmath
import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from rfverify import jordan
from rfverify.errors import ConeDomainError
from rfverify.solver.cones import ProductCone

LD = np.longdouble
DTYPES = [np.float64, LD]
dtypes = pytest.mark.parametrize("dtype", DTYPES, ids=["float64", "longdouble"])


def _point(rng, cones, dtype, log_kappa, scale):
    """A strictly interior point with λ2/λ1 down to 10^-log_kappa, entries times 2^scale."""
    x = rng.standard_normal(cones.nz)
    x3 = x[:3 * cones.n3].reshape(cones.n3, 3)
    nb = np.hypot(x3[:, 1], x3[:, 2])
    # x0 = ‖x̄‖(1 + t) gives λ2/λ1 = t/(2 + t).
    x3[:, 0] = nb * (1 + 10.0 ** rng.uniform(-log_kappa, 0.5, cones.n3))
    x[3 * cones.n3:] = 10.0 ** rng.uniform(-2, 2, cones.n1)
    x = x.astype(dtype)
    if dtype == LD:  # bits below float64 precision, so longdouble must keep them
        x = x * (1 + dtype(2.0) ** -60 * rng.uniform(-1, 1, x.size).astype(dtype))
    return np.ldexp(x, scale)


def _direction(rng, cones, dtype, scale):
    d = rng.standard_normal(cones.nz).astype(dtype)
    d[rng.random(cones.nz) < 0.1] = 0
    return np.ldexp(d, scale)


def _by_family(cones, fn, *args):
    """The public jordan function on each family, joined like ProductCone joins."""
    parts = [fn(*(cones.split(a)[i] for a in args)) for i, n in ((0, cones.n3), (1, cones.n1)) if n]
    return np.concatenate([np.ravel(p) for p in parts]) if parts else np.empty(0, np.result_type(*args))


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape, (a.dtype, b.dtype, a.shape, b.shape)
    assert np.array_equal(a, b), f"max difference {float(np.max(np.abs(a - b))):.3e}"


def _assert_flat_equals_jordan(cones, z, s, dz, ds):
    """Every ProductCone operation the solver uses equals jordan's, bit for bit."""
    _same(cones.product(z, dz), _by_family(cones, jordan.jordan_product, z, dz))
    _same(cones.quad_operator(z)(dz), _by_family(cones, jordan.quad_apply, z, dz))
    _same(cones.quad_apply(s, ds), _by_family(cones, jordan.quad_apply, s, ds))
    _same(cones.arrow_solve(z, dz), _by_family(cones, jordan.arrow_solve, z, dz))
    _same(cones.inverse(z), _by_family(cones, jordan.inverse, z))
    for t in (2, -2, -1, 0.5, -0.7):
        _same(cones.power(z, t), _by_family(cones, lambda a: jordan.power(a, t), z))
    _same(cones.lambda2(z), _by_family(cones, lambda a: jordan.spectral_values(a)[1], z))
    with np.errstate(over="ignore"):  # huge longdouble blocks overflow to inf in float64, as in the solver
        _same(cones.quad_blocks(z), _by_family(cones, jordan.quad_matrix, z).astype(np.float64))
        _same(cones.arrow_blocks(dz), _by_family(cones, jordan.arrow, dz).astype(np.float64))
    p, p_inv, lam, cond = cones.nt_scaling(z, s)
    for got, name in ((p, "p"), (p_inv, "p_inv"), (lam, "lam")):
        _same(got, _by_family(cones, lambda a, b: getattr(jordan.nt_scaling(a, b), name), z, s))
    _same(cond, _by_family(cones, lambda a, b: jordan.nt_scaling(a, b).cond, z, s).astype(np.float64))
    alphas = np.concatenate([_by_family(cones, jordan.step_to_boundary, z, dz),
                             _by_family(cones, jordan.step_to_boundary, s, ds)])
    step, limit = cones.stepper(z, s)(dz, ds)
    assert step == float(np.min(alphas, initial=np.inf))
    # the cone named is the first (z before s) whose own step by jordan is the step
    assert limit is None if step == np.inf else (
        int(np.argmin(alphas)) == limit[0] + (cones.n_cones if limit[1] == "s" else 0))
    assert cones.max_step(z, dz) == float(np.min(_by_family(cones, jordan.step_to_boundary, z, dz),
                                                 initial=np.inf))


cases = st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 6), st.integers(0, 4),
                  st.floats(0, 8), st.integers(-40, 40))


@dtypes
@given(case=cases)
@example(case=(0, 5, 0, 8.0, 0))     # λ2/λ1 ~ 1e-8, L3 only
@example(case=(1, 0, 4, 0.0, 0))     # L1 only
@example(case=(2, 3, 2, 4.0, 40))    # large scale
@example(case=(3, 3, 2, 4.0, -40))   # small scale
@example(case=(4, 0, 0, 0.0, 0))     # no cones at all
def test_flat_operations_equal_jordan(dtype, case):
    seed, n3, n1, log_kappa, scale = case
    rng = np.random.default_rng(seed)
    cones = ProductCone(n3, n1)
    z = _point(rng, cones, dtype, log_kappa, scale)
    s = _point(rng, cones, dtype, log_kappa, -scale)
    dz = _direction(rng, cones, dtype, scale)
    ds = _direction(rng, cones, dtype, -scale)
    _assert_flat_equals_jordan(cones, z, s, dz, ds)


def _spy_on_rescaling(monkeypatch):
    calls = []
    from rfverify.jordan import _checks

    real = _checks._scale_exponents

    def spy(x):
        calls.append(x.shape)
        return real(x)

    monkeypatch.setattr(_checks, "_scale_exponents", spy)
    return calls


@dtypes
def test_hot_path_neither_rescales_nor_revalidates_ordinary_data(dtype, monkeypatch):
    # The solver calls these a dozen times per iteration: ordinary data must pass the one cheap
    # magnitude test, never reach the row-by-row exponents, and never go through the public
    # functions' argument parsing (power, inverse, quad_apply and arrow_blocks used to).
    rng = np.random.default_rng(3)
    cones = ProductCone(4, 2)
    z, s = (_point(rng, cones, dtype, 6.0, 0) for _ in range(2))
    dz, ds = (_direction(rng, cones, dtype, 0) for _ in range(2))
    calls = _spy_on_rescaling(monkeypatch)

    def refuse(*args, **kw):
        raise AssertionError("the hot path went through the public façade")

    for name in jordan.__all__:
        if name not in ("NTScaling", "identity"):
            monkeypatch.setattr(jordan, name, refuse)
    cones.product(z, dz)
    cones.arrow_solve(z, dz)
    cones.quad_operator(z)(dz)
    cones.quad_apply(z, dz)
    cones.inverse(z)
    cones.power(z, 2)
    cones.power(z, -2)
    cones.quad_blocks(z)
    cones.arrow_blocks(z)
    cones.nt_scaling(z, s)
    cones.stepper(z, s)(dz, ds)
    cones.max_step(z, dz)
    cones.min_lambda2(z)
    assert calls == []


@pytest.mark.parametrize("dtype, scale, cheap_test_suffices", [
    (np.float64, 300, False), (np.float64, -300, False),  # beyond 2^±128: rescaled
    (LD, 300, True), (LD, -300, True),                    # ordinary for longdouble
    (LD, -1100, False),  # below float64's range: the float64 image cannot vouch, rows can
    (LD, 3000, False),   # beyond 2^2048 (and beyond float64's range): rescaled
], ids=["f64-big", "f64-small", "ld-big", "ld-small", "ld-sub-f64", "ld-huge"])
def test_extreme_magnitudes_are_rescaled_exactly_like_jordan(dtype, scale, cheap_test_suffices,
                                                               monkeypatch):
    rng = np.random.default_rng(7)
    cones = ProductCone(3, 2)
    z = _point(rng, cones, dtype, 3.0, 0) * dtype(2.0) ** scale
    s = _point(rng, cones, dtype, 3.0, 0) * dtype(2.0) ** scale
    dz = _direction(rng, cones, dtype, 0) * dtype(2.0) ** scale
    ds = _direction(rng, cones, dtype, 0) * dtype(2.0) ** scale
    calls = _spy_on_rescaling(monkeypatch)
    cones.product(z, dz)
    assert (calls == []) == cheap_test_suffices
    _assert_flat_equals_jordan(cones, z, s, dz, ds)
    if dtype == np.float64:  # the plain formulas would overflow or flush to zero here
        big = cones.quad_operator(z)(dz)
        assert np.all(np.isfinite(big)) and np.all(big[np.asarray(dz) != 0] != 0)


def _boundary_at(z, cones, cone):
    """z with cone `cone` moved onto the boundary (λ2 = 0) exactly."""
    z = z.copy()
    if cone < cones.n3:
        z[3 * cone:3 * cone + 3] = [5.0, 3.0, 4.0]
    else:
        z[3 * cones.n3 + cone - cones.n3] = 0.0
    return z


@dtypes
@pytest.mark.parametrize("bad_cone", [0, 2, 4])  # L3 cones 0..2, L1 cones 3..4
def test_domain_errors_name_the_operation_and_the_global_cone(dtype, bad_cone):
    rng = np.random.default_rng(11)
    cones = ProductCone(3, 2)
    z = _point(rng, cones, dtype, 2.0, 0)
    s = _point(rng, cones, dtype, 2.0, 0)
    outside = z.copy()
    if bad_cone < 3:
        outside[3 * bad_cone] = -abs(outside[3 * bad_cone])  # λ2 < 0
    else:
        outside[9 + bad_cone - 3] = -1.0
    on_boundary = _boundary_at(z, cones, bad_cone)
    calls = [("nt_scaling", lambda: cones.nt_scaling(outside, s)),
             ("step_to_boundary", lambda: cones.stepper(outside, s)(s, s)),
             ("step_to_boundary", lambda: cones.max_step(on_boundary, s)),
             ("inverse", lambda: cones.inverse(on_boundary)),
             ("power(-2)", lambda: cones.power(on_boundary, -2)),
             ("power(-0.5)", lambda: cones.power(outside, -0.5)),
             ("arrow_solve", lambda: cones.arrow_solve(on_boundary, s))]
    for op, call in calls:
        with pytest.raises(ConeDomainError) as info:
            call()
        assert (info.value.operation, info.value.cone) == (op, bad_cone), str(info.value)


@dtypes
def test_nan_is_reported_with_its_cone_not_propagated(dtype):
    rng = np.random.default_rng(5)
    cones = ProductCone(2, 2)
    z = _point(rng, cones, dtype, 2.0, 0)
    for bad, cone in ((4, 1), (7, 3)):  # an L3 and an L1 entry
        d = _direction(rng, cones, dtype, 0)
        d[bad] = np.nan
        for call in (lambda: cones.product(z, d), lambda: cones.arrow_solve(z, d),
                     lambda: cones.quad_apply(z, d), lambda: cones.arrow_blocks(d),
                     lambda: cones.power(d, 2), lambda: cones.stepper(z, z)(d, z)):
            with pytest.raises(ConeDomainError) as info:
                call()
            assert info.value.cone == cone and "non-finite" in str(info.value)


# ---- the closed forms p^±2 against mpmath ----------------------------------------------------


def _mp(v):
    num, den = (LD(v) if isinstance(v, LD) else float(v)).as_integer_ratio()
    return mpmath.mpf(num) / den


@dtypes
@given(case=st.tuples(st.integers(0, 2**32 - 1), st.floats(0, 12), st.integers(-60, 60)))
@example(case=(0, 12.0, 0))    # λ2/λ1 ~ 1e-12
@example(case=(1, 0.0, 60))
@example(case=(2, 6.0, -60))
def test_closed_form_squares_against_mpmath(dtype, case):
    """x² = (‖x‖²; 2 x0 x̄) and x⁻² = R x²/det(x)² per cone, from ProductCone.power.

    x²: each entry is a sum of k products rounded once each, error ≤ (k+1)·u·|x|² per entry
    against max |x²_i| = ‖x‖² (k = 3).  x⁻² = x² r² with r = 1/det x = (1/λ1)/λ2, which carries
    the relative error of λ2, ≤ 4·u·κ with κ = λ1/λ2, doubled by the square; bound
    16·u·κ·max|x⁻²_i| per cone.  (The spectral formula agrees only to O(u·κ²) in the c2 part of x⁻²; these are
    cancellation-free.)
    """
    seed, log_kappa, scale = case
    rng = np.random.default_rng(seed)
    cones = ProductCone(4, 2)
    x = _point(rng, cones, dtype, log_kappa, scale)
    u = float(np.finfo(dtype).eps)
    sq, inv_sq = cones.power(x, 2), cones.power(x, -2)
    with mpmath.workprec(400):
        for c in range(cones.n_cones):
            sl = slice(3 * c, 3 * c + 3) if c < cones.n3 else slice(3 * cones.n3 + c - cones.n3,
                                                                     3 * cones.n3 + c - cones.n3 + 1)
            xm = [_mp(v) for v in x[sl]]
            nrm2 = mpmath.fsum(v * v for v in xm)
            x2 = [nrm2] + [2 * xm[0] * v for v in xm[1:]]
            nb = mpmath.sqrt(mpmath.fsum(v * v for v in xm[1:]))
            det = (xm[0] + nb) * (xm[0] - nb)
            xi2 = [x2[0] / det**2] + [-v / det**2 for v in x2[1:]]
            kappa = (xm[0] + nb) / (xm[0] - nb)
            for got, want, bound in ((sq[sl], x2, 4 * u), (inv_sq[sl], xi2, 16 * u * kappa)):
                scale_ = max(abs(w) for w in want)
                err = max(abs(_mp(g) - w) for g, w in zip(got, want))
                assert err <= bound * scale_, (c, float(err / scale_), float(bound))
