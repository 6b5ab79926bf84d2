"""Claims of the certificate guarded where a mutation audit (2026-12-07) found them unguarded:
each case is tiny, its exact solution is known in closed form, and the test fails if the proof
drops the check or the term that makes the claim true (the audit's mutants, each shown to print
a false claim on the input here, are named per test)."""

from __future__ import annotations

import dataclasses
from fractions import Fraction

import numpy as np
import pytest

import rfverify
from rfverify.proof import Point, ProofContext
from rfverify.proof.dyadic import Dyadic


def _problem(M, H, f, mu, mur, w=None, **kw):
    H = np.asarray(H, dtype=float)
    w = np.zeros(H.shape[1]) if w is None else np.asarray(w, dtype=float)
    return rfverify.Problem.from_arrays(np.asarray(M, dtype=float), H, np.asarray(f, dtype=float), w,
                                        np.atleast_1d(mu).astype(float), np.atleast_1d(mur).astype(float), **kw)


def _certify_at(p, v, r, digits, **kw):
    """The certificate of (v, r) proven at that very point (no computed point to hide behind)."""
    v, r = np.asarray(v, dtype=float), np.asarray(r, dtype=float)
    u = p.H.T @ v + p.w
    return rfverify.certify(p, v, u, r, digits=digits, point=Point(v, 0 * v, r, 0 * r), **kw)


def _sound(cert, errors: dict):
    """Every quantity the certificate vouches for is true: its bound covers the true error."""
    for name, err in errors.items():
        q = cert.quantities.get(name)
        if q is not None and q.certified and q.mode != "information":
            assert q.abs_bound >= err, (name, q.abs_bound, err, cert.verdict)


def test_u_outside_the_dual_cone_through_both_parts_is_no_proof():
    """u = (1.5, 1, 0, 1, 0) with μ = μr = 1: each part alone fits (1.5 ≥ 1), the sum does not
    (1.5 < 1 + 1). Mutant B3 (the K* test without its c² ≥ 4ab term) certified 'v 15.9 digits'
    for a v off by 0.17 (v* = (5/3, 5/6, 0, 5/6, 0))."""
    p = _problem(np.eye(5), np.eye(5), [1.5, 1, 0, 1, 0], 1.0, 1.0)
    v = np.array([1.5, 1, 0, 1, 0])
    cert = _certify_at(p, v, np.zeros(5), 10)
    assert not cert.certified and not cert.proof.valid, cert.verdict
    _sound(cert, {"v": 1 / 6, "u": 1 / 6})


def test_r_outside_the_rolling_cone_is_no_proof():
    """r = (1, 0, 0, 2, 0) with μr = 1 breaks the rolling cone only. Mutant B4 (r ∈ K without
    its rolling part) proved 'v exactly 0' where v* = (0.5, 0, 0, −0.5, 0)."""
    p = _problem(np.eye(5), np.eye(5), [-1, 0, 0, -2, 0], 1.0, 1.0)
    cert = _certify_at(p, np.zeros(5), [1, 0, 0, 2, 0], 10)
    assert not cert.certified and not cert.proof.valid, cert.verdict
    _sound(cert, {"v": 0.5})


def test_stored_unsymmetric_m_bounds_on_hr_and_r_are_attained_not_undercut():
    """M = [[1, 1], [−1, 1]] as stored, H = e_N, f = w = 0: v* = 0, r* = 0. At v = (½, ½), r = e_N
    (g = 0) the true errors of Hr and r are 1; the proof's Hr bound is 1 + 8e-15 (attained).
    Mutants B11 (√(M_s)_ii for √(m_iᵀM_s⁻¹m_i)) and R5 (no skew term in r's bound) gave 0.707."""
    H = np.zeros((2, 5))
    H[0, 0] = 1.0
    p = _problem([[1.0, 1.0], [-1.0, 1.0]], H, [0, 0], 0.5, 0.25, max_asymmetry=10.0)
    cert = _certify_at(p, [0.5, 0.5], [1, 0, 0, 0, 0], 1, as_stored=True)
    assert cert.proof.valid, cert.verdict
    hr = cert.quantities["Hr"].abs_bound
    assert 1.0 <= hr <= 1.01, hr
    q = cert.quantities["r"]
    assert q.mode == "information" or q.abs_bound >= 1.0, q
    _sound(cert, {"v": 0.5, "u": 0.5, "Hr": 1.0, "r": 1.0})


