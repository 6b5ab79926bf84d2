"""Which cone cuts the double solve's steps short: the float64 kernel's arg-min, the product
cone's ``stepper``, the trace's ``step_cone``/``step_side``, ``SolveResult.steps_held``, the
``--verbose`` table's "held by" column and the progress line, each checked against an
independent recomputation (each cone's own step, and the steps the kept iterates took)."""

from __future__ import annotations

import json
import re

import mpmath
import numpy as np
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rfverify
from rfverify.cli import main
from rfverify.cli.common import IterationProgress
from rfverify.model.lifting import lift
from rfverify.scenes.random_problems import random_problem
from rfverify.solver.cones import ProductCone
from rfverify.solver.log import row
from rfverify.solver.presolve import presolve
from rfverify.solver.result import IterationInfo, Settings


def _interior(rng, n3, n1, dtype=np.float64):
    x = rng.normal(size=3 * n3 + n1)
    x[0:3 * n3:3] = np.hypot(x[1:3 * n3:3], x[2:3 * n3:3]) * (1 + rng.uniform(1e-6, 1, n3))
    x[3 * n3:] = np.abs(x[3 * n3:]) + rng.uniform(1e-6, 1, n1)
    return x.astype(dtype)


def _own_steps(n3, x, dx, compiled):
    """Each cone's step to the boundary, measured on that cone alone."""
    one3, one1 = ProductCone(1, 0, compiled=compiled), ProductCone(0, 1, compiled=compiled)
    return ([one3.max_step(x[3 * c:3 * c + 3], dx[3 * c:3 * c + 3]) for c in range(n3)]
            + [one1.max_step(x[i:i + 1], dx[i:i + 1]) for i in range(3 * n3, x.size)])


@given(seed=st.integers(0, 2**31), n3=st.integers(0, 7), n1=st.integers(0, 4), compiled=st.booleans(),
       longdouble=st.booleans(), tie=st.sampled_from(["none", "cones", "sides"]))
@example(seed=3, n3=4, n1=0, compiled=True, longdouble=False, tie="cones")   # equal cones: the first
@example(seed=4, n3=0, n1=3, compiled=True, longdouble=False, tie="cones")   # equal L1 cones
@example(seed=5, n3=2, n1=2, compiled=True, longdouble=False, tie="sides")   # z and s equal: z
@example(seed=9, n3=3, n1=0, compiled=False, longdouble=True, tie="cones")   # the numpy route, longdouble
@example(seed=6, n3=3, n1=2, compiled=False, longdouble=False, tie="sides")
def test_the_stepper_names_the_first_cone_whose_own_step_is_the_step(seed, n3, n1, compiled, longdouble, tie):
    if n3 + n1 == 0:
        n3 = 1
    rng = np.random.default_rng(seed)
    dtype = np.longdouble if longdouble else np.float64
    z, s = _interior(rng, n3, n1, dtype), _interior(rng, n3, n1, dtype)
    dz, ds = (rng.normal(size=3 * n3 + n1).astype(dtype) for _ in range(2))
    if tie == "cones":  # every cone of a family a copy of its first, and s never limits: the first is named
        for x in (z, dz):
            x[:3 * n3] = np.tile(x[:3], n3)
            x[3 * n3:] = x[3 * n3] if n1 else x[3 * n3:]
        dz[:] = -np.abs(dz) if n3 == 0 else dz
        ds[:] = 0
    elif tie == "sides":  # the same pair on both sides: the z side is named
        s, ds = z.copy(), dz.copy()
    cone = ProductCone(n3, n1, compiled=compiled)
    step, limit = cone.stepper(z, s)(dz, ds)
    own = {"z": _own_steps(n3, z, dz, compiled), "s": _own_steps(n3, s, ds, compiled)}
    if step == np.inf:
        assert limit is None and min(min(own["z"]), min(own["s"])) == np.inf
        return
    k, side = limit
    assert own[side][k] == step  # the named cone sets the step, to the bit
    assert all(x > step for x in own[side][:k]) and all(x >= step for x in own[side])  # the first such cone
    other = own["s" if side == "z" else "z"]
    assert all(x > step for x in other) if side == "s" else all(x >= step for x in other)  # z on a tie
    assert cone.max_step_pair(z, dz, s, ds) == step and cone.max_step(z, dz) == min(own["z"])


def _exact(a) -> mpmath.mpf:
    """A float64 or longdouble number exactly (as the sum of two doubles)."""
    hi = float(a)
    return mpmath.mpf(hi) + mpmath.mpf(float(a - np.longdouble(hi)))


