"""Seconds this process has spent compiling numba kernels.

The float64 cone kernels (:mod:`rfverify.solver.kernels`) and the double-double ones
(:mod:`rfverify.extended`) are compiled on their first call and then cached by numba in its
cache folder (``NUMBA_CACHE_DIR``, else ``__pycache__`` beside the sources).  On a fresh
machine the first solve therefore pays for compilation, later processes load the compiled
code.  The stage timings of :class:`~rfverify.solver.SolveResult` and
:class:`~rfverify.digits.DigitsSolution` report that cost as its own entry, ``"compile"``,
and leave it out of the stage it happened in, so that a cold start is not mistaken for a
slow phase.

Counted through numba's event API (``numba:compile``, fired only for a real compilation,
not for a load from the cache); a compilation nested in another one counts once.
"""

from __future__ import annotations

import threading
import time

from numba.core import event as _event

_lock = threading.Lock()
_state = {"total": 0.0, "depth": 0, "start": 0.0}


class _CompileClock(_event.Listener):
    def on_start(self, event):
        with _lock:
            if _state["depth"] == 0:
                _state["start"] = time.perf_counter()
            _state["depth"] += 1

    def on_end(self, event):
        with _lock:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                _state["total"] += time.perf_counter() - _state["start"]


_event.register("numba:compile", _CompileClock())


def compile_seconds() -> float:
    """Wall seconds spent compiling numba functions in this process so far (a difference of
    two readings is the compilation inside a stage)."""
    with _lock:
        total = _state["total"]
        if _state["depth"]:
            total += time.perf_counter() - _state["start"]
        return total
