"""The ``rfverify`` console script: Ctrl-C ends it cleanly from its first instant.

The package's imports (numpy, scipy, numba, h5py) take a second or more, and a Ctrl-C during
them would print a traceback from inside an import, before :func:`rfverify.cli.main` has its
handler.  This module is imported before any of them: it turns a Ctrl-C during start-up into
the command's one line and exit 130, then hands over to :func:`rfverify.cli.main`, which handles
every later one itself.  (A top-level module, because importing anything inside the
``rfverify`` package first runs the package's own imports.)
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
    sys.exit(run())


if __name__ == "__main__":
    main()
