"""The mpmath reference solver: converges far below double precision on the bundled problems,
its solution passes the tests' independent recheck and rfverify's criterion recomputed at
higher precision, the double-precision solver agrees with it to the digits its stopping test
promises, and its one-time build serves every step and run (``reference.Solver``)."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest

import reference
import rfverify
from reference import jordan as RJ
from rfverify.model.measures import measures
from rfverify.solver import solve as solve_double

try:
    from test_solver import recheck_file
except ImportError:  # tests/ made a package
    from tests.test_solver import recheck_file

BUNDLED = ["chute", "sphere", "cube", "sphere-from-global"]


def recheck_reference(problem, res, tmp_path, dps):
    """The reference solution judged twice, by code that shares nothing with reference/:
    its float64 rounding, written to a file, by the tests' oracle (recheck_file), and the
    solution itself, all its digits, by rfverify's criterion in ``dps``-digit arithmetic.
    Returns (worst measure of the file, criterion at ``dps`` digits)."""
    path = tmp_path / "reference.h5"
    sol = rfverify.StoredSolution(res.as_float("v"), res.as_float("u"), res.as_float("r"))
    rfverify.save(problem.with_solution(sol), path)
    exact = (np.array(getattr(res, name), dtype=object) for name in ("v", "u", "r"))
    return max(recheck_file(path, problem).values()), measures(problem, *exact, arith=dps).max


@pytest.mark.parametrize("name", BUNDLED)
def test_reference_converges_far_below_double(name, tmp_path):
    problem = rfverify.load(f"bundled:{name}")
    res = reference.solve(problem, dps=50)
    assert res.status == "Solved", res.message
    assert max(res.pinfeas, res.dinfeas, res.mu) <= mpmath.mpf(10) ** -40
    in_file, exact = recheck_reference(problem, res, tmp_path, 60)
    # Its double rounding is as good as double can be; itself it is solved to ~1e-35 or better.
    assert in_file <= 1e-15 and exact <= 1e-33, (in_file, exact)


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


def test_reference_zero_coefficients(tmp_path):
    from rfverify.scenes.random_problems import random_problem

    problem = random_problem(5, 7, seed=4, mu_zero_fraction=0.4, mu_r_zero_fraction=0.4)
    assert np.any((problem.mu == 0) & (problem.mu_r == 0)) or np.any(problem.mu == 0)
    res = reference.solve(problem, dps=40)
    assert res.status == "Solved", res.message
    in_file, exact = recheck_reference(problem, res, tmp_path, 50)
    assert in_file <= 1e-15 and exact <= 1e-25, (in_file, exact)
    r = res.as_float("r").reshape(-1, 5)
    assert np.all(r[problem.mu == 0, 1:3] == 0) and np.all(r[problem.mu_r == 0, 3:5] == 0)


def _bits(it):
    """An iterate as exact mpf tuples (for bit-for-bit comparisons)."""
    return ([x._mpf_ for x in it.v], [x._mpf_ for x in it.r_t], [[x._mpf_ for x in c] for c in it.z])


def test_solve_is_one_build_and_a_run():
    """reference.solve is Solver(problem, dps).run(...) bit for bit, and run's iterations are
    Solver.step applied in turn with γ_{k+1} = 0.9 + 0.09·α_k — the step lockstep uses."""
    problem = rfverify.load("bundled:sphere")
    solver = reference.Solver(problem, dps=30)
    res = reference.solve(problem, dps=30, max_iter=6, sigma_rule="siconos")
    run = solver.run(max_iter=6, sigma_rule="siconos")
    assert (run.status, run.nit, run.trace) == (res.status, res.nit, res.trace)
    assert _bits(run.iterate) == _bits(res.iterate)
    assert [x._mpf_ for x in run.u] == [x._mpf_ for x in res.u]
    it, gamma = solver.start(), 0.9
    for _ in range(6):
        step = solver.step(it, gamma, "siconos")
        it, gamma = step.iterate, solver.ctx.mpf("0.9") + solver.ctx.mpf("0.09") * step.alpha
    assert _bits(it) == _bits(run.iterate)
    assert [float(solver.residuals(it).mu)] == run.trace["mu"][-1:]


def test_warm_run_continues_from_a_double_iterate():
    """Warm mode: from the float64 rounding of an early iterate the run converges to the same
    solution as the independent run, in fewer iterations; a start on the cone boundary is not
    used (the standard start is, and the message says so)."""
    problem = rfverify.load("bundled:cube")
    solver = reference.Solver(problem, dps=30)
    cold = solver.run()
    early = solver.run(max_iter=5)
    start = {"v": early.as_float("v"), "r_t": early.as_float("r_t"),
             "z": [np.array([float(x) for x in c]) for c in early.z]}
    warm = solver.run(start=start)
    assert cold.success and warm.success and warm.message.endswith("(warm start)")
    assert warm.nit < cold.nit
    # Both stop at μ ≤ 1e-20, which fixes v to about √μ.
    assert max(abs(a - b) for a, b in zip(warm.v, cold.v)) <= 1e-8 * max(abs(b) for b in cold.v)
    boundary = dict(start, z=[np.concatenate([[np.linalg.norm(c[1:])], c[1:]]) for c in start["z"]])
    assert not solver.is_interior(solver.iterate(boundary["v"], boundary["r_t"], boundary["z"]))
    fallback = solver.run(start=boundary, max_iter=3)
    assert "warm start not interior: standard start used" in fallback.message
    assert _bits(fallback.iterate) == _bits(solver.run(max_iter=3).iterate)
    with pytest.raises(ValueError, match="layout"):
        solver.iterate(start["v"][:-1], start["r_t"], start["z"])
    with pytest.raises(RJ.ReferenceDomainError):
        solver.step(solver.iterate(boundary["v"], boundary["r_t"], boundary["z"]), 0.9)


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
