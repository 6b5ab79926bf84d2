"""The solver's column-wise cone kernels (:mod:`rfverify.solver.columns`) against the validated
:mod:`rfverify.jordan`, through :class:`~rfverify.solver.cones.ProductCone`, in float64 and
longdouble.

Both evaluate the same formulas; they differ only in the order of a few sums (einsum against
explicit column sums), so they agree to rounding amplified by the conditioning of the point:
``κ = λ1/λ2`` for anything that goes through λ2 (step lengths go through Q_{x^{-1/2}}, whose
condition number is κ).  Bounds below are ``C·u·κ^j`` relative to the largest entry, with C
calibrated on the observed ratios (worst seen ≈ 0.1 of the bound).  Points are drawn with
λ2/λ1 ≥ 1e-8 and overall scale 2^±40; the declines — extreme magnitudes, points outside
the cone, NaN — are pinned and must give exactly what :mod:`rfverify.jordan` gives, errors
included, with the global cone index.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from rfverify import jordan
from rfverify.errors import ConeDomainError
from rfverify.solver import columns
from rfverify.solver.cones import ProductCone

DTYPES = [np.float64, np.longdouble]
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
    if dtype == np.longdouble:  # bits below float64 precision, so longdouble must keep them
        x = x * (1 + dtype(2.0) ** -60 * rng.uniform(-1, 1, x.size).astype(dtype))
    return np.ldexp(x, scale)


def _direction(rng, cones, dtype, scale):
    d = rng.standard_normal(cones.nz).astype(dtype)
    d[rng.random(cones.nz) < 0.1] = 0
    return np.ldexp(d, scale)


def _kappa(cones, x):
    x3, x1 = cones.split(np.asarray(x, dtype=np.longdouble))
    nb = np.hypot(x3[:, 1], x3[:, 2])
    k = (x3[:, 0] + nb) / (x3[:, 0] - nb)
    return float(k.max(initial=1.0))


def _generic(cones, fn, *args):
    """The operation by rfverify.jordan, family by family (the pre-kernel route)."""
    return cones._flat(fn, *args, op=fn.__name__)


def _close(fast, ref, bound):
    ref = np.asarray(ref, dtype=np.longdouble)
    err = np.abs(np.asarray(fast, dtype=np.longdouble) - ref).max(initial=0)
    scale = np.abs(ref).max(initial=0)
    assert err <= bound * scale, f"error {float(err):.3e} > {bound:.3e} · {float(scale):.3e}"


cases = st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 6), st.integers(0, 4),
                  st.floats(0, 8), st.integers(-40, 40))


@dtypes
@given(case=cases)
@example(case=(0, 5, 0, 8.0, 0))     # λ2/λ1 ~ 1e-8, L3 only
@example(case=(1, 0, 4, 0.0, 0))     # L1 only
@example(case=(2, 3, 2, 4.0, 40))    # large scale
@example(case=(3, 3, 2, 4.0, -40))   # small scale
def test_kernels_agree_with_jordan(dtype, case):
    seed, n3, n1, log_kappa, scale = case
    if n3 + n1 == 0:
        return
    rng = np.random.default_rng(seed)
    cones = ProductCone(n3, n1)
    u = float(np.finfo(dtype).eps)
    z = _point(rng, cones, dtype, log_kappa, scale)
    s = _point(rng, cones, dtype, log_kappa, -scale)
    dz = _direction(rng, cones, dtype, scale)
    ds = _direction(rng, cones, dtype, -scale)
    kz, ks = _kappa(cones, z), _kappa(cones, s)
    kappa = max(kz, ks)

    # Products and the quadratic representation: sums of three products, no λ2.
    _close(cones.product(z, dz), _generic(cones, jordan.jordan_product, z, dz), 8 * u)
    _close(cones.quad_operator(z)(dz), _generic(cones, jordan.quad_apply, z, dz), 16 * u * kz)
    # Arw(x)⁻¹ y divides by λ1 λ2 and x0.
    _close(cones.arrow_solve(z, dz), _generic(cones, jordan.arrow_solve, z, dz), 16 * u * kz ** 2)
    # λ2 itself: absolute error O(u·S), the same expression in both.
    _close(cones.lambda2(z), np.concatenate([jordan.spectral_values(cones.split(z)[0])[1] if n3 else [],
                                             cones.split(z)[1][:, 0]]), 8 * u)
    q3, q1 = cones._map(jordan.quad_matrix, z, op="quad_matrix")
    _close(cones.quad_blocks(z), np.concatenate([np.ravel(q) for q in (q3, q1) if q is not None]).astype(np.float64),
           8 * max(u, float(np.finfo(np.float64).eps)))

    # NT scaling: every output goes through √det of z and s.
    p, p_inv, lam, cond = cones.nt_scaling(z, s)
    fams = [jordan.nt_scaling(*(cones.split(a)[i] for a in (z, s))) for i, n in ((0, n3), (1, n1)) if n]
    for fast, name in ((p, "p"), (p_inv, "p_inv"), (lam, "lam")):
        _close(fast, np.concatenate([np.ravel(getattr(r, name)) for r in fams]), 32 * u * kappa)
    # cond(Q_p) is a float64 diagnostic in both.
    _close(cond, np.concatenate([np.ravel(r.cond) for r in fams]), 32 * float(np.finfo(np.float64).eps) * kappa)

    # Step lengths: y = Q_{x^{-1/2}} dx has condition κ; compare what the solver uses, min(α, 1),
    # with an absolute floor for a step that lands within rounding of the boundary.
    step = cones.stepper(z, s)(dz, ds)
    ref = cones._max_step_pair_checked(z, dz, s, ds)
    assert abs(min(step, 1.0) - min(ref, 1.0)) <= 64 * u * kappa ** 2 * max(min(ref, 1.0), 1e-3)


@pytest.mark.parametrize("dtype, scale, declined", [
    (np.float64, 300, True), (np.float64, -300, True),            # beyond 2^±128
    (np.longdouble, 300, False), (np.longdouble, -300, False),    # moderate for longdouble
    (np.longdouble, -1100, False),  # below float64's range: flushed to 0 in the float64 image
    (np.longdouble, 3000, True),    # beyond 2^2048 (and beyond float64's range)
], ids=["f64-big", "f64-small", "ld-big", "ld-small", "ld-sub-f64", "ld-huge"])
def test_extreme_magnitudes_take_the_rescaling_route(dtype, scale, declined):
    # Entries beyond [2^-T, 2^T] (T = maxexp/8): the kernels decline and ProductCone returns
    # exactly rfverify.jordan's rescaled result.  Longdouble entries below float64's range
    # pass the float64-image check; their fourth powers are still normal longdouble numbers.
    rng = np.random.default_rng(7)
    cones = ProductCone(3, 2)
    z = _point(rng, cones, dtype, 3.0, 0) * dtype(2.0) ** scale
    s = _point(rng, cones, dtype, 3.0, 0) * dtype(2.0) ** scale
    dz = _direction(rng, cones, dtype, 0) * dtype(2.0) ** scale
    assert (columns.product(z, dz, cones.n3) is None) == declined
    assert (columns.nt_scaling(z, s, cones.n3) is None) == declined
    assert (columns.step_point(z, cones.n3) is None) == declined
    if declined:
        np.testing.assert_array_equal(cones.product(z, dz), _generic(cones, jordan.jordan_product, z, dz))
        np.testing.assert_array_equal(cones.arrow_solve(z, dz), _generic(cones, jordan.arrow_solve, z, dz))
        np.testing.assert_array_equal(cones.quad_operator(z)(dz), _generic(cones, jordan.quad_apply, z, dz))
        assert cones.stepper(z, s)(dz, dz) == cones._max_step_pair_checked(z, dz, s, dz)
        p_fast = cones.nt_scaling(z, s)[0]
        r3 = jordan.nt_scaling(cones.split(z)[0], cones.split(s)[0])
        np.testing.assert_array_equal(p_fast[:9], np.ravel(r3.p))
    else:
        u = float(np.finfo(dtype).eps)
        _close(cones.product(z, dz), _generic(cones, jordan.jordan_product, z, dz), 8 * u)
        _close(cones.nt_scaling(z, s)[0], _generic(cones, lambda a, b: jordan.nt_scaling(a, b).p, z, s),
               32 * u * max(_kappa(cones, z), _kappa(cones, s)))


@dtypes
@pytest.mark.parametrize("bad_cone", [0, 2, 4])  # L3 cones 0..2, L1 cones 3..4
def test_points_outside_the_cone_raise_jordans_error_with_the_global_cone(dtype, bad_cone):
    rng = np.random.default_rng(11)
    cones = ProductCone(3, 2)
    z = _point(rng, cones, dtype, 2.0, 0)
    s = _point(rng, cones, dtype, 2.0, 0)
    if bad_cone < 3:
        z[3 * bad_cone] = -abs(z[3 * bad_cone])  # λ2 < 0
    else:
        z[9 + bad_cone - 3] = -1.0
    with pytest.raises(ConeDomainError) as info:
        cones.nt_scaling(z, s)
    assert info.value.cone == bad_cone and info.value.operation == "nt_scaling"
    with pytest.raises(ConeDomainError) as info:
        cones.stepper(z, s)(s, s)
    assert info.value.cone == bad_cone and info.value.operation == "step_to_boundary"


@dtypes
def test_nan_is_reported_by_jordan_not_propagated(dtype):
    rng = np.random.default_rng(5)
    cones = ProductCone(2, 1)
    z = _point(rng, cones, dtype, 2.0, 0)
    d = _direction(rng, cones, dtype, 0)
    d[4] = np.nan  # cone 1
    for call in (lambda: cones.product(z, d), lambda: cones.arrow_solve(z, d),
                 lambda: cones.stepper(z, z)(d, z)):
        with pytest.raises(ConeDomainError) as info:
            call()
        assert info.value.cone == 1
