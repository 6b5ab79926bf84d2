"""Claims of the self-stress search, the face move, the mass matrix's definiteness bound and the
certificates guarded where a mutation audit (2026-12-07) found them unguarded: each input is
tiny with its truth known in closed form (an exactly feasible velocity, an exact v* over Q, an
exact power-of-two scaling), and each test fails on the audit's mutant named in its docstring,
which prints a false claim on that input."""

from __future__ import annotations

from fractions import Fraction

import h5py
import numpy as np

import rfverify
from rfverify.cli import main
from rfverify.proof import Point, ProofContext, face
from rfverify.proof.dyadic import Dyadic, Quotient

KIND_STUCK = face.KINDS["stuck"]  # "u = 0 (no relative motion)"


def _in_K(y5, mu: Fraction, mur: Fraction) -> bool:
    """y ∈ K exactly: y_N ≥ 0, ‖y_T‖ ≤ μ y_N, ‖y_R‖ ≤ μr y_N."""
    yN = y5[0]
    return (yN >= 0 and y5[1] ** 2 + y5[2] ** 2 <= mu * mu * yN * yN
            and y5[3] ** 2 + y5[4] ** 2 <= mur * mur * yN * yN)


def _rolling_lever(w, mur, f=(0.0, 0.0, 0.0, 0.0)):
    """Four dofs, one contact: u_N = v₀ + w_N, u_T = (v₁, v₂), u_R = (−v₀ + w_R1, v₃) (the
    rolling column R1 is minus the normal one), so y = (c, 0, 0, c, 0) has Hy = 0 and
    wᵀy = c (w_N + w_R1)."""
    H = np.zeros((4, 5))
    H[0, 0], H[1, 1], H[2, 2], H[0, 3], H[3, 4] = 1.0, 1.0, 1.0, -1.0, 1.0
    p = rfverify.Problem.from_arrays(np.eye(4), H, np.asarray(f, dtype=float), np.asarray(w, dtype=float),
                                     np.array([0.5]), np.array([mur]))
    return p, H


def _check_stress_exactly(p, s):
    """What a reported self-stress asserts, re-checked in exact arithmetic from the data."""
    cols = (5 * s.contacts[:, None] + np.arange(5)).ravel()
    y = list(s.y)
    Hq = [[Fraction(float(x)) for x in row] for row in p.H.toarray()[:, cols]]
    assert all(sum((h * yk for h, yk in zip(row, y)), Fraction(0)) == 0 for row in Hq)
    for i, c in enumerate(s.contacts):
        assert _in_K(y[5 * i:5 * i + 5], Fraction(float(p.mu[c])), Fraction(float(p.mu_r[c]))), (c, y)
    assert s.w_dot_y == sum((Fraction(float(wk)) * yk for wk, yk in zip(p.w[cols], y)), Fraction(0))


# ------------------------------------------------------------------------------- face.py
def test_a_stress_outside_the_rolling_cone_is_not_a_self_stress():
    """Catches F3 (face.py _exact_stress: the exact y ∈ K check without ``yR2 > μr² yN²``).

    μr = 1 − 1e-9, w = (−1, 0, 0, 0, 0): y = (c, 0, 0, c, 0) has Hy = 0 and wᵀy = −c < 0 but
    ‖y_R‖ = c > μr·c, so y ∉ K.  Truth: v = (1/(1 − μr), 0, 0, 0) (μr the float, exactly) gives
    u = (v₀ − 1, 0, 0, −v₀, 0) with u_N − μr|u_R| = 0: a feasible velocity exists, so no y ∈ K
    with Hy = 0 has wᵀy < 0.  Original: no stress found.  Mutant: 'contact 0 … forces y ∈ K
    with Hy = 0 and wᵀy < 0 …: the problem has no solution' with that y (wᵀy = −0.999…)."""
    mur = 1 - 1e-9
    p, _ = _rolling_lever([-1.0, 0, 0, 0, 0], mur)
    m = Fraction(mur)
    v0 = 1 / (1 - m)
    u = [v0 - 1, Fraction(0), Fraction(0), -v0, Fraction(0)]
    assert u[0] >= Fraction(1, 2) * abs(u[1]) + m * abs(u[3]) and u[0] == m * abs(u[3])  # u ∈ K* exactly
    stresses = face.find_self_stress(p, [0])
    for s in stresses:
        _check_stress_exactly(p, s)
        assert not s.infeasible and s.w_dot_y >= 0, s.describe()
        assert "no solution" not in s.describe()


