"""Long compiled kernels obey the time limit and Ctrl-C, and a double-double factorisation that
cannot fit or cannot end in time is refused before it starts (rfverify.extended.stoppable,
DDCholesky.factor).  A 96 256-contact touching bed was inside its double-double fallback
factorisation 50 minutes into its run, past its 2400 s time limit and two Ctrl-Cs, with 1 GB of
memory left."""

from __future__ import annotations

import _thread
import threading
import time

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

import rfverify
from rfverify.algorithm.interfaces import OutOfTime
from rfverify.extended import ldl
from rfverify.extended.ldl import DDCholesky, FactorTooLarge
from rfverify.extended.stoppable import long_kernels, run_stoppable


def _laplacian_factor(k: int, with_matrix: bool = False):
    """DDCholesky of a 3-D Laplacian (k³ rows, shifted to be SPD) and its values (and the matrix)."""
    eye = sp.identity(k)
    T = sp.diags([-1.0, 2.5, -1.0], [-1, 0, 1], shape=(k, k))
    A = (sp.kron(sp.kron(T, eye), eye) + sp.kron(sp.kron(eye, T), eye) + sp.kron(sp.kron(eye, eye), T)).tocsc()
    chol = DDCholesky(A)
    values = _values_for(chol, A)
    return (chol, values, A) if with_matrix else (chol, values)


def _values_for(factor, A):
    """A's entries in ``factor``'s stored upper triangle (its ``positions``)."""
    cols = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    values = np.zeros(factor.nnz_upper)
    values[factor.positions(A.indices, cols)] = A.data
    return values


@pytest.fixture(scope="module")
def long_factor():
    """A factorisation of about 2·10⁹ multiply-adds (over 10 s at the measured rate)."""
    chol, values = _laplacian_factor(28)
    assert chol.multiply_adds > 1.5e9 > 10 * ldl.STOPPABLE_ABOVE
    return chol, values


def test_the_time_limit_stops_a_running_factorisation(long_factor, monkeypatch):
    """Stopped partway (the last pivot never computed), OutOfTime naming what was stopped; the
    same factor then factors a small-enough matrix again from scratch correctly."""
    chol, values = long_factor
    monkeypatch.setattr(ldl, "FASTEST_RATE", 1e15)  # not refused up front: started, then stopped
    said = []
    with long_kernels(time.perf_counter() + 0.5, said.append), pytest.raises(OutOfTime, match="was stopped"):
        chol.factor(values, np.zeros_like(values))
    assert chol.Dh[-1] == 0.0 and not chol.factored  # stopped before its last row
    assert said and "multiply-adds" in said[0] and "Ctrl-C or the time limit stop it" in said[0]


