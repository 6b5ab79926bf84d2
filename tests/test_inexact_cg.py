"""Inexact Newton solves on touching piles (issue 47).  The conjugate gradients stop at the
residual the Newton driver asks for (INNER_FRACTION·η·‖c‖∞ in the complementarity row), since
it refines against the unreduced system itself: the stop must report the residual it stopped at
truthfully and take fewer steps than the full solve.  The driver's refinement stops where a
block's residual cannot be evaluated any better (rules._evaluation_floors).  The 10-digit path
must prove with each what it proved without it."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest

import rfverify
from rfverify.algorithm import newton as N
from rfverify.algorithm import rules
from rfverify.extended import krylov
from rfverify.extended import mixed as mixed_module
from rfverify.scenes import generate

from test_digits_scale import _touching_engine, outlier_matrix


def _residual_norm_80_digits(A, xh, xl, b) -> float:
    """‖b − Ax‖∞ in 80 digits (A: the matrix's values, high + low)."""
    with mpmath.workdps(80):
        x = [mpmath.mpf(float(h)) + float(lo) for h, lo in zip(xh, xl)]
        return float(max(abs(mpmath.fsum(mpmath.mpf(float(a)) * t for a, t in zip(row, x)) - b[i])
                         for i, row in enumerate(A)))


@pytest.mark.parametrize("fraction", [1e-3, 1e-8])
def test_a_stop_at_a_residual_norm_takes_fewer_steps_and_reports_its_true_residual(fraction):
    A, (Ap, Ai, vals), rng = outlier_matrix(seed=4)
    n = A.shape[0]
    b = rng.normal(size=n)
    wanted = fraction * float(np.max(np.abs(b)))
    full = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 1e-29)
    early = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 1e-29,
                                                        stop_norm=wanted)
    assert early.steps < full.steps and early.residual_norm <= wanted
    # and not later than that: no iterate before the one returned met it
    before = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 1e-29,
                                                         stop_norm=wanted, max_steps=early.steps - 1)
    assert before.residual_norm > wanted
    true = _residual_norm_80_digits(A, *early.x, b)
    assert true == pytest.approx(early.residual_norm, rel=1e-6), (true, early.residual_norm)
    assert true > 1e-6 * wanted  # it stopped there, not at double-double accuracy
    assert full.residual_norm < 1e-3 * wanted


def test_an_early_stop_is_accepted_by_the_engine_without_a_new_shift(monkeypatch):
    """On the touching matrix in miniature (entries up to 1e39), a checked solve stopped at the
    residual the caller asked for is returned as it is, though its componentwise backward error
    is far above the 1e-20 a checked solve otherwise needs: no further shift, no double-double
    factor, and the time line says how many solves stopped so."""
    hi, lo, chol, _ = _touching_engine(monkeypatch, krylov.CG_RESTARTS, (1.0, 4.0))
    chol.set_backward_target(1e-29)
    n = hi.shape[0]
    b = hi @ np.random.default_rng(17).normal(size=n)  # met in a step or two
    wanted = 1e-6 * float(np.max(np.abs(b)))
    chol.residual_target = wanted
    xh, xl = chol.solve(b, np.zeros(n))
    assert chol.cg_stopped_early == 1 and chol.precision == "mixed" and chol.shifts_used == {1.0}
    assert chol.last_backward_error > 1e-20
    assert _residual_norm_80_digits(hi + lo, xh, xl, b) <= wanted
    assert "1 solve stopped at the residual the Newton refinement asked for" in chol.describe_cost()
    chol.residual_target = None
    xh, xl = chol.solve(b, np.zeros(n))
    assert chol.cg_stopped_early == 1 and chol.last_backward_error <= 1e-20


@pytest.fixture(scope="module")
def touching_bed():
    """A turned touching bed (generic frames, hyperstatic, 2800 contacts) neither change was
    developed on, and its default 10-digit run with every Newton solve's outcome recorded."""
    problem = generate("GranularBed", count=1, seed=43, size=1000, orientation=1, gap_jitter=0)[0]
    with pytest.MonkeyPatch.context() as mp:
        solves = _record_solves(mp)
        out = rfverify.solve_to_digits(problem, digits=10)
    return problem, out, solves


def _record_solves(mp) -> list:
    """(η, settled, refinement steps) of every Newton solve of the runs under ``mp``."""
    seen = []
    real = rules.refined_newton

    def spy(*args, **kw):
        out = real(*args, **kw)
        seen.append((kw.get("enough"), out[5], out[3]))
        return out

    mp.setattr(N, "refined_newton", spy)
    return seen


def _digits_agree(one, other):
    for name, q in one.certificate.quantities.items():
        if q.digits is not None:
            assert abs(q.digits - other.certificate.quantities[name].digits) < 0.05, name


def test_the_10_digit_path_proves_the_same_with_the_early_stop(touching_bed, monkeypatch):
    """The same iterations and proven digits (to 0.05) with and without the stop, and fewer
    conjugate-gradient steps with it."""
    problem, with_stop, _ = touching_bed
    assert "stopped at the residual the Newton refinement asked for" in with_stop.extended.factorisation
    monkeypatch.setattr(N.ReducedNewton, "solve", _without_stop(N.ReducedNewton.solve))
    without = rfverify.solve_to_digits(problem, digits=10)
    assert with_stop.certificate.certified and without.certificate.certified
    _digits_agree(with_stop, without)
    assert "stopped at the residual" not in without.extended.factorisation
    steps = [out.extended.stats["refinement_steps"] for out in (with_stop, without)]
    assert steps[0] < steps[1], steps


