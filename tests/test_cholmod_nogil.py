"""CHOLMOD through ctypes with rfverify's own cholmod_common (rfverify.engines.cholmod_nogil): the
same factor and solves as cvxopt's own calls under its default options, bit for bit; other
threads run during it; an indefinite matrix is refused as before; anything unexpected means the
QDLDL fallback; and cvxopt's global ``cholmod.options`` is neither read nor written (issue 48
item 3): a user's settings there change no answer, and a user's thread never sees rfverify's."""

import sys
import threading
import time

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.engines import cholmod_nogil
from rfverify.engines.factor import CholmodEngine

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="the ctypes call finds libcholmod in /proc/self/maps (Linux)")


def grid(k):
    """Lower triangle of a k² × k² grid Laplacian (+ 0.5 I): quick to factor, its analysis (AMD and
    nested dissection) takes tens of milliseconds."""
    T = sp.diags([-1.0, 4.5, -1.0], [-1, 0, 1], shape=(k, k))
    A = sp.kron(sp.identity(k), T) + sp.kron(sp.diags([-1.0, -1.0], [-1, 1], shape=(k, k)), sp.identity(k))
    return sp.tril(A.tocsc(), format="csc")


def spd(n, seed, density=4e-3):
    rng = np.random.default_rng(seed)
    A = sp.random(n, n, density=density, random_state=rng)
    return sp.tril((A @ A.T + sp.identity(n) * 2.0).tocsc(), format="csc")


class CvxoptReference:
    """cvxopt's own cholmod.symbolic/numeric/solve on a lower triangle, under cvxopt's default
    options (an empty ``cholmod.options``): what rfverify's engine must equal bit for bit."""

    releases_gil = False

    def __init__(self):
        self._A = self._F = None

    def factor(self, K):
        import cvxopt
        from cvxopt import cholmod

        assert dict(cholmod.options) == {}, "the reference needs cvxopt's default options"
        K = sp.csc_matrix(K)
        K.sort_indices()
        n = K.shape[0]
        cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(K.indptr))
        self._A = cvxopt.spmatrix(cvxopt.matrix(K.data.astype(np.float64)), cvxopt.matrix(K.indices.astype(np.int64)),
                                  cvxopt.matrix(cols), (n, n))
        if self._F is None:
            from rfverify.engines.factor import ND_MIN_ROWS, nested_dissection

            perm = nested_dissection(K) if n >= ND_MIN_ROWS else None
            self._F = (cholmod.symbolic(self._A, uplo="L") if perm is None
                       else cholmod.symbolic(self._A, p=cvxopt.matrix(perm.astype(np.int64)), uplo="L"))
        try:
            cholmod.numeric(self._A, self._F)
        except ArithmeticError as exc:
            raise ArithmeticError(f"CHOLMOD: not positive definite (column {exc})") from None

    def solve(self, b):
        import cvxopt
        from cvxopt import cholmod

        x = cvxopt.matrix(np.array(b, dtype=np.float64))
        cholmod.solve(self._F, x)
        return np.array(x).ravel()

    def permutation(self):
        import cvxopt
        from cvxopt import cholmod

        n = self._A.size[0]
        p = cvxopt.matrix(np.arange(n, dtype=np.float64))
        cholmod.solve(self._F, p, sys=7)  # x = P b
        return np.array(p).ravel().astype(np.int64)


def test_available_here_and_bit_for_bit_cvxopts_own_calls():
    assert cholmod_nogil.session() is not None, "cvxopt's libcholmod was not found among the mapped files"
    for seed in range(3):
        K = spd(1500 + 500 * seed, seed)  # AMD, then nested dissection or AMD from 2000 rows
        ours, theirs = CholmodEngine(), CvxoptReference()
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


def _progress_during(work):
    """Steps a Python thread makes while ``work()`` runs (a GIL-free call lets it run)."""
    count, stop = [0], [False]

    def spin():
        while not stop[0]:
            count[0] += 1

    thread = threading.Thread(target=spin)
    thread.start()
    time.sleep(0.02)
    try:
        before = count[0]
        work()
        return count[0] - before
    finally:
        stop[0] = True
        thread.join()


def test_other_threads_run_while_it_analyses_and_factors():
    K = spd(6000, 7, density=1.5e-3)
    ours, theirs = CholmodEngine(), CvxoptReference()
    theirs.factor(K)
    t0 = time.perf_counter()
    theirs.factor(K)
    assert time.perf_counter() - t0 > 0.02, "the matrix must take a while to factor for this test to say anything"
    ours.factor(K)
    G = grid(100)
    analysed = _progress_during(lambda: CholmodEngine().analyse(G))
    free, held = _progress_during(lambda: ours.factor(K)), _progress_during(lambda: theirs.factor(K))
    assert free > 20 * max(held, 1000), (free, held)
    assert analysed > 1000


