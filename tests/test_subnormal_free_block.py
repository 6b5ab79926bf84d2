"""A false bound found in the code itself (not a mutant) by the mutation audit's follow-up
(2026-12-07): the proof of a contact-free block used the float (M + Mᵀ)/2 within 2u|·| + ETA of
the exact one in *equilibrated* units, but the underflow part of that rounding is ETA in the
*data's* units, 2^(e_i + e_j)·ETA after the equilibration S M S (S = diag(2^e)): of the order of
the block itself for subnormal entries."""

from fractions import Fraction

import numpy as np
import pytest

import rfverify
from rfverify.proof import Point, ProofContext

E = 2.0 ** -1074


def _subnormal_block_problem():
    M = np.zeros((3, 3))
    M[0, 0] = 1.0
    M[1:, 1:] = [[1000 * E, 997 * E], [998 * E, 1000 * E]]
    H = np.zeros((3, 5))
    H[0, 0] = 1.0
    f = np.array([-1.0, 1000 * E, 0.0])
    return rfverify.Problem.from_arrays(M, H, f, np.zeros(5), np.array([0.5]), np.array([0.25]), max_asymmetry=1.0)


def test_free_block_bound_with_subnormal_unsymmetric_mass():
    """Free block M_F = [[1000, 997], [998, 1000]]·2^-1074: the float M/2 + Mᵀ/2 has 997·2^-1074
    off the diagonal, the exact (M + Mᵀ)/2 997.5·2^-1074. With f_F = (1000·2^-1074, 0) and v = 0
    the exact error is ‖A_ex⁻¹ f_F‖∞ = 200.25; the bound was 166.917."""
    p = _subnormal_block_problem()
    M = p.M.toarray()
    off = (Fraction(M[1, 2]) + Fraction(M[2, 1])) / 2
    a, c = Fraction(M[1, 1]), Fraction(M[2, 2])
    det = a * c - off * off
    x = [c * Fraction(p.f[1]) / det, -off * Fraction(p.f[1]) / det]  # A_ex⁻¹ f_F, exact
    v, r = np.zeros(3), np.array([1.0, 0, 0, 0, 0])
    pr = ProofContext(p).prove(Point(v, 0 * v, r, 0 * r), v, p.H.T @ v, r, requested=1)
    if pr.valid:
        assert Fraction(pr.quantities["v"].abs_bound) >= max(abs(t) for t in x)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the solvers' own overflow on these data
def test_a_point_whose_iteration_broke_down_proves_nothing_and_raises_nothing():
    """certify on the same data: the multiple-precision tail's iterate held NaN, and proving it
    raised 'exact arithmetic needs finite numbers' (exit 3 from the CLI)."""
    p = _subnormal_block_problem()
    v, r = np.zeros(3), np.array([1.0, 0, 0, 0, 0])
    cert = rfverify.certify(p, v, p.H.T @ v, r, digits=1)
    assert not cert.certified
    nan = Point(np.full(3, np.nan), np.zeros(3), r, 0 * r)
    proof = ProofContext(p).prove(nan, v, p.H.T @ v, r, requested=1)
    assert not proof.valid and "NaN or Inf" in proof.failure
