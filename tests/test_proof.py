"""The rigorous error bound (rfverify.proof): exact arithmetic, verified bounds on M, and the
claim itself — every proven bound must be at least the true error, measured against an
independent 60-digit reference.  A false certificate is the worst bug this project can have,
so the mutation tests at the end check that these tests catch a wrong bound."""

from __future__ import annotations

import math
from fractions import Fraction

import mpmath
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

import reference
import rfverify
from rfverify.proof import FLOAT64_DIGITS, Point, ProofContext, bound as B
from rfverify.proof.dyadic import Dyadic, DyadicCSR
from rfverify.proof.massbounds import verify_lambda_min_sparse, verify_mass_matrix
from rfverify.scenes.random_problems import random_problem

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


# ---------------------------------------------------------------------- exact arithmetic
@given(st.lists(finite, min_size=1, max_size=20), st.lists(finite, min_size=1, max_size=20))
@example([5e-324, -1e308, 0.0], [1.0])
@example([2.2250738585e-313], [2.2250738585072014e-308])  # −2^-1022 + tiny: ldexp rounded up to DBL_MIN
def test_dyadic_is_exact_and_directed_rounding_encloses(a, b):
    da = Dyadic.from_float(np.array(a))
    assert all(da.fraction(i) == Fraction(x) for i, x in enumerate(a))
    n = min(len(a), len(b))
    prod = Dyadic.from_float(np.array(a[:n])) * Dyadic.from_float(np.array(b[:n]))
    s = prod - Dyadic.from_float(np.array(b[:n]))
    for i in range(n):
        exact = Fraction(a[i]) * Fraction(b[i]) - Fraction(b[i])
        assert s.fraction(i) == exact
        lo, hi = s.lower()[i], s.upper()[i]
        assert Fraction(lo) <= exact if math.isfinite(lo) else lo == -math.inf
        assert exact <= Fraction(hi) if math.isfinite(hi) else hi == math.inf
        up = s.abs_upper()[i]
        assert up == math.inf or Fraction(up) >= abs(exact)


@given(st.integers(1, 8), st.integers(1, 8), st.integers(0, 2**31))
def test_sparse_matvec_and_transpose_are_exact(rows, cols, seed):
    rng = np.random.default_rng(seed)
    A = sp.random(rows, cols, density=0.6, random_state=seed, format="csr")
    A.data = rng.normal(size=A.nnz) * 10.0 ** rng.integers(-30, 30, A.nnz)
    hi = rng.normal(size=cols)
    lo = hi * 2.0 ** -60 * rng.normal(size=cols)
    x = Dyadic.from_dd(hi, lo)
    D = DyadicCSR.from_scipy(A)
    y = D.matvec(x)
    dense = A.toarray()
    for i in range(rows):
        exact = sum(Fraction(dense[i, j]) * (Fraction(hi[j]) + Fraction(lo[j])) for j in range(cols))
        assert y.fraction(i) == exact
    z = D.transpose().matvec(Dyadic.from_float(np.ones(rows)))
    for j in range(cols):
        assert z.fraction(j) == sum(Fraction(dense[i, j]) for i in range(rows))


def test_from_mpf_keeps_the_sign():
    ctx = reference.jordan.context(40)
    d = Dyadic.from_mpf([ctx.mpf(-3) / 7, ctx.mpf(2) ** -80])
    assert d.fraction(0) < 0 and d.fraction(1) == Fraction(1, 2**80)


# ---------------------------------------------------------------------- verified bounds on M
def _spd_block(rng, s, cond):
    Q, _ = np.linalg.qr(rng.normal(size=(s, s)))
    lam = np.logspace(0, -np.log10(cond), s) * 10.0 ** rng.uniform(-8, 8)
    A = (Q * lam) @ Q.T
    return (A + A.T) / 2


