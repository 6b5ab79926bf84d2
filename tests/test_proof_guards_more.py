"""More guards on rfverify's proof code: inputs on which a weakened bound makes a false claim.

Each test passes on the code as written and fails on the named mutant (see the docstrings)."""

from fractions import Fraction

import numpy as np
import pytest

import rfverify
from rfverify.proof import Point, ProofContext

# A 2×2 SPD block that is exactly definite (det = 0.229248046875 > 0, computed in rationals) but so
# ill-conditioned (κ ≈ 1e37) that a float LU solve of B x = -B e1 returns x ≈ (-0.13, -7.5e8),
# not the exact -e1.
_A = 1000003 * 2.0 ** 40
_B = 1281100871.0
_C = 6722414665864825 * 2.0 ** -52


def _held_ill_conditioned():
    """Dof 0 (mass 1) and the block B on dofs 1, 2, every dof pushed into its own contact
    (normal = +dof): f = -(1, a, b) = -M (1, 1, 0), so M⁻¹f = (-1, -1, 0) exactly,
    ‖M⁻¹f‖∞ = ‖HᵀM⁻¹f + w‖∞ = 1 exactly, and v* = 0, u* = 0, r*_N = (1, a, b)."""
    assert Fraction(_A) * Fraction(_C) - Fraction(_B) ** 2 == Fraction(939, 4096)
    M = np.zeros((3, 3))
    M[0, 0] = 1.0
    M[1:, 1:] = [[_A, _B], [_B, _C]]
    f = -np.array([1.0, _A, _B])
    H = np.zeros((3, 15))
    H[0, 0] = H[1, 5] = H[2, 10] = 1.0
    p = rfverify.Problem.from_arrays(M, H, f, np.zeros(15), np.full(3, 0.5), np.full(3, 0.25))
    v = np.zeros(3)
    r = np.zeros(15)
    r[0], r[5], r[10] = 1 + 2.0 ** -30, _A, _B  # r_N,0 off by 2^-30: a residual, error bounds ≈ 4.4
    return p, v, H.T @ v, r


@pytest.mark.parametrize("name", ["v", "u"])
def test_data_scales_of_an_ill_conditioned_block_stay_below_the_exact_ones(name):
    """Catches B14 (bound.py data_scales: ``x_lo = np.abs(x)``, the v scale without the solve's
    error bound) with name="v", and B15 (``u_lo = mag_lo``, the u scale likewise) with name="u".

    Exact: ‖M⁻¹f‖∞ = ‖HᵀM⁻¹f + w‖∞ = 1.  The float solve gives |x̃|∞ ≈ 7.49e8.  Original: scales
    v = u = 0, v and u not certified (error bound 4.42 for both).  Mutant B14: v scale 7.49e8, and
    v is certified 'zero within 4.42 = 8.2 digits below the data scale ‖M⁻¹f‖∞ = 7.49e8' at 1
    digit, while 4.42 > 0.1 · 1 (the true data scale); B15: the same for u."""
    p, v, u, r = _held_ill_conditioned()
    ctx = ProofContext(p)
    assert ctx.mass.proven
    pr = ctx.prove(Point(v, 0 * v, r, 0 * r), v, u, r, requested=1)
    q = pr.quantities[name]
    assert q.abs_bound > 0.1  # larger than 10⁻¹ of the true data scale 1: no absolute claim can hold
    assert not q.certified
    # the scales must be proven lower bounds of the exact ones (= 1)
    assert ctx.scales[name] <= 1.0