def test_ctrl_c_stops_a_running_factorisation(long_factor):
    chol, values = long_factor
    timer = threading.Timer(0.5, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            chol.factor(values, np.zeros_like(values))
    finally:
        timer.cancel()
    assert chol.Dh[-1] == 0.0 and not chol.factored
    for thread in threading.enumerate():  # the kernel returned: its thread ends
        if thread.name == "rfverify-stoppable":
            thread.join(10.0)
            assert not thread.is_alive()


def test_a_factorisation_that_cannot_end_in_time_is_not_started(long_factor):
    chol, values = long_factor
    chol.Dh[:] = 0.0
    with long_kernels(time.perf_counter() + 0.1), pytest.raises(OutOfTime, match="was not started"):
        chol.factor(values, np.zeros_like(values))
    assert not chol.Dh.any()  # refused before the first row


def test_a_factor_larger_than_the_memory_available_is_refused(monkeypatch):
    chol, values, A = _laplacian_factor(6, with_matrix=True)
    monkeypatch.setattr(ldl, "memory_available", lambda: chol.factor_bytes)  # 80 % of it is not enough
    with pytest.raises(FactorTooLarge, match=r"not started: its factor needs .* GiB is available"):
        chol.factor(values, np.zeros_like(values))
    monkeypatch.setattr(ldl, "memory_available", lambda: 2 * chol.factor_bytes)
    assert chol.factor(values, np.zeros_like(values)) == -1  # it fits: factored, and right
    b = np.arange(chol.n, dtype=np.float64)
    assert np.allclose(chol.solve(b, np.zeros(chol.n))[0], spsolve(A, b), rtol=1e-13, atol=0)


def test_a_solve_without_a_successful_factor_is_refused(monkeypatch):
    """A refused factorisation leaves no L, a failed one a partial L: neither may be solved with."""
    chol, values = _laplacian_factor(4)
    b = np.ones(chol.n)
    with pytest.raises(RuntimeError, match="without a successful factor"):
        chol.solve(b, np.zeros(chol.n))  # never factored
    monkeypatch.setattr(ldl, "memory_available", lambda: chol.factor_bytes)
    with pytest.raises(FactorTooLarge):
        chol.factor(values, np.zeros_like(values))
    with pytest.raises(RuntimeError, match="without a successful factor"):
        chol.solve(b, np.zeros(chol.n))  # refused
    monkeypatch.setattr(ldl, "memory_available", lambda: 2 * chol.factor_bytes)
    assert chol.factor(-values, np.zeros_like(values)) != -1  # −A: the first pivot fails
    with pytest.raises(RuntimeError, match="without a successful factor"):
        chol.solve(b, np.zeros(chol.n))


def test_the_multiply_add_count():
    """A dense n × n matrix: column j of L has n − 1 − j entries, Σ c(c − 1)/2 = C(n, 3)."""
    chol = DDCholesky(sp.csc_matrix(np.ones((10, 10))))
    assert chol.nnz_L == 45 and chol.multiply_adds == 120


def test_run_stoppable_hands_back_results_and_errors():
    assert run_stoppable(lambda a, b, stop: a + b + int(stop[0]), (2, 3), "an addition") == 5

    def broken(stop):
        raise ValueError("inside the kernel")

    with pytest.raises(ValueError, match="inside the kernel"):
        run_stoppable(broken, (), "a broken kernel")


def _hanging_kernel(calls):
    """A stand-in for numeric_ldl that runs until it is stopped (gives up after 60 s, saying so,
    so that a broken stop fails the test instead of hanging it)."""

    def kernel(*args):
        stop = args[-1]
        calls.append("started")
        t0 = time.perf_counter()
        while not stop[0]:
            if time.perf_counter() - t0 > 60:
                calls.append("never stopped")
                return -1
            time.sleep(0.005)
        calls.append("stopped")
        return -2

    return kernel


@pytest.mark.parametrize("threads", ["1", "2"])
def test_the_k_digit_path_ends_at_its_time_limit_inside_a_factorisation(monkeypatch, threads):
    """Every double-double factorisation hangs (as a huge one would): the path still ends at its
    time limit, status MaxTime, with the best proof reached before.  With one thread the hang is
    in the extended phase's first update; with two, in the set-up built beside the double solve
    (a thread Ctrl-C does not reach), and the first update then finds the time used up."""
    monkeypatch.setenv("RFVERIFY_THREADS", threads)
    problem = rfverify.load("bundled:chute")
    t0 = time.perf_counter()
    rfverify.solve_to_digits(problem, digits=10, factor_engine="ldl")  # warm: compiled, and timed
    warm = time.perf_counter() - t0
    calls = []
    monkeypatch.setattr(ldl, "numeric_ldl", _hanging_kernel(calls))
    monkeypatch.setattr(ldl, "STOPPABLE_ABOVE", 0.0)
    monkeypatch.setattr(ldl, "FASTEST_RATE", np.inf)
    sol = rfverify.solve_to_digits(problem, digits=10, factor_engine="ldl", time_limit=3.0 + 2.0 * warm)
    assert calls and calls[-1] == "stopped" and "never stopped" not in calls
    assert sol.timed_out and str(sol.status) == "MaxTime" and "time limit" in sol.message
    assert sol.certificate.proof is not None and sol.certificate.proof.valid  # the best proof so far stands
    if threads == "1":
        assert sol.extended.status == "MaxTime" and "was stopped" in sol.extended.message


def test_cancelling_the_set_up_stops_its_long_factorisation(monkeypatch):
    """The set-up built beside the double solve (a thread Ctrl-C does not reach) is cancelled
    when the path ends early (a Ctrl-C, the double answer proven): a factorisation it is inside
    stops, and cancel() returns."""
    from rfverify.verify.prepare import Preparation

    calls = []
    monkeypatch.setattr(ldl, "numeric_ldl", _hanging_kernel(calls))
    monkeypatch.setattr(ldl, "STOPPABLE_ABOVE", 0.0)
    prepared = Preparation(rfverify.load("bundled:chute"), "auto", "ldl", background=True)
    prepared.start()
    t0 = time.perf_counter()
    while not calls and time.perf_counter() - t0 < 60:
        time.sleep(0.01)
    assert calls == ["started"]
    prepared.cancel()
    assert calls == ["started", "stopped"]


def test_a_refused_fallback_is_named_in_the_time_line_and_not_counted(monkeypatch):
    """The refinement's fallback to the double-double factor, refused for memory: the time line
    counts no double-double factorisation and says which one was not finished, and why."""
    from rfverify.extended.mixed import MixedCholesky

    _, _, A = _laplacian_factor(6, with_matrix=True)
    mixed = MixedCholesky(A)
    values = _values_for(mixed, A)
    assert mixed.factor(values, np.zeros_like(values)) == -1
    monkeypatch.setattr(ldl, "memory_available", lambda: 1024)
    with pytest.raises(FactorTooLarge):
        mixed._fall_back("a test's reason")
    cost = mixed.describe_cost()
    assert "in double-double" not in cost and ", double-double 0.0 s (double-double from factorisation 1: " \
                                                "a test's reason)" in cost
    assert "; not finished: factorisation 1: the double-double factorisation of 216 rows was not started: " \
           "its factor needs" in cost


def test_the_cholmod_fallback_factors_in_cholmods_order():
    """The double-double fallback of a CHOLMOD-refined factor takes CHOLMOD's fill-reducing
    order (no minimum-degree LU of the pattern of its own), and solves right in it."""
    from rfverify.extended.mixed import CholmodMixed

    _, _, A = _laplacian_factor(8, with_matrix=True)
    mixed = CholmodMixed(A)
    values = _values_for(mixed, A)
    assert mixed.factor(values, np.zeros_like(values)) == -1
    order = mixed._engine.permutation()
    assert mixed._fall_back("a test's reason") == -1
    assert np.array_equal(mixed._dd.perm, order) and mixed.precision == "double-double"
    b = np.linspace(-1.0, 1.0, A.shape[0])
    assert np.allclose(mixed.solve(b, np.zeros_like(b))[0], spsolve(A, b), rtol=1e-13, atol=0)


def test_a_conjugate_gradient_solve_stops_at_the_time_limit():
    """At 10⁵ contacts one CG solve took over three minutes: each step checks the time limit."""
    from rfverify.extended import krylov

    chol, values, A = _laplacian_factor(4, with_matrix=True)
    U = sp.triu(A, format="csc")
    U.sort_indices()
    Ap, Ai = U.indptr.astype(np.int64), U.indices.astype(np.int64)
    b = np.ones(A.shape[0])
    with long_kernels(time.perf_counter() - 1.0), pytest.raises(OutOfTime, match="conjugate-gradient solve"):
        krylov.conjugate_gradients_in_double_double(Ap, Ai, (U.data.copy(), np.zeros(U.nnz)), b, np.zeros(b.size),
                                                    lambda r: r, 1e-29)
    out = krylov.conjugate_gradients_in_double_double(Ap, Ai, (U.data.copy(), np.zeros(U.nnz)), b, np.zeros(b.size),
                                                      lambda r: r, 1e-29)  # no time limit: solved
    assert out.backward <= 1e-29