@settings(max_examples=40)
@given(st.integers(0, 2**31), st.sampled_from([1, 3, 6, 12]), st.sampled_from([1.0, 1e3, 1e8, 1e12]))
@example(0, 6, 1e12)
def test_mass_bounds_enclose_the_exact_values(seed, s, cond):
    rng = np.random.default_rng(seed)
    blocks = [_spd_block(rng, s, cond) for _ in range(3)]
    M = sp.block_diag(blocks, format="csc")
    mb = verify_mass_matrix(M)
    assume(mb.proven)  # cond 1e12 may be beyond what double precision can prove; never wrong
    H = sp.random(M.shape[0], 4, density=0.7, random_state=seed, format="csc")
    W = mb.quad_upper_columns(H)
    with mpmath.workdps(60):
        for b, A in enumerate(blocks):
            Am = mpmath.matrix(A.tolist())
            ev = min(mpmath.eigsy(Am, eigvals_only=True))
            assert mb.lam_lower[b] <= ev
            Ainv = Am ** -1
            for j in range(s):
                assert mb.minv_diag_upper[b * s + j] >= Ainv[j, j]
        Minv = mpmath.matrix(M.toarray().tolist()) ** -1
        Hd = H.toarray()
        for k in range(H.shape[1]):
            h = mpmath.matrix(Hd[:, k].tolist())
            assert W[k] >= (h.T * Minv * h)[0]
        assert mb.lam_max_upper >= max(max(mpmath.eigsy(mpmath.matrix(A.tolist()), eigvals_only=True))
                                       for A in blocks)


def test_indefinite_block_is_not_proven():
    A = np.diag([1.0, 2.0, -1e-9])
    mb = verify_mass_matrix(sp.csc_matrix(A))
    assert not mb.proven and "not positive definite" in mb.failures[0].reason


def test_sparse_lambda_bound_encloses_and_refuses_singular():
    A = sp.random(200, 200, density=0.02, random_state=3)
    S = (A @ A.T + 1e-3 * sp.identity(200)).tocsc()
    lam, why = verify_lambda_min_sparse(S, abs(S) * 2.0 ** -52)
    assert not why and 0 < lam <= np.linalg.eigvalsh(S.toarray()).min()
    lam, why = verify_lambda_min_sparse((A @ A.T).tocsc(), abs(A @ A.T) * 2.0 ** -52)
    assert why and math.isnan(lam)


# ---------------------------------------------------------------------- the claim against the truth
_TRUTH = {}


def _truth(problem, key):
    """(v*, u*, r*, unique r?) from the independent reference at 60 digits, as mpf lists.  For a
    local file the reference solves the file's own W exactly (:func:`local_as_global`), never
    the solver's lifting."""
    if key not in _TRUTH:
        target = local_as_global(problem) if problem.local is not None else problem
        ref = reference.solve(target, dps=60, tol=1e-50)
        assert ref.success, ref.message
        _TRUTH[key] = ref
    return _TRUTH[key]


def local_as_global(problem):
    """u = W r + q as the global problem M = W_FF, H = W_F: (F: nonzero diagonal), f = 0, w = q:
    then v = r_F and u = Hᵀv + w = W r + q with no factorisation of W (needs W_FF ≻ 0 and
    W exactly symmetric, as the tests generate it)."""
    import types

    W = sp.csr_matrix(problem.local.W)
    assert (W != W.T).nnz == 0
    F = np.flatnonzero(W.diagonal() != 0)
    return types.SimpleNamespace(M_sym=W[F][:, F].tocsc(), H=W[F].tocsc(), f=np.zeros(F.size),
                                 w=np.asarray(problem.local.q), mu=problem.mu, mu_r=problem.mu_r)


def _true_errors(problem, ref, v, u, r):
    """max |x − x*| and max |x*| for v, u, Hr and r (80-digit arithmetic on the mpf data); for a
    local problem u and r only (its v and H are the solver's lifting, not the file's)."""
    out, norms = {}, {}
    with mpmath.workdps(80):
        if problem.local is not None:
            for name, x in (("u", u), ("r", r)):
                out[name] = max(abs(mpmath.mpf(float(a)) - b) for a, b in zip(x, getattr(ref, name)))
                norms[name] = max(abs(b) for b in getattr(ref, name))
            return out, norms
        for name, x in (("v", v), ("u", u), ("r", r)):
            out[name] = max(abs(mpmath.mpf(float(a)) - b) for a, b in zip(x, getattr(ref, name)))
            norms[name] = max(abs(b) for b in getattr(ref, name))
        H = problem.H.tocoo()
        Hr = [mpmath.mpf(0)] * problem.n_dofs
        Hr_ref = [mpmath.mpf(0)] * problem.n_dofs
        for i, j, x in zip(H.row, H.col, H.data):
            Hr[i] += mpmath.mpf(float(x)) * mpmath.mpf(float(r[j]))
            Hr_ref[i] += mpmath.mpf(float(x)) * ref.r[j]
        out["Hr"] = max(abs(a - b) for a, b in zip(Hr, Hr_ref))
        norms["Hr"] = max(abs(b) for b in Hr_ref)
    return out, norms


