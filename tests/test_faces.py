"""Issue 45: data whose feasible set has no interior (a self-stress), found, verified exactly,
and proven through their face — and never a false proof on the way (DESIGN §6.8)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import rfverify
from rfverify.proof import ProofContext, face
from rfverify.proof.dyadic import Dyadic, Quotient
from rfverify.proof.reduction import reduce_to_face

from corner_problems import corner_problem


def _exact_corner_velocity(problem, body: int, sign: float) -> np.ndarray:
    """v* of a corner sphere, by hand: its feasible set is the ray V = s(0, sign, 1), ω = 0
    (the two friction cones touch along it), so v* = s*(0, sign, 1, 0, 0, 0) with
    s* = max(0, ⟨(0, sign, 1), V_free⟩ / 2), V_free = M⁻¹f (translational mass m·I)."""
    dofs = slice(6 * body, 6 * body + 6)
    M = problem.M.toarray()[dofs, dofs]
    v_free = np.linalg.solve(M, problem.f[dofs])
    s = max(0.0, (sign * v_free[1] + v_free[2]) / 2)
    return np.array([0.0, sign * s, s, 0.0, 0.0, 0.0])


@pytest.mark.parametrize("seed", [0, 1, 5])
@pytest.mark.parametrize("second_corner", [False, True])
def test_corner_spheres_are_proven_and_every_digit_is_true(seed, second_corner):
    """A planted zero-gap corner sphere with μ = 1 (and a second in the other corner): the
    self-stress is found on exactly its two contacts, 10 digits are proven, and the known
    exact velocity of each corner sphere lies within the proven bound of the answer."""
    problem = corner_problem(seed, second_corner)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.success, out.message
    proof = out.certificate.proof
    assert proof.face is not None
    expected = [[0, 1], [3, 4]] if second_corner else [[0, 1]]
    assert sorted(list(map(int, s.contacts)) for s in proof.face.stresses) == expected
    e_v = proof.quantities["v"].abs_bound
    exact = [(0, -1.0)] + ([(2, 1.0)] if second_corner else [])
    for body, sign in exact:
        v_star = _exact_corner_velocity(problem, body, -sign if body == 2 else 1.0)
        assert np.max(np.abs(out.v[6 * body:6 * body + 6] - v_star)) <= e_v
    assert proof.quantities["r"].mode == "information" and "self-stress" in proof.quantities["r"].note


def test_without_the_face_step_the_corner_is_not_certified(monkeypatch):
    """Remove the face step (no self-stress found): the same problem reverts to "not certified"."""
    monkeypatch.setattr(face, "find_self_stress", lambda *a, **k: [])
    out = rfverify.solve_to_digits(corner_problem(0), digits=10)
    assert not out.success
    assert "no self-stress" in out.message or not out.certificate.proof.valid


def _corner_point(problem):
    """A point of the corner problem near its face (the reduced problem's answer lifted back)."""
    ctx = ProofContext(problem)
    stresses = face.find_self_stress(problem, [0, 1], ctx.exact.face_search)
    red = reduce_to_face(problem, stresses)
    sub = rfverify.solve_to_digits(red.problem, digits=12)
    return ctx, red.lift(sub.point), stresses


def _proven_after_a_face_move(problem):
    """(problem, its ProofContext, the double answer's point, its proof), the point having been
    moved onto the face of the problem's self-stress (asserted)."""
    from rfverify.verify.certificate import candidate_point

    double = rfverify.solve(problem, tol=1e-10)
    point = candidate_point(double.v, double.r)
    ctx = ProofContext(problem)
    proof = ctx.prove(point, *ctx.rounded(point), requested=6)
    assert proof.valid and proof.face is not None and proof.face.moved > 0
    return problem, ctx, point, proof


def test_a_point_left_slightly_off_the_face_is_never_proven(monkeypatch):
    """The face move replaced by one that leaves v' 2⁻⁶⁰ off the face on one dof: the proof must
    refuse (exact cone test), not certify."""
    problem, ctx, point, good = _proven_after_a_face_move(corner_problem(0))  # off the face by the double solve's error
    real_restore = face.restore

    def off_face(problem_, exact, point_v, stresses):
        repair = real_restore(problem_, exact, point_v, stresses)
        q = repair.point_v
        ints = q.num.ints.copy()
        ints[1] += (q.den << max(-q.num.exp - 60, 0)) if q.num.exp < -60 else 1  # +2⁻⁶⁰ on V_y
        repair.point_v = Quotient(Dyadic(ints, q.num.exp), q.den)
        return repair

    monkeypatch.setattr(face, "restore", off_face)
    ctx2 = ProofContext(problem)
    bad = ctx2.prove(point, *ctx2.rounded(point), requested=6)
    assert not bad.valid and not bad.certified
    assert "after it was moved onto a face" in bad.failure


def test_r_outside_K_is_refused_when_no_shift_along_the_stress_helps():
    """r on a stress contact on the wrong side of its edge (gᵀr < 0): r + τy ∉ K for every τ,
    so the proof must be invalid."""
    problem = corner_problem(0)
    ctx, point, stresses = _corner_point(problem)
    r = point.r_hi.copy()
    r[0:5] = [1.0, 0.0, 1.5, 0.0, 0.0]  # floor contact: N = 1, T2 = 1.5 towards the edge's side
    from rfverify.proof import Point

    bad = ctx.prove(Point(point.v_hi, point.v_lo, r, np.zeros_like(r)), *ctx.rounded(point), requested=10)
    assert not bad.valid


def test_the_self_stress_is_exact_and_its_checks_reject_a_wrong_one():
    problem = corner_problem(3)
    (stress,) = face.find_self_stress(problem, [0])
    y = np.array([float(x) for x in stress.y])
    H = problem.H[:, :10].toarray()
    assert not np.any(H @ np.array(stress.y, dtype=object))  # H y = 0 exactly (Fractions)
    assert stress.w_dot_y == 0 and not stress.infeasible
    assert stress.kinds == ("friction", "friction")
    from scipy import sparse as sp

    H = sp.csc_matrix(problem.H)
    # float noise of a conic solver's answer is removed: the same exact y comes back
    noisy = y * (1 + 1e-9 * np.arange(1, 11))
    again = face._exact_stress(problem, H, np.array([0, 1]), noisy, 1)
    assert again is not None and again.kinds == stress.kinds
    # forces that do not balance (the floor's tangential force turned round) are not accepted
    wrong = y.copy()
    wrong[2] = -wrong[2]
    for den in face.SNAP_DENOMINATORS:
        assert face._exact_stress(problem, H, np.array([0, 1]), wrong, den) is None
    assert face._exact_stress(problem, H, np.array([0, 1]), -y, 1) is None  # pulling, not pushing


def test_infeasible_data_are_named():
    """w_N < 0 on both corner contacts (penetration to undo at 45° from both walls): the forces
    y give wᵀy < 0, so no velocity is feasible; the verdict says so."""
    base = corner_problem(0)
    w = np.zeros(base.w.size)
    w[0], w[5] = -1.0, -1.0
    problem = rfverify.Problem.from_arrays(base.M, base.H, base.f, w, base.mu, base.mu_r)
    stresses = face.find_self_stress(problem, [0, 1])
    assert stresses and stresses[0].infeasible
    assert "no velocity satisfies" in stresses[0].describe()


def test_no_self_stress_where_there_is_none():
    """A sphere on the floor alone (contact 2) carries no self-stress."""
    assert face.find_self_stress(corner_problem(0), [2]) == []


def test_written_solution_rechecks_and_certifies_from_the_file(tmp_path):
    """The written answer of a self-stressed problem passes the independent recheck of the
    criterion at 1e-10 (its r is r₀ + τy, in K to 1e-11) and certifies again from the file's
    float64 numbers alone (no stored point: the certify path solves on the face too)."""
    from rfverify.model.check import check_solution
    from rfverify.io import save
    from rfverify.model.problem import StoredSolution

    problem = corner_problem(1, True)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.success
    chk = check_solution(problem, StoredSolution(out.v, out.u, out.r))
    assert chk.ok(1e-10), chk.as_dict()
    path = tmp_path / "corner.h5"
    save(problem.with_solution(StoredSolution(out.v, out.u, out.r)), path)
    stored = rfverify.load(path)
    again = rfverify.certify(stored, stored.solution.v, stored.solution.u, stored.solution.r, digits=10)
    assert again.certified, again.verdict
    assert "face" in again.extra


@given(st.lists(st.fractions(min_value=-10 ** 6, max_value=10 ** 6, max_denominator=10 ** 9), min_size=1,
                max_size=8))
def test_quotient_bounds_enclose_the_exact_values(values):
    q = Quotient.from_fractions(values)
    assert q.fractions() == [Fraction(v) for v in values]
    lo, hi = q.lower(), q.upper()
    for v, a, b in zip(values, lo, hi):
        assert Fraction(float(a)) <= v <= Fraction(float(b))
        assert b - a <= 4 * np.spacing(max(abs(a), abs(b), 1e-300))


def test_a_rational_point_is_proven_as_its_equal_with_another_denominator(monkeypatch):
    """The moved point v' = V / den: the same point written with den·3 (numerator ×3) must give
    the same proof up to rounding — every bound divides by den exactly once (g and rᵀu) or
    twice (gᵀM⁻¹g), and a missing or extra division changes ε by 3× or 9×."""
    problem, ctx, point, one = _proven_after_a_face_move(corner_problem(2, True))
    real_restore = face.restore

    def thirds(problem_, exact, point_v, stresses):
        repair = real_restore(problem_, exact, point_v, stresses)
        q = repair.point_v
        repair.point_v = Quotient(q.num.times_int(3), q.den * 3)
        return repair

    monkeypatch.setattr(face, "restore", thirds)
    ctx3 = ProofContext(problem)
    three = ctx3.prove(point, *ctx3.rounded(point), requested=6)
    assert three.valid
    assert three.eps_M == pytest.approx(one.eps_M, rel=1e-12)
    for name in ("v", "u", "Hr"):
        assert three.quantities[name].abs_bound == pytest.approx(one.quantities[name].abs_bound, rel=1e-12)
    # an answer 1e-3 away from the point: its distance to v' (divided by den) dominates the bounds
    v, u, r = ctx.rounded(point)
    far = (v + 1e-3, u + 1e-3, r)
    monkeypatch.setattr(face, "restore", real_restore)
    one_far = ProofContext(problem).prove(point, *far, requested=6)
    monkeypatch.setattr(face, "restore", thirds)
    three_far = ProofContext(problem).prove(point, *far, requested=6)
    for name in ("v", "u"):
        assert one_far.quantities[name].abs_bound >= 1e-3
        assert three_far.quantities[name].abs_bound == pytest.approx(one_far.quantities[name].abs_bound, rel=1e-12)


@pytest.mark.parametrize("turn", [0.3, 1.1])
def test_generic_frames_never_give_a_false_claim(turn):
    """The corner with its tangent frames turned about the normals (generic floats): the cones
    touch only up to rounding (they may overlap by ~√eps ≈ 1e-8 in velocity: v* then differs from
    the idealised corner's by ~1e-9) and no exact self-stress is found.  Not proven to 10 digits
    today (DESIGN §6.8); whatever is claimed must hold against the independent mpmath reference
    solved on the same float data to 60 digits."""
    import reference

    problem = corner_problem(4, turn=turn)
    out = rfverify.solve_to_digits(problem, digits=10)
    proof = out.certificate.proof
    if proof is not None and proof.valid:
        ref = reference.solve(problem, dps=60, tol=1e-40, max_iter=200)
        assert ref.success
        v_ref = np.array([float(x) for x in ref.v])
        assert np.max(np.abs(out.v - v_ref)) <= proof.quantities["v"].abs_bound
    else:
        assert "no self-stress" in out.message


def test_the_face_runs_step_reports_name_the_posed_problems_contacts():
    """The run on the face numbers its contacts its own way (the kept ones first, then the
    face's edge contacts); what it reports of its steps names the posed problem's contact, or
    the face's edge contact, never a reduced index as if it were the problem's."""
    problem = corner_problem(1, True)
    lines = []
    out = rfverify.solve_to_digits(problem, digits=10, progress=lines.append)
    note = out.certificate.extra["face"]
    in_stress = {int(c) for s in note["self_stresses"] for c in s["contacts"]}
    kept = sorted(set(range(problem.n_contacts)) - in_stress)  # the contacts no self-stress touches
    n_edges = note["reduced_contacts"] - len(kept)
    held = note["extended_steps_held"]
    assert held and n_edges > 0
    for h in held:
        if h["contact"] is None:
            assert 0 <= h["face_edge"] < n_edges
        else:
            assert h["contact"] in kept and "face_edge" not in h
    said = [line for line in lines if "(on the face)" in line and "held by" in line]
    assert len(said) == len(held)
    for h, line in zip(held, said):
        who = f"contact {h['contact']}'s" if h["contact"] is not None else f"the face's edge contact {h['face_edge']}'s"
        assert f"held by {who} {h['part']} cone ({h['side']})" in line


def test_a_face_whose_problem_has_no_data_is_answered_exactly():
    # One body (M = I), one contact whose rolling cone carries a self-stress y = (1, 0, 0, 1, 0)
    # (Hy = 0, wᵀy = 0); on its face the reduced problem has f' = w' = 0.  Its iterates divided
    # by μ = 0 (a ZeroDivisionError, exit 3, found by a mutation audit); its answer, no motion
    # along the face, is exact.  Truth: v* = M⁻¹f = e1 is feasible (u(e1) = 0 ∈ K*).
    H = np.zeros((4, 5))
    H[0, 0] = H[1, 1] = H[2, 2] = H[3, 4] = 1.0
    H[0, 3] = -1.0
    p = rfverify.Problem.from_arrays(np.eye(4), H, np.array([1.0, 0, 0, 0]), np.array([-1.0, 0, 0, 1.0, 0]),
                                     np.array([0.5]), np.array([1.0]))
    out = rfverify.solve_to_digits(p, digits=10)
    assert out.status is rfverify.Status.CERTIFIED, out.message
    assert np.array_equal(out.v, [1.0, 0, 0, 0]) and not np.any(out.u)
    assert out.certificate.bounds["v"] == 0.0
    assert "face" in out.certificate.extra