def test_refinement_stops_where_a_block_can_be_evaluated_no_better(touching_bed, monkeypatch):
    """Without the evaluation floors (rules._evaluation_floors) the driver chases residuals that
    its own evaluation cannot resolve — a dual row whose rhs is 1e-20 of its terms — through
    more solves and ends more of them unsettled; with them, the same proven digits."""
    problem, with_floors, solves = touching_bed
    monkeypatch.setattr(rules, "_evaluation_floors", lambda evaluated, predicted, floors, inf: floors)
    without_solves = _record_solves(monkeypatch)
    without = rfverify.solve_to_digits(problem, digits=10)
    assert with_floors.certificate.certified and without.certificate.certified
    _digits_agree(with_floors, without)
    unsettled = [sum(1 for eta, settled, _ in runs if eta and not settled) for runs in (solves, without_solves)]
    refinements = [sum(steps for *_, steps in runs) for runs in (solves, without_solves)]
    assert unsettled[0] < unsettled[1] and 2 * refinements[0] < refinements[1], (unsettled, refinements)


def test_the_10_digit_path_proves_the_same_multiplying_through_the_factors(touching_bed, monkeypatch):
    """The conjugate gradients multiply by S' through its factors on this bed (the time line says
    so) and prove what the stored upper triangle's products prove, to 0.05 digits."""
    from rfverify.extended import contactspace

    problem, through, _ = touching_bed
    assert "through its factors" in through.extended.factorisation
    monkeypatch.setattr(contactspace.ContactSpace, "_offer_scaled_product", lambda self, *args: None)
    stored = rfverify.solve_to_digits(problem, digits=10)
    assert through.certificate.certified and stored.certificate.certified
    assert "through its factors" not in stored.extended.factorisation
    _digits_agree(through, stored)


def _without_stop(solve):
    def wrapped(self, a, b, c, phase):
        set_accuracy = self.backend.set_accuracy
        self.backend.set_accuracy = lambda residual_norm: set_accuracy(None)
        try:
            return solve(self, a, b, c, phase)
        finally:
            del self.backend.set_accuracy
    return wrapped


def test_a_preconditioned_residual_orthogonal_to_the_residual_ends_the_pass_without_dividing_by_zero():
    """rᵀM⁻¹r = 0 with M⁻¹r ≠ 0 (a float64 preconditioner that is not positive definite can do
    it): the step is zero and β would divide by zero.  The pass must end with its best iterate
    (this raised ZeroDivisionError on the generated 888-contact Chute of bench_digits)."""
    import scipy.sparse as sp

    A = sp.triu(sp.csc_matrix(np.array([[2.0, 0.5], [0.5, 1.0]]))).tocsc()
    A.sort_indices()
    args = (A.indptr.astype(np.int64), A.indices.astype(np.int64), (A.data.copy(), np.zeros(A.nnz)))
    b = np.array([1.0, 0.0])
    out = krylov.conjugate_gradients_in_double_double(*args, b, np.zeros(2), lambda r: np.array([-r[1], r[0]]), 1e-29)
    assert out.steps == 1 and out.backward == 1.0 and np.all(out.x[0] == 0)


def test_the_chute_that_divided_by_zero_is_proven():
    """The first generated 700-size Chute (888 contacts, a self-stress) of bench_digits: at
    df61386 its conjugate gradients met rᵀM⁻¹r = 0 and the path ended in ZeroDivisionError (the
    test above pins that case; this one, that the path proves the Chute)."""
    problem = generate("Chute", count=1, seed=0, size=700)[0]
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.certificate.certified and problem.n_contacts == 888


def test_a_residual_that_grows_first_does_not_end_the_solve_at_x_zero():
    """A residual-norm stop judges iterates by ‖r‖∞, which CG does not decrease monotonically:
    b mostly on small eigenvalues with a trace of a huge one makes the first residual ~1e3 × b.
    Patience counted on ‖r‖∞ from x = 0 returned x = 0 (the 96 256-contact touching bed's checked
    solves, backward error 1.0); while the error's A-norm still falls it must go on."""
    import scipy.sparse as sp

    n = 60
    rng = np.random.default_rng(5)
    eigenvalues = np.concatenate([np.linspace(1.0, 2.0, n - 1), [1e10]])
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    A = (Q * eigenvalues) @ Q.T
    U = sp.triu(sp.csc_matrix((A + A.T) / 2), format="csc")
    U.sort_indices()
    Ap, Ai, vals = U.indptr.astype(np.int64), U.indices.astype(np.int64), (U.data.copy(), np.zeros(U.data.size))
    b = Q[:, :n - 1] @ rng.standard_normal(n - 1) + 1e-3 * Q[:, -1]
    out = krylov.conjugate_gradients_in_double_double(Ap, Ai, vals, b, np.zeros(n), lambda r: r, 0.0, patience=1,
                                                      stop_norm=1e-20 * float(np.max(np.abs(b))))
    assert np.any(out.x[0] != 0.0) and out.residual_norm < 0.1 * float(np.max(np.abs(b)))
