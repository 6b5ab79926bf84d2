"""``python -m rfverify`` and the ``rfverify`` console script (``rfverify.__main__:main``): Ctrl-C
ends it cleanly from its first instant.

The commands' imports (numpy, scipy, numba, h5py) take a second or more, and a Ctrl-C during
them would print a traceback from inside an import, before :func:`rfverify.cli.main` has its
handler.  The package itself starts light (its public names are made on first use, PEP 562), so
this module runs before any of those imports: it turns a Ctrl-C during start-up into the
command's one line and exit 130, then hands over to :func:`rfverify.cli.main`, which handles
every later one itself.
"""

import os
import signal
import sys


def _interrupted_while_starting(signum, frame):
    command = next((a for a in sys.argv[1:] if not a.startswith("-")), "")
    sys.stderr.write(f"rfverify{' ' + command if command else ''}: interrupted\n")
    sys.stderr.flush()
    os._exit(130)  # nothing is written yet; no import is left half-done to clean up


def _ending(code: int) -> None:
    """The command has returned ``code`` and its output is complete.  After a Ctrl-C, a CHOLMOD
    factorisation may still run on its thread (it cannot be stopped,
    :mod:`rfverify.engines.cholmod_nogil`): the process waits for it, saying so, since ending
    under it in the normal way would crash, and a second Ctrl-C leaves at once with ``code``.
    Then the interpreter's teardown (a few tenths of a second at 10⁴ contacts: freeing the
    factors) ignores Ctrl-C: Python restores SIGINT's default action there, and a second Ctrl-C
    would end the process by the signal instead of with ``code``, or print a traceback."""

    def leave(signum, frame):
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)  # also skips the library teardown a running factorisation would crash in

    signal.signal(signal.SIGINT, leave)
    engine = sys.modules.get("rfverify.engines.cholmod_nogil")
    threads = engine.left_running() if engine is not None else []
    if threads:
        sys.stderr.write("rfverify: waiting for a CHOLMOD factorisation that cannot be stopped to finish; "
                         "Ctrl-C again to leave at once\n")
        sys.stderr.flush()
    for thread in threads:
        while thread.is_alive():
            thread.join(0.1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def main():
    previous = signal.signal(signal.SIGINT, _interrupted_while_starting)
    from rfverify.cli import main as run

    signal.signal(signal.SIGINT, previous)
    code = run()
    _ending(code)
    # A Ctrl-C that lands inside an exec() of a string (dataclasses make their methods so, as
    # modules are imported) leaves CPython's "unhandled KeyboardInterrupt" flag set even when the
    # command catches it; `python -m` then ends by SIGINT (-2) instead of with the code returned.
    # An exec() of a string clears the flag again.
    exec("")
    sys.exit(code)


if __name__ == "__main__":
    main()