def test_an_indefinite_matrix_is_refused_at_the_same_column_as_by_cvxopt(capfd):
    K = spd(800, 3)
    bad = K.copy()
    bad.data = bad.data.copy()
    bad.data[bad.indptr[400]] = -5.0  # a negative diagonal entry (column 400's first stored entry)
    messages = []
    for engine in (CholmodEngine(), CvxoptReference()):
        engine.factor(K)
        with pytest.raises(ArithmeticError) as info:
            engine.factor(bad)
        messages.append(str(info.value))
        engine.factor(K)  # the factor is usable again afterwards
    assert messages[0] == messages[1] and "not positive definite" in messages[0]
    assert capfd.readouterr() == ("", "")  # CHOLMOD prints nothing (print = 0, as cvxopt sets it)


def test_an_error_reported_by_cholmod_is_raised_not_ignored(monkeypatch):
    K = spd(600, 4)
    engine = CholmodEngine()
    monkeypatch.setattr(cholmod_nogil.Cholmod, "factorize", lambda self, values: None)  # CHOLMOD said: error
    with pytest.raises(MemoryError, match="CHOLMOD"):
        engine.factor(K)
    assert engine.factorisations == 0


def test_an_unexpected_cholmod_common_layout_means_qdldl(monkeypatch):
    from rfverify.engines.factor import QDLDLEngine, cholmod_available, schur_engine

    monkeypatch.setattr(cholmod_nogil, "_checked", False)
    monkeypatch.setattr(cholmod_nogil, "_lib", None)
    wrong = tuple((off, fmt, want + 1) if off == cholmod_nogil._PRINT_OFFSET else (off, fmt, want)
                  for off, fmt, want in cholmod_nogil._EXPECTED_DEFAULTS)
    monkeypatch.setattr(cholmod_nogil, "_EXPECTED_DEFAULTS", wrong)
    assert cholmod_nogil.session() is None and not cholmod_available()
    with pytest.raises(ImportError, match="not usable here"):
        CholmodEngine()
    assert isinstance(schur_engine(), QDLDLEngine)


def test_calls_out_of_order_are_refused():
    chol = cholmod_nogil.session()
    with pytest.raises(ValueError, match="analyse first"):
        chol.factorize(np.ones(3))
    K = spd(50, 1)
    assert chol.analyse(K.indptr, K.indices)
    with pytest.raises(ValueError, match="successful numeric"):
        chol.solve(np.ones(50))
    with pytest.raises(ValueError, match="values"):
        chol.factorize(K.data[:-1])
    assert chol.factorize(K.data) == 50
    with pytest.raises(ValueError, match="right-hand side"):
        chol.solve(np.ones(49))
    chol.release()
    assert chol.counts() is None


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
    from rfverify.extended.ldl import symbolic_ldl, upper_csc

    for n, seed in ((900, 1), (3000, 2)):  # AMD, and nested dissection or AMD (ND_MIN_ROWS)
        K = spd(n, seed)
        ours, theirs = CholmodEngine(), CvxoptReference()
        assert ours.permutation() is None and ours.column_counts() is None
        ours.factor(K)
        theirs.factor(K)
        perm = ours.permutation()
        assert np.array_equal(perm, theirs.permutation())
        full = (K + sp.tril(K, -1).T).tocsc()
        Ap, Ai, _ = upper_csc(full[perm][:, perm])
        assert np.array_equal(ours.column_counts(), np.diff(symbolic_ldl(n, Ap, Ai)[1]))


# ---------------------------------------------------------------------- cvxopt's global options
USER_OPTIONS = [{"postorder": False}, {"nmethods": 1}, {"supernodal": 0}, {"print": 5}, {"not_an_option": 1}]
"""Settings a user of cvxopt may leave in ``cvxopt.cholmod.options`` (the last one makes every
cvxopt.cholmod call raise ValueError)."""


def _cholmod_problem():
    """A problem on which both paths factor with CHOLMOD: the schur form, and the double-double
    phase's contact-space factor forced to CHOLMOD."""
    from rfverify.scenes.random_problems import random_problem

    return random_problem(40, 90, seed=3)


def _answers(problem):
    out = rfverify.solve(problem, method="schur")
    digits = rfverify.solve_to_digits(problem, digits=10, method="schur", factor_engine="cholmod")
    return [out.v, out.u, out.r, np.array([out.nit])], [digits.v, digits.u, digits.r, np.array([digits.nit])]


@pytest.fixture
def user_options():
    from cvxopt import cholmod

    saved = dict(cholmod.options)
    yield cholmod.options
    cholmod.options.clear()
    cholmod.options.update(saved)


@pytest.mark.parametrize("setting", USER_OPTIONS, ids=lambda d: next(iter(d)))
def test_answers_are_bit_for_bit_the_same_whatever_the_users_cvxopt_options(setting, user_options, capfd):
    problem = _cholmod_problem()
    user_options.clear()
    plain = _answers(problem)
    user_options.update(setting)
    theirs = _answers(problem)
    assert dict(user_options) == setting  # rfverify left the user's setting as it was
    for a, b in zip(plain, theirs):
        for x, y in zip(a, b):
            assert np.array_equal(x, y)
    assert capfd.readouterr().err == ""  # nothing printed by CHOLMOD (the user's "print" is not ours)