def test_w_dot_y_is_summed_over_every_component():
    """Catches F6 (face.py _exact_stress: wᵀy summed over every 5th component only, i.e. the
    normals: ``zip(problem.w[cols][::5], y[::5])``).

    μr = 1, w = (−1, 0, 0, 1, 0): y = (c, 0, 0, c, 0) is a self-stress on the rolling cone's
    boundary (Hy = 0, ‖y_R‖ = μr y_N) with wᵀy = −c + c = 0 exactly.  Truth: v = (1, 0, 0, 0)
    gives u = 0 ∈ K*, so the problem is feasible and every self-stress has wᵀy = 0.  Original:
    that stress, 'rolling', wᵀy = 0.  Mutant: wᵀy = −c (the normal part alone) and 'no velocity
    satisfies Hᵀv + w ∈ K*, so the problem has no solution'."""
    p, H = _rolling_lever([-1.0, 0, 0, 1.0, 0], 1.0, f=[1.0, 0, 0, 0])
    assert not np.any(H.T @ np.array([1.0, 0, 0, 0]) + p.w)  # u(e₀) = 0 exactly (a feasible velocity)
    stresses = face.find_self_stress(p, [0])
    assert stresses  # y = (c, 0, 0, c, 0) is one
    for s in stresses:
        _check_stress_exactly(p, s)
        assert s.w_dot_y == 0 and not s.infeasible, s.describe()


def test_a_stress_on_the_friction_cone_boundary_does_not_force_u_to_zero():
    """Catches F8 (face.py _exact_stress: ``strict_T`` with ``yT2 <= μ² yN²``, so a y_i exactly on
    the friction cone's boundary counts as strictly inside and the contact is called 'stuck').

    μ = 1; tan(θ/2) = n/m with m = 2³² + 15, n = 2³¹ (a denominator beyond every snap denominator),
    y₀ = (m² + n², m² − n², 2mn, 0, 0): ‖y_T‖ = y_N exactly.  H's two rows (exact floats) are
    orthogonal to y₀, so null(H) = span(y₀) on the N, T part.  Truth: v = (v₀, v₁) solving the
    first two columns exactly gives u = (m² + n², −(m² − n²), −2mn, 0, 0) ≠ 0, on the edge of K*:
    a feasible velocity with u ≠ 0 at contact 0, so 'u = 0 at 0' is false.  Original: kind 'face'.
    Mutant: kind 'stuck': 'every admissible one has u = 0 (no relative motion) at 0'."""
    m, n = 2 ** 32 + 15, 2 ** 31
    a, b, c = m * m - n * n, 2 * m * n, m * m + n * n
    s = 2.0 ** -32
    H = np.zeros((4, 5))
    H[0, :3] = np.array([-n, -n, m]) * s
    H[1, :3] = np.array([-m, m, n]) * s
    H[2, 3] = H[3, 4] = 1.0
    p = rfverify.Problem.from_arrays(np.eye(4), H, np.array([1.0, 1.0, 0, 0]), np.zeros(5), np.array([1.0]),
                                     np.array([0.5]))
    Hq = [[Fraction(float(x)) for x in row] for row in H]
    assert all(sum(h * y for h, y in zip(row, [c, a, b, 0, 0])) == 0 for row in Hq)
    A = [[Hq[0][0], Hq[1][0]], [Hq[0][1], Hq[1][1]]]
    rhs = [Fraction(c), Fraction(-a)]
    det = A[0][0] * A[1][1] - A[0][1] * A[1][0]
    v0 = (rhs[0] * A[1][1] - A[0][1] * rhs[1]) / det
    v1 = (A[0][0] * rhs[1] - A[1][0] * rhs[0]) / det
    u = [Hq[0][j] * v0 + Hq[1][j] * v1 for j in range(3)]
    assert u == [c, -a, -b] and u[0] ** 2 == u[1] ** 2 + u[2] ** 2 and u[0] > 0  # u ∈ ∂K*, u ≠ 0
    stresses = face.find_self_stress(p, [0])
    assert stresses  # y₀ is one
    for st in stresses:
        _check_stress_exactly(p, st)
        assert list(st.contacts) == [0]
        assert st.kinds[0] != "stuck", st.describe()
        assert KIND_STUCK not in st.describe()