def assert_sound(problem, key, cert, v, u, r):
    """Every proven bound is ≥ the true error (r only where the proof says it is unique)."""
    errs, norms = _true_errors(problem, _truth(problem, key), v, u, r)
    proof = cert.proof
    assert proof is not None and proof.valid, cert.verdict
    for name, q in proof.quantities.items():
        if q.mode == "information":
            continue
        assert errs[name] <= q.abs_bound, (name, float(errs[name]), q.abs_bound)
        # the scale is a lower bound of ‖x*‖∞, so the digits are a lower bound of the true ones
        assert q.own_scale <= norms[name]
        if q.digits is not None and errs[name] > 0:
            assert q.digits <= -math.log10(float(errs[name] / norms[name])) + 1e-9
    return errs


SMALL = {
    "chute": lambda: rfverify.load("bundled:chute"),
    "sphere": lambda: rfverify.load("bundled:sphere"),
    "local-diag": lambda: _local_problem(np.diag([1.0, 1.0, 1e-6, 1.0, 1.0]), [-1.0, 0, 1e-3, 0, 0], 0.5, 0.1),
    "random-mixed": lambda: random_problem(6, 9, seed=11, mu_zero_fraction=0.2, mu_r_zero_fraction=0.3),
    "random-massratio": lambda: random_problem(5, 7, seed=4, mass_ratio=1e6),
}


@pytest.fixture(scope="module", params=sorted(SMALL))
def digits_case(request):
    problem = SMALL[request.param]()
    return request.param, problem, rfverify.solve_to_digits(problem, digits=10)


def test_ten_digit_path_is_proven_and_true(digits_case):
    key, problem, out = digits_case
    assert out.success, out.certificate.verdict
    errs = assert_sound(problem, key, out.certificate, out.v, out.u, out.r)
    # Independently of the proof: the returned v really has ≥ 10 digits.
    _, norms = _true_errors(problem, _truth(problem, key), out.v, out.u, out.r)
    for name, q in out.certificate.quantities.items():
        if q.mode == "relative":  # ≥ 10 correct significant digits, measured
            assert float(errs[name]) <= 1e-10 * float(norms[name]), name
        elif q.mode == "absolute":  # zero within 1e-10 of its data scale, measured
            assert float(norms[name]) + float(errs[name]) <= 1e-10 * q.data_scale * (1 + 1e-12), name


def test_double_solution_bound_is_true_and_not_too_pessimistic(digits_case):
    """The bound carried to the double solution: sound, and at most 100 × its true error plus
    the point's own bound (when the double solution is worse than the point, the distance
    between them dominates and the bound is nearly the truth)."""
    key, problem, out = digits_case
    res = rfverify.solve(problem, tol=1e-10)
    cert = rfverify.certify(problem, res, digits=5, point=out.point)
    errs = assert_sound(problem, key, cert, res.v, res.u, res.r)
    which = "u" if problem.local is not None else "v"
    q = cert.quantities[which]
    assert q.abs_bound <= 100 * float(errs[which]) + 1.01 * out.certificate.quantities[which].abs_bound


@pytest.mark.parametrize("which", ["v", "u", "r"])
@pytest.mark.parametrize("digit", [9, 10, 11])
def test_perturbation_at_a_digit_is_never_overclaimed(which, digit):
    """Change the given digit of the largest entries of a proven 10-digit solution: the claim
    tracks the truth — a 9th-digit change is never certified at 10, and whatever is claimed is
    at most the true error."""
    key, problem = "chute", rfverify.load("bundled:chute")
    out = _digits_once(key, problem)
    x = {"v": out.v.copy(), "u": out.u.copy(), "r": out.r.copy()}
    big = np.abs(x[which]) >= 0.5 * np.abs(x[which]).max()
    x[which] = np.where(big, x[which] * (1 + 3 * 10.0 ** (-digit)), x[which])
    cert = rfverify.certify(problem, x["v"], x["u"], x["r"], digits=10, point=out.point)
    assert_sound(problem, key, cert, x["v"], x["u"], x["r"])
    if digit == 9:
        assert not cert.certified, cert.verdict
        assert cert.quantities[which if which != "r" else "r"].digits < 10


_DIGITS = {}


def _digits_once(key, problem):
    if key not in _DIGITS:
        _DIGITS[key] = rfverify.solve_to_digits(problem, digits=10)
    return _DIGITS[key]


