"""The criterion of 'Solved' (rfverify.model.measures), the stored-solution check and the
physical problem's check guarded where a mutation audit (2026-12-07) found them unguarded: tiny
candidates whose verdict is known in closed form; each test fails on the audit's mutant named in
its docstring (and the last one on a bug of the code itself: a pulling frictionless contact)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import rfverify
from rfverify.coulomb.model import check_physical_solution
from rfverify.model.measures import measures
from rfverify.model.problem import StoredSolution


def _block3(f, mu, mur, M=None, **kw):
    M = np.eye(3) if M is None else np.asarray(M, dtype=float)
    return rfverify.Problem.from_arrays(M, np.c_[np.eye(3), np.zeros((3, 2))], np.asarray(f, dtype=float),
                                        np.zeros(5), [mu], [mur], **kw)


def _block5(f, mu, mur):
    return rfverify.Problem.from_arrays(np.eye(5), np.eye(5), np.asarray(f, dtype=float), np.zeros(5), [mu], [mur])


def _candidate(p, v, r):
    v, r = np.asarray(v, dtype=float), np.asarray(r, dtype=float)
    return v, p.H.T @ v + p.w, r


def test_u_outside_the_dual_cone_is_not_solved():
    """u = (0, 1.2, 1.6) with μ = 0.5: ‖u_T‖ = 2 > u_N/μ. Mutants S01 (cone = primal only) and C01
    (max_error without dual_cone) called it solved; C03 named 'dynamics' as the failure."""
    p = _block3([0, 1.2, 1.6], 0.5, 0.0)
    v, u, r = _candidate(p, [0, 1.2, 1.6], np.zeros(5))
    m = measures(p, v, u, r)
    assert m.dual_cone > 0.5 and not m.meets(1e-8)
    assert m.max == max(m.dynamics, m.velocity, m.primal_cone, m.dual_cone, m.complementarity)
    chk = rfverify.check_solution(p, StoredSolution(v, u, r))
    assert not chk.ok(1e-8) and "dual_cone residual 6.25e-01" in chk.verdict(1e-8)


def test_a_gap_with_no_energy_scale_is_infinite_not_zero():
    """f = w = 0 (energy scale 0), v = (1, 0, 0), r = e_N: dynamics and cones hold exactly but
    rᵀu = 1. Mutant S02 (x/0 → 0) called it solved."""
    p = _block3([0, 0, 0], 0.5, 0.0)
    v, u, r = _candidate(p, [1, 0, 0], [1, 0, 0, 0, 0])
    m = measures(p, v, u, r)
    assert m.complementarity == math.inf and not m.meets(1e-8)
    assert not rfverify.check_solution(p, StoredSolution(v, u, r)).ok(1e-8)


def test_the_dynamics_residual_is_of_the_posed_equations():
    """M = [[1, .5, 0], [0, 1, 0], [0, 0, 1]] is posed as (M + Mᵀ)/2; v = M⁻¹f solves the stored
    equations, not the posed ones: (M + Mᵀ)/2 v − f = (−.25, .125, 0). Mutant S08 (the raw M)
    measured 0."""
    M = [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]
    p = _block3([1, 1, 0], 0.3, 0.0, M=M, max_asymmetry=0.5)
    v, u, r = _candidate(p, [0.5, 1, 0], np.zeros(5))
    assert measures(p, v, u, r).dynamics > 0.1


# ------------------------------------------------------------------ the physical problem's check
def _physical(p, v, r, shift):
    v, u, r = _candidate(p, v, r)
    return check_physical_solution(p, StoredSolution(v, u, r), np.asarray(shift, dtype=float), 1e-8)


@pytest.mark.parametrize("case, worst", [
    ("rolling cone", "cone"),            # ‖r_R‖ = .3 > μr r_N = .1 (mutant M03: μ for μr)
    ("penetrating", "normal"),           # u_N = −1 (mutants M04, M05: no normal check)
    ("penetrating, shifted", "normal"),  # u_N = −1, ũ_N = 0 (mutant M10: the check on ũ_N)
    ("separated and loaded", "complementarity"),  # r_N u_N = 1e6 (mutant M08: ÷ ‖r‖²)
    ("pulling, frictionless", "cone"),   # r_N = −1 with μ = μr = 0: the code itself passed it
])
def test_physical_answers_that_are_not_are_called_so(case, worst):
    cases = {
        "rolling cone": (_block5([-1, 0, 0, -0.3, 0], 0.5, 0.1), np.zeros(5), [1, 0, 0, 0.3, 0], [0.0]),
        "penetrating": (_block3([-1, 0, 0], 0.5, 0.0), [-1, 0, 0], np.zeros(5), [0.0]),
        "penetrating, shifted": (_block3([-1, 1.2, 1.6], 0.5, 0.0), [-1, 1.2, 1.6], np.zeros(5), [1.0]),
        "separated and loaded": (_block3([-999999, 0, 0], 0.5, 0.0), [1, 0, 0], [1e6, 0, 0, 0, 0], [0.0]),
        "pulling, frictionless": (_block3([1, 0, 0], 0.0, 0.0), np.zeros(3), [-1, 0, 0, 0, 0], [0.0]),
    }
    out = _physical(*cases[case])
    assert not out["consistent"], out["verdict"]
    assert worst in out["verdict"], out["verdict"]


def test_the_exact_rolling_answer_is_consistent():
    """μ = 0.3, μr = 0.5, f_R = (1.2, 1.6): r = (1, 0, 0, −.3, −.4), u = (0, 0, 0, .9, 1.2),
    shift μr‖u_R‖ = .75 solve the physical problem exactly. Mutant M06 (rᵀũ without r_R·u_R)
    called it 'NOT a solution … complementarity 4.69e-01'."""
    out = _physical(_block5([-1, 0, 0, 1.2, 1.6], 0.3, 0.5), [0, 0, 0, 0.9, 1.2], [1, 0, 0, -0.3, -0.4], [0.75])
    assert out["consistent"], out["verdict"]


def test_the_physical_check_judges_the_stored_u():
    """Stored u_N = −1e-6 where Hᵀv + w = 0: the file's own u is judged. Mutant M07 (recomputed
    u) called it consistent."""
    p = rfverify.Problem.from_arrays(np.eye(3), np.c_[np.eye(3), np.zeros((3, 2))], np.array([-1000.0, 0, 0]),
                                     np.array([1000.0, 0, 0, 0, 0]), [0.5], [0.0])
    v, r = np.array([-1000.0, 0, 0]), np.zeros(5)
    u = np.array([-1e-6, 0, 0, 0, 0])
    out = check_physical_solution(p, StoredSolution(v, u, r), np.zeros(1), 1e-8)
    assert not out["consistent"] and "normal" in out["verdict"], out["verdict"]