# ------------------------------------------------------------------------------- dyadic.py
def test_the_move_onto_a_face_reports_a_bound_of_its_size():
    """Catches D10 (dyadic.py Quotient.abs_upper: ``self.upper()`` for max(upper, −lower), so a
    negative entry's |x| is bounded by a negative number).

    Exact: Quotient(−1/3).abs_upper() ≥ 1/3.  On the corner problem (a sphere wedged in a μ = 1
    corner, tests/corner_problems.py), a v sliding along x (v₀ = 1e-3) is moved onto the face:
    v′ − v = (−1e-3, 3.7e-20, 3.7e-20, 0, …) (v₀ → 0 exactly: max|v′ − v| is the double 1e-3).
    Original: 'v changed by at most 1.0e-03'.  Mutant: 'at most 3.7e-20' (the negative entry's
    bound is negative)."""
    from corner_problems import corner_problem

    p = corner_problem(0)
    stresses = face.find_self_stress(p, [0, 1])
    assert stresses
    v = np.zeros(p.n_dofs)
    v[1] = v[2] = 0.1
    v[0] = 1e-3
    rep = face.restore(p, None, Dyadic.from_float(v), stresses)
    assert rep is not None
    true_moved = max(abs(a - Fraction(b)) for a, b in zip(rep.point_v.fractions(), v))
    assert true_moved > 0
    assert Fraction(rep.moved) >= true_moved, (rep.moved, float(true_moved))
    # the bound itself, on a negative entry: |−1/3| ≤ abs_upper
    q = Quotient.from_fractions([Fraction(-1, 3), Fraction(2, 3)])
    assert q.den == 3
    assert all(Fraction(float(b)) >= abs(x) for b, x in zip(q.abs_upper(), q.fractions()))


# ------------------------------------------------------------------------------- definiteness.py
def _exact_solve(A, b):
    """x with A x = b over Q (Gauss-Jordan, A nonsingular)."""
    m = len(b)
    T = [row[:] + [x] for row, x in zip(A, b)]
    for c in range(m):
        piv = next(i for i in range(c, m) if T[i][c])
        T[c], T[piv] = T[piv], T[c]
        T[c] = [x / T[c][c] for x in T[c]]
        for i in range(m):
            if i != c and T[i][c]:
                T[i] = [x - T[i][c] * y for x, y in zip(T[i], T[c])]
    return [T[i][m] for i in range(m)]


def test_an_ill_conditioned_mass_matrix_bound_covers_the_true_error():
    """Catches M5 (definiteness.py: ``frob = n`` for n + Σ (n − k) 4^(k−1), the bound of
    ‖L⁻¹‖²_F of a unit triangular factor with entries ≤ 1, so λmin(M) is overestimated).

    M = L D Lᵀ (floats, symmetric) with L = I − 0.9·(strictly lower ones), D = diag(10^−k),
    n = 14: SPD with λmin ≈ 9.5e-18.  One contact far away (w_N = 1e6) is never active, so
    v* = M⁻¹f exactly (over Q; u*_N = v*₀ + 1e6 > 0, r* = 0).  The point is v* moved 1000 along
    L⁻ᵀe_n (M L⁻ᵀe_n ≈ 1e-13 e_n: a tiny residual).  Exact true error |v − v*|∞ = 1000.
    Original: bound 4.2e4 (≥ 1000).  Mutant: a valid proof with bound 0.91."""
    n = 14
    L = np.eye(n) + np.tril(-0.9 * np.ones((n, n)), -1)
    A = L @ np.diag(0.1 ** np.arange(n)) @ L.T
    M = (A + A.T) / 2
    H = np.zeros((n, 5))
    H[0, 0] = 1.0
    w = np.zeros(5)
    w[0] = 1e6
    f = M @ np.ones(n)
    p = rfverify.Problem.from_arrays(M, H, f, w, np.array([0.5]), np.array([0.25]))
    vstar = _exact_solve([[Fraction(x) for x in row] for row in M], [Fraction(x) for x in f])
    assert vstar[0] + 10 ** 6 > 0  # the contact is open at v*: v* = M⁻¹f is the solution
    x = np.linalg.solve(L.T, np.eye(n)[-1])
    v = np.array([float(t) for t in vstar]) + 1e3 * x / np.max(np.abs(x))
    truth = max(abs(Fraction(t) - s) for t, s in zip(v, vstar))
    assert truth >= 999
    z = np.zeros(5)
    pr = ProofContext(p).prove(Point(v, 0 * v, z, z), v, H.T @ v + w, z, requested=6)
    assert pr.valid  # the point is feasible (the contact stays open): the proof must speak
    assert Fraction(pr.quantities["v"].abs_bound) >= truth, (pr.quantities["v"], float(truth))


