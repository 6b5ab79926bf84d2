"""Issue 48 item 1: positive definiteness of M decided whatever its scale (rfverify.model.definiteness).

M = D·M0·D with M0 an exact SPD integer matrix and D = diag(2^±k) is exactly SPD at every k
(the scaling is exact); before the equilibrated test it was called "not positive definite" at
k = 12 (a positive "smallest eigenvalue") and at k = 20 (a negative one).  The problems here
keep their exact solution (v* = D⁻¹v0*, u*, r* unchanged), so every proven digit is checked
against the truth, and every bound of the proof against exact (mpmath) values of M⁻¹.
"""

from __future__ import annotations

from fractions import Fraction

import mpmath
import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.cli import main
from rfverify.model.definiteness import EXACT_LIMIT, exact_ldlt, verify_definite
from rfverify.errors import InvalidProblemError
from rfverify.proof.massbounds import verify_mass_matrix

from exact_problems import exact_problem


def scaled_exact(k: int, seed: int = 1, n: int = 4, pattern: str = "alternate"):
    """(problem, v*, u*, r*) of exact_problem(seed, n) in units scaled by D = diag(2^e_j),
    e_j = ±k: alternating per dof (every body's block badly scaled), or one exponent per body."""
    p, v, u, r = exact_problem(seed, n)
    m = p.n_dofs
    if pattern == "alternate":
        e = np.where(np.arange(m) % 2 == 0, k, -k)
    else:
        e = np.repeat(np.random.default_rng(seed).integers(-k, k + 1, size=m // 6), 6)
    d = np.ldexp(1.0, e)
    D = sp.diags(d)
    M, H = sp.csc_matrix(D @ p.M @ D), sp.csc_matrix(D @ p.H)
    # exact: a product by a power of two, far inside the float64 range
    assert np.array_equal(np.ldexp(M.toarray(), -(e[:, None] + e[None, :])), p.M.toarray())
    q = rfverify.Problem.from_arrays(M, H, d * p.f, p.w, p.mu, p.mu_r, title=f"exact seed {seed}, D = 2^±{k}")
    return q, v / d, u, r


def true_errors(problem, out, v, u, r):
    errs = {"v": np.abs(out.v - v).max(), "u": np.abs(out.u - u).max(), "r": np.abs(out.r - r).max(),
            "Hr": np.abs(problem.H @ out.r - problem.H @ r).max()}
    norms = {"v": np.abs(v).max(), "u": np.abs(u).max(), "r": np.abs(r).max(), "Hr": np.abs(problem.H @ r).max()}
    return errs, norms


@pytest.mark.parametrize("k", [12, 20, 40])
def test_an_exactly_spd_badly_scaled_mass_matrix_is_accepted(k):
    q, *_ = scaled_exact(k)
    assert q.blocks.proven and np.all(q.blocks.lam_scaled > 0.1)  # the equilibrated blocks: well conditioned
    assert np.linalg.cond(q.M.toarray()) > 1e14  # ... of a matrix that is not


def test_the_k12_case_is_proven_to_10_digits_and_every_stated_digit_is_true():
    q, v, u, r = scaled_exact(12)
    out = rfverify.solve_to_digits(q, digits=10)
    assert out.success and out.status == rfverify.Status.CERTIFIED, out.message
    errs, norms = true_errors(q, out, v, u, r)
    for name, qb in out.certificate.proof.quantities.items():
        if qb.mode == "information":
            continue
        assert errs[name] <= qb.abs_bound, (name, errs[name], qb.abs_bound)  # the bound holds
        if qb.digits is not None and errs[name] > 0:  # the stated digits are true ones
            assert -np.log10(errs[name] / norms[name]) >= qb.digits - 1e-9, (name, qb.digits)
    assert out.digits["r"] is not None  # r is proven unique, as it is at k = 4 (full column rank of H)


@pytest.mark.parametrize("k, pattern", [(30, "alternate"), (30, "body"), (60, "alternate")])
def test_stated_bounds_hold_far_beyond(k, pattern):
    q, v, u, r = scaled_exact(k, seed=2, n=5, pattern=pattern)
    out = rfverify.solve_to_digits(q, digits=10)
    assert out.success, out.message
    errs, _ = true_errors(q, out, v, u, r)
    for name, qb in out.certificate.proof.quantities.items():
        if qb.mode != "information":
            assert errs[name] <= qb.abs_bound, (name, errs[name], qb.abs_bound)


def test_solve_digits_cli_exits_0_on_the_k12_file(tmp_path, capsys):
    q, *_ = scaled_exact(12)
    path = tmp_path / "scaled.hdf5"
    rfverify.save(q, path)
    assert main(["solve", str(path), "--digits", "10", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "not positive definite" not in out and "proven to 10 digits" in out


def _exact_inverse(M: np.ndarray):
    mp = mpmath.mp.clone()
    mp.dps = 80
    A = mp.matrix([[mp.mpf(float(x)) for x in row] for row in 0.5 * (M + M.T)])
    return A, A ** -1, mp


def test_mass_bounds_of_a_badly_scaled_matrix_enclose_the_exact_values():
    q, *_ = scaled_exact(20, n=2)
    M = q.M.toarray()
    mb = verify_mass_matrix(q.M, q.M_sym, q.blocks)
    assert mb.proven
    A, Ainv, mp = _exact_inverse(M)
    for j in range(M.shape[0]):
        assert mb.minv_diag_upper[j] >= Ainv[j, j]
    H = q.H.toarray()
    quad = mb.quad_upper_columns(q.H)
    for c in range(H.shape[1]):
        h = mp.matrix([mp.mpf(float(x)) for x in H[:, c]])
        assert quad[c] >= (h.T * Ainv * h)[0]
    from rfverify.proof.bound import gMinvg_upper
    from rfverify.proof.dyadic import Dyadic

    rng = np.random.default_rng(5)
    for _ in range(5):  # gᵀM⁻¹g, the theorem's residual term, through the scaled blocks
        g = np.ldexp(rng.standard_normal(M.shape[0]), rng.integers(-30, 30, size=M.shape[0]))
        gm = mp.matrix([mp.mpf(float(x)) for x in g])
        assert gMinvg_upper(Dyadic.from_float(g), mb) >= (gm.T * Ainv * gm)[0]
    eigs = mp.eigsy(A, eigvals_only=True)
    lam_min = min(eigs)
    assert 0 < np.nanmin(mb.lam_lower) <= lam_min
    # the bounds are about as tight as the data allow: within a factor 4 of (M⁻¹)_jj
    assert all(mb.minv_diag_upper[j] <= 4 * Ainv[j, j] for j in range(M.shape[0]))


# ---------------------------------------------------------------------- the words
def test_an_exactly_indefinite_block_is_called_not_positive_definite_at_any_scale():
    p, *_ = exact_problem(1, 4)
    M0 = p.M.toarray()
    M0[0, 1] = M0[1, 0] = np.sqrt(M0[0, 0] * M0[1, 1]) * 1.5  # a 2×2 minor < 0, diagonal still positive
    M0[0, 1] = M0[1, 0] = np.round(M0[0, 1])
    for k in (0, 20):
        e = np.where(np.arange(M0.shape[0]) % 2 == 0, k, -k)
        d = np.ldexp(1.0, e)
        M = (d[:, None] * M0) * d[None, :]
        with pytest.raises(InvalidProblemError) as info:
            rfverify.Problem.from_arrays(M, sp.diags(d) @ p.H, d * p.f, p.w, p.mu, p.mu_r)
        text = str(info.value)
        assert "is not positive definite" in text and "exact" in text, text


def test_a_singular_block_is_proven_singular_by_the_exact_test():
    A = np.eye(6) * 4.0
    A[:2, :2] = [[3.0, 3.0], [3.0, 3.0]]  # exactly singular
    A[1, 2] = A[2, 1] = A[2, 3] = A[3, 2] = A[3, 4] = A[4, 3] = A[4, 5] = A[5, 4] = 1e-3
    facts = verify_definite(sp.csr_matrix(A))
    assert len(facts.failures) == 1 and facts.failures[0].proven, facts.failures
    assert "not positive definite" in facts.failures[0].reason


def _nearly_singular_chain(n: int) -> np.ndarray:
    """An exactly SPD n×n tridiagonal block (one connected component) with λmin ≈ 2^-53 relative
    to its diagonal: a floating-point test cannot prove it (its rounding bound is ~n·u)."""
    A = np.eye(n)
    A[0, 1] = A[1, 0] = 1 - 2.0 ** -53
    for i in range(1, n - 1):
        A[i, i + 1] = A[i + 1, i] = 2.0 ** -30
    assert exact_ldlt([[Fraction(float(x)) for x in row] for row in A])[0] == "definite"
    return A


def test_a_small_spd_block_that_floating_point_cannot_prove_is_proven_exactly():
    A = _nearly_singular_chain(8)
    facts = verify_definite(sp.csr_matrix(A))
    assert facts.proven and facts.exact_blocks == 1
    lam = float(mpmath.mp.eigsy(mpmath.matrix(A.tolist()), eigvals_only=True)[0])
    assert 0 < facts.lam_lower[0] <= lam


def test_an_undecided_large_block_is_never_called_not_positive_definite(tmp_path, capsys):
    n = EXACT_LIMIT + 12
    A = _nearly_singular_chain(n)
    facts = verify_definite(sp.csr_matrix(A))
    assert len(facts.failures) == 1 and not facts.failures[0].proven
    reason = facts.failures[0].reason
    assert reason.startswith("could not verify positive definiteness") and "equilibrated" in reason
    assert "not positive definite" not in reason
    # the refusal of a problem with that block: one line, exit 2, the same honest words
    H = np.zeros((n, 5))
    H[0, 0] = 1.0
    with pytest.raises(InvalidProblemError) as info:
        rfverify.Problem.from_arrays(A, H, np.zeros(n), np.ones(5), [0.5], [0.1])
    assert "could not verify positive definiteness" in str(info.value)
    assert "is not positive definite" not in str(info.value)
