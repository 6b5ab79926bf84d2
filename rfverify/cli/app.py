"""The ``rfverify`` program: the parser assembled from the command modules, and :func:`main`,
which runs a command and maps what it raises to an exit code (see :mod:`rfverify.cli`)."""

from __future__ import annotations

import argparse
import difflib
import os
import re
import sys
import warnings

from .. import __version__
from ..errors import DataWarning, RfverifyError
from . import bench, certify, diagnose, generate, info, report, solve
from .common import DOCS_DIR, EXIT_BAD_INPUT, EXIT_INTERNAL

COMMANDS = (info, solve, certify, diagnose, bench, report, generate)
"""Command modules in the order ``rfverify --help`` lists them; each has ``add_parser(sub)``."""


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error format and exit code 2: the command, what is
    wrong, a "did you mean" where a near option or choice exists, and a fix."""

    def error(self, message):
        message = " ".join(str(message).split())
        choice = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if choice:
            options = re.findall(r"'([^']*)'", choice.group(2))
            message += _did_you_mean(choice.group(1), options)
        if "fix:" not in message:
            message += f"; fix: see '{self.prog} --help'"
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")

    def unrecognized(self, extra: list) -> None:
        """Exit 2 naming the arguments this command does not take, with the nearest options."""
        options = [o for action in self._actions for o in action.option_strings]
        hints = "".join(_did_you_mean(t.split("=")[0], options) for t in extra if t.startswith("-"))
        what = "argument" if len(extra) == 1 else "arguments"
        self.error(f"unrecognized {what}: {' '.join(extra)}{hints}")


def _did_you_mean(given: str, options) -> str:
    close = difflib.get_close_matches(given, list(options), n=1, cutoff=0.6)
    return f" (did you mean {close[0]}?)" if close else ""


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="rfverify",
        description="Verification-focused toolkit for rolling-friction contact problems "
                    "(FCLIB conventions: M v = H r + f, u = Hᵀ v + w, K* ∋ u ⊥ r ∈ K). "
                    "Conventions, cones, the algorithm, the stopping criterion and what a "
                    "certificate proves: DESIGN.md; a walk-through with your own file: "
                    "TUTORIAL.md; every option, exit code and file rule: REFERENCE.md; the "
                    f"result objects: RESULTS.md — installed with rfverify in {DOCS_DIR}.",
        epilog="Exit codes: 0 success, 1 tolerance not reached (solve; diagnose: its double run) or not "
               "certified (solve --digits, certify), 2 bad input or arguments, 3 internal error, 130 "
               "interrupted, 141 stdout closed early (e.g. | head), 143 bench stopped by SIGTERM "
               "(per command: REFERENCE.md, 'Guarantees', and each command's --help). "
               "--json output is strict JSON: non-finite numbers are null.",
    )
    parser.add_argument("--version", action="version", version=f"rfverify {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for command in COMMANDS:
        command.add_parser(sub)
    parser.commands = sub.choices  # name -> its parser: unrecognized arguments are its to report
    return parser


EXIT_BROKEN_PIPE = 141
"""Exit code when stdout is closed early (``rfverify info ... | head -1``): 128 + SIGPIPE, what
a shell reports for a program killed by the signal."""


def main(argv=None) -> int:
    try:
        parser = build_parser()
        args, extra = parser.parse_known_args(argv)
    except Exception as exc:  # a Ctrl-C inside an extension's import comes as an ImportError
        if not _caused_by_ctrl_c(exc):
            raise
        return _interrupted_before_parsing(argv)
    except KeyboardInterrupt:
        return _interrupted_before_parsing(argv)
    if extra:
        parser.commands[args.command].unrecognized(extra)
    try:
        with warnings.catch_warnings(record=True) as caught:
            # numpy/matplotlib warnings are not for the user's terminal: they are recorded and
            # shown only with RFVERIFY_DEBUG (commands turn the ones that matter into messages).
            warnings.simplefilter("always")
            if os.environ.get("RFVERIFY_THREADS", "").strip():  # a bad value is refused by every command, first
                from ..extended.workers import threads

                threads()
            check = getattr(args, "check_outputs", None)
            if check is not None:  # refuse an unusable output path before any work
                check(args)
            code = args.func(args)
            sys.stdout.flush()
        _print_data_warnings(args.command, caught)
        if os.environ.get("RFVERIFY_DEBUG"):
            for w in caught:
                print(f"rfverify {args.command}: debug: {w.category.__name__}: {w.message} "
                      f"({w.filename}:{w.lineno})", file=sys.stderr)
        return code
    except BrokenPipeError:
        _silence_stdout()
        return EXIT_BROKEN_PIPE
    except RfverifyError as exc:
        exc = _with_problem_file(exc, args)
        print(f"rfverify {args.command}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"rfverify {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # a bug, not bad input: say so in one line unless debugging
        if _caused_by_ctrl_c(exc):
            print(f"rfverify {args.command}: interrupted", file=sys.stderr)
            return 130
        if os.environ.get("RFVERIFY_DEBUG"):
            raise
        print(f"rfverify {args.command}: internal error: {type(exc).__name__}: {_one_line(exc)} "
              "(please report; set RFVERIFY_DEBUG=1 for a traceback)", file=sys.stderr)
        return EXIT_INTERNAL


def _interrupted_before_parsing(argv) -> int:
    """Ctrl-C before the parser has named the command: the first word that is not an option
    names it in the one line."""
    words = [a for a in (sys.argv[1:] if argv is None else argv) if not str(a).startswith("-")]
    print(f"rfverify{' ' + str(words[0]) if words else ''}: interrupted", file=sys.stderr)
    return 130


def _caused_by_ctrl_c(exc: BaseException) -> bool:
    """Whether ``exc`` comes from a KeyboardInterrupt.  A Ctrl-C that lands while a compiled
    extension initialises (scipy.spatial's pybind11 modules, imported on first use) is re-raised
    by the extension as ``ImportError: initialization failed`` from the KeyboardInterrupt: it is
    still the user's Ctrl-C, not a bug."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _print_data_warnings(command: str, caught) -> None:
    """Each distinct :class:`DataWarning` (something of an input file read with a stated change
    that leaves the problem as stored, e.g. an info string that is not UTF-8) as one line on
    stderr: the user must hear about it, unlike the numerical warnings recorded above.  After
    an error only the error is printed (one line)."""
    seen = set()
    for w in caught:
        if issubclass(w.category, DataWarning):
            line = _one_line(w.message)
            if line not in seen:
                seen.add(line)
                print(f"rfverify {command}: warning: {line}", file=sys.stderr)


def _silence_stdout() -> None:
    """After EPIPE: point stdout at /dev/null so the interpreter's final flush stays quiet."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):  # not a real file (e.g. captured in tests)
        return
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, fd)
    os.close(devnull)


def _with_problem_file(exc, args):
    """A data error raised after loading names the PROBLEM file it is about."""
    from ..errors import InvalidProblemError

    spec = getattr(args, "problem", None)
    if isinstance(exc, InvalidProblemError) and exc.path is None and spec:
        return exc.with_path(spec)
    return exc


def _one_line(exc) -> str:
    return " ".join(str(exc).split())
