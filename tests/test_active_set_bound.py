"""The local proof's second, linear bound from the active set, and the long-double retry of the
verified λmin test (the two pieces that certify piles at rest: FCLIB's Boxes Stack).

Checks are independent of the library's proof: the exact solution of the small problems is
known in closed form, λmin is computed in 40-digit mpmath, and the bundled Boxes Stack answer is
rechecked against the file's own W and q in 40-digit arithmetic.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import io
import json
from pathlib import Path

import h5py
import mpmath
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import rfverify
from rfverify.model import definiteness as D
from rfverify.proof import Point
from rfverify.proof import local as L

BOXES = Path(__file__).parent / "data" / "fclib" / "local_problem_test.hdf5"
BOXES_SHA256 = "ee89f0978af4e17720ffdcbb542c43a517b2441b6de93af40814f38f926f67eb"


def _stuck_problem(scale: float):
    """W = scale·I (one contact, μ = 0.5, μr = 0.1), q = −scale·(1, −0.1, 0, 0, 0): the contact
    sticks with r* = (1, −0.1, 0, 0, 0) and u* = 0 exactly (scale a power of two: every product
    is exact)."""
    from rfverify.io.local_lift import LocalProblem, lift_local
    from rfverify.model.problem import make_local_form

    W = scale * np.eye(5)
    q = -scale * np.array([1.0, -0.1, 0, 0, 0])
    data = LocalProblem(W=W, q=q, mu=np.array([0.5]), mu_r=np.array([0.1]))
    lifted, _ = lift_local(data)
    return dataclasses.replace(lifted, local=make_local_form(W, q))


def _certify_near_solution(scale: float, offset_exp: int = -60):
    """The certificate of r_p = r* + 2^offset_exp e_N (a double-double point), whose exact
    u_p = W r_p + q = scale·2^offset_exp e_N ∈ K*: (certificate, true ‖u − u*‖∞)."""
    problem = _stuck_problem(scale)
    r_hi = np.array([1.0, -0.1, 0, 0, 0])
    r_lo = np.array([2.0 ** offset_exp, 0, 0, 0, 0])
    point = Point(problem.H @ r_hi, problem.H @ r_lo, r_hi, r_lo)
    u = np.array([scale * 2.0 ** offset_exp, 0, 0, 0, 0])  # exactly u_p, and u − u* = u
    cert = rfverify.certify(problem, point.v_hi, u, r_hi, digits=10, point=point)
    return cert, float(np.max(np.abs(u)))


def test_a_stuck_contact_is_bounded_linearly_in_its_velocity_not_by_a_square_root():
    """√(rᵀu) would bound ‖d‖_W by √(2⁻⁶²) ≈ 2e-10; the active-set bound gives ‖u_S‖/√λ: the
    true error (2⁻⁶² in u) within a factor 2 (λ is proven a little below 1/4)."""
    cert, true_u = _certify_near_solution(0.25)
    proof = cert.proof
    assert proof.valid and proof.terms.get("active_set_stuck") == 1, cert.verdict
    assert proof.terms["eps_W_first"] > 1e-11  # the square-root bound, for comparison
    bound = cert.quantities["u"].abs_bound
    assert true_u <= bound <= 2 * true_u, (bound, true_u)


def test_mutation_forgetting_lambda_in_the_active_set_bound_is_caught(monkeypatch):
    """‖d_S‖₂ ≤ ‖d‖_W/√λ: with √λ = 1/2 dropped, the bound on u would fall below the true error
    of the test above (a false claim it must see)."""
    real_sqrt = L.math.sqrt

    class NoLambda:
        def __getattr__(self, name):
            return getattr(L.math, name)

        @staticmethod
        def sqrt(x):
            return 1.0 if 0.2 < x < 0.26 else real_sqrt(x)  # √λ for λ ≈ 1/4 replaced by 1

    monkeypatch.setattr(L, "math", NoLambda())
    cert, true_u = _certify_near_solution(0.25)
    assert cert.quantities["u"].abs_bound < true_u  # what the real code never does


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 31), rank=st.integers(2, 16), shift_exp=st.integers(-56, -38))
@example(seed=1, rank=8, shift_exp=-44)  # proven only through the long-double residual
@example(seed=2, rank=16, shift_exp=-56)  # below every bound: nothing proven
def test_the_verified_lambda_min_is_never_above_the_true_one(seed, rank, shift_exp):
    """A rank-deficient GGᵀ (24 rows, float-rounded) plus 2^shift_exp·‖A‖·I: wherever the
    verified test proves λmin ≥ λ > 0, 40-digit mpmath agrees."""
    rng = np.random.default_rng(seed)
    G = rng.normal(size=(24, rank))
    A = G @ G.T
    A = 0.5 * (A + A.T)
    A = A + 2.0 ** shift_exp * np.max(np.abs(A)) * np.eye(24)
    lam, _, _ = D.dense_lambda_lower(A[None])
    with mpmath.workdps(40):
        true = min(mpmath.eigsy(mpmath.matrix(A.tolist()), eigvals_only=True))
    if lam[0] > 0:
        assert mpmath.mpf(float(lam[0])) <= true, (float(lam[0]), float(true))


@pytest.mark.skipif(not D.HAS_LONG_DOUBLE, reason="numpy's long double is a double on this platform")
def test_long_double_residual_proves_what_float64_cannot(monkeypatch):
    rng = np.random.default_rng(1)
    G = rng.normal(size=(24, 8))
    A = G @ G.T
    A = 0.5 * (A + A.T) + 2.0 ** -44 * np.max(np.abs(A)) * np.eye(24)
    assert D.dense_lambda_lower(A[None])[0][0] > 0
    monkeypatch.setattr(D, "HAS_LONG_DOUBLE", False)
    assert not D.dense_lambda_lower(A[None])[0][0] > 0


def _file_W_q_mu(path):
    with h5py.File(path, "r") as f:
        g = f["fclib_local/W"]
        n3 = int(g["n"][0])
        assert int(g["nz"][0]) == -2  # FCLIB: nz = −2 is CSR (p row pointers, i column indices)
        W = sp.csr_matrix((g["x"][:], g["i"][:], g["p"][:]), shape=(n3, n3))
        return W, f["fclib_local/vectors/q"][:], f["fclib_local/vectors/mu"][:]


def test_the_bundled_boxes_stack_is_the_fclib_file():
    assert hashlib.sha256(BOXES.read_bytes()).hexdigest() == BOXES_SHA256


def test_boxes_stack_at_rest_is_certified_for_the_physical_problem_and_rechecked(tmp_path):
    """48 boxes at rest (W of rank 72 in 144, not PSD as stored): with --psd-shift the physical
    problem is certified to 10 digits, r is claimed for no digits (unique only through D), and
    the written answer meets the physical conditions against the file's own W and q at 1e-10
    of ‖q‖∞ in 40-digit arithmetic."""
    from rfverify.cli import main

    out = tmp_path / "boxes.h5"
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        code = main(["solve", str(BOXES), "--psd-shift", "--problem", "coulomb", "--digits", "10", "--out", str(out),
                     "--json", "--quiet"])
    assert code == 0
    verdict = json.loads(printed.getvalue())["verdict"]
    assert ") with (W + Wᵀ)/2 for data q differing from the file's by δ e_N + D r*" in verdict
    assert "r not proven unique" in verdict
    W, q, mu = _file_W_q_mu(BOXES)
    WT = W.T.tocsr()
    with h5py.File(out, "r") as f:
        r, u_file = f["solution/r"][:], f["solution/u"][:]
    scale = float(np.max(np.abs(q)))
    worst = 0.0
    with mpmath.workdps(40):
        R = [mpmath.mpf(float(x)) for x in r]
        for i in range(W.shape[0] // 3):
            # u = (W + Wᵀ)/2 r + q, the equations the verdict names (W is unsymmetric by 2e-16)
            u = [mpmath.mpf(float(q[k])) + mpmath.fsum(mpmath.mpf(float(A.data[j])) * R[A.indices[j]] / 2
                                                       for A in (W, WT) for j in range(A.indptr[k], A.indptr[k + 1]))
                 for k in range(3 * i, 3 * i + 3)]
            rN, rT = R[3 * i], mpmath.sqrt(R[3 * i + 1] ** 2 + R[3 * i + 2] ** 2)
            assert rT <= mu[i] * rN  # r ∈ K exactly
            u_tilde_N = u[0] + mu[i] * mpmath.sqrt(u[1] ** 2 + u[2] ** 2)
            comp = abs(rN * u_tilde_N + R[3 * i + 1] * u[1] + R[3 * i + 2] * u[2]) / max(abs(x) for x in R)
            worst = max(worst, float(max(-u[0], 0)), float(comp),
                        *(float(abs(u[k] - mpmath.mpf(float(u_file[3 * i + k])))) for k in range(3)))
    assert worst <= 1e-10 * scale, worst / scale


@pytest.mark.skipif(not D.HAS_LONG_DOUBLE, reason="numpy's long double is a double on this platform")
def test_the_long_double_residual_is_within_its_a_priori_rounding_bound():
    """The retry's error model, checked against exact rationals: the long-double residual
    F = (A − τI) − GGᵀ of :func:`dense_lambda_lower` differs from the exact one by at most
    γ_{s+4}(|G||G|ᵀ + |A| + τI) with γ of long double's unit roundoff — the platform's long
    double rounds as finfo says (a long double of fewer bits than claimed fails here)."""
    from fractions import Fraction

    rng = np.random.default_rng(3)
    s = 12
    G0 = rng.normal(size=(s, 5))
    A = G0 @ G0.T + 1e-12 * np.eye(s)
    A = 0.5 * (A + A.T)
    lam, V = np.linalg.eigh(A)
    tau = lam[0] * (1 - 2.0 ** -20)
    G = V * np.sqrt(np.maximum(lam - tau, 0.0))[None, :]
    GL = G.astype(np.longdouble)
    FL = (A.astype(np.longdouble) - np.longdouble(tau) * np.eye(s)) - GL @ GL.T
    bound = D.gamma_long(s + 4) * (np.abs(G) @ np.abs(G).T + np.abs(A) + abs(tau) * np.eye(s))
    worst = 0.0
    for i in range(s):
        for j in range(s):
            exact = (Fraction(float(A[i, j])) - (Fraction(tau) if i == j else 0)
                     - sum(Fraction(float(G[i, k])) * Fraction(float(G[j, k])) for k in range(s)))
            err = abs(Fraction(*FL[i, j].as_integer_ratio()) - exact)  # a long double converts exactly
            assert err <= Fraction(float(bound[i, j])), (i, j, float(err), bound[i, j])
            worst = max(worst, float(err) / bound[i, j]) if bound[i, j] > 0 else worst
    assert worst > 1e-6  # the check is not vacuous: rounding of this size occurs
