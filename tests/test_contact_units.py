"""Reactions in mismatched units from contact to contact: the same problem with each contact's
five columns of H and rows of w multiplied by its own power of two 2^s_c (its reactions in units
2^s_c smaller).  The problem is the same; the interior-point start is not.  With s_c spread over
2^±12 the double solve of a 1355-contact Chute ended InsufficientProgress, the Chute below took
88 iterations instead of 26, and the 274-contact Lattice at 2^±20 was not proven.  Such units are
now brought back to the median contact's (rfverify.model.scaling.contact_units), the answer
scaled back and judged, and every proof made in the problem's own units; checked here against the
original problem's answer, scaled by hand."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.model.measures import measures
from rfverify.model.scaling import CONTACT_UNIT_EXPONENT, contact_units
from rfverify.proof import ProofContext

DATA = Path(__file__).parent / "data"
HARD = DATA / "hard"


def in_contact_units(p, spread: int, seed: int):
    """``p`` with contact c's reactions in units 2^s_c smaller, s_c uniform in ±``spread``."""
    s = np.random.default_rng(seed).integers(-spread, spread + 1, p.n_contacts)
    C = sp.diags(np.ldexp(1.0, np.repeat(s, 5)))
    return rfverify.Problem.from_arrays(p.M, p.H @ C, p.f, C @ p.w, p.mu, p.mu_r), s


@pytest.mark.parametrize("name", sorted(rfverify.bundled_problems()))
def test_shipped_problems_keep_their_units(name):
    """The change applies only beyond 2^±8 between contacts: shipped and frozen problems are
    used as they are (bit for bit the same answers)."""
    assert contact_units(rfverify.load(f"bundled:{name}")) is None


@pytest.mark.parametrize("path", sorted((DATA / "scenes").glob("*.hdf5")) + sorted(HARD.glob("*.hdf5")),
                         ids=lambda p: p.name)
def test_generated_problems_keep_their_units(path):
    assert contact_units(rfverify.load(str(path))) is None


