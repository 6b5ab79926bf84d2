"""The k-digit path's set-up beside the double solve (rfverify.verify.digits.Preparation) and the double
answer's proof left until it is needed (double_answer_may_certify): the same answers as the
serial path, errors raised where the serial path raises them, and the gate a true necessary
condition — where it says no proof of the double answer can certify, none does."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from exact_problems import exact_problem
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rfverify
from rfverify.verify import digits as D
from rfverify.verify import driver as DR
from rfverify.verify import prepare as P
from rfverify.verify.certificate import candidate_point
from rfverify.extended.contactspace import ContactSpace
from rfverify.proof import ProofContext
from rfverify.scenes.random_problems import random_problem
from rfverify.scenes import generate


def _point(out):
    return np.concatenate([out.point.v_hi, out.point.v_lo, out.point.r_hi, out.point.r_lo])


@pytest.fixture
def beside(monkeypatch):
    """Force the set-up onto the second thread (True) or into the caller's (False); returns the
    list of Preparation objects made."""
    made = []
    real = D.Preparation

    def force(flag):
        monkeypatch.setattr(D, "preparing_beside", lambda: flag)

        class Spy(real):
            def __init__(self, *a, **k):
                super().__init__(*a, **k)
                made.append(self)
        monkeypatch.setattr(D, "Preparation", Spy)
        return made
    return force


@pytest.mark.parametrize("make", [lambda: generate("GranularBed", count=1, seed=3, size=125)[0],
                                  lambda: rfverify.load("bundled:chute"),
                                  lambda: random_problem(25, 70, seed=11)])
def test_set_up_beside_the_double_solve_gives_the_serial_answer_bit_for_bit(beside, make):
    problem = make()
    runs = {}
    for flag in (True, False):
        made = beside(flag)
        out = rfverify.solve_to_digits(problem, digits=10)
        assert made[-1].in_background is flag
        runs[flag] = out
    a, b = runs[True], runs[False]
    assert np.array_equal(_point(a), _point(b))
    assert a.certificate.verdict == b.certificate.verdict and a.digits == b.digits
    assert a.extended.nit == b.extended.nit > 0


@pytest.mark.parametrize("flag", [True, False])
def test_a_proof_context_error_is_raised_as_in_the_serial_path(beside, monkeypatch, flag):
    beside(flag)

    def broken(problem):
        raise RuntimeError("proof context broke")
    monkeypatch.setattr(P, "ProofContext", broken)
    with pytest.raises(RuntimeError, match="proof context broke"):
        rfverify.solve_to_digits(random_problem(10, 25, seed=2), digits=10)


@pytest.mark.parametrize("flag", [True, False])
def test_a_back_end_error_is_raised_only_where_the_serial_path_needs_the_back_end(beside, monkeypatch, flag):
    beside(flag)

    def broken(*a, **k):
        raise MemoryError("no room for the back end")
    monkeypatch.setattr(P, "choose_backend", broken)
    with pytest.raises(MemoryError, match="no room"):
        rfverify.solve_to_digits(random_problem(10, 25, seed=2), digits=10)
    # an exact answer is proven from the double solve: the back end is never needed
    out = rfverify.solve_to_digits(_wedge(), digits=10)
    assert out.certificate.certified and out.extended.status == "NotRun"


def _wedge():
    """M = 1, H = e_N, f = −1: the exact answer v = 0, r = e_N, with no strictly feasible point."""
    H = sp.csc_matrix(np.array([[1.0, 0, 0, 0, 0]]))
    return rfverify.Problem.from_arrays(sp.identity(1, format="csc"), H, np.array([-1.0]), np.zeros(5),
                                        np.zeros(1), np.zeros(1))


def test_a_failed_prepare_is_left_to_the_first_update(beside, monkeypatch):
    problem = generate("GranularBed", count=1, seed=3, size=125)[0]
    beside(False)
    serial = rfverify.solve_to_digits(problem, digits=10)
    made = beside(True)

    def broken(self):
        raise RuntimeError("prepare broke")
    monkeypatch.setattr(ContactSpace, "prepare", broken)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert made[-1].in_background and out.certificate.certified
    assert np.array_equal(_point(out), _point(serial))


def test_a_cancelled_preparation_builds_what_is_asked_for_afterwards():
    problem = random_problem(8, 20, seed=4)
    prep = P.Preparation(problem, "auto", "auto", background=True)
    prep.cancel()
    ctx = prep.context()
    data, system = prep.system()
    assert ctx.hypotheses_proven and data.n == problem.n_contacts and system is prep.system()[1]


def test_cancel_waits_for_a_thread_that_had_begun():
    """A thread left running inside a C extension at interpreter exit aborted the process (exit
    134, about 1 run in 15 of `solve bundled:cube --digits 10`): cancel() must wait for it."""
    problem = random_problem(30, 90, seed=6)
    prep = P.Preparation(problem, "auto", "auto", background=True)
    prep.start()  # as the double solve's first factorisation does
    prep.cancel()
    assert not prep._thread.is_alive()


# ---- the gate: a necessary condition for the double answer's proof to certify


def _gate_and_proof(problem, v, r, digits=10):
    ctx = ProofContext(problem)
    point = candidate_point(v, r)
    vv, uu, rr = ctx.rounded(point)
    proof = ctx.prove(point, vv, uu, rr, requested=digits)
    return P.double_answer_may_certify(ctx, problem, v, r, digits), proof


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("scale", [1.0, 2.0 ** 400, 2.0 ** -400])
def test_an_exact_answer_always_passes_the_gate_and_is_proven(seed, scale):
    problem, v, _, r = exact_problem(seed, n_contacts=6, asymmetry=0)
    if scale != 1.0:  # M, f scaled by a power of two: the same v*, and r* scaled (exactly)
        problem = rfverify.Problem(problem.M * scale, problem.H, problem.f * scale, problem.w, problem.mu,
                                   problem.mu_r)
        r = r * scale
    may, proof = _gate_and_proof(problem, v, r)
    assert may and proof.certified, proof.summary()


def test_the_wedges_exact_double_answer_passes_the_gate():
    may, proof = _gate_and_proof(_wedge(), np.zeros(1), np.array([1.0, 0, 0, 0, 0]), digits=15)
    assert may and proof.certified


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 50), tol_exp=st.integers(4, 12), digits=st.integers(2, 10))
@example(seed=3, tol_exp=12, digits=6)
@example(seed=5, tol_exp=10, digits=4)
def test_where_the_gate_says_no_the_proof_does_not_certify(seed, tol_exp, digits):
    """Double answers of fresh random problems solved to 1e-4 … 1e-12, asked for 2 … 10 digits:
    the gate may let through a proof that fails, never stop one that would certify."""
    problem = rfverify.solver.posed(random_problem(6, 14, seed=seed), None, "auto")
    double = rfverify.solve(problem, tol=10.0 ** -tol_exp)
    may, proof = _gate_and_proof(problem, double.v, double.r, digits)
    assert may or not proof.certified, (proof.summary(), tol_exp, digits)


def test_the_gate_lets_through_the_double_answers_that_certify():
    """Not vacuous: some of those answers certify (and pass), some are stopped by the gate."""
    seen = set()
    for seed in range(6):
        problem = rfverify.solver.posed(random_problem(6, 14, seed=seed), None, "auto")
        for tol_exp in (6, 12):
            double = rfverify.solve(problem, tol=10.0 ** -tol_exp)
            for digits in (3, 10):
                may, proof = _gate_and_proof(problem, double.v, double.r, digits)
                seen.add((may, proof.certified))
    assert (True, True) in seen and (False, False) in seen


def test_the_gate_skips_a_granular_beds_double_answer_and_its_proof_would_not_certify():
    problem = rfverify.solver.posed(generate("GranularBed", count=1, seed=3, size=216)[0], None, "auto")
    double = rfverify.solve(problem, tol=1e-10, **D.DOUBLE_SETTINGS)
    may, proof = _gate_and_proof(problem, double.v, double.r)
    assert not may and not proof.certified


def test_the_double_answers_proof_stands_where_no_iterate_beats_it():
    """The extended phase gets no iteration: its start (the double answer, r moved into the cone
    where it is not) is proven beside the double answer, and the double answer is the answer
    unless that start's proof scores strictly higher.  (Which one wins depends on the last bits of
    the double solve: on seed 3 the double answer on one machine, the start on another.)"""
    problem = generate("GranularBed", count=1, seed=3, size=125)[0]
    out = rfverify.solve_to_digits(problem, digits=10, extended_max_iter=0, wide_tail=False)
    posed = rfverify.solver.posed(problem, None, "auto")
    _, own = _gate_and_proof(posed, out.double.v, out.double.r)
    is_double = np.array_equal(out.point.v_hi, out.double.v) and np.array_equal(out.point.r_hi, out.double.r)
    if is_double:
        assert out.certificate.proof.summary() == own.summary()
    else:
        assert DR.ProofDriver.score(out.certificate.proof) > DR.ProofDriver.score(own)


def test_on_a_tie_the_double_answers_proof_is_the_one_reported(monkeypatch):
    """As when it was proven first and an iterate had to beat it: with every proof scored alike,
    the double answer (proven last now) is the answer."""
    monkeypatch.setattr(DR.ProofDriver, "score", staticmethod(lambda proof: 0.0))
    problem = generate("GranularBed", count=1, seed=3, size=125)[0]
    out = rfverify.solve_to_digits(problem, digits=15, extended_max_iter=3, wide_tail=False)
    assert out.extended.nit > 0 and not out.certificate.certified
    assert np.array_equal(out.point.v_hi, out.double.v) and np.array_equal(out.point.r_hi, out.double.r)


def test_an_exact_answer_whose_gap_rounds_up_still_passes_the_gate():
    """u_N = 2⁶⁴ + 3 − 2⁶⁴ − 3 = 0 exactly, but 2⁶⁴ + 3 rounds up even in long double: the
    computed gap is 1, not 0.  The rounding allowance keeps the exact answer (v = 1, r = e_N,
    ε = 0) from being stopped."""
    big = 2.0 ** 64
    H = sp.csc_matrix(np.array([[big, 0, 0, 0, 0], [3.0, 0, 0, 0, 0], [-big, 0, 0, 0, 0]]))
    M = sp.diags([big, 4.0, big], format="csc")
    v, r = np.ones(3), np.array([1.0, 0, 0, 0, 0])
    w = np.array([-3.0, 0, 0, 0, 0])
    problem = rfverify.Problem.from_arrays(M, H, M @ v - H @ r, w, np.array([0.5]), np.array([0.1]))
    u = np.asarray(sp.csr_matrix(H.T, dtype=np.longdouble) @ v.astype(np.longdouble) + w)
    assert float(r @ u) == 1.0  # the rounding this test is about
    may, proof = _gate_and_proof(problem, v, r)
    assert may and proof.certified, proof.summary()


def test_the_set_up_begins_at_the_double_solves_first_factorisation_or_when_asked():
    """Its thread keeps off the GIL while the double solve sets itself up: it waits for the first
    GIL-free CHOLMOD factorisation of an engine made inside the hook's block (the double solve),
    or until its results are asked for; a factorisation elsewhere does not start it."""
    from rfverify.engines.factor import CholmodEngine, on_factoring

    problem = random_problem(8, 20, seed=4)
    K = sp.tril(sp.identity(50, format="csc") * 2.0, format="csc")
    waiting = P.Preparation(problem, "auto", "auto", background=True)
    CholmodEngine().factor(K)  # outside the block: not its signal
    assert not waiting._ctx_ready.wait(0.3)  # nothing factored for it yet: not begun
    with on_factoring(waiting.start):
        engine = CholmodEngine()
    engine.factor(K)  # made inside the block: its first factorisation is the signal
    assert waiting._ctx_ready.wait(30) and waiting.context().hypotheses_proven
    asked = P.Preparation(problem, "auto", "auto", background=True)
    assert asked.context().hypotheses_proven and asked.system()[0].n == problem.n_contacts


def test_the_gate_refuses_a_bound_between_the_relative_and_the_absolute_tests():
    """The proof certifies v relatively (bound ≤ 10⁻ᵏ‖v‖∞) or, only where ‖v‖∞ itself is below
    10⁻ᵏ of its data scale, absolutely.  A bound that fits 10⁻ᵏ of the scale but not of a v that
    is not small certifies nothing, so the gate must say no (it said yes, and a 9675-contact bed
    spent 0.5 s proving an iterate to 9.6 digits)."""
    problem = rfverify.solver.posed(random_problem(6, 14, seed=1), None, "auto")
    ctx = ProofContext(problem)
    coupled = ctx.exact.free_blocks(ctx.mass, problem.as_stored).coupled
    root_minv = float(np.sqrt(np.max(ctx.mass.minv_diag_upper[coupled])))
    scale, tol, u_ok = ctx.scales["v"], 1e-10, 1e300
    assert scale > 0
    eps = 0.5 * tol * scale / root_minv  # v's bound is then at least half of 10⁻¹⁰ of the scale
    assert not ctx.may_certify(eps, scale / 10, u_ok, 10)
    assert ctx.may_certify(eps, 0.5 * tol * scale, u_ok, 10)  # v below 10⁻¹⁰ of its scale
    assert not ctx.may_certify(eps, 0.5 * tol * scale, u_ok, 10, relative=True)
    assert ctx.may_certify(eps, 1e3 * scale, u_ok, 10)  # the bound fits 10⁻¹⁰ of v itself


@pytest.mark.parametrize("relative", [False, True])
def test_the_gate_says_yes_wherever_the_proofs_own_rule_certifies(relative):
    """At and around both thresholds of :func:`quantity_bound` (bound against 10⁻ᵏ‖v‖∞, and ‖v‖∞
    against 10⁻ᵏ of the scale): wherever the proof would certify v, the gate lets the proof be
    made.  A gate tighter by a few per cent fails here."""
    from rfverify.proof.quantity import quantity_bound

    problem = rfverify.solver.posed(random_problem(6, 14, seed=1), None, "auto")
    ctx = ProofContext(problem)
    coupled = ctx.exact.free_blocks(ctx.mass, problem.as_stored).coupled
    root_minv = float(np.sqrt(np.max(ctx.mass.minv_diag_upper[coupled])))
    scale, tol = ctx.scales["v"], 1e-10
    certified = 0
    for norm in (tol * scale * f for f in (0.0, 0.2, 0.98, 0.999, 1.0, 1.01, 1.05, 10.0, 1e6)):
        for bound in (tol * ref * f for ref in (norm, scale) for f in (0.5, 0.97, 0.999, 0.99999, 1.0, 1.02)):
            proof_says = quantity_bound("v", np.array([bound]), np.array([norm]), ctx.scales, 10,
                                        relative=relative).certified
            certified += proof_says
            assert not proof_says or ctx.may_certify(bound / root_minv, norm, 1e300, 10, relative=relative), \
                (norm / (tol * scale), bound / (tol * norm))
    assert certified > 10  # the grid does reach the thresholds from both sides


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 50), tol_exp=st.integers(6, 12), digits=st.integers(2, 8))
def test_where_the_gate_says_no_to_relative_digits_the_proof_does_not_certify_them(seed, tol_exp, digits):
    problem = rfverify.solver.posed(random_problem(6, 14, seed=seed), None, "auto")
    double = rfverify.solve(problem, tol=10.0 ** -tol_exp)
    ctx = ProofContext(problem)
    point = candidate_point(double.v, double.r)
    vv, uu, rr = ctx.rounded(point)
    proof = ctx.prove(point, vv, uu, rr, requested=digits, relative=True)
    may = P.double_answer_may_certify(ctx, problem, double.v, double.r, digits, relative=True)
    assert may or not proof.certified, (proof.summary(), tol_exp, digits)
