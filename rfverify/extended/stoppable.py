"""Compiled kernels that can run for minutes, stoppable by the time limit and by Ctrl-C.

A compiled loop never returns to the interpreter, so neither a signal handler nor a deadline
check runs until it ends: a 96 256-contact touching bed was inside its double-double fallback
factorisation 50 minutes into its run, past its 2400 s time limit and two Ctrl-Cs
(docs/DECISIONS.md, "Stoppable kernels").
:func:`run_stoppable` therefore runs such a kernel (``nogil=True``, polling a stop flag) on a
helper thread while the main thread waits in short slices: a Ctrl-C (which Python delivers to
the main thread) or the time limit sets the flag, the kernel returns at its next poll, and the
main thread raises :class:`KeyboardInterrupt` or :class:`OutOfTime` — which the Algorithm 1 loop
turns into the best iterate so far (:func:`rfverify.algorithm.loop.iterate`).

The time limit and the progress line reach the kernels through :func:`long_kernels` (context
variables the k-digit path sets around its extended phases), so no back end needs them as
arguments.
"""

from __future__ import annotations

import contextlib
import contextvars
import threading
import time

import numpy as np

from ..algorithm.interfaces import OutOfTime

POLL_SECONDS = 0.1
"""How often the waiting main thread looks at the clock (a Ctrl-C interrupts the wait at once)."""

_DEADLINE: contextvars.ContextVar[float | None] = contextvars.ContextVar("rfverify_kernel_deadline", default=None)
_SAY: contextvars.ContextVar = contextvars.ContextVar("rfverify_kernel_progress", default=None)
_CANCEL: contextvars.ContextVar[threading.Event | None] = contextvars.ContextVar("rfverify_kernel_cancel",
                                                                                default=None)


class Cancelled(Exception):
    """A stoppable kernel on a thread other than the main one was stopped by its owner's
    ``cancel`` event (:func:`long_kernels`): the work it was part of is abandoned."""


@contextlib.contextmanager
def long_kernels(deadline: float | None, say=None, cancel: threading.Event | None = None):
    """``with long_kernels(t, say, cancel):`` — stoppable kernels run inside stop at
    ``time.perf_counter() > t`` (None: no time limit) or once ``cancel`` is set (for a thread
    other than the main one, which Ctrl-C does not reach: :class:`Cancelled`), and
    :func:`announce` tells ``say`` (a progress callable of one string; None: nobody) what a
    long one is about to do."""
    tokens = _DEADLINE.set(deadline), _SAY.set(say), _CANCEL.set(cancel)
    try:
        yield
    finally:
        _DEADLINE.reset(tokens[0])
        _SAY.reset(tokens[1])
        _CANCEL.reset(tokens[2])


def announce(message: str) -> None:
    """One progress line, where :func:`long_kernels` gave a ``say``."""
    say = _SAY.get()
    if say is not None:
        say(message)


def seconds_left() -> float | None:
    """Seconds until the kernels' deadline (negative once past), or None without one."""
    deadline = _DEADLINE.get()
    return None if deadline is None else deadline - time.perf_counter()


def run_stoppable(kernel, args: tuple, what: str):
    """``kernel(*args, stop)`` — ``stop`` an int64 array of one zero that the kernel polls and
    returns at once when it is nonzero — on a helper thread; its return value.  A Ctrl-C
    meanwhile stops it and is raised again; the deadline of :func:`long_kernels` stops it and
    raises :class:`OutOfTime` naming ``what`` was stopped, its cancel event :class:`Cancelled`."""
    stop = np.zeros(1, dtype=np.int64)
    deadline, cancel = _DEADLINE.get(), _CANCEL.get()
    done, failed = [], []
    finished = threading.Event()  # not Thread.join: a Ctrl-C inside join() can leave it returning early

    def work():
        try:
            done.append(kernel(*args, stop))
        except BaseException as exc:  # handed to the main thread, raised there
            failed.append(exc)
        finally:
            finished.set()

    try:
        threading.Thread(target=work, name="rfverify-stoppable", daemon=True).start()
        while not finished.wait(POLL_SECONDS):
            if deadline is not None and time.perf_counter() > deadline:
                raise OutOfTime(f"the time limit was reached during {what}, which was stopped")
            if cancel is not None and cancel.is_set():
                raise Cancelled(f"{what} was cancelled")
    except BaseException:  # Ctrl-C, or the two above: the kernel returns at its next poll
        stop[0] = 1
        finished.wait()
        raise
    if failed:
        raise failed[0]
    return done[0]