def test_free_block_solve_bound_covers_the_left_residual():
    """Catches MB7 (massbounds.py solve_upper: ``out = inflate(t, 2)``, the bound |Xg| without
    the residual term rows·‖d‖∞/(1 − ρ)).

    Dof 0 (mass 1) rests on a contact (f_0 = -1, r_N = 1, v_0 = 0: exact); dofs 1, 2 form a free
    block B (no contact, f = 0, so v*_B = 0 exactly) with eigenvalues 1 and 1e-13, and the
    returned v_B is B's smallest eigenvector q (floats): the true error is ‖q‖∞ = 0.9092876550577076
    exactly.  Original: bound 0.9154 (≥ the error).  Mutant: bound 0.9090774 < 0.9092877, and it
    claims ‖v*‖∞ ≥ 2.1e-4 where v* = 0."""
    B = np.array([float.fromhex(x) for x in ("0x1.62b4904c5ae7ep-3", "-0x1.837fa3d60a49dp-2",
                                             "-0x1.837fa3d60a49dp-2", "0x1.a752dbece97e6p-1")]).reshape(2, 2)
    q = np.array([float.fromhex("-0x1.d18e26ca423e8p-1"), float.fromhex("-0x1.aa27fe4d4a930p-2")])
    M = np.zeros((3, 3))
    M[0, 0] = 1.0
    M[1:, 1:] = B
    H = np.zeros((3, 5))
    H[0, 0] = 1.0
    f = np.array([-1.0, 0.0, 0.0])
    p = rfverify.Problem.from_arrays(M, H, f, np.zeros(5), np.array([0.5]), np.array([0.25]))
    ctx = ProofContext(p)
    v = np.r_[0.0, q]
    r = np.zeros(5)
    r[0] = 1.0
    pr = ctx.prove(Point(v, 0 * v, r, 0 * r), v, H.T @ v, r, requested=3)
    assert pr.terms["free_dofs_solved"] == 2  # the verified free-block solve is what is exercised
    truth = max(abs(Fraction(x)) for x in q)  # v* = 0: the error is |v| exactly
    assert Fraction(pr.quantities["v"].abs_bound) >= truth
    assert pr.quantities["v"].own_scale == 0.0  # nothing may be claimed about ‖v*‖∞ > 0


def _local(W, q, mu, mur):
    import dataclasses

    from rfverify.io.local_lift import LocalProblem, lift_local
    from rfverify.model.problem import make_local_form

    lifted, _ = lift_local(LocalProblem(W=W, q=q, mu=mu, mu_r=mur))
    return dataclasses.replace(lifted, local=make_local_form(W, q))


def test_active_set_refinement_keeps_the_dual_shift_term():
    """Catches L5 (local.py _active_set_refinement: ``a = up(uS_norm)/root``, the ‖e‖₂ of the point
    raised into K* dropped from the linear term).

    W = I (10×10), two frictionless contacts, q_N = (-1, -1): exactly r* = (1, 0.., 1, 0..),
    u* = 0.  Point r_N = (0.25, 1): u_N = (-0.75, 0) is outside K*, raised by e = 0.75 on contact 0
    (class 'rest'), contact 1 is 'stuck'.  True |r − r*|∞ = |u − u*|∞ = 0.75.  Original: bounds
    0.7500007 (r) and 0.7500004 (u).  Mutant: both ≤ 4.14e-07 and r claimed to 6.3 digits."""
    W = np.eye(10)
    q = np.zeros(10)
    q[0] = q[5] = -1.0
    problem = _local(W, q, np.zeros(2), np.zeros(2))
    from rfverify.proof.dyadic import Dyadic
    from rfverify.proof.local import prove_local

    r = np.zeros(10)
    r[0], r[5] = 0.25, 1.0
    u = W @ r + q
    pr = prove_local(problem, Dyadic.from_float(r), u, r, requested=2)
    assert pr.valid
    assert pr.quantities["r"].abs_bound >= 0.75  # = |r_0 − r*_0| exactly
    assert pr.quantities["u"].abs_bound >= 0.75  # = |u_0 − u*_0| exactly
    assert not pr.quantities["r"].certified


