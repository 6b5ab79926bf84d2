"""Seconds this process has spent compiling numba kernels.

The float64 cone kernels (:mod:`rfverify.solver.kernels`) and the double-double ones
(:mod:`rfverify.extended`) are compiled on their first call and then cached by numba in its
cache folder (``NUMBA_CACHE_DIR``, else ``__pycache__`` beside the sources).  On a fresh
machine the first solve therefore pays for compilation, later processes load the compiled
code.  The stage timings of :class:`~rfverify.solver.SolveResult` and
:class:`~rfverify.verify.digits.DigitsSolution` report that cost as its own entry, ``"compile"``,
and leave it out of the stage it happened in, so that a cold start is not mistaken for a
slow phase.

Counted through numba's event API (``numba:compile``, fired only for a real compilation,
not for a load from the cache); a compilation nested in another one counts once.

On a cold cache, :func:`compile_extended_in_background` starts a child process that compiles
the double-double kernels (the most expensive first, then the others in the reverse order of
their first use) into the same cache, while this process runs the double solve and compiles
forward: on two cores the two meet in the middle and the cold k-digit path pays about half of
its compilation (docs/DECISIONS.md, "Cold start").  The float64 cone kernels of the double
solve are left to the child too (:func:`float64_kernels_deferred`): the parent's double solve
runs their numpy formulas meanwhile.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time

from numba.core import event as _event

_lock = threading.Lock()
_state = {"total": 0.0, "depth": 0, "start": 0.0}
_announce = {"say": None, "said": False}
COMPILING = ("compiling numba kernels missing from numba's cache (first: {kernel}); seconds, once: numba caches "
             "what it compiles for later runs")
"""The line :class:`announcing` says, ``{kernel}`` the kernel whose compilation started it.  Not
"the first run": a kernel is compiled wherever the cache lacks it — a fresh machine, changed
sources, a signature not compiled before, or the float64 kernels that a cold k-digit path left to
its background child (:func:`float64_kernels_deferred`) when the path ended first."""


def _kernel_name(event) -> str:
    """``module.function`` of the kernel a ``numba:compile`` event is about."""
    try:
        func = event.data["dispatcher"].py_func
        return f"{func.__module__}.{func.__qualname__}"
    except Exception:  # numba's event data is not a public interface: say less rather than fail
        return "a kernel"


class _CompileClock(_event.Listener):
    def on_start(self, event):
        say = None
        with _lock:
            if _state["depth"] == 0:
                _state["start"] = time.perf_counter()
                if _announce["say"] is not None and not _announce["said"]:
                    say, _announce["said"] = _announce["say"], True
            _state["depth"] += 1
        if say is not None:
            say(COMPILING.format(kernel=_kernel_name(event)))

    def on_end(self, event):
        with _lock:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                _state["total"] += time.perf_counter() - _state["start"]


_event.register("numba:compile", _CompileClock())


class announcing:
    """``with announcing(say):`` — the first numba compilation inside the block (a kernel missing
    from the cache) is named by one progress line, :data:`COMPILING` with that kernel, as it
    starts, instead of a silent pause named only in the timings at the end.  Once per process;
    ``say=None`` says nothing."""

    def __init__(self, say):
        self.say = say

    def __enter__(self):
        self.previous = _announce["say"]
        _announce["say"] = self.say
        return self

    def __exit__(self, *exc):
        _announce["say"] = self.previous
        return False


def compile_seconds() -> float:
    """Wall seconds spent compiling numba functions in this process so far (a difference of
    two readings is the compilation inside a stage)."""
    with _lock:
        total = _state["total"]
        if _state["depth"]:
            total += time.perf_counter() - _state["start"]
        return total


EXTENDED_KERNELS = (
    ("cones", "arrow_solve", "(int64, float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "product", "(int64, float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("dd", "vscale", "(float64, float64, float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("dd", "vaxpy", "(float64, float64, float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "max_step_at", "(int64, float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("blocks", "block_apply", "(int64, int64[::1], int64[::1], float64[:, :, ::1], float64[:, :, ::1], boolean, float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("ldl", "_solve", "(int64, int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "quad_spectral", "(int64, float64[:, ::1], float64[:, ::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "spectral_table", "(int64, int64, float64[:, ::1], float64[:, ::1])"),
    ("contactspace", "_scaled_blocks", "(int64[::1], int64[::1], float64[:, :, ::1], float64[:, :, ::1], int64[::1], float64[:, :, ::1], float64[:, :, ::1], int64[:, :, ::1], float64[::1], float64[::1])"),
    ("blocks", "contact_factor_inverse", "(int64, int64[::1], int64[::1], int64[::1], int64[::1], float64[:, ::1], float64[:, :, ::1], float64[:, :, ::1])"),
    ("contactspace", "_small_blocks_W", "(int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], float64[::1], float64[::1], int64[::1], int64[::1], int64[::1], int64[::1], float64[::1], float64[::1], int64[::1], int64[::1], int64[::1], int64, int64[::1], float64[:, :, ::1], float64[:, :, ::1])"),
    ("ldl", "numeric_ldl", "(int64, int64[::1], int64[::1], float64[::1], float64[::1], int64[::1], int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], int64[::1], int64[::1], int64[::1], int64[::1])"),
    ("blocks", "scatter_add", "(int64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "nt_scaling", "(int64, float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[:, ::1])"),
    ("dd", "vmul_d", "(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("dd", "vnorm2", "(float64[::1], float64[::1])"),
    ("dd", "vdot", "(float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("dd", "vadd", "(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("dd", "vsub", "(float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("cones", "min_lambda2", "(int64, float64[::1], float64[::1])"),
    ("dd", "csr_matvec", "(int64[::1], int64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1], float64[::1])"),
    ("ldl", "_symbolic_kernel", "(int64, int64[::1], int64[::1], int64[::1], int64[::1], int64[::1], int64[::1])"),
)
"""(module of :mod:`rfverify.extended`, kernel, argument types) of the double-double kernels
the k-digit path calls from Python, in the reverse order of their first use on the bundled
Chute (the same with either float64 factorisation engine: QDLDL and CHOLMOD are not numba
code).  A test keeps the list equal to what such a run compiles.  The child compiles them in the order of
:data:`CHILD_ORDER`; the kernels they call are compiled with them."""

FLOAT64_KERNELS = tuple(("rfverify.solver.kernels", name, "(int64" + ", float64[::1]" * arrays + ")") for name, arrays in (
    ("lambda2", 2), ("nt_scaling", 6), ("quad_det", 2), ("quad_blocks", 2), ("quad_apply", 4), ("step_point", 3),
    ("min_ray_lambda2_at", 3), ("product", 3), ("arrow_solve", 3)))
"""The float64 cone kernels of the double solver (:mod:`rfverify.solver.kernels`, every one of
them, as the product cone calls them: the number of cones and flat float64 vectors).  On a cold
cache the k-digit path's double solve runs their numpy formulas instead of waiting for them
(:func:`float64_kernels_deferred`), and the child compiles them for the next run."""

CHILD_FIRST = ("blocks", "contact_factor_inverse")
"""The kernel the child compiles before all others: the most expensive one (2–3 s of the
~11 s), which the two processes would otherwise meet at on the Chute — the parent reaches it
about halfway through its share and would compile it a second time while the child is still
at it.  Taken first, it is in the cache long before the parent's first call, and the two meet
among kernels of a few tenths of a second."""

CHILD_ORDER = (tuple(k for k in EXTENDED_KERNELS if k[:2] == CHILD_FIRST) + FLOAT64_KERNELS
               + tuple(k for k in EXTENDED_KERNELS if k[:2] != CHILD_FIRST))
"""What the child compiles, in order: :data:`CHILD_FIRST`; the :data:`FLOAT64_KERNELS`, which
the parent does not call in this run, so that they are in the cache before the parent exits
(and ends the child); then the double-double kernels from the last used to the first, towards
the parent, which compiles them from the first."""

BACKGROUND_ENV = "RFVERIFY_BACKGROUND_COMPILE"
"""Set to ``0`` to never start the background compilation."""

_child: subprocess.Popen | None = None


def _dispatcher(module: str, name: str):
    """The kernel ``name`` of ``module``: a module of :mod:`rfverify.extended` by its short name,
    or a full module name."""
    import importlib

    return getattr(importlib.import_module(module if "." in module else f"rfverify.extended.{module}"), name)


def cache_is_cold(dispatcher) -> bool:
    """True when numba's cache holds no compiled version of ``dispatcher`` (an
    ``@njit(cache=True)`` kernel) for its current source, so that its first call compiles.
    Reads numba's cache index, a private interface: any surprise there answers False (callers
    then do what they do on a warm cache)."""
    try:
        index = dispatcher._cache._cache_file._load_index()
    except Exception:
        return False
    return not index


def float64_kernels_deferred() -> bool:
    """True when this process has started the child and numba's cache holds no compiled float64
    cone kernels: the double solve then runs their numpy formulas (bit for bit the same,
    ``Settings.compiled_kernels=False``) rather than compile them on the critical path, and the
    child compiles them for later runs (:data:`CHILD_ORDER`)."""
    return _child is not None and _kernel_cache_is_cold("rfverify.solver.kernels", "nt_scaling")


def extended_cache_is_cold() -> bool:
    """True when numba's cache holds no compiled version of the most expensive double-double
    kernel for the current sources (so the k-digit path would compile them all)."""
    return _kernel_cache_is_cold("blocks", "contact_factor_inverse")


def _kernel_cache_is_cold(module: str, name: str) -> bool:
    """Whether numba's cache lacks the kernel ``name`` of ``module`` (see :func:`_dispatcher`);
    False when the kernel cannot be found at all: then nothing is deferred or announced."""
    try:
        dispatcher = _dispatcher(module, name)
    except Exception:
        return False
    return cache_is_cold(dispatcher)


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def compile_extended_in_background() -> bool:
    """Start the child that compiles :data:`EXTENDED_KERNELS` into numba's cache, when that
    cache is cold, the process may use two cores or more, and ``RFVERIFY_BACKGROUND_COMPILE``
    is not ``0``.  Returns whether a child was started (at most one
    per process); it is ended when this process exits.  Results never depend on it: a kernel
    the child has not finished is compiled here as before, and a compiled kernel is the same
    code either way."""
    global _child
    if _child is not None or os.environ.get(BACKGROUND_ENV, "1") == "0" or _cores() < 2:
        return False
    if not extended_cache_is_cold():
        return False
    try:
        _child = subprocess.Popen([sys.executable, "-m", "rfverify.compilation"], stdin=subprocess.DEVNULL,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=os.environ.copy())
    except OSError:
        return False
    import atexit

    atexit.register(_end_child)
    return True


def _end_child() -> None:
    """Stop the child at exit: numba writes each cache file to a temporary name and renames
    it, so an interrupted child leaves no partial entry."""
    if _child is not None and _child.poll() is None:
        _child.terminate()
        try:
            _child.wait(timeout=5)
        except subprocess.TimeoutExpired:
            _child.kill()


def compile_extended(kernels=CHILD_ORDER) -> None:
    """Compile ``kernels`` (with numba's cache on, so they are saved; one already there is only
    loaded) in the given order."""
    from numba.core import sigutils

    for module, name, signature in kernels:
        # As a tuple of types, the form a call compiles and keys numba's cache index by: a
        # signature string would be saved under another key, and never found by a call.
        args, _ = sigutils.normalize_signature(signature)
        _dispatcher(module, name).compile(tuple(args))


if __name__ == "__main__":  # the background child: lowest priority, so the solve keeps its core
    try:
        os.nice(19)
    except OSError:
        pass
    compile_extended()
