"""The physical problem's backward error guarded where a mutation audit (2026-12-07) found it
unguarded: sliding and rolling blocks whose exact answers are in closed form, the bound of each
term checked against the exact δ. Each test fails on the audit's mutant named in its docstring."""

from __future__ import annotations

from fractions import Fraction

import mpmath
import numpy as np
import pytest

import rfverify
from rfverify.coulomb import backward, certify_coulomb, model


def _block(f, mu, mur, rolling=False):
    if rolling:
        return rfverify.Problem.from_arrays(np.eye(5), np.eye(5), np.asarray(f, dtype=float), np.zeros(5), [mu], [mur])
    return rfverify.Problem.from_arrays(np.eye(3), np.c_[np.eye(3), np.zeros((3, 2))], np.asarray(f, dtype=float),
                                        np.zeros(5), [mu], [mur])


def _exact_delta(p, s_hat: float, part: str) -> float:
    """δ = ŝ − c‖u*_part‖ of the convex problem shifted by ŝ, for a block pushed along one part
    (c = μ for T, μr for R): r*_N = (f_N + cF − ŝ)/(1 + c²), ‖u*_part‖ = F − c r*_N."""
    with mpmath.workdps(60):
        i = 1 if part == "T" else 3
        c = mpmath.mpf(float(p.mu[0] if part == "T" else p.mu_r[0]))
        F = mpmath.sqrt(mpmath.mpf(float(p.f[i])) ** 2 + mpmath.mpf(float(p.f[i + 1])) ** 2)
        s = mpmath.mpf(Fraction(s_hat).numerator) / Fraction(s_hat).denominator
        rN = (-mpmath.mpf(float(p.f[0])) + c * F - s) / (1 + c * c)
        return abs(float(s - c * (F - c * rN)))


@pytest.mark.parametrize("mu, mur, vR, offset", [
    (0.3, 0.5, (0.9, 1.2), 0.0),      # B02: the Lipschitz term's μr·√2·e_u dropped
    (0.0, 0.2, (1.08, 1.44), -1e-5),  # B04: Φ's upper bound without μr‖u_R‖ (ŝ below Φ)
])
def test_the_rolling_part_of_the_backward_error_is_bounded(mu, mur, vR, offset):
    """A block rolling under f_R = (1.2, 1.6): candidate u_R off its exact value by (0.6, 0.8)e-6,
    the shift Φ(u) + offset. Mutants B02 and B04 bounded |δ| by 2.7e-7 and 2.7e-6 where it is
    4.0e-7 and 9.4e-6."""
    p = _block([-1.0, 0, 0, 1.2, 1.6], mu, mur, rolling=True)
    v = np.array([0, 0, 0, vR[0] + 0.6e-6, vR[1] + 0.8e-6])
    r = np.array([1.0, 0, 0, -mur * 0.6, -mur * 0.8])
    s_hat = float(model.phi(p, p.H.T @ v + p.w)[0]) + offset
    cert = certify_coulomb(p, v, None, r, digits=9, shift=[s_hat])
    assert float(cert.backward.delta[0]) >= _exact_delta(p, s_hat, "R"), cert.backward


def _relaxed_u(f, c, i):
    """u'* of the unshifted convex problem for a block sliding along part i (c its coefficient)."""
    fN, F = f[0], float(np.hypot(f[i], f[i + 1]))
    t = (c * fN + F) / (1 + c * c)
    u = np.zeros(5)
    u[0], u[i], u[i + 1] = c * t, t * f[i] / F, t * f[i + 1] / F
    return u, c * t


def test_a_loaded_rolling_contact_is_not_proven_open():
    """μ = 0.3, μr = 0.5, f_R = (1.2, 1.6), shift 0, û = u'* (loaded, r*_N > 0): δ = −μr‖u*_R‖ = −0.6.
    Mutant B06 (the open test without μr‖u_R‖) proved it open, δ = 0."""
    p = _block([-1.0, 0, 0, 1.2, 1.6], 0.3, 0.5, rolling=True)
    u, phi = _relaxed_u(p.f, 0.5, 3)
    be = backward.backward_bound(p, model.shifted_problem(p, [0.0]), u, 1e-12, 1.0, "scale")
    assert be.open_contacts == 0 and be.delta[0] >= phi * (1 - 1e-12)


def test_the_open_test_uses_the_corner_of_the_error_box():
    """A sliding block at its relaxed answer, û moved by e_u to the corner of its box (u_N + e,
    u_T − e): still loaded, |δ| = μ‖u*_T‖ = 0.6485. Mutants B07 (û_N without −e_u) and B09 (e_u for
    √2·e_u) proved it open, δ = 0."""
    p = _block([-1.0, 1.5, 1.5], 0.5, 0.0)
    u, phi = _relaxed_u(p.f, 0.5, 1)
    e = 1e-6
    u_box = u + e * np.array([1, -1, -1, 0, 0])
    be = backward.backward_bound(p, model.shifted_problem(p, [0.0]), u_box, e * (1 + 1e-9), 1.0, "scale")
    assert be.open_contacts == 0 and be.delta[0] >= phi * (1 - 1e-9)


def test_slow_sliding_inside_the_error_keeps_its_bound():
    """‖u*_T‖ = (F − μ)/(1 + μ²) < e_u = 2⁻²⁰ with û = 0 and ŝ = 0: the fixed-point part is 0 but
    δ = −μ‖u*_T‖ ≠ 0. Mutant B18 (δ zeroed where the fixed-point part is 0) gave 0."""
    F = 0.5 + 2.0 ** -20
    p = _block([-1.0, F, 0.0], 0.5, 0.0)
    be = backward.backward_bound(p, model.shifted_problem(p, [0.0]), np.zeros(5), 2.0 ** -20, 1.0, "scale")
    assert be.delta[0] >= 0.5 * (F - 0.5) / 1.25


def test_a_shifted_w_with_unbounded_reactions_proves_no_backward_error():
    """W shifted to W + D (D = 0.1) with r* not bounded (r_upper None): the data change holds
    D r*, unknown. Mutant B20 (that part taken as 0) claimed δ ≤ 7.1e-13."""
    p = _block([-1.0, 1.2, 1.6], 0.5, 0.0)
    u = np.array([0.75, 0.9, 1.2, 0, 0])
    be = backward.backward_bound(p, model.shifted_problem(p, [0.75]), u, 1e-12, 1.0, "scale",
                                 diag_shift=0.1, r_upper=None)
    assert not be.proven