def test_no_self_stress_is_claimed_where_w_dot_y_is_positive():
    """Catches FA2 (face.py _exact_stress: ``if False:`` instead of ``if w_dot_y > 0:``, a y with
    wᵀy > 0 accepted as a self-stress).

    One dof between two opposite contacts (H = [1 | -1] on the normals), w_N = (1, -1 + 2^-40):
    v = -1 + 2^-41 gives u_N = (2^-41, 2^-41) > 0, u_T = u_R = 0, a strictly feasible velocity.
    y = (1, 1) on the normals has Hy = 0 but wᵀy = 2^-40 > 0: no self-stress.  Original: none
    found.  Mutant: reports 'contacts 0 and 1 carry a self-stress (…, wᵀy = 0, verified in exact
    arithmetic): the data allow no strictly feasible velocity, and every admissible one has u = 0
    (no relative motion) at 0, 1' with its own w_dot_y = 9007199253070695/9903520314283042199192993792 > 0."""
    H = np.zeros((1, 10))
    H[0, 0], H[0, 5] = 1.0, -1.0
    w = np.zeros(10)
    w[0], w[5] = 1.0, -1.0 + 2.0 ** -40
    p = rfverify.Problem.from_arrays(np.eye(1), H, np.zeros(1), w, np.full(2, 0.5), np.full(2, 0.25))
    # a strictly feasible velocity, checked exactly
    v = Fraction(-1) + Fraction(1, 2 ** 41)
    uN = (v + Fraction(w[0]), -v + Fraction(w[5]))
    assert uN[0] > 0 and uN[1] > 0
    ctx = ProofContext(p)
    r = np.zeros(10)
    r[0] = r[5] = 1e6  # the most loaded contacts: where a self-stress would be
    stresses = ctx.look_for_self_stress(r)
    assert all(s.w_dot_y <= 0 for s in stresses)
    assert stresses == []


def test_r_shifted_along_a_self_stress_must_meet_the_rolling_cone():
    """Catches FA3 (face.py _in_K: the rolling-cone condition |r_R|² ≤ μr² r_N² dropped, so
    shift_into_K accepts r + τy outside K).

    Dofs (x, θ), M = I, f = 0; contact 0: normal +x, rolling R1 = θ; contact 1: normal -x,
    rolling R1 = θ; μ = 0.5, μr = 0.25, w_N = (1, 1), w_R1 = (-4, 4).  y = (1,0,0,μr,0, 1,0,0,-μr,0)
    is a self-stress (Hy = 0, wᵀy = 0).  v = 0 is feasible (u_N = 1 = μr·|u_R| on both), so
    v* = 0 exactly.  Point v = (-0.125, 0.5), r with only r_R1 = 0.5 on contact 0 (r_N = 0: r ∉ K,
    and r + τy ∉ K for every τ ≥ 0).  True |v − v*|∞ = 0.5.  Original: no proof (r + τy ∉ K).
    Mutant: a valid proof with |v error| ≤ 0.0625 and ‖v*‖∞ ≥ 0.437, 0.8 digits."""
    mur = 0.25
    H = np.zeros((2, 10))
    H[0, 0], H[1, 3], H[0, 5], H[1, 8] = 1.0, 1.0, -1.0, 1.0
    w = np.zeros(10)
    w[0] = w[5] = 1.0
    w[3], w[8] = -4.0, 4.0
    p = rfverify.Problem.from_arrays(np.eye(2), H, np.zeros(2), w, np.full(2, 0.5), np.full(2, mur))
    ctx = ProofContext(p)
    alpha = 0.5
    v = np.array([-mur * alpha, alpha])
    r = np.zeros(10)
    r[3] = alpha
    pr = ctx.prove(Point(v, 0 * v, r, 0 * r), v, H.T @ v + w, r, requested=1)
    if pr.valid:  # whatever it proves must hold: v* = 0
        assert pr.quantities["v"].abs_bound >= 0.5
        assert pr.quantities["v"].own_scale == 0.0
