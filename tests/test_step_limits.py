"""Which cone cuts a step short: the double-double step kernel's arg-min, the scaling's
``limit``, its contact and part (checked against the lifting's own J), and what the extended
phase reports of it (progress lines and the certificate's ``extended_steps_held``)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import rfverify
from rfverify.extended import cones as C
from rfverify.extended import workers as W
from rfverify.extended.data import ExtendedData
from rfverify.extended.ipm import V, DDScaling
from rfverify.model.lifting import CONE_PARTS
from rfverify.verify.extend import held_by, step_words, steps_held
from tests.exact_problems import exact_problem


def _interior(rng, n3, n1):
    x = rng.normal(size=3 * n3 + n1)
    x[0:3 * n3:3] = np.hypot(x[1:3 * n3:3], x[2:3 * n3:3]) * (1 + rng.uniform(1e-6, 1, n3))
    x[3 * n3:] = np.abs(x[3 * n3:]) + rng.uniform(1e-6, 1, n1)
    return x


def _cone_steps(n3, x, dx):
    """Each cone's own step to the boundary, by the kernel on that cone alone."""
    zero = np.zeros(3)
    steps = [C.max_step(1, x[3 * c:3 * c + 3], zero, dx[3 * c:3 * c + 3], zero) for c in range(n3)]
    steps += [C.max_step(0, x[i:i + 1], zero[:1], dx[i:i + 1], zero[:1]) for i in range(3 * n3, x.size)]
    return steps


@given(st.integers(0, 2**31), st.integers(0, 8), st.integers(0, 5), st.booleans(), st.integers(2, 4))
@example(0, 5, 2, True, 3)   # a tie between cones 1 and 3: the first is named
@example(5, 0, 4, False, 2)  # L1 cones only
@example(7, 2, 0, False, 2)  # L3 cones only
def test_the_step_kernel_names_the_first_cone_that_sets_the_step(seed, n3, n1, tie, parts):
    if n3 + n1 == 0:
        return
    rng = np.random.default_rng(seed)
    x, dx = _interior(rng, n3, n1), rng.normal(size=3 * n3 + n1)
    if tie and n3 >= 4:  # cone 3 a copy of cone 1, both leaving at α = 1/4; the others never
        dx = x.copy()
        x[9:12] = x[3:6]
        dx[3:6], dx[9:12] = -4 * x[3:6], -4 * x[3:6]
    zero = np.zeros(x.size)
    best, at = C.max_step_at(n3, x, zero, dx, zero)
    assert best == C.max_step(n3, x, zero, dx, zero)
    steps = _cone_steps(n3, x, dx)
    if best == math.inf:
        assert at == -1 and all(s == math.inf for s in steps)
        return
    assert steps[at] == best
    assert all(s > best for s in steps[:at]) and all(s >= best for s in steps[at:])
    if tie and n3 >= 4:
        assert at == 1 and steps[3] == best
    # over the threads, split anywhere: the same step and the same cone
    old = C.split
    C.split = lambda n_items, run, min_items=0: W.split(n_items, run, min_items=1, parts=parts)
    try:
        assert C.max_step_at_threaded(n3, x, zero, dx, zero) == (best, at)
        assert C.max_step_threaded(n3, x, zero, dx, zero) == best
    finally:
        C.split = old


@pytest.mark.parametrize("side, cone", [("z", 0), ("z", 4), ("s", 2), ("s", 5), ("z", 6), ("s", 7)])
def test_the_scaling_names_the_side_and_the_cone_that_cut_the_step(side, cone):
    """n3 = 6 L3 cones then 2 L1 cones; the direction sends ``cone`` of ``side`` out at α = 1/8,
    every other cone of either side later."""
    rng = np.random.default_rng(3)
    n3, n1 = 6, 2
    nz = 3 * n3 + n1
    z, s = _interior(rng, n3, n1), _interior(rng, n3, n1)
    e = np.zeros(nz)
    e[0:3 * n3:3] = 1.0
    e[3 * n3:] = 1.0
    sc = DDScaling(n3, nz, n3 + n1, V(e), V(z), V(s))
    dz, ds = -0.5 * z, -0.5 * s  # both sides leave at α = 2
    entries = slice(3 * cone, 3 * cone + 3) if cone < n3 else slice(2 * n3 + cone, 2 * n3 + cone + 1)
    (dz if side == "z" else ds)[entries] *= 16  # this one at α = 1/8
    step = sc.max_step(V(dz), V(ds))
    assert step == pytest.approx(0.125, rel=1e-12)
    assert sc.limit == (cone, side)
    assert sc.max_step(V(np.zeros(nz)), V(np.zeros(nz))) == math.inf and sc.limit is None