def test_units_within_the_margin_are_kept_and_beyond_it_brought_back():
    p = rfverify.load(str(HARD / "Chute-ndof-1200-nc-240-3.hdf5"))
    assert contact_units(in_contact_units(p, CONTACT_UNIT_EXPONENT // 2 - 1, 3)[0]) is None
    q, s = in_contact_units(p, 12, 3)
    units = contact_units(q)
    assert units is not None
    # each contact ends within a factor 2 of its original units, up to one shift shared by all
    net = s + units.exponents
    assert np.ptp(net) <= 1


def test_solve_brings_the_units_back_and_judges_the_answer_in_its_own():
    p = rfverify.load(str(HARD / "Chute-ndof-1200-nc-240-3.hdf5"))
    base = rfverify.solve(p)
    q, s = in_contact_units(p, 12, 1)
    res = rfverify.solve(q)
    assert res.success, res.message
    assert res.nit <= base.nit + 5  # 88 iterations before the change (26 for the original)
    assert "contact_units" in res.extras and "units moved by exact powers of two" in res.message
    # judged independently on the problem as given
    assert measures(q, res.v, q.H.T @ res.v + q.w, res.r, "longdouble").max <= 1e-10
    np.testing.assert_allclose(res.u, q.H.T @ res.v + q.w, rtol=0, atol=1e-12 * np.max(np.abs(res.u)))
    # scaled back by hand, the reactions are an answer of the original problem
    r_orig = res.r * np.repeat(np.ldexp(1.0, s), 5)
    assert measures(p, res.v, p.H.T @ res.v + p.w, r_orig, "longdouble").max <= 1e-10
    assert np.max(np.abs(res.v - base.v)) <= 1e-6 * np.max(np.abs(base.v))  # both to a criterion of 1e-10


@pytest.fixture(scope="module")
def lattice_at_20():
    p = rfverify.load(str(HARD / "Lattice-ndof-360-nc-274-0.hdf5"))
    q, s = in_contact_units(p, 20, 1)
    return p, q, s, rfverify.solve_to_digits(q, 10)


def test_digits_are_proven_in_the_problems_own_units(lattice_at_20):
    """Not proven before the change.  The certificate is the proof of the returned point and
    answer made afresh on the problem as given (a proof in the scaled units would state other
    digits of u and r: they are relative to the problem's own ‖u*‖∞ and ‖r*‖∞)."""
    p, q, s, res = lattice_at_20
    assert res.certificate.certified, res.message
    assert "contact_units" in res.certificate.extra
    again = ProofContext(q).prove(res.point, res.v, res.u, res.r, requested=10)
    assert again.certified
    for name, q_bound in again.quantities.items():  # (r's bound is NaN: r is not unique here)
        mine = res.certificate.proof.quantities[name]
        assert mine.abs_bound == q_bound.abs_bound or (np.isnan(mine.abs_bound) and np.isnan(q_bound.abs_bound))
        assert mine.digits == q_bound.digits


def test_proven_bounds_hold_against_the_original_problems_answer(lattice_at_20):
    """Independent: the original problem proven on its own, its answer scaled by hand; v and Hr
    of the two proven answers differ by no more than the sum of their bounds."""
    p, q, s, res = lattice_at_20
    ref = rfverify.solve_to_digits(p, 10)
    assert ref.certificate.certified
    bound = {name: qb.abs_bound for name, qb in res.certificate.proof.quantities.items()}
    ref_bound = {name: qb.abs_bound for name, qb in ref.certificate.proof.quantities.items()}
    assert np.max(np.abs(res.v - ref.v)) <= bound["v"] + ref_bound["v"]
    r_orig = res.r * np.repeat(np.ldexp(1.0, s), 5)
    assert np.max(np.abs(p.H @ r_orig - p.H @ ref.r)) <= 1.001 * (bound["Hr"] + ref_bound["Hr"]) + 1e-15
    u_orig = res.u * np.repeat(np.ldexp(1.0, -s), 5)
    assert np.allclose(u_orig, p.H.T @ res.v + p.w, rtol=1e-12, atol=1e-14)


def test_a_self_stress_between_contacts_in_units_far_apart_is_found():
    """Contacts 201 and 202 of this Chute carry a self-stress (its feasible set has no interior:
    the answer is proven through their face).  With their units 2^±20 apart the float search
    for it (bound y_N ≤ 1, a relative support threshold, a least-squares fit) found nothing, and
    the k-digit path ended "no self-stress was found"; it now searches in units brought together
    and maps the exact stress back."""
    from fractions import Fraction

    from rfverify.proof.face import find_self_stress

    p = rfverify.load(str(HARD / "Chute-ndof-1200-nc-240-3.hdf5"))
    (orig,) = find_self_stress(p, [201, 202])
    q, s = in_contact_units(p, 20, 1)
    assert abs(s[201] - s[202]) > 6  # the seed puts the pair's units far apart
    (found,) = find_self_stress(q, [201, 202])
    assert list(found.contacts) == [201, 202] and found.kinds == orig.kinds
    # q's columns are p's times 2^s_c: the stress is p's, each contact's part divided by 2^s_c
    # (up to one positive factor, as any multiple of a self-stress is one)
    ratio = [found.y[5 * i] * Fraction(2) ** int(s[c]) / orig.y[5 * i] for i, c in enumerate([201, 202])]
    assert ratio[0] == ratio[1] > 0
    res = rfverify.solve_to_digits(q, 10)
    assert res.certificate.certified, res.message
    assert "face" in res.certificate.extra


def test_diagnose_runs_what_solve_runs_in_one_set_of_units():
    """The diagnosis replays the run `rfverify solve --method jqinv` makes, which brings the
    units together; its lockstep compares iterates of that one problem.  Before, the run was
    another (46 iterations against solve's 21) and its steps 'agreed to -0.6 digits'."""
    p = rfverify.load(str(HARD / "Chute-ndof-1200-nc-240-3.hdf5"))
    q, _ = in_contact_units(p, 12, 1)
    d = rfverify.diagnose(q, witness_time=0, remedies=False)
    assert d.status == "Solved" and d.nit == rfverify.solve(q, method="jqinv").nit
    assert "units brought together" in d.to_dict()["evidence"]["units"]
    digits = [s["digits_v"] for s in d.to_dict()["iterations"] if s.get("digits_v") is not None]
    assert digits and min(digits) > 5


def test_what_auto_said_before_the_judgement_is_kept():
    """The answer is judged again in the problem's own units; what auto (its attempts, its time
    limit) put before the judged message stays, and only the judgement is redone."""
    from rfverify.model.scaling import problem_in_contact_units
    from rfverify.solver.in_units import in_own_contact_units

    p = rfverify.load(str(HARD / "Chute-ndof-1200-nc-240-3.hdf5"))
    q, _ = in_contact_units(p, 12, 1)
    units = contact_units(q)
    scaled = problem_in_contact_units(q, units)
    res = rfverify.solve(scaled)
    res.message = "auto returned jqinv [reduced: InsufficientProgress]: " + res.message
    out = in_own_contact_units(res, q, scaled, units)
    assert out.message.startswith("auto returned jqinv [reduced: InsufficientProgress]: criterion ")
    assert f"{out.criterion:.2e}" in out.message and out.message.count("≤ tol") == 1


@pytest.mark.parametrize("seed", [0, 8])
def test_against_an_exact_solution_with_contact_units_and_a_binary_scaling(seed):
    """Exact 8-contact problems (tests/exact_problems.py) with contact units spread over 2^±14:
    the problem brought together in contact units would then be scaled again by the exact binary
    scaling, and a run proven in those units fell short in the problem's own (r 9.9 and 9.97
    digits for 10, where the binary scaling alone proves 10.1 and 10.2).  One change of units
    only: such problems take the binary scaling alone.  The bounds hold against the exact
    solution either way."""
    from exact_problems import exact_problem

    p, vs, us, rs = exact_problem(seed, 8)
    q, s = in_contact_units(p, 14, 100 + seed)
    res = rfverify.solve_to_digits(q, 10)
    assert res.certificate.certified, res.message
    quantities = res.certificate.proof.quantities
    exact = {"v": np.asarray(vs, float), "u": np.asarray(us, float) * np.repeat(np.ldexp(1.0, s), 5),
             "r": np.asarray(rs, float) * np.repeat(np.ldexp(1.0, -s), 5)}
    for name in ("v", "u", "r"):
        assert np.max(np.abs(getattr(res, name) - exact[name])) <= quantities[name].abs_bound
