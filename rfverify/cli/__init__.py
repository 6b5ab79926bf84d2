"""Command-line interface: ``rfverify <command> ...``.

One module per command (:mod:`.info`, :mod:`.solve`, :mod:`.certify`, :mod:`.diagnose`,
:mod:`.bench`, :mod:`.report`, :mod:`.generate`), each with ``add_parser(sub)`` and its
``cmd_*`` function; :mod:`.argtypes` holds the argument types, :mod:`.common` what the commands
share, and :mod:`.app` assembles the parser and maps errors to exit codes.  The CLI only reads
arguments, calls the library and prints: no module outside this package imports it.

Exit codes: 0 success; 1 a solve that did not reach its tolerance; 2 bad input (unreadable or invalid problem, bad arguments) with a
one-line message on stderr; 3 an internal error (a bug: please report it; set
``RFVERIFY_DEBUG=1`` for the traceback); 141 stdout closed early (``| head``), silently.
"""

from .app import EXIT_BROKEN_PIPE, build_parser, main
from .common import EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_NOT_SOLVED, EXIT_OK

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_NOT_SOLVED", "EXIT_BAD_INPUT", "EXIT_INTERNAL",
           "EXIT_BROKEN_PIPE"]
