"""Cold start (issue 28 item 1): the background compilation of the double-double kernels.

The child only fills numba's cache; these tests check that what it compiles is what the
k-digit path calls (so the list cannot go stale unnoticed), that it starts only on a cold
cache and can be switched off, and that a child's compilation lands in the cache another
process reads."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

import rfverify
from rfverify import compilation


@pytest.fixture(scope="module")
def chute_run():
    return rfverify.solve_to_digits(rfverify.load("bundled:chute"), 10, factor_engine="ldl")


def test_every_listed_kernel_is_one_the_k_digit_path_compiles(chute_run):
    from numba.core import sigutils

    assert chute_run.status == "Certified"
    listed = set()
    for module, name, signature in compilation.EXTENDED_KERNELS:
        dispatcher = compilation._dispatcher(module, name)
        args, _ = sigutils.normalize_signature(signature)
        assert tuple(args) in [tuple(s) for s in dispatcher.signatures], (
            f"{module}.{name}{signature} is not what the Chute's k-digit path compiles: "
            "regenerate compilation.EXTENDED_KERNELS (docs/DECISIONS.md, 'Cold start')")
        listed.add((module, name))
    assert len(listed) == len(compilation.EXTENDED_KERNELS), "a kernel is listed twice"
    # The most expensive kernels are in the list, or the child would save little.
    assert {("blocks", "contact_factor_inverse"), ("cones", "nt_scaling"), ("ldl", "numeric_ldl")} <= listed


def test_no_child_on_a_warm_cache_or_when_switched_off(chute_run, monkeypatch):
    assert not compilation.extended_cache_is_cold()  # the run above compiled or loaded them
    assert compilation.compile_extended_in_background() is False
    monkeypatch.setattr(compilation, "extended_cache_is_cold", lambda: True)
    monkeypatch.setenv(compilation.BACKGROUND_ENV, "0")
    assert compilation.compile_extended_in_background() is False
    monkeypatch.setenv(compilation.BACKGROUND_ENV, "1")
    monkeypatch.setattr(compilation, "_cores", lambda: 1)
    assert compilation.compile_extended_in_background() is False


def test_the_float64_kernels_are_deferred_only_to_a_child_on_a_cold_cache(monkeypatch):
    monkeypatch.setattr(compilation, "cache_is_cold", lambda dispatcher: True)
    monkeypatch.setattr(compilation, "_child", None)
    assert compilation.float64_kernels_deferred() is False  # nobody would compile them
    monkeypatch.setattr(compilation, "_child", object())
    assert compilation.float64_kernels_deferred() is True
    monkeypatch.setattr(compilation, "cache_is_cold", lambda dispatcher: False)
    assert compilation.float64_kernels_deferred() is False  # in the cache: the compiled kernels


def test_a_childs_compilation_is_found_by_another_process(tmp_path):
    """In a fresh cache folder the cache is cold; one kernel compiled by one process is loaded,
    not compiled, by the next."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    child = textwrap.dedent("""
        from rfverify import compilation
        kernel = [k for k in compilation.EXTENDED_KERNELS if k[:2] == ("dd", "vsub")]
        from rfverify.solver import kernels
        print(compilation.extended_cache_is_cold(), compilation.cache_is_cold(kernels.nt_scaling))
        before = compilation.compile_seconds()
        compilation.compile_extended(kernel)
        print(compilation.compile_seconds() > before)
    """)
    # The next process calls vsub as the k-digit path does (arrays, not a signature): the
    # child's entry must be the one that call looks up.
    caller = textwrap.dedent("""
        import numpy as np
        from rfverify import compilation
        from rfverify.extended import dd
        before = compilation.compile_seconds()
        a = [np.ones(3) for _ in range(6)]
        dd.vsub(*a)
        print(compilation.compile_seconds() > before)
    """)
    first = subprocess.run([sys.executable, "-c", child], env=env, capture_output=True, text=True, timeout=300)
    assert first.returncode == 0, first.stderr
    assert first.stdout.split() == ["True", "True", "True"]  # cold (both kinds), and vsub was compiled
    second = subprocess.run([sys.executable, "-c", caller], env=env, capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    assert second.stdout.split() == ["False"]  # the call loaded the child's vsub, compiled nothing


def test_a_cholmod_run_calls_every_listed_kernel_too():
    """The list is the same for both float64 factorisation engines (neither is numba code): a
    run that factors with CHOLMOD calls every listed kernel, as the ``ldl`` run above does."""
    script = textwrap.dedent("""
        import rfverify
        from rfverify import compilation
        rfverify.solve_to_digits(rfverify.load("bundled:chute"), 10, factor_engine="cholmod")
        called = {(m, n) for m, n, _ in compilation.EXTENDED_KERNELS if compilation._dispatcher(m, n).signatures}
        print(sorted({(m, n) for m, n, _ in compilation.EXTENDED_KERNELS} - called))
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"


def test_the_child_compiles_the_most_expensive_kernel_first_then_the_float64_ones(monkeypatch):
    order = []

    class Recorder:
        def __init__(self, kernel):
            self.kernel = kernel

        def compile(self, args):
            order.append(self.kernel)

    monkeypatch.setattr(compilation, "_dispatcher", lambda module, name: Recorder((module, name)))
    compilation.compile_extended()
    extended = [kernel[:2] for kernel in compilation.EXTENDED_KERNELS]
    float64 = [kernel[:2] for kernel in compilation.FLOAT64_KERNELS]
    assert order == ([compilation.CHILD_FIRST] + float64
                     + [kernel for kernel in extended if kernel != compilation.CHILD_FIRST])


def test_the_float64_kernels_listed_are_those_the_double_solve_compiles():
    """Each listed signature is the one a compiled double solve calls (else the child's entry
    would never be found), and every kernel of the module is listed."""
    import numba
    from numba.core import sigutils

    from rfverify.solver import kernels

    result = rfverify.solve(rfverify.load("bundled:chute"), tol=1e-10, compiled_kernels=True)
    assert result.success
    for module, name, signature in compilation.FLOAT64_KERNELS:
        args, _ = sigutils.normalize_signature(signature)
        assert tuple(args) in [tuple(s) for s in compilation._dispatcher(module, name).signatures], name
    called = {name for name in dir(kernels) if isinstance(getattr(kernels, name), numba.core.registry.CPUDispatcher)
              and getattr(kernels, name).signatures}
    assert called == {name for _, name, _ in compilation.FLOAT64_KERNELS}


def test_a_cold_cache_runs_the_double_solve_in_numpy_with_the_same_answer(monkeypatch):
    """On a cold cache the k-digit path's double solve does not wait for the float64 cone
    kernels to compile; its answer, and so the whole run's, is bit for bit the warm one."""
    from rfverify.verify import digits

    monkeypatch.setenv(compilation.BACKGROUND_ENV, "0")
    runs = {}
    for cold in (False, True):
        monkeypatch.setattr(digits, "float64_kernels_deferred", lambda cold=cold: cold)
        runs[cold] = rfverify.solve_to_digits(rfverify.load("bundled:chute"), 10, factor_engine="ldl")
    assert runs[False].double.settings.compiled_kernels is True
    assert runs[True].double.settings.compiled_kernels is False
    assert runs[True].status == runs[False].status == "Certified"
    for name in ("v", "u", "r"):
        assert getattr(runs[True], name).tobytes() == getattr(runs[False], name).tobytes()
        assert getattr(runs[True].double, name).tobytes() == getattr(runs[False].double, name).tobytes()
