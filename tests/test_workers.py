"""The double-double kernels over threads (rfverify.extended.workers): every split call gives
the single call's result bit for bit, reports the first bad item by its global index, and
survives a fork; ``RFVERIFY_THREADS`` is validated."""

from __future__ import annotations

import multiprocessing as mp

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st

import rfverify
from rfverify.errors import InvalidArgumentError
from rfverify.extended import blocks as B
from rfverify.extended import cones as C
from rfverify.extended import contactspace as CS
from rfverify.extended import data as D
from rfverify.extended import workers as W
from rfverify.scenes.random_problems import random_problem


def _force_split(monkeypatch, parts: int):
    """Every split call site splits into ``parts`` ranges whatever its size."""
    real = W.split

    def forced(n_items, run, min_items=0, parts_=None):
        return real(n_items, run, min_items=1, parts=parts)

    for module in (C, B, CS, D):
        monkeypatch.setattr(module, "split", forced)


@given(st.integers(0, 50), st.integers(1, 7))
@example(0, 3)
@example(2, 5)
def test_ranges_cover_every_item_once_in_order(n, parts):
    chunks = W.ranges(n, parts)
    covered = [i for lo, hi in chunks for i in range(lo, hi)]
    assert covered == list(range(n))
    assert all(hi > lo for lo, hi in chunks) and len(chunks) <= parts


def test_split_runs_every_range_and_keeps_their_order():
    seen = []
    out = W.split(10, lambda lo, hi: (seen.append((lo, hi)), (lo, hi))[1], min_items=1, parts=3)
    assert out == [(0, 3), (3, 6), (6, 10)] and sorted(seen) == out
    assert W.split(10, lambda lo, hi: (lo, hi), min_items=11, parts=3) == [(0, 10)]  # too few items: one call
    assert W.split(10, lambda lo, hi: (lo, hi), min_items=1, parts=1) == [(0, 10)]


def test_an_error_in_a_worker_range_reaches_the_caller():
    def run(lo, hi):
        if lo > 0:
            raise ZeroDivisionError("in the second range")
        return 0

    with pytest.raises(ZeroDivisionError, match="second range"):
        W.split(10, run, min_items=1, parts=2)


@pytest.mark.parametrize("value", ["0", "-2", "two", "1.5"])
def test_a_bad_thread_count_is_refused_naming_the_variable(monkeypatch, value):
    monkeypatch.setenv("RFVERIFY_THREADS", value)
    with pytest.raises(InvalidArgumentError, match="RFVERIFY_THREADS"):
        W.threads()


def test_the_thread_count_follows_the_variable(monkeypatch):
    monkeypatch.setenv("RFVERIFY_THREADS", "3")
    assert W.threads() == 3
    monkeypatch.delenv("RFVERIFY_THREADS")
    assert W.threads() >= 1


def _split_in_child(queue):
    queue.put(W.split(6, lambda lo, hi: hi - lo, min_items=1, parts=2))


def test_a_forked_child_can_split_after_its_parent_did():
    """The parent's pool threads do not exist in a forked child (the bench forks its tasks):
    the child must start its own instead of queueing work for threads that never run."""
    W.split(6, lambda lo, hi: hi - lo, min_items=1, parts=2)  # the parent's pool exists now
    ctx = mp.get_context("fork")
    queue = ctx.Queue()
    child = ctx.Process(target=_split_in_child, args=(queue,))
    child.start()
    child.join(60)
    hung = child.is_alive()
    if hung:
        child.kill()
    assert not hung and child.exitcode == 0 and queue.get(timeout=5) == [3, 3]


def _interior(rng, n3, n1):
    x = rng.normal(size=3 * n3 + n1)
    x[0:3 * n3:3] = np.hypot(x[1:3 * n3:3], x[2:3 * n3:3]) * (1 + rng.uniform(1e-6, 1, n3))
    x[3 * n3:] = np.abs(x[3 * n3:]) + rng.uniform(1e-6, 1, n1)
    return x


@given(st.integers(0, 2**31), st.integers(1, 9), st.integers(0, 6), st.integers(2, 4))
@example(0, 5, 3, 3)
@example(1, 1, 0, 2)
def test_cone_kernels_split_give_the_single_call_bit_for_bit(seed, n3, n1, parts):
    rng = np.random.default_rng(seed)
    z, s, y, dy = _interior(rng, n3, n1), _interior(rng, n3, n1), rng.normal(size=3 * n3 + n1), rng.normal(size=3 * n3 + n1)
    low = [1e-17 * rng.normal(size=z.size) for _ in range(4)]
    nz, nc = z.size, n3 + n1
    results = []
    for k in (1, parts):
        W_split = (lambda n_items, run, min_items=0, k=k: W.split(n_items, run, min_items=1, parts=k))
        old = C.split
        C.split = W_split
        try:
            out = [np.zeros(nz) for _ in range(6)] + [np.zeros((nc, 8))]
            assert C.nt_scaling_threaded(n3, z, low[0], s, low[1], *out) == -1
            table = np.zeros((nc, 6))
            C.spectral_table(n3, -1, out[6], table)
            qh, ql = np.zeros(nz), np.zeros(nz)
            C.quad_spectral_threaded(n3, table, out[6], y, low[2], qh, ql)
            step = C.max_step_threaded(n3, z, low[0], dy, low[3])
        finally:
            C.split = old
        results.append(([a.copy() for a in out], qh, ql, step))
    (a1, q1h, q1l, st1), (a2, q2h, q2l, st2) = results
    assert all(np.array_equal(x, y_) for x, y_ in zip(a1, a2))
    assert np.array_equal(q1h, q2h) and np.array_equal(q1l, q2l) and st1 == st2
    # and the single call is the kernel itself
    ref = [np.zeros(nz) for _ in range(6)] + [np.zeros((nc, 8))]
    C.nt_scaling(n3, z, low[0], s, low[1], *ref)
    assert all(np.array_equal(x, y_) for x, y_ in zip(a1, ref))
    assert st1 == C.max_step(n3, z, low[0], dy, low[3])


