"""The double-double kernels over the machine's cores: a kernel that loops over independent
items (rows, cones, contacts, block pairs) runs on contiguous ranges of them at once, one range
per thread, each range a call of the same compiled kernel on array views.

Why threads and not ``numba.prange``: numba's parallel runtime is either not fork-safe (GNU
OpenMP: a forked bench task would hang) or not thread-safe (workqueue: two solves in two
threads abort the process); a plain thread pool is both, and the kernels release the GIL
(``nogil=True``).  Every item is computed by the same arithmetic as in one call, so the result is
bit for bit the single-threaded one, whatever the number of threads (tests compare them).

``RFVERIFY_THREADS`` (an integer ≥ 1) sets the number of threads; default: the CPUs this process
may run on.  A kernel call shorter than about a millisecond runs as one call: handing a range to a
thread and waiting for it costs about 0.3 ms (measured: a 1.7 ms matrix-vector product took 1.1 ms
on two threads, a 0.4 ms one 0.5 ms), so each caller gives the fewest items worth splitting."""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

def _count() -> int:
    raw = os.environ.get("RFVERIFY_THREADS", "").strip()
    if raw:
        try:
            n = int(raw)
        except ValueError:
            n = 0
        if n < 1:
            from ..errors import InvalidArgumentError

            raise InvalidArgumentError("RFVERIFY_THREADS", f"must be an integer ≥ 1, got {raw!r}",
                                       fix="set RFVERIFY_THREADS=1 (one thread) or unset it (all CPUs)")
        return n
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no sched_getaffinity (macOS, Windows)
        return max(1, os.cpu_count() or 1)


_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_lock = threading.Lock()


def _reset_after_fork() -> None:  # a forked child has the pool object but not its threads
    global _pool, _pool_size
    _pool, _pool_size = None, 0


if os.name == "posix":  # where fork exists (os.register_at_fork is POSIX-only)
    os.register_at_fork(after_in_child=_reset_after_fork)


def threads() -> int:
    """Threads a split kernel uses (``RFVERIFY_THREADS``, else the CPUs available)."""
    return _count()


def _executor(helpers: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size != helpers:
            if _pool is not None:  # RFVERIFY_THREADS changed: let the old threads go now
                _pool.shutdown(wait=False)
            _pool = ThreadPoolExecutor(max_workers=helpers, thread_name_prefix="rfverify-kernel")
            _pool_size = helpers
        return _pool


def ranges(n_items: int, parts: int) -> list[tuple[int, int]]:
    """``parts`` contiguous (lo, hi) ranges covering 0 … n_items, as equal as possible."""
    bounds = [n_items * i // parts for i in range(parts + 1)]
    return [(bounds[i], bounds[i + 1]) for i in range(parts) if bounds[i + 1] > bounds[i]]


def split(n_items: int, run, min_items: float, parts: int | None = None) -> list:
    """``run(lo, hi)`` over contiguous ranges of ``range(n_items)``, the first range in this
    thread and the others in the pool; the list of their return values, in range order.  One
    call ``run(0, n_items)`` when there are fewer than ``min_items`` items (``math.inf``: always
    one call; the caller knows its kernel's cost per item) or one thread."""
    if n_items < min_items:
        return [run(0, n_items)]
    parts = threads() if parts is None else parts
    if parts <= 1:
        return [run(0, n_items)]
    chunks = ranges(n_items, parts)
    pool = _executor(parts - 1)
    futures = [pool.submit(run, lo, hi) for lo, hi in chunks[1:]]
    first = run(*chunks[0])
    return [first] + [f.result() for f in futures]
