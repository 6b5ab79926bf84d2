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


def main():
    previous = signal.signal(signal.SIGINT, _interrupted_while_starting)
    from rfverify.cli import main as run

    signal.signal(signal.SIGINT, previous)
    code = run()
    # A Ctrl-C that lands inside an exec() of a string (dataclasses make their methods so, as
    # modules are imported) leaves CPython's "unhandled KeyboardInterrupt" flag set even when the
    # command catches it; `python -m` then ends by SIGINT (-2) instead of with the code returned.
    # An exec() of a string clears the flag again.
    exec("")
    sys.exit(code)


if __name__ == "__main__":
    main()
