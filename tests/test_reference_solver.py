"""The mpmath reference solver: converges far below double precision on the bundled problems,
its solution's residuals are tiny when recomputed independently at higher precision, and the
double-precision solver agrees with it to the digits its stopping test promises."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest

import reference
import rfverify
from rfverify.solver import solve as solve_double

BUNDLED = ["chute", "sphere", "cube", "sphere-from-global"]


def residuals_at(problem, res, dps):
    """max relative residual of the reference solution recomputed at ``dps`` digits in the
    global mpmath context (inside workdps), independently of the solver's own bookkeeping:
    dynamics, velocity, complementarity |uᵀr|/n and the K / K* violations."""
    with mpmath.workdps(dps):
        mpf = mpmath.mpf
        v = [mpf(x) for x in res.v]
        u = [mpf(x) for x in res.u]
        r = [mpf(x) for x in res.r]
        M = problem.M_sym.tocoo()
        H = problem.H.tocoo()
        Mv = [mpf(0)] * problem.n_dofs
        for i, j, x in zip(M.row, M.col, M.data):
            Mv[i] += mpf(float(x)) * v[j]
        Hr = [mpf(0)] * problem.n_dofs
        HTv = [mpf(0)] * (5 * problem.n_contacts)
        for i, j, x in zip(H.row, H.col, H.data):
            Hr[i] += mpf(float(x)) * r[j]
            HTv[j] += mpf(float(x)) * v[i]
        f = [mpf(float(x)) for x in problem.f]
        w = [mpf(float(x)) for x in problem.w]
        scale_f = max(max(abs(x) for x in Mv), max(abs(x) for x in f), max(abs(x) for x in Hr))
        dyn = max(abs(a - b - c) for a, b, c in zip(Mv, Hr, f)) / scale_f
        scale_u = max(max(abs(x) for x in HTv), max(abs(x) for x in w))
        vel = max(abs(a - b - c) for a, b, c in zip(u, HTv, w)) / scale_u
        comp = abs(mpmath.fsum(a * b for a, b in zip(u, r))) / problem.n_contacts
        viol = mpf(0)
        for i in range(problem.n_contacts):
            m_, mr = mpf(float(problem.mu[i])), mpf(float(problem.mu_r[i]))
            R, U = r[5 * i:5 * i + 5], u[5 * i:5 * i + 5]
            viol = max(viol, mpmath.hypot(R[1], R[2]) - m_ * R[0], mpmath.hypot(R[3], R[4]) - mr * R[0],
                       m_ * mpmath.hypot(U[1], U[2]) + mr * mpmath.hypot(U[3], U[4]) - U[0])
        return float(max(dyn, vel, comp, viol))


@pytest.mark.parametrize("name", BUNDLED)
def test_reference_converges_far_below_double(name):
    problem = rfverify.load(f"bundled:{name}")
    res = reference.solve(problem, dps=50)
    assert res.status == "Solved", res.message
    assert max(res.pinfeas, res.dinfeas, res.mu) <= mpmath.mpf(10) ** -40
    # Recomputed outside the solver, at 60 digits: the solution is exact to ~1e-35 or better.
    assert residuals_at(problem, res, 60) <= 1e-35


@pytest.mark.parametrize("name", BUNDLED)
def test_double_solver_agrees_with_reference(name):
    problem = rfverify.load(f"bundled:{name}")
    ref = reference.solve(problem, dps=40)
    dbl = solve_double(problem, method="jqinv", tol=1e-10)
    v_ref = ref.as_float("v")
    r_ref = ref.as_float("r")
    dv = np.max(np.abs(dbl.v - v_ref)) / np.max(np.abs(v_ref))
    dHr = np.max(np.abs(problem.H @ (dbl.r - r_ref))) / max(np.max(np.abs(problem.H @ r_ref)), 1e-300)
    # A 1e-10 stopping test is worth about five to six digits here (the Chute figure in the
    # project brief); fewer than four would mean one of the two solvers is wrong.
    assert dv < 1e-4 and dHr < 1e-4, (dv, dHr)


def test_reference_precision_is_private():
    before = mpmath.mp.prec
    res = reference.solve(rfverify.load("bundled:sphere"), dps=30)
    assert mpmath.mp.prec == before
    assert res.ctx.dps == 60 and res.dps == 30  # arithmetic at 2·dps digits
    assert res.v[0].context is res.ctx


def test_reference_zero_coefficients():
    from rfverify.random_problems import random_problem

    problem = random_problem(5, 7, seed=4, mu_zero_fraction=0.4, mu_r_zero_fraction=0.4)
    assert np.any((problem.mu == 0) & (problem.mu_r == 0)) or np.any(problem.mu == 0)
    res = reference.solve(problem, dps=40)
    assert res.status == "Solved", res.message
    assert residuals_at(problem, res, 50) <= 1e-25
    r = res.as_float("r").reshape(-1, 5)
    assert np.all(r[problem.mu == 0, 1:3] == 0) and np.all(r[problem.mu_r == 0, 3:5] == 0)


def test_reference_does_not_import_rfverify():
    """The reference is only evidence if it is independent: no module of it imports rfverify."""
    import ast
    from pathlib import Path

    for path in Path(reference.__file__).parent.glob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            assert not any(n.split(".")[0] == "rfverify" for n in names), f"{path.name} imports {names}"