@pytest.mark.parametrize("c, x1", [(1.4e-3, 7e-4), (9e-4, 4.5e-4)])
def test_a_quantity_bounded_absolutely_counts_its_error_too(c, x1):
    """f = (−1, c): v* = (0, c), data scale ‖M⁻¹f‖∞ = 1, 3 digits asked. At v = (0, x1) the proof
    may call v zero only if ‖v‖ + e ≤ 1e-3 and must say ‖v*‖∞ ≤ ‖v‖ + e. Mutant Q3 (‖v‖ alone)
    certified c = 1.4e-3 > 1e-3 as zero; mutant Q6 printed ‖v*‖∞ ≤ 4.5e-4 for c = 9e-4."""
    H = np.zeros((2, 5))
    H[0, 0] = 1.0
    p = _problem(np.eye(2), H, [-1.0, c], 0.5, 0.25)
    cert = _certify_at(p, [0.0, x1], [1, 0, 0, 0, 0], 3)
    q = cert.quantities["v"]
    if q.mode == "absolute" and q.certified:
        assert q.zero_within >= c and c <= 1e-3, (q, cert.verdict)
    if c > 1e-3:
        assert not cert.certified, cert.verdict
    _sound(cert, {"v": abs(c - x1)})


def test_a_contact_is_proven_open_only_beyond_the_error_of_u():
    """M = 1, H = e_N, μ = μr = 0, f = −1: r* = e_N. At v = 1e-3, r = 0 the point's u_N = 1e-3 > 0
    but its error bound is larger. Mutant R1 ('proven open' without u's radius) claimed
    'r exactly 0' (a quantity marked certified) for a true error of 1."""
    H = np.zeros((1, 5))
    H[0, 0] = 1.0
    p = _problem(np.eye(1), H, [-1.0], 0.0, 0.0)
    cert = _certify_at(p, [1e-3], np.zeros(5), 3)
    assert not cert.certified
    _sound(cert, {"r": 1.0, "v": 1e-3})


def test_a_frictionless_contact_keeps_its_rolling_columns():
    """μ = 0, μr = 0.5: r* = (1, 0, 0, 0.4, 0) (H maps R1 to dof 1 with 0.01, f = (−1, −0.004, 0)).
    At r = e_N the true error is 0.4. Mutant R2 (rolling columns kept where μ > 0) certified
    'r 2.0 digits' with a bound of 0.008."""
    H = np.zeros((3, 5))
    H[0, 0], H[1, 3], H[2, 4] = 1.0, 0.01, 0.01
    p = _problem(np.eye(3), H, [-1.0, -0.004, 0.0], 0.0, 0.5)
    cert = _certify_at(p, np.zeros(3), [1, 0, 0, 0, 0], 1)
    _sound(cert, {"r": 0.4, "Hr": 0.004, "v": 0.0})


def test_the_r_bound_divides_by_the_singular_value_not_its_square():
    """H = 4 e_N (σmin² = 16), f = −4: r* = e_N. At r = 1 + 1e-6 the true error is 1e-6. Mutant R4
    (÷λ instead of ÷√λ) claimed r to 6.3 digits, above the true 6.0."""
    H = np.zeros((1, 5))
    H[0, 0] = 4.0
    p = _problem(np.eye(1), H, [-4.0], 0.0, 0.0)
    cert = _certify_at(p, [0.0], [1 + 1e-6, 0, 0, 0, 0], 5)
    _sound(cert, {"r": 1e-6 * (1 + 1e-9), "Hr": 4e-6})
    assert cert.quantities["r"].abs_bound >= 1e-6


# ---------------------------------------------------------------------- local files (u = W r + q)
def _local(W, q, mu, mur, like=None):
    """A local problem with the file's own W and q (its lifting from ``like``, a PSD stand-in
    where W is not PSD: the proof must judge W itself)."""
    from rfverify.io.local_lift import LocalProblem, lift_local
    from rfverify.model.problem import make_local_form

    W, q = np.asarray(W, dtype=float), np.asarray(q, dtype=float)
    lifted, _ = lift_local(LocalProblem(W=W if like is None else like, q=q, mu=np.asarray(mu, dtype=float),
                                        mu_r=np.asarray(mur, dtype=float)))
    return dataclasses.replace(lifted, local=make_local_form(W, q))


def _prove_local(problem, r, digits):
    from rfverify.proof.local import prove_local

    r = np.asarray(r, dtype=float)
    return prove_local(problem, Dyadic.from_float(r), problem.local.W @ r + problem.local.q, r, requested=digits)


def test_a_zero_diagonal_entry_with_a_nonzero_row_is_not_semidefinite():
    """W_NN = 1, W_NT = W_TN = 2, W_TT = 0: indefinite. r = (1, −¼, 0, 0, 0), u = (0.5, 2, 0, 0, 0)
    solves the file as well as r = 0 does. Mutant L1 (no 'W_kk = 0 ⇒ row k is zero' check)
    proved 'u exactly 0'."""
    W = np.zeros((5, 5))
    W[0, 0], W[0, 1], W[1, 0] = 1.0, 2.0, 2.0
    pr = _prove_local(_local(W, np.zeros(5), [0.25], [0.0], like=np.diag([1.0, 1, 1, 0, 0])), np.zeros(5), 10)
    assert not pr.valid and not pr.certified


