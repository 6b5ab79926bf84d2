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
    assert {("blocks", "contact_factor_inverse"), ("cones", "nt_scaling"), ("ldl", "_numeric")} <= listed


def test_no_child_on_a_warm_cache_or_when_switched_off(chute_run, monkeypatch):
    assert not compilation.extended_cache_is_cold()  # the run above compiled or loaded them
    assert compilation.compile_extended_in_background() is False
    monkeypatch.setattr(compilation, "extended_cache_is_cold", lambda: True)
    monkeypatch.setenv(compilation.BACKGROUND_ENV, "0")
    assert compilation.compile_extended_in_background() is False
    monkeypatch.setenv(compilation.BACKGROUND_ENV, "1")
    monkeypatch.setattr(compilation, "_cores", lambda: 1)
    assert compilation.compile_extended_in_background() is False


def test_a_childs_compilation_is_found_by_another_process(tmp_path):
    """In a fresh cache folder the cache is cold; one kernel compiled by one process is loaded,
    not compiled, by the next."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    child = textwrap.dedent("""
        from rfverify import compilation
        kernel = [k for k in compilation.EXTENDED_KERNELS if k[:2] == ("dd", "vsub")]
        print(compilation.extended_cache_is_cold())
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
    assert first.stdout.split() == ["True", "True"]  # cold, and vsub was compiled
    second = subprocess.run([sys.executable, "-c", caller], env=env, capture_output=True, text=True, timeout=300)
    assert second.returncode == 0, second.stderr
    assert second.stdout.split() == ["False"]  # the call loaded the child's vsub, compiled nothing
