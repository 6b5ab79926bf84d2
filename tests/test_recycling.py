"""Recycled conjugate-gradient directions (issue 47): the directions one solve found deflate the
later solves with the same matrix and preconditioner; they only change the speed, never the
answer, and the engine drops them where they fail a solve."""

from __future__ import annotations

import numpy as np
import pytest

from rfverify.extended import krylov
from rfverify.extended import mixed as mixed_module

from test_digits_scale import _residual_of_hi_lo, _touching_engine, outlier_matrix


def test_a_second_solve_deflated_by_the_first_ones_directions_takes_far_fewer_steps():
    """The first solve finds the outliers in 25 steps or more; a second right-hand side, deflated
    by the first solve's directions, needs a few, and both answers hold against an 80-digit
    residual.  Without the directions the second takes as many steps as the first (so the
    test can tell recycling from an easy right-hand side)."""
    A, (Ap, Ai, vals), rng = outlier_matrix()
    n = A.shape[0]
    recycled = krylov.RecycledDirections(n)
    b1, b2 = rng.normal(size=n), rng.normal(size=n)
    best1, x1, steps1, _ = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b1, np.zeros(n), lambda r: r,
                                                                    1e-22, recycled=recycled)
    assert best1 <= 1e-22 and steps1 >= 25 and recycled.count == steps1
    plain = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b2, np.zeros(n), lambda r: r, 1e-22)
    best2, (xh, xl), steps2, _ = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b2, np.zeros(n),
                                                                          lambda r: r, 1e-22, recycled=recycled)
    assert plain[2] >= 25 and steps2 <= plain[2] // 3, (plain[2], steps2)
    assert best2 <= 1e-22
    for b, (h, lo) in ((b1, x1), (b2, (xh, xl))):
        res, scale = _residual_of_hi_lo(A, np.zeros_like(A), h, lo, b)
        assert res <= 1e-21 * scale


def test_recycled_directions_keep_the_first_within_their_memory_and_forget_on_clear():
    n = 50
    kept = krylov.RecycledDirections(n, max_bytes=16 * n * 7)  # room for 7 (p, Ap) pairs
    assert kept.capacity == 7
    pairs = [(np.full(n, float(i + 1)), np.full(n, float(i + 1))) for i in range(5)]
    kept.add(pairs)
    kept.add(pairs)
    assert kept.count == 7 and kept.room == 0
    assert [kept._W[0, j] for j in range(7)] == [1, 2, 3, 4, 5, 1, 2]  # the earliest are kept
    kept.clear()
    inner = lambda r: 2 * r  # noqa: E731
    assert kept.count == 0 and kept.preconditioner(inner) is inner


def test_a_new_factor_starts_without_the_old_ones_directions(monkeypatch):
    """Directions belong to one matrix and one float64 factor: a refactorisation clears them."""
    monkeypatch.setattr(krylov, "CG_MAX_STEPS", 40)
    hi, lo, chol, refactor = _touching_engine(monkeypatch, krylov.CG_RESTARTS, (64.0,))
    n = hi.shape[0]
    chol.set_backward_target(1e-29)
    chol.solve(np.random.default_rng(1).normal(size=n), np.zeros(n))
    assert chol._recycled.count > 0 and chol.recycled_most == chol._recycled.count
    assert refactor() == -1 and chol._recycled.count == 0


def test_directions_that_fail_a_solve_are_dropped_and_the_solve_runs_again_without_them(monkeypatch):
    """The recycled directions' Gram matrix is float64: where it is poor the deflated solve can
    stall.  Forced here (the deflation returns a useless direction): the engine runs the solve
    again undeflated, reaches 1e-20 (checked by an 80-digit residual), recycles nothing more for
    this factor and says so in its time line."""
    monkeypatch.setattr(krylov, "CG_MAX_STEPS", 40)
    hi, lo, chol, _ = _touching_engine(monkeypatch, krylov.CG_RESTARTS, (64.0,))
    n = hi.shape[0]
    chol.set_backward_target(1e-29)
    rng = np.random.default_rng(2)
    chol.solve(rng.normal(size=n), np.zeros(n))
    assert chol._recycled.count > 0 and chol.recycling_dropped == 0
    real = krylov.RecycledDirections.preconditioner

    def useless(self, inner):
        if not self.count:
            return inner
        real(self, inner)  # counts the deflated pass
        return lambda r: np.ones_like(r) * 1e-300

    monkeypatch.setattr(krylov.RecycledDirections, "preconditioner", useless)
    b = rng.normal(size=n)
    xh, xl = chol.solve(b, np.zeros(n))
    assert chol.recycling_dropped == 1 and chol._recycled.count == 0 and chol._recycling_off
    assert chol.precision == "mixed" and chol.last_backward_error <= 1e-20
    res, scale = _residual_of_hi_lo(hi, lo, xh, xl, b)
    assert res <= 1e-20 * scale
    assert "dropped where they failed a solve, 1 time)" in chol.describe_cost()


@pytest.mark.parametrize("seed", [3, 5])
def test_recycling_never_changes_what_a_solve_reports(seed):
    """Deflation is a float64 preconditioner: the backward error a deflated solve returns is the
    one recomputed from A, x and b in double-double, as undeflated."""
    from test_digits_scale import _touching_cg_args

    hi, lo, b, args = _touching_cg_args(seed)
    n = b.size
    recycled = krylov.RecycledDirections(n)
    krylov.restarted_conjugate_gradients(*args, good_enough=1e-29, recycled=recycled)
    b2 = np.random.default_rng(seed + 100).normal(size=n)
    args2 = args[:3] + (b2, np.zeros(n)) + args[5:]
    best, (xh, xl), _, _ = krylov.restarted_conjugate_gradients(*args2, good_enough=1e-29, recycled=recycled)
    res, scale = _residual_of_hi_lo(hi, lo, xh, xl, b2)
    ax = np.abs(hi) @ np.abs(xh) + np.abs(b2)
    assert res <= max(best, 1e-30) * 2 * float(np.max(ax)) + 1e-30 * scale