@pytest.mark.parametrize("bad", [0, 4, 6, 9])
def test_a_non_interior_cone_is_reported_by_its_own_index_from_any_range(monkeypatch, bad):
    """n3 = 6 L3 cones then 4 L1 cones, split in three: cone ``bad`` (L3 below 6, L1 from 6)
    leaves its cone; the split call names it as the single call does."""
    rng = np.random.default_rng(3)
    n3, n1 = 6, 4
    z, s = _interior(rng, n3, n1), _interior(rng, n3, n1)
    if bad < n3:
        z[3 * bad] = -1.0
    else:
        z[3 * n3 + bad - n3] = -1.0
    zero = np.zeros(z.size)
    out = lambda: [np.zeros(z.size) for _ in range(6)] + [np.zeros((n3 + n1, 8))]
    single = C.nt_scaling(n3, z, zero, s, zero, *out())
    monkeypatch.setattr(C, "split", lambda n, run, min_items=0: W.split(n, run, min_items=1, parts=3))
    assert single == bad and C.nt_scaling_threaded(n3, z, zero, s, zero, *out()) == bad


def test_contact_factors_split_are_the_single_call_and_name_the_first_singular_contact(monkeypatch):
    """contact_factor_inverse over three ranges: the same blocks bit for bit as one call, and a
    singular contact named by its global index (its index inside a later range plus where that
    range starts; the kernel's own singular case is exercised by a stand-in that flags it)."""
    problem = random_problem(8, 30, seed=2)
    data = D.ExtendedData(problem)
    res = rfverify.solve(problem, tol=1e-8)
    from rfverify.extended import dd

    zh, zl = dd.from_longdouble(res.extras["z"])
    sh, sl = data.JT.matvec(*dd.from_longdouble(res.extras["r_t"]))
    nz, nc = data.nz, data.n3 + data.n1
    ph, pl, pih, pil, lh, ll = (np.zeros(nz) for _ in range(6))
    spec = np.zeros((nc, 8))
    assert C.nt_scaling(data.n3, zh, zl, sh, sl, ph, pl, pih, pil, lh, ll, spec) == -1
    assert np.any(data.kinds == 0)  # full contacts: the Householder blocks
    F = lambda: (np.zeros((data.n, 5, 5)), np.zeros((data.n, 5, 5)))
    args = (data.n, data.kinds, data.fric_cone, data.roll_cone, data.normal_cone)
    monkeypatch.setattr(B, "split", lambda n, run, min_items=0: W.split(n, run, min_items=1, parts=3))
    F1, F2 = F(), F()
    assert B.contact_factor_inverse(*args, spec, *F1) == -1 == B.contact_factor_inverse_threaded(*args, spec, *F2)
    assert np.array_equal(F1[0], F2[0]) and np.array_equal(F1[1], F2[1])

    def flags_99(n, kinds, *rest):  # stands in for the kernel: the first contact of kind 99 is singular
        hits = np.flatnonzero(kinds[:n] == 99)
        return int(hits[0]) if hits.size else -1

    monkeypatch.setattr(B, "contact_factor_inverse", flags_99)
    for victims in ([data.n - 1], [1, data.n - 1], [data.n // 2, data.n - 2]):
        kinds = data.kinds.copy()
        kinds[victims] = 99
        assert B.contact_factor_inverse_threaded(data.n, kinds, *args[2:], spec, *F()) == min(victims)


def test_the_ten_digit_path_is_the_same_bit_for_bit_on_one_thread_and_on_three(monkeypatch):
    """Every split kernel of the double-double phase (matrix products, cones, contact factors,
    S' assembly, block products) in three ranges: the same proven point as in one call."""
    problem = random_problem(30, 90, seed=7)
    points = []
    for parts in (1, 3):
        _force_split(monkeypatch, parts)
        out = rfverify.solve_to_digits(problem, digits=10)
        assert out.certificate.certified and out.extended.nit > 0
        points.append(np.concatenate([out.point.v_hi, out.point.v_lo, out.point.r_hi, out.point.r_lo]))
    assert np.array_equal(points[0], points[1])


def test_the_cli_refuses_a_bad_thread_count_in_one_line_before_solving(monkeypatch, capsys):
    from rfverify.cli import main

    monkeypatch.setenv("RFVERIFY_THREADS", "0")
    code = main(["solve", "bundled:chute", "--digits", "10"])
    out, err = capsys.readouterr()
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "RFVERIFY_THREADS" in err and "fix:" in err
