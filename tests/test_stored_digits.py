"""Issue 48 item 6: the proven digits of the stored (unsymmetric) equations' solution, bounded
through the stored blocks' own verified inverses where no contact touches them, and with r
refitted to the stored equations (DESIGN §6.1, rfverify/proof/freeblocks.py).

Every stated bound is checked against the exact solution of the stored equations
(tests/exact_problems.py); the free-body bound is tight enough there that a bound 10× smaller
is caught; the bundled Chute's stored-equations digits (0.7 before) are checked against an
independent solution of its stored equations in tests/test_stored_equations.py."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rfverify
from rfverify.model.directed import digits_text
from rfverify.proof import ProofContext
from rfverify.proof.bound import prove
from rfverify.proof.freeblocks import FreeBlocks
from rfverify.proof.massbounds import solve_upper, verified_left_inverses

from exact_problems import exact_problem, solve_rational


def _true_errors(answer, v, u, r, H):
    return {"v": np.max(np.abs(answer.v - v)), "u": np.max(np.abs(answer.u - u)),
            "Hr": np.max(np.abs(H @ answer.r - H @ r)), "r": np.max(np.abs(answer.r - r))}


def _check_stored_claims(seed, n, free, contact_skew):
    """The symmetrised answer's proof about the *stored* equations: every bound it states holds
    against their exact solution.  Returns (proof, true errors)."""
    p, v, u, r = exact_problem(seed, n, asymmetry=12, free_bodies=free, contact_skew=contact_skew)
    sym = rfverify.solve_to_digits(p, digits=10)
    assert sym.success, sym.message
    stored = sym.certificate.stored_equations
    assert stored is not None and stored.valid
    errs = _true_errors(sym, v, u, r, p.H)
    for name, q in stored.quantities.items():
        if q.mode != "information":
            assert errs[name] <= q.abs_bound * (1 + 1e-12), (name, errs[name], q.abs_bound)
    if stored.fewest_digits() is not None:
        assert f"{digits_text(stored.fewest_digits())} proven digits" in sym.certificate.verdict
    return stored, errs


CASES = [(20261204, 5, 3, False), (7, 9, 4, False), (3, 5, 2, True)]


@pytest.mark.parametrize("seed, n, free, contact_skew", CASES)
def test_stored_equations_digits_are_true(seed, n, free, contact_skew):
    stored, errs = _check_stored_claims(seed, n, free, contact_skew)
    assert stored.terms["free_blocks_solved"] == free  # one 6×6 block per free body
    if not contact_skew:
        # The equations differ on the free bodies only: v's error is theirs, bounded through
        # their own inverses within a few ulps; u, Hr and r are proven to ≥ 10 digits (none before).
        assert errs["v"] <= stored.quantities["v"].abs_bound <= 1.001 * errs["v"]
        assert all(stored.quantities[k].digits >= 10 for k in ("u", "Hr", "r"))


def test_a_free_block_bound_ten_times_smaller_is_caught(monkeypatch):
    real = FreeBlocks.bound
    monkeypatch.setattr(FreeBlocks, "bound", lambda self, g: real(self, g) / 10)
    with pytest.raises(AssertionError):
        _check_stored_claims(*CASES[0])


def test_an_epsilon_of_the_coupled_blocks_ten_times_smaller_is_caught(monkeypatch):
    """The bounds that use ε_C (u, Hr, r of a problem whose contact bodies differ too)."""
    from rfverify.proof import bound as B

    real = B.eps_M_upper
    monkeypatch.setattr(B, "eps_M_upper", lambda q, gap: real(q, gap) / 10)
    with pytest.raises(AssertionError):
        _check_stored_claims(*CASES[2])


def test_the_refitted_point_is_proven_true():
    """The companion's third point (r moved within its face of K to fit the stored equations),
    proven directly: valid, and every bound true against the exact solution."""
    p, v, u, r = exact_problem(3, 5, asymmetry=12, free_bodies=2, contact_skew=True)
    sym = rfverify.solve_to_digits(p, digits=10)
    ctx = ProofContext(p)
    refit = ctx._refitted(sym.point)
    assert refit is not None
    pv, pr = refit.exact()
    assert pr.nearest().tolist() != sym.point.r_hi.tolist()  # r moved
    proof = prove(p.stored_equations(), pv, pr, sym.v, sym.u, sym.r, requested=10, mass=ctx.mass, exact=ctx.exact)
    assert proof.valid, proof.failure
    errs = _true_errors(sym, v, u, r, p.H)
    for name, q in proof.quantities.items():
        if q.mode != "information":
            assert errs[name] <= q.abs_bound * (1 + 1e-12), name


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), s=st.integers(1, 6), skew=st.floats(0, 0.9))
def test_the_verified_inverse_bounds_the_exact_solve(seed, s, skew):
    """|A⁻¹g| ≤ solve_upper(...) entrywise, A⁻¹g in exact rationals, for unsymmetric blocks
    (mildly scaled: the proof equilibrates them first) and g given as an interval; a block
    whose residual bound is not below 1 gets ∞."""
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(s, s))
    A = B @ B.T + s * np.eye(s) + skew * s * (B - B.T)
    D = np.diag(2.0 ** rng.integers(-3, 4, size=s))
    A = D @ A @ D
    g_mid = rng.normal(size=s) * 2.0 ** rng.integers(-20, 20)
    g_rad = np.abs(g_mid) * 1e-12
    X, rows, rho = verified_left_inverses(A[None])
    bound = solve_upper(X, rows, rho, g_mid[None], g_rad[None])[0]
    if not rho[0] < 1:
        assert np.all(bound == np.inf)
        return
    Af = [[Fraction(x) for x in row] for row in A]
    for corner in (g_mid - g_rad, g_mid + g_rad, g_mid):
        exact = solve_rational(Af, [Fraction(x) for x in corner])
        assert all(abs(x) <= Fraction(b) for x, b in zip(exact, bound))
    # and not wildly loose: within 1% of the exact solve at the midpoint (plus the interval)
    exact = solve_rational(Af, [Fraction(x) for x in g_mid])
    assert np.all(bound <= 1.01 * np.abs(np.array([float(x) for x in exact])) + 1e-6 * np.max(bound))