def _ray_step(x, dx) -> mpmath.mpf:
    """The step from an interior x along dx to the boundary of its cone (L3 for 3 entries, else
    L1), from the quadratic x0 + αdx0 = ‖x̄ + αdx̄‖ in 50-digit arithmetic."""
    with mpmath.workdps(50):
        x, dx = [_exact(a) for a in x], [_exact(a) for a in dx]
        if len(x) == 1:
            return -x[0] / dx[0] if dx[0] < 0 else mpmath.inf
        a = dx[0] ** 2 - dx[1] ** 2 - dx[2] ** 2
        b = 2 * (x[0] * dx[0] - x[1] * dx[1] - x[2] * dx[2])
        c = x[0] ** 2 - x[1] ** 2 - x[2] ** 2
        roots = [-c / b] if a == 0 else ([] if b * b < 4 * a * c else
                                          [(-b - mpmath.sqrt(b * b - 4 * a * c)) / (2 * a),
                                           (-b + mpmath.sqrt(b * b - 4 * a * c)) / (2 * a)])
        ok = [t for t in roots if t > 0 and x[0] + t * dx[0] >= 0]
        return min(ok) if ok else mpmath.inf


def _rows(lp, cone):
    return slice(3 * cone, 3 * cone + 3) if cone < lp.n3 else slice(2 * lp.n3 + cone, 2 * lp.n3 + cone + 1)


def _check_steps_from_iterates(problem, res):
    """Each step the trace says a cone held: the kept iterates moved by α·(dz, Jᵀdr̃), and along
    that direction the named cone's boundary is α/γ away and no cone's, on either side, is
    nearer (to the rounding of the iterates: 1e-4 relative)."""
    lp = lift(problem)
    tr, its = res.trace, res.extras["iterates"]
    J = lp.J.tocsc()
    checked = 0
    for k in range(len(its) - 1):
        alpha, gamma, cone, side = (float(tr["alpha"][k]), float(tr["gamma"][k]), int(tr["step_cone"][k]),
                                    int(tr["step_side"][k]))
        if alpha >= 1.0:
            assert cone == -1 and side == -1
            continue
        assert cone >= 0 and side in (0, 1)
        (_, r0, z0), (_, r1, z1) = its[k], its[k + 1]
        pairs = []
        for x0, x1 in ((z0, z1), (J.T @ r0, J.T @ r1)):
            x0, x1 = np.asarray(x0), np.asarray(x1)
            pairs.append((x0, (x1 - x0) / alpha))
        steps = [[_ray_step(x0[_rows(lp, c)], dx[_rows(lp, c)]) for c in range(lp.n_cones)] for x0, dx in pairs]
        named = steps[side][cone]
        assert abs(named - alpha / gamma) <= 1e-4 * alpha / gamma, (k, named, alpha / gamma)
        assert min(min(steps[0]), min(steps[1])) >= named * (1 - 1e-4), k
        checked += 1
    return checked


@given(seed=st.integers(0, 10**6), bodies=st.integers(2, 6), contacts=st.integers(3, 12))
@settings(max_examples=8, deadline=None)
@example(seed=11, bodies=4, contacts=9)
def test_the_named_cone_is_where_the_kept_iterates_met_the_boundary(seed, bodies, contacts):
    problem = random_problem(bodies, contacts, seed=seed, mu_zero_fraction=0.2, mu_r_zero_fraction=0.2)
    res = rfverify.solve(problem, method="jqinv", keep_iterates=True)
    _check_steps_from_iterates(problem, res)


def test_the_chutes_steps_are_checked_against_its_iterates():
    problem = rfverify.load("bundled:chute")
    res = rfverify.solve(problem, method="jqinv", keep_iterates=True)
    assert _check_steps_from_iterates(problem, res) >= 3  # the test saw short steps