def _all_kinds():
    """A 7-contact problem with every kind of contact: μ = 0 at contacts 2 and 5, μ_r = 0 at 3
    and 5 (so 0, 1, 4, 6 full; 2 rolling only; 3 Coulomb only; 5 normal only)."""
    problem = exact_problem(11, 7)[0]
    mu, mu_r = problem.mu.copy(), problem.mu_r.copy()
    mu[[2, 5]] = 0.0
    mu_r[[3, 5]] = 0.0
    return dataclasses.replace(problem, mu=mu, mu_r=mu_r)


def test_a_limit_is_named_by_the_contact_and_part_the_lifting_gave_that_cone():
    """Every cone of a problem with all four contact kinds, mapped back through J (the lifting's
    matrix from kept components to cone entries) and ``keep`` (kept component → contact, part)."""
    data = ExtendedData(_all_kinds())
    lp = data.lp
    assert len(set(lp.kinds.tolist())) == 4  # full, Coulomb only, rolling only, normal only
    J = lp.J.tocsc()
    for cone in range(lp.n3 + lp.n1):
        first_entry = 3 * cone if cone < lp.n3 else 3 * lp.n3 + (cone - lp.n3)
        row = J.indices[J.indptr[first_entry]:J.indptr[first_entry + 1]]
        assert row.size == 1  # a cone's first entry is one kept component: the normal one
        entry_rows = [J.indices[J.indptr[i]:J.indptr[i + 1]][0]
                      for i in range(first_entry, first_entry + (3 if cone < lp.n3 else 1))]
        components = [int(lp.keep[k] % 5) for k in entry_rows]
        contact = int(lp.keep[row[0]] // 5)
        part = "normal" if cone >= lp.n3 else ("friction" if components[1:] == [1, 2] else "rolling")
        for side, words in (("z", "velocity"), ("s", "reaction")):
            assert held_by(data, (cone, side)) == {"contact": contact, "part": part, "side": words}
    assert held_by(data, None) is None
    assert set(CONE_PARTS) == {"friction", "rolling", "normal"}


def test_the_step_words_and_the_list_say_what_the_trace_holds():
    data = ExtendedData(_all_kinds())
    assert step_words(data, None) == ""
    assert step_words(data, (1.0, (0, "z"))) == "; full step"
    assert step_words(data, (0.5, None)) == "; step 0.5"
    held = held_by(data, (3, "s"))
    assert step_words(data, (0.9371, (3, "s"))) == (f"; step 0.937, held by contact {held['contact']}'s "
                                                    f"{held['part']} cone (reaction)")
    trace = {"alpha": [0.9, 1.0, 0.5], "limit": [(3, "s"), (0, "z"), None]}
    assert steps_held(data, trace) == [{"from_iteration": 0, "alpha": 0.9, **held},
                                       {"from_iteration": 2, "alpha": 0.5}]


def test_the_ten_digit_path_reports_each_short_step_and_its_cone(capsys):
    """The certificate lists the double-double run's steps shorter than 1, each with the cone
    whose boundary cut it short; the progress lines say the same of the step before each
    iterate."""
    problem = rfverify.load("bundled:chute")
    lines = []
    res = rfverify.solve_to_digits(problem, 10, progress=lines.append)
    held = res.certificate.extra["extended_steps_held"]
    trace = res.extended.trace
    assert [h["from_iteration"] for h in held] == [k for k, a in enumerate(trace["alpha"]) if a < 1]
    assert held and all(0 < h["alpha"] < 1 and h["part"] in CONE_PARTS and h["side"] in ("velocity", "reaction")
                        and 0 <= h["contact"] < problem.n_contacts for h in held)
    said = [line for line in lines if "extended iteration" in line and "step" in line]
    for h in held:
        want = (f"extended iteration {h['from_iteration'] + 1}: ", f"held by contact {h['contact']}'s "
                f"{h['part']} cone ({h['side']})")
        assert any(all(w in line for w in want) for line in said), (want, said)


@given(st.integers(0, 2**31), st.integers(0, 6), st.integers(0, 4))
@example(3, 5, 2)
def test_the_multiple_precision_step_names_the_same_cone_as_double_double(seed, n3, n1):
    """The 320-bit tail's arg-min (jordan.mpfr.max_step_at) and the double-double kernel's agree
    on the same exactly representable data: the same cone, steps within double-double rounding."""
    from rfverify.extended import wide_data
    from rfverify.jordan import mpfr as JM

    if n3 + n1 == 0:
        return
    rng = np.random.default_rng(seed)
    x, dx = _interior(rng, n3, n1), rng.normal(size=3 * n3 + n1)
    zero = np.zeros(x.size)
    best, at = C.max_step_at(n3, x, zero, dx, zero)
    with wide_data.context(320):
        wide_best, wide_at = JM.max_step_at(n3, wide_data.from_dd(x), wide_data.from_dd(dx))
    steps = sorted(_cone_steps(n3, x, dx))
    if best == math.inf:
        assert wide_best == math.inf and wide_at == -1
    elif len(steps) < 2 or steps[1] > steps[0] * (1 + 1e-20):  # a clear minimum: both name it
        assert wide_at == at and wide_best == pytest.approx(best, rel=1e-25)