def test_solution_of_a_similar_problem_is_refused():
    """A 10-digit solution of the Chute problem with f changed in the 8th digit, and its own
    extended point: for the original problem the bound sees the changed dynamics."""
    problem = rfverify.load("bundled:chute")
    other = rfverify.Problem.from_arrays(problem.M, problem.H, problem.f * (1 + 1e-8), problem.w, problem.mu,
                                         problem.mu_r)
    out = rfverify.solve_to_digits(other, digits=10)
    assert out.success
    cert = rfverify.certify(problem, out.v, out.u, out.r, digits=10, point=out.point)
    assert not cert.certified, cert.verdict
    cert_own = rfverify.certify(problem, out.v, out.u, out.r, digits=7)
    assert_sound(problem, "chute", cert_own, out.v, out.u, out.r)


def _local_problem(W, q, mu, mu_r):
    """A local problem (W 5n × 5n, q) read as rfverify reads a full-precision local file."""
    from rfverify.io.local_lift import LocalProblem, lift_local
    from rfverify.model.problem import make_local_form
    import dataclasses

    n = len(np.atleast_1d(mu))
    data = LocalProblem(W=np.asarray(W, dtype=float), q=np.asarray(q, dtype=float), mu=np.full(n, mu, dtype=float),
                        mu_r=np.full(n, mu_r, dtype=float))
    lifted, _ = lift_local(data)
    return dataclasses.replace(lifted, local=make_local_form(data.W, data.q))


def test_point_outside_the_cones_proves_nothing():
    problem = rfverify.load("bundled:sphere")
    out = _digits_once("sphere", problem)
    bad = Point(out.point.v_hi, out.point.v_lo, -np.abs(out.point.r_hi), out.point.r_lo)
    cert = rfverify.certify(problem, out, digits=3, point=bad)
    assert not cert.certified and not cert.proof.valid and "r ∉ K" in cert.verdict


# ---------------------------------------------------------------------- vanishing scales
def test_zero_quantities_are_judged_absolutely_never_zero_or_inf_digits():
    """All contacts sticking (bundled sphere: u* = 0) and all open (r* = 0): a correct answer
    is certified with its absolute bound against a stated data scale."""
    sphere = rfverify.load("bundled:sphere")
    out = _digits_once("sphere", sphere)
    q = out.certificate.quantities["u"]
    assert out.success and q.mode == "absolute" and q.certified and q.abs_bound < 1e-9 * q.data_scale
    for qq in out.certificate.quantities.values():
        assert qq.digits is None or (0 < qq.digits <= FLOAT64_DIGITS)
    allopen = _all_open_problem()
    out2 = rfverify.solve_to_digits(allopen, digits=10)
    r = out2.certificate.quantities["r"]
    assert out2.success, out2.certificate.verdict
    assert r.mode == "absolute" and r.abs_bound <= 1e-10 * r.data_scale


def _all_open_problem():
    """Two bodies, contacts whose w separates strongly: r* = 0, v* = M⁻¹f."""
    base = random_problem(3, 4, seed=2)
    w = base.w.copy()
    w[0::5] = 10.0  # u_N ≥ 10 far beyond μ‖u_T‖ + μr‖u_R‖ for moderate v
    return rfverify.Problem.from_arrays(base.M, base.H, base.f * 1e-3, w, base.mu, base.mu_r)


# ---------------------------------------------------------------------- digits arguments
@pytest.mark.parametrize("bad", [0, -5, 2.5, 16, 18, "10", True])
def test_digit_requests_beyond_float64_or_malformed_are_refused(bad):
    problem = rfverify.load("bundled:sphere")
    with pytest.raises(rfverify.InvalidArgumentError):
        rfverify.certify(problem, np.zeros(problem.n_dofs), None, np.zeros(5 * problem.n_contacts), digits=bad)
    with pytest.raises(rfverify.InvalidArgumentError):
        rfverify.solve_to_digits(problem, digits=bad)