def test_a_split_problems_cones_are_the_lifted_problems():
    """Solved as independent components, every cone a trace names (the held steps and the
    smallest λ2) is one of that component's cones of the lifted problem, not its index inside
    the component; steps_held says the same as the traces, in words."""
    problem = rfverify.load("bundled:chute")
    res = rfverify.solve(problem, method="jqinv")
    lp = lift(problem)
    groups = presolve(problem, Settings()).groups
    runs = res.extras["component_runs"]
    assert len(runs) == len(groups) > 1
    want = []
    for c, (run, (*_, cone_ids, _n)) in enumerate(zip(runs, groups)):
        tr = run["trace"]
        for key in ("min_lam2_z_cone", "min_lam2_s_cone"):
            assert set(np.asarray(tr[key]).tolist()) <= set(cone_ids.tolist()), (c, key)
        for k, (alpha, cone, side) in enumerate(zip(tr["alpha"], tr["step_cone"], tr["step_side"])):
            if cone >= 0:
                assert cone in cone_ids and alpha < 1
                want.append({"from_iteration": k, "alpha": float(alpha), "cone": int(cone),
                             "contact": int(lp.cone_contact[cone]),
                             "part": ("friction", "rolling", "normal")[int(lp.cone_part[cone])],
                             "side": ("velocity", "reaction")[int(side)], "component": c})
    assert want and res.steps_held == want
    assert {h["component"] for h in want} != {0}  # the components after the first are named too
    assert res.as_dict()["steps_held"] == want


def test_the_verbose_table_and_the_json_name_the_cone(capsys):
    code = main(["solve", "bundled:chute", "--method", "jqinv", "--verbose"])
    table = capsys.readouterr().out.splitlines()
    assert code == 0
    head = next(i for i, line in enumerate(table) if line.startswith("comp iter"))
    assert table[head].endswith("  held by")
    code = main(["solve", "bundled:chute", "--method", "jqinv", "--json"])
    out = json.loads(capsys.readouterr().out)
    held = {(h["component"], h["from_iteration"]): h for h in out["steps_held"]}
    rows = [line.split() for line in table[head + 2:] if line[:4].strip().isdigit()]
    assert len(rows) == sum(len(c["trace"]["iter"]) for c in out["component_traces"])
    for cells in rows:
        comp, k, line = int(cells[0]), int(cells[1]), " ".join(cells)
        h = held.pop((comp, k), None)
        if h is None:
            assert "held by" not in line and "cone (" not in line
        else:
            assert line.endswith(f"contact {h['contact']}'s {h['part']} cone ({h['side']})"), line
    assert held == {}  # every listed step had its row


def _info(k, alpha, held, method="schur", component=0):
    nan = float("nan")
    return IterationInfo(component=component, iteration=k, criterion=1e-5, pinfeas=nan, dinfeas=nan, mu=1e-6,
                         sigma=0.1, alpha_aff=0.9, alpha=alpha, min_lam2_z=nan, min_lam2_s=nan, max_cond_Qp=nan,
                         solve_residual=nan, elapsed=1.0, method=method, held_by=held)


def test_the_progress_line_names_the_step_that_led_to_its_iterate_and_the_row_its_own():
    """As the extended phase's lines do, each progress line ends with the step from the previous
    iteration (shown or not) to its iterate; the table's row, like its α, has the step taken from
    it."""
    held = {"cone": 12, "contact": 5, "part": "rolling", "side": "velocity"}
    lines = []
    progress = IterationProgress(lines.append, after=0.0, every=0.0)
    for info in (_info(6, 0.953, held), _info(7, 1.0, None), _info(8, 0.5, {"cone": 3, "side": "reaction"}),
                 _info(9, 0.9, held), _info(0, 0.9, held, method="jqinv"), _info(4, 0.9, held, component=1)):
        progress(info)
    assert [re.sub(r"^.*, [\d.]+ s", "", line) for line in lines] == [
        "",  # the first line of the run: no step led to it here
        "; step 0.953, held by contact 5's rolling cone (velocity)",
        "; full step",
        "; step 0.5",  # a cone without a contact (a run given no names)
        "", ""]  # another form, another component: not the previous line's step
    quiet = []
    spaced = IterationProgress(quiet.append, after=0.0, every=3600.0)
    spaced(_info(0, 0.7, held)), spaced(_info(1, 0.9, None)), spaced(_info(2, 1.0, None))
    assert len(quiet) == 1  # spaced out; the step of a line not shown is still the next one's
    spaced.every = 0.0
    spaced(_info(3, 1.0, None))
    assert quiet[-1].endswith("; full step")
    assert row(_info(6, 0.953, held), False).endswith(" contact 5's rolling cone (velocity)")
    assert row(_info(7, 1.0, None), False).endswith("1.000")


def test_a_peer_has_no_steps_to_name():
    res = rfverify.solve(rfverify.load("bundled:sphere"), method="clarabel")
    assert res.steps_held == [] and res.as_dict()["steps_held"] == []
