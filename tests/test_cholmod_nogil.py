"""CHOLMOD's numeric factorisation without the GIL (rfverify.solver.cholmod_nogil): the same
factor as cvxopt's own call bit for bit, other threads run during it, an indefinite matrix is
refused as before, and anything unexpected falls back to cvxopt's call."""

import ctypes
import sys
import threading
import time

import numpy as np
import pytest
import scipy.sparse as sp

from rfverify.solver import cholmod_nogil
from rfverify.solver.engines import CholmodEngine

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="the GIL-free call reads /proc/self/maps (Linux)")


def spd(n, seed, density=4e-3):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng)
    return sp.tril((A @ A.T + sp.identity(n) * 2.0).tocsc(), format="csc")


def cvxopt_engine():
    engine = CholmodEngine()
    engine._nogil = None  # cvxopt's own cholmod.numeric
    return engine


def test_available_here_and_bit_for_bit_cvxopts_factor():
    assert cholmod_nogil.factorizer() is not None, "cvxopt's libcholmod was not found among the mapped files"
    for seed in range(3):
        K = spd(1500 + 500 * seed, seed)
        ours, theirs = CholmodEngine(), cvxopt_engine()
        assert ours.releases_gil and not theirs.releases_gil
        b = np.random.default_rng(seed).standard_normal(K.shape[0])
        for scale in (1.0, 3.0):  # the first factorisation and a refactorisation on the same pattern
            K2 = K.copy()
            K2.data = K.data * scale
            ours.factor(K2)
            theirs.factor(K2)
            x, y = ours.solve(b), theirs.solve(b)
            assert np.array_equal(x, y)
            full = K2 + sp.tril(K2, -1).T
            assert np.abs(full @ x - b).max() < 1e-10 * np.abs(b).max() * np.abs(x).max() * 10


def _progress_during(engine, K):
    """Steps a Python thread makes while ``engine`` factors ``K`` (the GIL-free call lets it run)."""
    count, stop = [0], [False]

    def spin():
        while not stop[0]:
            count[0] += 1

    thread = threading.Thread(target=spin)
    thread.start()
    time.sleep(0.02)
    try:
        before = count[0]
        engine.factor(K)
        return count[0] - before
    finally:
        stop[0] = True
        thread.join()


def test_other_threads_run_while_it_factors():
    K = spd(6000, 7, density=1.5e-3)
    ours, theirs = CholmodEngine(), cvxopt_engine()
    ours.factor(K)  # analysed: the timed calls only factor
    theirs.factor(K)
    t0 = time.perf_counter()
    theirs.factor(K)
    assert time.perf_counter() - t0 > 0.02, "the matrix must take a while to factor for this test to say anything"
    free, held = _progress_during(ours, K), _progress_during(theirs, K)
    assert free > 20 * max(held, 1000), (free, held)


def test_an_indefinite_matrix_is_refused_at_the_same_column_as_by_cvxopt(capfd):
    K = spd(800, 3)
    bad = K.copy()
    bad.data = bad.data.copy()
    bad.data[bad.indptr[400]] = -5.0  # a negative diagonal entry (column 400's first stored entry)
    messages = []
    for engine in (CholmodEngine(), cvxopt_engine()):
        engine.factor(K)
        with pytest.raises(ArithmeticError) as info:
            engine.factor(bad)
        messages.append(str(info.value))
        assert engine.factorisations == 1
        engine.factor(K)  # the factor is usable again afterwards
    assert messages[0] == messages[1] and "not positive definite" in messages[0]
    assert capfd.readouterr() == ("", "")  # CHOLMOD prints nothing (print = 0, as cvxopt sets it)


def test_an_error_reported_by_cholmod_goes_to_cvxopts_call(monkeypatch):
    K = spd(600, 4)
    engine = CholmodEngine()
    calls = []
    monkeypatch.setattr(cholmod_nogil.Factorizer, "factorize", lambda self, *a: calls.append(1))  # returns None
    engine.factor(K)
    b = np.ones(K.shape[0])
    reference = cvxopt_engine()
    reference.factor(K)
    assert calls and np.array_equal(engine.solve(b), reference.solve(b))