def test_the_local_reaction_scale_is_the_largest_diagonal_entry():
    """W = diag(100, 1, 1, 1, 1), q = (−0.01, 1, 0, 0, 0): r* = 1e-4 e_N, data scale ‖q‖∞ / max W_kk
    = 0.01, so r* is not zero to 2 digits of it. Mutant L3b (the median W_kk: scale 1) certified
    'r zero within 2.4e-04'."""
    p = _local(np.diag([100.0, 1, 1, 1, 1]), [-0.01, 1.0, 0, 0, 0], [0.0], [0.0])
    pr = _prove_local(p, [1.5e-4, 0, 0, 0, 0], 2)
    q = pr.quantities["r"]
    assert q.data_scale <= 0.01 and not (q.mode == "absolute" and q.certified), q
    assert q.abs_bound >= 0.5e-4 or not q.certified


def test_the_shift_path_bound_covers_a_point_just_outside_the_dual_cone():
    """W = I (two contacts), μ = μr = 0, q = −e₀: r* = e₀. At r₀ = 1 − 2⁻³⁰ (u₀ just outside K*),
    r₅ = 2⁻¹⁰ the true error is 2⁻¹⁰ = 9.77e-4; the proof's bound is just above. Mutant L4
    (4λ → 2λ in δ) gave 6.9e-4."""
    q = np.zeros(10)
    q[0] = -1.0
    r = np.zeros(10)
    r[0], r[5] = 1 - 2.0 ** -30, 2.0 ** -10
    pr = _prove_local(_local(np.eye(10), q, [0.0, 0.0], [0.0, 0.0]), r, 2)
    if pr.valid:
        assert pr.quantities["r"].abs_bound >= 2.0 ** -10, pr.quantities["r"]


def test_a_stored_unsymmetric_w_bounds_u_with_its_skew_part():
    """W = I + 1.5(e₀e₁ᵀ − e₁e₀ᵀ) as stored, q = 0: r* = 0, u* = 0. At r = e_N, u = W r has
    ‖u‖∞ = 1.5, the true error. Mutant L8 (no skew term) bounded it by 1.0."""
    W = np.eye(5)
    W[0, 1], W[1, 0] = 1.5, -1.5
    p = _local(W, np.zeros(5), [0.5], [0.5], like=np.eye(5)).stored_equations()
    pr = _prove_local(p, [1.0, 0, 0, 0, 0], 1)
    if pr.valid:
        assert pr.quantities["u"].abs_bound >= 1.5, pr.quantities["u"]


def test_the_stored_equations_sentence_uses_the_stored_data_scale():
    """M = [[1, 3], [−3, 1]], f = (−1, 5e-4): for M as stored, v* = (0, 5e-4) and ‖M⁻¹f‖∞ = 0.30,
    so at v = (0, 2.5e-4) the stored companion may call v zero only within 1e-3 of 0.30. Mutant P1
    (the symmetrised data scales, 1.0) said '3.3 digits of ‖M⁻¹f‖∞'."""
    H = np.zeros((2, 5))
    H[0, 0] = 1.0
    M = np.array([[1.0, 3.0], [-3.0, 1.0]])
    f = np.array([-1.0, 5e-4])
    p = _problem(M, H, f, 0.5, 0.25, max_asymmetry=10.0)
    cert = _certify_at(p, [0.0, 2.5e-4], [1 + 3 * 5e-4, 0, 0, 0, 0], 3)
    st = cert.stored_equations
    if st is not None and st.valid:
        scale = float(np.max(np.abs(np.linalg.solve(M, f))))
        assert st.quantities["v"].data_scale <= scale * (1 + 1e-12), (st.quantities["v"], scale)


def test_stored_unsymmetric_m_bound_on_r_covers_its_true_error():
    """The same stored M = [[1, 1], [−1, 1]] with a frictionless contact (r unique, one column):
    at v = (½, ½), r = e_N the true error of r is 1; the proof's bound is 1.41. Mutant R5 (no skew
    term in the r bound) gave 0.707."""
    H = np.zeros((2, 5))
    H[0, 0] = 1.0
    p = _problem([[1.0, 1.0], [-1.0, 1.0]], H, [0, 0], 0.0, 0.0, max_asymmetry=10.0)
    cert = _certify_at(p, [0.5, 0.5], [1, 0, 0, 0, 0], 1, as_stored=True)
    q = cert.quantities["r"]
    assert cert.proof.valid and q.mode != "information", (q, cert.verdict)
    assert q.abs_bound >= 1.0, q


# ------------------------------------------------------- from the mutation audit's follow-up
# Six more mutants (the v and u data scales without the float solve's error, the free-block
# solve's residual term, a face's wᵀy ≤ 0 and rolling-cone checks, the local dual-shift term),
# each shown to print a false claim on the input of its test; each test fails on its mutant.

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
