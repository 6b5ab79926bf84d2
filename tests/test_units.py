"""Grossly mismatched units (issue 47's 'bad units', found by an audit): the same problem with its
forces in units 2^20 smaller ended InsufficientProgress, and with its velocities in units 2^100
larger MaxIterations, though every number stays far inside float64.  Such problems are now
brought back to units near 1 by an exact power-of-two change (answers scaled back), the same for
every unit variant; the answers are checked against the original's, scaled by hand."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

import rfverify
from rfverify.model.measures import measures
from rfverify.model.scaling import UNIT_EXPONENT, BinaryScaling, binary_scaling, scaled_problem


@pytest.fixture(scope="module")
def chute():
    p = rfverify.load("bundled:chute")
    return p, rfverify.solve(p, tol=1e-10)


def variant(p, force: int, velocity: int):
    """The problem with reactions in units 2^force smaller and velocities 2^velocity smaller:
    M·2^force, f·2^(force+velocity), w·2^velocity (H unchanged), built by hand."""
    return rfverify.Problem.from_arrays(p.M * 2.0 ** force, p.H, p.f * 2.0 ** (force + velocity),
                                        p.w * 2.0 ** velocity, p.mu, p.mu_r)


@pytest.mark.parametrize("force, velocity", [(20, 0), (-20, 0), (40, 0), (0, 30), (0, -100), (-20, 20), (60, -60)])
def test_unit_variants_of_the_chute_are_solved_to_the_same_answer(chute, force, velocity):
    p, base = chute
    q = variant(p, force, velocity)
    res = rfverify.solve(q, tol=1e-10)
    assert res.success, res.message
    # judged independently on the variant as given, in long double
    assert measures(q, res.v, q.H.T @ res.v + q.w, res.r, "longdouble").max <= 1e-10
    # units are exact powers of two: scaled back, the answer is one of the original problem's,
    # judged there as tightly, and it is the original's answer to what that criterion allows
    v, r = res.v / 2.0 ** velocity, res.r / 2.0 ** (force + velocity)
    assert measures(p, v, p.H.T @ v + p.w, r, "longdouble").max <= 1.01e-10
    np.testing.assert_allclose(v, base.v, rtol=0, atol=1e-6 * np.max(np.abs(base.v)))


@settings(max_examples=20, deadline=None)
@given(force=st.integers(-150, 150), velocity=st.integers(-150, 150))
@example(force=UNIT_EXPONENT + 1, velocity=0)
@example(force=0, velocity=-UNIT_EXPONENT - 1)
def test_every_grossly_scaled_variant_is_brought_to_the_same_problem(chute, force, velocity):
    p, _ = chute
    q = variant(p, force, velocity)
    scaling = binary_scaling(q)
    if max(abs(force), abs(velocity), abs(force + velocity)) <= UNIT_EXPONENT - 6:
        assert scaling is None  # well inside: untouched, bit for bit
    if scaling is None:
        return
    a = scaled_problem(q, scaling)
    ref = variant(p, 40, 0)  # one far variant: its scaled problem is the one every variant gets
    b = scaled_problem(ref, binary_scaling(ref))
    for x, y in ((a.M, b.M), (a.H, b.H)):
        assert (x != y).nnz == 0
    assert np.array_equal(a.f, b.f) and np.array_equal(a.w, b.w)


def test_problems_in_reasonable_units_are_untouched(chute):
    p, _ = chute
    assert binary_scaling(p) is None
    assert binary_scaling(variant(p, 8, -8)) is None


def test_a_tiny_problem_is_solved_and_proven():
    """M ~ 2^-664 and f ~ 2^-830: brought into the safe range before, it kept f ~ 2^-166 there
    (MaxIterations, no digits); now its units are normalised too."""
    p = rfverify.load("bundled:chute")
    q = rfverify.Problem.from_arrays(p.M * 2.0 ** -664, p.H, p.f * 2.0 ** -830, p.w * 2.0 ** -166, p.mu, p.mu_r)
    out = rfverify.solve_to_digits(q, digits=10)
    assert out.success, out.certificate.verdict


@pytest.mark.parametrize("e", [830, -700, 0])
def test_a_local_problem_with_W_and_q_at_the_ends_of_the_range_is_proven(e):
    # u = W r + q with W = BᵀB (integers) and a planted answer: contact 0 slides (r = (5, -1.5, 2),
    # u = (2.5, 3, -4), μ = 0.5, a 3-4-5 direction), contact 1 sticks (r = (3, 0, 0), u = 0), so
    # q = u* − W r* exactly.  W and q ×2^e keep r* and give u* ×2^e.  Scaling q alone (W as it
    # was) left reactions of 2^-841 beside a W of 2^830, where the double solve failed and the
    # verdict blamed an overflow (an audit, 2026-12-07).
    from rfverify.io.fclib3d import LOCAL, extract, local_3d_problem, provenance_3d

    B = np.array([[9, 1, -2, 0, 1, 0], [0, 8, 1, 2, 0, -1], [1, 0, 9, 0, -2, 1],
                  [-1, 2, 0, 8, 1, 0], [0, 1, 1, -1, 9, 2], [2, 0, -1, 1, 0, 8]], dtype=float)
    W = B.T @ B
    r_star = np.array([5.0, -1.5, 2.0, 3.0, 0.0, 0.0])
    u_star = np.array([2.5, 3.0, -4.0, 0.0, 0.0, 0.0])
    q = u_star - W @ r_star
    p = local_3d_problem(np.ldexp(W, e), np.ldexp(q, e), np.array([0.5, 0.5]), "dense",
                         provenance=provenance_3d(LOCAL, []))
    out = rfverify.solve_to_digits(p, digits=10)
    assert out.status is rfverify.Status.CERTIFIED, out.message
    r, u = extract(np.asarray(out.r)), extract(np.asarray(out.u))
    assert np.max(np.abs(r - r_star)) <= out.certificate.bounds["r"] <= 1e-9 * 5
    assert np.max(np.abs(u - np.ldexp(u_star, e))) <= out.certificate.bounds["u"] <= np.ldexp(1e-9 * 4, e)


def test_an_unproven_answer_that_overflows_when_scaled_back_is_not_called_proven(monkeypatch, tmp_path):
    # The scaling of q alone (the one before W was scaled too) makes the run fail on the 2^830 local
    # problem above; its answer overflows when scaled back, and the verdict had said "the proven
    # answer overflows float64".
    from rfverify.io.fclib3d import LOCAL, local_3d_problem, provenance_3d
    from rfverify.model import scaling

    B = np.array([[9, 1, -2, 0, 1, 0], [0, 8, 1, 2, 0, -1], [1, 0, 9, 0, -2, 1],
                  [-1, 2, 0, 8, 1, 0], [0, 1, 1, -1, 9, 2], [2, 0, -1, 1, 0, 8]], dtype=float)
    W = B.T @ B
    q = np.array([2.5, 3.0, -4.0, 0.0, 0.0, 0.0]) - W @ np.array([5.0, -1.5, 2.0, 3.0, 0.0, 0.0])
    p = local_3d_problem(np.ldexp(W, 830), np.ldexp(q, 830), np.array([0.5, 0.5]), "dense",
                         provenance=provenance_3d(LOCAL, []))
    rfverify.save(p, tmp_path / "local.hdf5")  # as the audit had it: read back from its file
    p = rfverify.load(tmp_path / "local.hdf5")
    monkeypatch.setattr(scaling, "binary_scaling", lambda problem: BinaryScaling(0, 0, -841)
                        if np.max(np.abs(problem.w)) > 1e200 else None)  # (the scaled problem is in range)
    out = rfverify.solve_to_digits(p, digits=10, max_iter=15, extended_max_iter=4, wide_tail=False)
    assert out.status is not rfverify.Status.CERTIFIED
    assert not np.all(np.isfinite(out.u))  # the case under test: the answer overflowed
    assert "the proven answer overflows" not in out.message and "not proven" in out.message, out.message


def test_a_local_W_whose_small_entries_would_not_survive_its_scaling_is_not_refused():
    # W at 2^830 with one coupling of 1e-60: scaling W down to the safe range would make that entry
    # subnormal and inexact, so W is left as it is and q alone is scaled (the problem runs; it was
    # refused with "no exact power-of-two change of units" when W was always scaled).
    from rfverify.io.fclib3d import LOCAL, local_3d_problem, provenance_3d

    B = np.array([[9, 1, -2, 0, 1, 0], [0, 8, 1, 2, 0, -1], [1, 0, 9, 0, -2, 1],
                  [-1, 2, 0, 8, 1, 0], [0, 1, 1, -1, 9, 2], [2, 0, -1, 1, 0, 8]], dtype=float)
    W = np.ldexp(B.T @ B, 830)
    W[0, 5] = W[5, 0] = 1e-60
    p = local_3d_problem(W, np.ldexp(np.ones(6), 830), np.array([0.5, 0.5]), "dense",
                         provenance=provenance_3d(LOCAL, []))
    scaling = binary_scaling(p)
    assert scaling is not None and scaling.exponent("W") == 0 and scaling.exponent("q") < -600
    assert scaled_problem(p, scaling).local.W[0, 7] == 1e-60  # (3-D entry (0, 5) in the 5-per-contact layout)
