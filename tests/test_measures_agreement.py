"""The one criterion, value for value (issue 29): :func:`rfverify.model.measures.measures` against an
independent checker written here from the definitions in the module's docstring (DESIGN §4.5),
in exact rational arithmetic on dense matrices.

Earlier tests compared only "≤ tol" verdicts; a measure that is wrong by a constant factor,
uses another norm or another scale passes such a test near a solution and fails this one.
Candidates are the solver's answer perturbed in every direction by hypothesis (sizes from a
rounding to 10 %), plus pinned edge cases: the zero point, a point outside both cones, and
contacts with μ = 0 or μr = 0.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import rfverify
from exact_problems import solve_rational
from rfverify.model.measures import measures
from rfverify.scenes.random_problems import random_problem


def _q(x) -> Fraction:
    return Fraction(float(x))


def _qvec(x) -> list:
    return [_q(v) for v in np.asarray(x, dtype=np.float64)]


def _qmat(A) -> list:
    return [[_q(v) for v in row] for row in np.asarray(A.toarray(), dtype=np.float64)]


def _matvec(A, x) -> list:
    return [sum((a * b for a, b in zip(row, x) if a), Fraction(0)) for row in A]


def _transpose(A) -> list:
    return [list(col) for col in zip(*A)]


def _amax(x) -> Fraction:
    return max((abs(v) for v in x), default=Fraction(0))


def _norm2(x) -> float:
    return math.sqrt(float(sum(v * v for v in x)))


def _ratio(num, den) -> float:
    if den > 0:
        return float(num) / float(den)
    return 0.0 if num == 0 else math.inf


class IndependentChecker:
    """The criterion of DESIGN §4.5, from its definitions: M symmetrised, U₀ = ‖HᵀM⁻¹f + w‖∞,
    R₀ = ‖f‖∞ / max_k ‖h_k‖₂, E = max(|fᵀM⁻¹f|, ‖w‖∞² / max_k Σ_j H_jk²/M_jj), ∞-norms of
    the data's rows for ‖M‖ and ‖Hᵀ‖.  Everything exact except the square roots of 2-norms
    (computed in float from exact sums of squares)."""

    def __init__(self, problem):
        M = _qmat(problem.M)
        self.M = [[(M[i][j] + M[j][i]) / 2 for j in range(len(M))] for i in range(len(M))]
        self.H = _qmat(problem.H)
        self.HT = _transpose(self.H)
        self.f, self.w = _qvec(problem.f), _qvec(problem.w)
        self.mu, self.mu_r = _qvec(problem.mu), _qvec(problem.mu_r)
        v_free = solve_rational(self.M, self.f)
        self.U0 = _amax([a + b for a, b in zip(_matvec(self.HT, v_free), self.w)])
        col_norm = max(_norm2(col) for col in self.HT)
        self.R0 = float(_amax(self.f)) / col_norm if col_norm > 0 else 0.0
        W_diag = [sum(h * h / self.M[j][j] for j, h in enumerate(col)) for col in self.HT]
        energy_w = _amax(self.w) ** 2 / max(W_diag) if max(W_diag) > 0 else Fraction(0)
        self.E = max(abs(sum(a * b for a, b in zip(self.f, v_free))), energy_w)
        self.norm_M = max(sum(abs(a) for a in row) for row in self.M)
        self.norm_HT = max(sum(abs(a) for a in row) for row in self.HT)

    def __call__(self, v, u, r) -> dict:
        V, Uv, Rv = _qvec(v), _qvec(u), _qvec(r)
        Mv, Hr, HTv = _matvec(self.M, V), _matvec(self.H, Rv), _matvec(self.HT, V)
        d_res = [a - b - c for a, b, c in zip(Mv, Hr, self.f)]
        v_inf = _amax(V)
        D = max(_amax(Mv), _amax(Hr), _amax(self.f), self.norm_M * v_inf)
        U = max(_amax(Uv), _amax(HTv), _amax(self.w), self.norm_HT * v_inf, self.U0)
        R = max(float(_amax(Rv)), self.R0)
        primal = dual = 0.0
        for k in range(len(self.mu)):
            rN, uN = Rv[5 * k], Uv[5 * k]
            rT, rR = math.hypot(Rv[5 * k + 1], Rv[5 * k + 2]), math.hypot(Rv[5 * k + 3], Rv[5 * k + 4])
            uT, uR = math.hypot(Uv[5 * k + 1], Uv[5 * k + 2]), math.hypot(Uv[5 * k + 3], Uv[5 * k + 4])
            mu, mu_r = float(self.mu[k]), float(self.mu_r[k])
            primal = max(primal, rT - mu * float(rN), rR - mu_r * float(rN), -float(rN))
            dual = max(dual, mu * uT + mu_r * uR - float(uN), -float(uN))
        return {"dynamics": _ratio(_amax(d_res), D),
                "velocity": _ratio(_amax([a - b - c for a, b, c in zip(Uv, HTv, self.w)]), U),
                "primal_cone": _ratio(primal, R),
                "dual_cone": _ratio(dual, U),
                "complementarity": _ratio(abs(sum(a * b for a, b in zip(Rv, Uv))), self.E)}


def _close(a: float, b: float, rel: float, floor: float) -> bool:
    return abs(a - b) <= rel * max(abs(a), abs(b)) + floor


PROBLEMS = {
    "random": lambda: random_problem(3, 4, seed=11, mu_r_zero_fraction=0.5, mass_ratio=1e3),
    "random-mu0": lambda: random_problem(2, 3, seed=12, mu_zero_fraction=0.4),
    "sphere": lambda: rfverify.load("bundled:sphere"),
}


@pytest.fixture(scope="module")
def cases():
    out = {}
    for name, make in PROBLEMS.items():
        problem = make()
        res = rfverify.solve(problem, method="jqinv", tol=1e-10)
        out[name] = (problem, IndependentChecker(problem), res.v, res.u, res.r)
    return out


def _compare(case, v, u, r):
    """Agreement to the rounding of the arithmetic: the residuals and rᵀu are computed in it,
    so each measure may differ from the exact one by (terms in a sum)·eps of the terms it is
    relative to — not more."""
    problem, independent, *_ = case
    want = independent(v, u, r)
    n5 = 5 * problem.n_contacts
    gap_terms = float(np.sum(np.abs(np.asarray(r) * np.asarray(u))))
    for arith, eps in (("float64", 2.0**-52), (40, 1e-40)):
        got = measures(problem, v, u, r, arith)
        floors = {"dynamics": 64 * eps, "velocity": 64 * eps,
                  # cone violations: differences of 2-norms, which the checker takes in float64
                  "primal_cone": 4 * 2.0**-52, "dual_cone": 4 * 2.0**-52,
                  "complementarity": 2 * n5 * eps * _ratio(gap_terms, independent.E)}
        for name, value in want.items():
            assert _close(getattr(got, name), value, 1e-9, floors[name]), (arith, name, getattr(got, name), value)


@given(name=st.sampled_from(sorted(PROBLEMS)),
       size=st.sampled_from([0.0, 1e-15, 1e-12, 1e-8, 1e-4, 1e-1]),
       seed=st.integers(0, 2**32 - 1),
       which=st.sampled_from(["v", "u", "r", "all"]))
@example(name="random", size=0.0, seed=0, which="all")  # the solver's answer itself
@example(name="sphere", size=1e-1, seed=1, which="r")
@example(name="random-mu0", size=1e-8, seed=2, which="u")
def test_measures_equal_an_independent_checker_on_perturbed_candidates(cases, name, size, seed, which):
    case = cases[name]
    rng = np.random.default_rng(seed)
    v, u, r = (np.array(x, dtype=np.float64) for x in case[2:])
    for key, arr in (("v", v), ("u", u), ("r", r)):
        if which in (key, "all"):
            scale = max(float(np.max(np.abs(arr), initial=0.0)), 1e-300)
            arr += size * scale * rng.standard_normal(arr.shape)
    _compare(case, v, u, r)


@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_measures_equal_an_independent_checker_at_the_edges(cases, name):
    case = cases[name]
    problem = case[0]
    m, n5 = problem.n_dofs, 5 * problem.n_contacts
    _compare(case, np.zeros(m), np.zeros(n5), np.zeros(n5))  # zero point: scales from the data alone
    outside = np.tile([-1.0, 2.0, -3.0, 0.5, 0.25], problem.n_contacts)  # outside both cones
    _compare(case, np.ones(m), outside, outside[::-1].copy())