# ------------------------------------------------------------------------------- io/certificate.py
def test_a_certificate_moved_to_a_local_file_with_another_q_is_about_another_problem(tmp_path, capsys):
    """Catches C5 (io/certificate.py problem_digest without ``vector("q", problem.local.q)``: two
    local files differing only in q get the same digest).

    W = I (one contact, 3-D), μ = 0.5.  a: q = (−1, 0, 0), r* = (1, 0, 0); b: q = (−2, 0, 0),
    r* = (2, 0, 0).  a is solved in place to 6 digits and its /solution and /certificate are
    copied into b: the stored claim is about a, and for b the stored r is off by exactly 1.
    Original: 'about ANOTHER problem'.  Mutant: 'about this problem and this /solution (both
    digests match); it claimed: proven to 6 digits'."""
    from test_fclib3d import write_local

    from rfverify.io.certificate import problem_digest, read_stored_certificate

    W = np.eye(3)
    a = write_local(tmp_path / "a.hdf5", W, [-1.0, 0, 0], [0.5])
    b = write_local(tmp_path / "b.hdf5", W, [-2.0, 0, 0], [0.5])
    assert main(["solve", str(a), "--digits", "6", "--out", str(a), "--quiet"]) == 0
    capsys.readouterr()
    with h5py.File(a, "r") as src, h5py.File(b, "r+") as dst:
        for g in ("solution", "certificate"):
            src.copy(src[g], dst, name=g)
        r_stored = np.array(dst["solution"]["r"], dtype=float).ravel()
    assert abs(r_stored[0] - 1.0) < 1e-5  # a's r*; b's is 2: the stored claim is false for b
    main(["certify", str(b), "--digits", "6", "--quiet"])
    out = capsys.readouterr().out
    assert "about ANOTHER problem" in out and "both digests match" not in out, out
    pb = rfverify.load(b)
    assert problem_digest(rfverify.load(a)) != problem_digest(pb)  # they differ in q alone
    assert read_stored_certificate(b, pb)["matches_problem"] is False


# ------------------------------------------------------------------------------- verify/certificate.py
def test_bounds_proven_in_scaled_units_are_scaled_back():
    """Catches C15 (verify/certificate.py unscaled_proof: ``abs_bound=q.abs_bound``, the bound left
    in the scaled units of a problem solved and proven in units 2^-601 of its own).

    M = 1, one contact on that dof (μ = 0.5, μr = 0.25), f = 2^600, w = 0: v* = u*_N = 2^600
    (the contact opens), r* = 0.  At v = 2^600 (1 + 2^-20) the exact errors of v and u are
    2^580 ≈ 3.9e174.  Original: bounds 3.96e174, 'v 6.0 digits'.  Mutant: bounds 4.8e-7, and
    'Hr zero within 9.6e-07 (186.6 digits of ‖f‖∞)'."""
    k = 600
    H = np.zeros((1, 5))
    H[0, 0] = 1.0
    p = rfverify.Problem.from_arrays(np.eye(1), H, np.array([2.0 ** k]), np.zeros(5), np.array([0.5]),
                                     np.array([0.25]))
    v = np.array([2.0 ** k * (1 + 2.0 ** -20)])
    r = np.zeros(5)
    cert = rfverify.certify(p, v, H.T @ v, r, digits=3, point=Point(v, 0 * v, r, 0 * r))
    assert "scaled" in str(cert.extra.get("binary_scaling"))  # the path under guard
    truth = Fraction(2) ** (k - 20)  # |v − v*| = |u_N − u*_N| exactly
    for name in ("v", "u"):
        q = cert.quantities[name]
        assert Fraction(q.abs_bound) >= truth, (name, q.abs_bound)
        assert Fraction(cert.bounds[name]) >= truth, (name, cert.bounds[name])
        assert Fraction(q.norm) <= Fraction(v[0]) * 2 and Fraction(q.norm) >= Fraction(2) ** k / 2, (name, q.norm)
    hr = cert.quantities["Hr"]
    if hr.mode == "absolute" and hr.certified:  # 'zero within …' is measured against ‖f‖∞ = 2^600
        assert hr.data_scale >= 2.0 ** (k - 1) and hr.abs_bound >= 2.0 ** (k - 60), hr