# ---------------------------------------------------------------------- mutations must be caught
def _all_open_offset_point(j_select="min"):
    """AllOpen-style problem with diagonal M: the point (v* + δ, r = 0) with δ = t·M⁻¹e_j has
    rᵀu = 0 and g = Mδ = t·e_j, so the bound is exactly tight for component j."""
    problem = _all_open_problem()
    Mi = np.linalg.inv(problem.M_sym.toarray())
    v_star = Mi @ problem.f
    j = int(np.argmin(np.diag(problem.M_sym.toarray())))
    delta = 1e-6 * Mi[:, j]
    v = v_star + delta
    u = (problem.H.T @ v + problem.w).reshape(-1, 5)
    assert np.all(u[:, 0] > 1.01 * (problem.mu * np.hypot(u[:, 1], u[:, 2]) + problem.mu_r * np.hypot(u[:, 3], u[:, 4])))
    point = Point(v, np.zeros_like(v), np.zeros(5 * problem.n_contacts), np.zeros(5 * problem.n_contacts))
    return problem, point, v, v_star, j


def _violated(problem, point, v, v_star):
    u = problem.H.T @ v + problem.w
    cert = rfverify.certify(problem, v, u, np.zeros(5 * problem.n_contacts), digits=1, point=point)
    if not cert.proof.valid:
        return False
    err = np.max(np.abs(v - v_star))
    return cert.quantities["v"].abs_bound < err * (1 - 1e-6)


def test_the_tight_case_is_sound_unmutated():
    problem, point, v, v_star, _ = _all_open_offset_point()
    assert not _violated(problem, point, v, v_star)


def test_mutation_dropping_gMinvg_is_caught(monkeypatch):
    problem, point, v, v_star, _ = _all_open_offset_point()
    monkeypatch.setattr(B, "gMinvg_upper", lambda g, mass: 0.0)
    assert _violated(problem, point, v, v_star)


def test_mutation_overestimating_lambda_min_is_caught(monkeypatch):
    problem, point, v, v_star, _ = _all_open_offset_point()
    real = B.gMinvg_upper

    def inflated(g, mass):  # λmin of the equilibrated blocks, which the bound divides by
        mass.lam_scaled = mass.lam_scaled * 100
        try:
            return real(g, mass)
        finally:
            mass.lam_scaled = mass.lam_scaled / 100

    monkeypatch.setattr(B, "gMinvg_upper", inflated)
    assert _violated(problem, point, v, v_star)


def test_mutation_wrong_cone_is_caught(monkeypatch):
    """Testing r against K* instead of K: r in K* but not in K can make rᵀu negative, and the bound
    then undercuts the true error.  One body, M = I, u = v + w with w deep inside K* (so
    v* = 0, r* = 0); the point v = δ = (d, 0, 0, 0, 0), r = t·(1, −1.5, 0, 0, 0) with t chosen
    so that 2rᵀu = −1.2‖δ‖²: the proof's q_g ≤ ‖g‖²/λ_lower with λ_lower = λmin/2 (= ½ here)
    is 2‖δ‖², so ε² ≈ 0.8‖δ‖² — below the true ‖v − v*‖² = ‖δ‖²."""
    mu = np.array([0.5])
    problem = rfverify.Problem.from_arrays(sp.identity(5, format="csc"), sp.identity(5, format="csc"),
                                           np.zeros(5), np.array([10.0, 10.0, 0, 0, 0]), mu, mu)
    d = 1e-3
    v = np.array([d, 0, 0, 0, 0])
    r0 = np.array([1.0, -1.5, 0, 0, 0])
    u = v + problem.w
    t = 1.2 * d * d / (-2 * float(r0 @ u))  # 2rᵀu = −1.2 d²
    r = t * r0
    point = Point(v, np.zeros(5), r, np.zeros(5))
    cert = rfverify.certify(problem, v, u, r, digits=1, point=point)
    assert not cert.proof.valid and "r ∉ K" in cert.verdict  # the real test refuses the point
    monkeypatch.setattr(B, "cone_violations", lambda data, u_, r_: (_kstar_violations(data, u_),
                                                                      _kstar_violations(data, r_)))
    cert = rfverify.certify(problem, v, u, r, digits=1, point=point)
    assert cert.proof.valid and cert.quantities["v"].abs_bound < d  # the mutation certifies a false bound


def _kstar_violations(data, x):
    """Contacts where x ∉ K* (u_N ≥ μ‖u_T‖ + μr‖u_R‖), exactly (squares only)."""
    n = data.problem.n_contacts
    idx = np.arange(n) * 5
    N, T1, T2, R1, R2 = (x[idx + k] for k in range(5))
    a = data.mu.square() * (T1.square() + T2.square())
    b = data.mu_r.square() * (R1.square() + R2.square())
    c = N.square() - a - b
    bad = (N.sign() < 0) | (c.sign() < 0) | ((c.square() - (a * b).scale2(2)).sign() < 0)
    return np.flatnonzero(bad)