def test_an_unexpected_cholmod_common_layout_means_cvxopts_call(monkeypatch):
    monkeypatch.setattr(cholmod_nogil, "_checked", False)
    monkeypatch.setattr(cholmod_nogil, "_lib", None)
    wrong = tuple((off, fmt, want + 1) if off == cholmod_nogil._PRINT_OFFSET else (off, fmt, want)
                  for off, fmt, want in cholmod_nogil._EXPECTED_DEFAULTS)
    monkeypatch.setattr(cholmod_nogil, "_EXPECTED_DEFAULTS", wrong)
    assert cholmod_nogil.factorizer() is None
    engine = CholmodEngine()
    assert not engine.releases_gil
    K = spd(500, 5)
    engine.factor(K)
    assert np.all(np.isfinite(engine.solve(np.ones(500))))


def test_only_cvxopts_factor_of_a_lower_triangle_is_accepted():
    fz = cholmod_nogil.factorizer()
    other = ctypes.pythonapi.PyCapsule_New
    other.restype = ctypes.py_object
    other.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_void_p]
    keep = ctypes.c_char_p(b"not a factor")
    capsule = other(ctypes.addressof(ctypes.c_int(0)), keep, None)
    z = np.zeros(2, dtype=np.int64)
    with pytest.raises(TypeError, match="not cvxopt's factor"):
        fz.factorize(capsule, z, z[:0], np.zeros(0))
    K = spd(50, 1)
    engine = CholmodEngine()
    engine.analyse(K)
    with pytest.raises(ValueError, match="int64"):
        fz.factorize(engine._factor, K.indptr.astype(np.int32), K.indices.astype(np.int64), K.data)
    with pytest.raises(ValueError, match="order"):
        small = spd(40, 2)
        fz.factorize(engine._factor, small.indptr.astype(np.int64), small.indices.astype(np.int64), small.data)


def test_analyse_then_factor_is_the_same_as_factor_alone():
    K = spd(2500, 9)
    a, b = CholmodEngine(), CholmodEngine()
    a.analyse(K)
    a.factor(K)
    b.factor(K)
    rhs = np.linspace(-1, 1, K.shape[0])
    assert np.array_equal(a.solve(rhs), b.solve(rhs)) and a.ordering == b.ordering
    assert np.array_equal(a.permutation(), b.permutation())


def test_the_factors_own_order_and_column_counts_are_those_of_the_pattern():
    """nnz(L) and Σc² for the statistics read from CHOLMOD's factor: the same as a symbolic
    analysis of the pattern in CHOLMOD's order, and the order the same as cvxopt's solve gives."""
    from rfverify.extended.ldl import _symbolic, upper_csc

    for n, seed in ((900, 1), (3000, 2)):  # AMD, and nested dissection or AMD (ND_MIN_ROWS)
        K = spd(n, seed)
        ours, theirs = CholmodEngine(), cvxopt_engine()
        assert ours.permutation() is None and ours.column_counts() is None
        ours.factor(K)
        theirs.factor(K)
        perm = ours.permutation()
        assert np.array_equal(perm, theirs.permutation()) and theirs.column_counts() is None
        full = (K + sp.tril(K, -1).T).tocsc()
        Ap, Ai, _ = upper_csc(full[perm][:, perm])
        assert np.array_equal(ours.column_counts(), np.diff(_symbolic(n, Ap, Ai)[1]))


def test_cvxopts_global_options_are_set_by_one_block_at_a_time():
    """The set-up thread analyses while the double solve may call cvxopt: two option blocks must
    not interleave, or one restores the other's settings and leaks them into the user's cvxopt."""
    from cvxopt import cholmod

    from rfverify.solver.engines import _cholmod_options

    original = dict(cholmod.options)
    inside, order = threading.Event(), []

    def first():
        with _cholmod_options(supernodal=1):
            order.append("first in")
            inside.set()
            time.sleep(0.3)
            order.append("first out")

    def second():
        inside.wait()
        with _cholmod_options(supernodal=0):
            order.append("second in")

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert order == ["first in", "first out", "second in"] and dict(cholmod.options) == original
