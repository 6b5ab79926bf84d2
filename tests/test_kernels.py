"""The compiled float64 cone kernels (rfverify.solver.kernels) against the numpy route.

ProductCone(compiled=True) sends float64 vectors of ordinary magnitude through numba
kernels that claim to be the numpy formulas of rfverify.jordan operation by operation:
every result must be bit for bit the one of ProductCone(compiled=False), on pure-L3, pure-L1
and mixed products, near the cone boundary and with x̄ = 0.  Vectors the kernels must not
take (extreme magnitudes, non-finite entries) and points outside an operation's domain must
give exactly the numpy route's answer or error.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from rfverify.errors import ConeDomainError
from rfverify.solver import kernels
from rfverify.solver.cones import ProductCone


def _interior(rng, n3, n1, scale, margin):
    """A point of int(L3^n3 × L1^n1): heads ‖x̄‖ + margin·scale (margin 0 → boundary up to
    rounding; a zero bar where the seed says so)."""
    x = rng.standard_normal(3 * n3 + n1) * scale
    bar = np.hypot(x[1:3 * n3:3], x[2:3 * n3:3])
    x[0:3 * n3:3] = bar * (1 + margin) + margin * scale
    if n3 and rng.random() < 0.3:
        x[1:3 * n3:3][: max(1, n3 // 3)] = 0.0  # x̄ = 0 on some cones
        x[2:3 * n3:3][: max(1, n3 // 3)] = 0.0
    x[3 * n3:] = np.abs(x[3 * n3:]) + margin * scale
    return x


def _pair(n3, n1):
    return ProductCone(n3, n1, compiled=True), ProductCone(n3, n1, compiled=False)


def _results(cone, z, s, y, y2):
    p, p_inv, lam, cond = cone.nt_scaling(z, s)
    step = cone.stepper(z, s)
    return {
        "nt_scaling": (p, p_inv, lam, cond),
        "quad_operator": cone.quad_operator(p)(y),
        "quad_operator_inv": cone.quad_operator(p_inv)(y2),
        "quad_blocks": cone.quad_blocks(p),
        "max_step_pair": step(y, y2)[0],
        # the cone that sets the step, and its side (1: s), the same on both routes
        "step_limit": (-1, -1) if step(y, y2)[1] is None else (step(y, y2)[1][0], int(step(y, y2)[1][1] == "s")),
        "max_step": cone.max_step(z, y),
        "min_lambda2": cone.min_lambda2(y),
        "lambda2": cone.lambda2(z),
        "product": cone.product(z, y),
        "arrow_solve": cone.arrow_solve(lam, y),
    }


def _assert_bitwise(a, b):
    for name in a:
        left = a[name] if isinstance(a[name], tuple) else (a[name],)
        right = b[name] if isinstance(b[name], tuple) else (b[name],)
        for u, v in zip(left, right):
            u, v = np.asarray(u), np.asarray(v)
            assert u.dtype == v.dtype and u.shape == v.shape, name
            assert np.array_equal(u, v, equal_nan=True), (name, np.max(np.abs(u - v)))


@given(seed=st.integers(0, 2**32 - 1), n3=st.integers(0, 12), n1=st.integers(0, 6),
       log_scale=st.integers(-30, 30), margin=st.sampled_from([1e-12, 1e-6, 1e-2, 1.0, 100.0]))
@example(seed=0, n3=5, n1=0, log_scale=0, margin=1e-12)   # pure L3, at the boundary
@example(seed=1, n3=0, n1=4, log_scale=0, margin=1.0)     # pure L1 (rows of width 1)
@example(seed=2, n3=3, n1=2, log_scale=20, margin=1e-6)   # mixed (L1 rows padded), large
@example(seed=3, n3=1, n1=0, log_scale=-25, margin=1e-2)  # one tiny cone
def test_compiled_kernels_are_bitwise_the_numpy_formulas(seed, n3, n1, log_scale, margin):
    if n3 + n1 == 0:
        n1 = 1
    rng = np.random.default_rng(seed)
    scale = 2.0 ** log_scale
    z = _interior(rng, n3, n1, scale, margin)
    s = _interior(rng, n3, n1, 1 / scale, margin)
    y, y2 = rng.standard_normal((2, 3 * n3 + n1)) * scale
    fast, slow = _pair(n3, n1)
    _assert_bitwise(_results(fast, z, s, y, y2), _results(slow, z, s, y, y2))


def test_the_compiled_route_is_taken_for_ordinary_float64_and_not_otherwise(monkeypatch):
    """Guards the test above against comparing the numpy route with itself."""
    calls = []
    for name in ("nt_scaling", "quad_det", "quad_apply", "quad_blocks", "step_point", "min_ray_lambda2_at",
                 "lambda2", "product", "arrow_solve"):
        fn = getattr(kernels, name)
        monkeypatch.setattr(kernels, name, lambda *a, _fn=fn, _name=name: (calls.append(_name), _fn(*a))[1])
    rng = np.random.default_rng(7)
    z, s = _interior(rng, 4, 2, 1.0, 0.5), _interior(rng, 4, 2, 1.0, 0.5)
    y, y2 = rng.standard_normal((2, 14))
    _results(ProductCone(4, 2), z, s, y, y2)
    assert set(calls) == {"nt_scaling", "quad_det", "quad_apply", "quad_blocks", "step_point", "min_ray_lambda2_at",
                          "lambda2", "product", "arrow_solve"}
    calls.clear()
    _results(ProductCone(4, 2, compiled=False), z, s, y, y2)
    _results(ProductCone(4, 2), *(v.astype(np.longdouble) for v in (z, s, y, y2)))
    assert calls == []


@pytest.mark.parametrize("big", [1e200, 1e-200])
def test_extreme_rows_take_the_rescaling_numpy_route(big):
    """Rows beyond 2^±128 would overflow or underflow the kernels' products; they go to the
    numpy route, which rescales them, so the compiled cone answers exactly as the numpy one."""
    rng = np.random.default_rng(3)
    z, s = _interior(rng, 3, 1, 1.0, 0.5), _interior(rng, 3, 1, 1.0, 0.5)
    z[3:6] *= big  # one cone of extreme magnitude
    y, y2 = rng.standard_normal((2, 10))
    fast, slow = _pair(3, 1)
    a, b = _results(fast, z, s, y, y2), _results(slow, z, s, y, y2)
    _assert_bitwise(a, b)
    assert np.all(np.isfinite(a["nt_scaling"][0]))


@pytest.mark.parametrize("where", ["L3", "L1"])
def test_domain_errors_are_the_numpy_routes(where):
    """A point outside an operation's domain makes the kernel hand back to numpy, which raises
    the precise ConeDomainError (operation and cone) — the same for both routes."""
    rng = np.random.default_rng(5)
    z, s = _interior(rng, 3, 2, 1.0, 0.5), _interior(rng, 3, 2, 1.0, 0.5)
    bad = z.copy()
    if where == "L3":
        bad[3] = -bad[3]  # cone 1 leaves L3
        cone_index = 1
    else:
        bad[-1] = -1.0  # the last L1 cone
        cone_index = 4
    zero_head = z.copy()
    zero_head[-1 if where == "L1" else 3] = 0.0
    fast, slow = _pair(3, 2)
    for call in (lambda c: c.nt_scaling(bad, s), lambda c: c.nt_scaling(s, bad),
                 lambda c: c.stepper(bad, s), lambda c: c.max_step(bad, s),
                 lambda c: c.arrow_solve(zero_head, s)):
        errors = []
        for cone in (fast, slow):
            with pytest.raises(ConeDomainError) as info:
                call(cone)
            errors.append((info.value.operation, info.value.cone, str(info.value)))
        assert errors[0] == errors[1]
        assert errors[0][1] == cone_index


def test_warm_up_compiles_every_kernel():
    kernels.warm_up()
    compiled = [name for name in dir(kernels)
                if hasattr(getattr(kernels, name), "signatures") and not name.startswith("_")]  # _lam is inlined
    assert compiled and all(getattr(kernels, name).signatures for name in compiled)


@pytest.mark.parametrize("method", ["jqinv", "noscaling"])
@pytest.mark.parametrize("case", ["bundled:chute", "random"])
def test_whole_solves_are_bitwise_the_same_with_and_without_the_kernels(case, method):
    """compiled_kernels=False is the numpy route throughout: every iterate, hence the answer
    and the iteration count, must be identical (at 1e-10 the run also passes through its
    longdouble phase, which the kernels leave to numpy)."""
    import rfverify
    from rfverify.scenes.random_problems import random_problem

    problem = rfverify.load(case) if case != "random" else random_problem(70, 130, seed=20261202, free_bodies=2)
    fast = rfverify.solve(problem, method=method, tol=1e-10)
    slow = rfverify.solve(problem, method=method, tol=1e-10, compiled_kernels=False)
    assert fast.nit == slow.nit and fast.status == slow.status
    for name in ("v", "u", "r"):
        assert np.array_equal(getattr(fast, name), getattr(slow, name))
    assert np.array_equal(fast.trace["alpha"], slow.trace["alpha"], equal_nan=True)
