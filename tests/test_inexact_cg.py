"""Conjugate gradients stopped at the caller's relative residual (issue 47): the Newton driver
asks for INNER_FRACTION·η only, since it refines against the unreduced system itself.  The stop
must report the residual it stopped at truthfully, take fewer steps than the full solve, and
the 10-digit path with it must prove what it proved without it."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest

import rfverify
from rfverify.algorithm import newton as N
from rfverify.extended import krylov
from rfverify.extended import mixed as mixed_module
from rfverify.scenes import generate

from test_digits_scale import _touching_engine, outlier_matrix


def _relative_residual_80_digits(A, xh, xl, b) -> float:
    with mpmath.workdps(80):
        x = [mpmath.mpf(float(h)) + float(lo) for h, lo in zip(xh, xl)]
        r = [mpmath.fsum(mpmath.mpf(float(a)) * t for a, t in zip(row, x)) - b[i] for i, row in enumerate(A)]
        return float(mpmath.sqrt(mpmath.fsum(t * t for t in r)) / mpmath.sqrt(mpmath.fsum(mpmath.mpf(t) ** 2 for t in b)))


@pytest.mark.parametrize("relative", [1e-3, 1e-8])
def test_a_relative_stop_takes_fewer_steps_and_reports_its_true_residual(relative):
    A, (Ap, Ai, vals), rng = outlier_matrix(seed=4)
    n = A.shape[0]
    b = rng.normal(size=n)
    full = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 1e-29)
    early = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 1e-29,
                                                        relative=relative)
    assert early.steps < full.steps and early.relative_residual <= relative
    true = _relative_residual_80_digits(A, *early.x, b)
    assert true == pytest.approx(early.relative_residual, rel=1e-6), (true, early.relative_residual)
    assert true > 1e-6 * relative  # it stopped there, not at double-double accuracy
    assert full.relative_residual < 1e-3 * relative


def test_a_relative_stop_is_accepted_by_the_engine_without_a_new_shift(monkeypatch):
    """On the touching matrix in miniature (entries up to 1e39), a checked solve stopped at the
    caller's relative residual is returned as it is, though its componentwise backward error is
    far above the 1e-20 a checked solve otherwise needs: no further shift, no double-double factor,
    and the time line says how many solves stopped so."""
    hi, lo, chol, _ = _touching_engine(monkeypatch, krylov.CG_RESTARTS, (1.0, 4.0))
    chol.set_backward_target(1e-29)
    n = hi.shape[0]
    b = hi @ np.random.default_rng(17).normal(size=n)  # met in a step or two
    chol.relative_target = 1e-6
    xh, xl = chol.solve(b, np.zeros(n))
    assert chol.cg_relative == 1 and chol.precision == "mixed" and chol.shifts_used == {1.0}
    assert chol.last_backward_error > 1e-20
    assert _relative_residual_80_digits(hi + lo, xh, xl, b) <= 1e-6
    assert "1 solve stopped at the relative residual the Newton refinement asked for" in chol.describe_cost()
    chol.relative_target = None
    xh, xl = chol.solve(b, np.zeros(n))
    assert chol.cg_relative == 1 and chol.last_backward_error <= 1e-20


def test_the_10_digit_path_proves_the_same_with_the_relative_stop(monkeypatch):
    """A turned touching bed (generic frames, hyperstatic) the stop was not tuned on: the same
    iterations and proven digits (to 0.05) with and without it, and fewer CG steps with it."""
    problem = generate("GranularBed", count=1, seed=43, size=1000, orientation=1, gap_jitter=0)[0]  # 2800 contacts
    with_stop = rfverify.solve_to_digits(problem, digits=10)
    assert "stopped at the relative residual the Newton refinement asked for" in with_stop.extended.factorisation
    monkeypatch.setattr(N.ReducedNewton, "solve", _without_relative(N.ReducedNewton.solve))
    without = rfverify.solve_to_digits(problem, digits=10)
    assert with_stop.certificate.certified and without.certificate.certified
    for name, q in with_stop.certificate.quantities.items():
        if q.digits is not None:
            assert abs(q.digits - without.certificate.quantities[name].digits) < 0.05, name
    assert "stopped at the relative residual" not in without.extended.factorisation
    steps = [out.extended.stats["refinement_steps"] for out in (with_stop, without)]
    assert steps[0] < steps[1], steps


def _without_relative(solve):
    def wrapped(self, a, b, c, phase):
        set_accuracy = self.backend.set_accuracy
        self.backend.set_accuracy = lambda relative: set_accuracy(None)
        try:
            return solve(self, a, b, c, phase)
        finally:
            del self.backend.set_accuracy
    return wrapped