def test_a_users_thread_never_sees_rfverifys_settings(user_options):
    """Another thread polls cvxopt.cholmod.options while rfverify analyses, factors and solves:
    the two paths on a small problem, and the engine on a matrix whose analysis takes a while
    (a setting made around it would be seen by the poller)."""
    problem = _cholmod_problem()
    K = grid(100)
    user_options.clear()
    user_options["postorder"] = True
    before = dict(user_options)
    seen, polls, stop = [], [0], threading.Event()

    def poll():
        while not stop.is_set():
            now = dict(user_options)
            if now != before:
                seen.append(now)
            polls[0] += 1

    interval = sys.getswitchinterval()
    sys.setswitchinterval(2e-4)  # switch threads often, so that a changed dictionary would be seen
    thread = threading.Thread(target=poll)
    thread.start()
    try:
        _answers(problem)
        for _ in range(12):  # a dozen analyses: a setting made around each would be seen at least once
            engine = CholmodEngine()
            engine.factor(K)
            engine.solve(np.ones(K.shape[0]))
    finally:
        stop.set()
        thread.join()
        sys.setswitchinterval(interval)
    assert polls[0] > 1000 and not seen, seen[:3]


class RecordingOptions(dict):
    """A stand-in for cvxopt.cholmod.options that records every change made to it from Python."""

    def __init__(self):
        super().__init__()
        self.changes = []

    def _record(name):
        def method(self, *args, **kwargs):
            self.changes.append((name, args, kwargs))
            return getattr(dict, name)(self, *args, **kwargs)
        return method

    for _name in ("__setitem__", "__delitem__", "update", "clear", "pop", "popitem", "setdefault"):
        locals()[_name] = _record(_name)
    del _name, _record


def test_rfverify_never_writes_cvxopts_options(monkeypatch):
    from cvxopt import cholmod

    recording = RecordingOptions()
    monkeypatch.setattr(cholmod, "options", recording)
    _answers(_cholmod_problem())
    engine = CholmodEngine()
    engine.factor(spd(2500, 9))  # nested dissection or AMD
    engine.solve(np.ones(2500))
    assert recording.changes == [] and dict(recording) == {}


def _laplacian3(k):
    """Lower triangle of a k³ × k³ grid Laplacian (+ 1e-3 I): at k = 44, L has about 3.6e7 entries
    with AMD and its factorisation takes about 2 s, long enough to interrupt."""
    T = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(k, k))
    I = sp.identity(k)
    A = sp.kron(sp.kron(T, I), I) + sp.kron(sp.kron(I, T), I) + sp.kron(sp.kron(I, I), T)
    K = sp.tril((A + 1e-3 * sp.identity(k ** 3)).tocsc(), format="csc")
    K.sort_indices()
    return K


def test_ctrl_c_is_raised_during_a_long_factorisation_which_then_finishes_on_its_thread():
    """CHOLMOD cannot be stopped, but the Ctrl-C need not wait for it: the main thread is told at
    once, the factorisation goes on on its helper thread (its factor refusing every other call
    meanwhile) and the factor is whole and usable once it is done."""
    import _thread

    K = _laplacian3(44)
    chol = cholmod_nogil.session()
    assert chol.analyse(K.indptr, K.indices) and chol._large
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            chol.factorize(K.data)
        still_running = chol._running.is_set()  # the interrupt did not wait for CHOLMOD
    finally:
        timer.cancel()
    assert still_running
    for call in (lambda: chol.solve(np.ones(K.shape[0])), lambda: chol.factorize(K.data), chol.release,
                 lambda: chol.analyse(K.indptr, K.indices)):
        with pytest.raises(RuntimeError, match="interrupted by Ctrl-C is still running"):
            call()
    deadline = time.perf_counter() + 120
    while chol._running.is_set() and time.perf_counter() < deadline:
        time.sleep(0.05)
    assert not chol._running.is_set()
    assert chol.factorize(K.data) == K.shape[0]  # the factor is whole: factored again, and solved with
    b = np.arange(K.shape[0], dtype=float) % 7
    x = chol.solve(b)
    A = K + sp.tril(K, -1).T
    assert np.linalg.norm(A @ x - b) <= 1e-10 * np.linalg.norm(b)


def test_a_factor_still_running_at_exit_is_not_freed_under_it():
    """The finaliser (also run at the interpreter's exit) leaves a factor alone while an
    interrupted factorisation still uses it, and frees it otherwise."""
    freed = []

    class Lib:
        def cholmod_l_free_factor(self, factor, common):
            freed.append("factor")

        def cholmod_l_finish(self, common):
            freed.append("common")

    import ctypes

    running = threading.Event()
    running.set()
    cholmod_nogil._finish(Lib(), ctypes.c_void_p(1234), None, running)
    assert freed == []
    running.clear()
    cholmod_nogil._finish(Lib(), ctypes.c_void_p(1234), None, running)
    assert freed == ["factor", "common"]
