"""Issue 39: Ctrl-C always stops.  SIGINT sent to the process group of a running ``bench`` at
random moments (importing, warming up, workers starting, running, writing records) must end it
with exit 130 and one line, kill every worker, and leave no half-written record; an
interrupted solve keeps its best iterate."""

from __future__ import annotations

import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time

import pytest

import rfverify

REPEATS = 20


def _command():
    """The console script as pyproject declares it (``rfverify.__main__:main``), run as its
    installed wrapper runs it: import that module, call that function.  (The wrapper beside this
    interpreter may come from an older install of another checkout.)"""
    import tomllib
    from pathlib import Path

    entry = tomllib.loads((Path(__file__).resolve().parent.parent / "pyproject.toml").read_text())
    module, func = entry["project"]["scripts"]["rfverify"].split(":")
    return [sys.executable, "-c", f"import sys; from {module} import {func}; sys.exit({func}())"]


@pytest.mark.parametrize("how", ["console script", "python -m rfverify"])
def test_ctrl_c_while_starting_gives_one_line_and_exit_130(how):
    """A Ctrl-C while the command's imports run (numpy, scipy, numba: most of a second) ends it
    with its one line and exit 130, for the console script and for ``python -m rfverify`` alike:
    the package starts light, so the handler is in place before any heavy import."""
    command = _command() if how == "console script" else [sys.executable, "-m", "rfverify"]
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    seen = []
    for delay in (0.25, 0.35, 0.45):
        proc = subprocess.Popen(command + ["solve", "bundled:chute", "--quiet"], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, env=env)
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=120)
        seen.append((proc.returncode, err.decode()))
    interrupted = [s for s in seen if s[0] != 0]
    assert interrupted, seen  # at least one signal landed before the solve ended
    # Its one line: bare while starting, with what it kept once the solve has an iterate.
    assert all(s[0] == 130 and re.fullmatch(r"rfverify solve: interrupted( \(the best iterate so far is "
                                            r"reported above\))?\n", s[1]) for s in interrupted), seen


def test_a_caught_ctrl_c_inside_an_exec_does_not_turn_the_exit_into_a_signal():
    """A Ctrl-C that lands inside an exec() of a string (dataclasses build their methods so while
    modules import) sets CPython's "unhandled KeyboardInterrupt" flag even though the command
    catches it, and ``python -m rfverify`` then died by SIGINT instead of exiting 130 (seen in
    CI).  The entry point clears the flag before it exits: checked here on the flag itself."""
    script = (
        "import ctypes, sys\n"
        "flag = ctypes.c_int.in_dll(ctypes.pythonapi, '_Py_UnhandledKeyboardInterrupt')\n"
        "import rfverify.cli\n"
        "def interrupted_in_an_exec(argv=None):\n"
        "    try:\n        exec('raise KeyboardInterrupt')\n    except KeyboardInterrupt:\n        return 130\n"
        "rfverify.cli.main = interrupted_in_an_exec\n"
        "from rfverify.__main__ import main\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    print(exc.code, flag.value)\n")
    if sys.implementation.name != "cpython" or sys.version_info >= (3, 12):
        pytest.skip("the flag is a CPython 3.11 global (3.12 keeps it in the runtime state)")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[-2:] == ["130", "0"], done.stdout


def _group_alive(pgid: int) -> bool:
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


@pytest.mark.slow
def test_ctrl_c_at_random_moments_always_stops_the_bench(tmp_path):
    rng = random.Random(20261204)
    codes = []
    for trial in range(REPEATS):
        run_dir = tmp_path / f"run{trial}"
        proc = subprocess.Popen(_command() + ["bench", "bundled:chute", "bundled:sphere", "--out", str(run_dir),
                                              "--quiet", "--jobs", "2"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        time.sleep(rng.uniform(0.3, 4.0))
        try:
            os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does: the whole group
        except ProcessLookupError:
            pass
        out, err = proc.communicate(timeout=120)
        err = err.decode()
        codes.append(proc.returncode)
        if proc.returncode == 0:  # the bench had already finished: nothing to interrupt
            continue
        if proc.returncode == -signal.SIGINT and err == "" and "runs done" in out.decode():
            # Finished too: the signal landed in the interpreter's last instants, after its
            # finalisation put SIGINT back to the default action (CPython's _PySignal_Fini).
            # Seen once in ~100 trials; anything else killed by SIGINT fails below.
            continue
        assert proc.returncode == 130, (trial, proc.returncode, err)
        assert err == "rfverify bench: interrupted\n", (trial, err)
        deadline = time.monotonic() + 10
        while _group_alive(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not _group_alive(proc.pid), f"trial {trial}: a worker outlived the bench"
        for rec in run_dir.rglob("*.json"):  # every record under its final name is whole
            json.loads(rec.read_text())
        assert not list(run_dir.rglob(".*.tmp")), trial
    assert codes.count(130) >= REPEATS // 2, codes  # most trials really interrupted a running bench


def test_an_interrupted_solve_keeps_its_best_iterate(monkeypatch):
    """Ctrl-C inside an iteration: the solve returns (status Stopped, ``interrupted``) with the
    best iterate so far instead of losing everything."""
    from rfverify.solver import ipm

    calls = {"n": 0}
    real = ipm._KKTNewton.solve

    def interrupt_at_iteration_5(self, a, b, c, phase):
        calls["n"] += 1
        if calls["n"] == 11:  # the 6th iteration's predictor
            raise KeyboardInterrupt
        return real(self, a, b, c, phase)

    monkeypatch.setattr(ipm._KKTNewton, "solve", interrupt_at_iteration_5)
    res = rfverify.solve(rfverify.load("bundled:sphere"), method="jqinv")
    assert res.status == "Stopped" and res.extras.get("interrupted") and "interrupted" in res.message
    assert res.nit >= 4 and res.criterion < 1


def _import_failed_by_ctrl_c() -> ImportError:
    """What a pybind11 extension (scipy.spatial's ``_distance_pybind``) raises when Ctrl-C lands
    while it initialises: ``ImportError: initialization failed`` from the KeyboardInterrupt.  The
    CI run of 2026-12-06 ended so, exit 1 with a traceback, while the parser imported scenes."""
    error = ImportError("initialization failed")
    error.__cause__ = KeyboardInterrupt()
    return error


@pytest.mark.parametrize("where", ["building the parser", "running the command"])
def test_a_ctrl_c_turned_into_an_import_error_is_still_an_interrupt(monkeypatch, capsys, where):
    from rfverify.cli import app

    error = _import_failed_by_ctrl_c()

    def raising(*args, **kwargs):
        raise error

    if where == "building the parser":
        monkeypatch.setattr(app, "build_parser", raising)
    else:
        parser = app.build_parser()
        monkeypatch.setattr(app, "build_parser", lambda: parser)
        parser.commands["solve"].set_defaults(func=raising)
    assert app.main(["solve", "bundled:chute", "--quiet"]) == 130
    assert capsys.readouterr().err == "rfverify solve: interrupted\n"


def test_an_import_error_of_its_own_is_not_taken_for_an_interrupt(monkeypatch, capsys):
    """The check follows the cause chain only: a real ImportError stays an internal error."""
    from rfverify.cli import app

    parser = app.build_parser()
    monkeypatch.setattr(app, "build_parser", lambda: parser)
    monkeypatch.delenv("RFVERIFY_DEBUG", raising=False)

    def broken(args):
        raise ImportError("initialization failed")

    parser.commands["solve"].set_defaults(func=broken)
    assert app.main(["solve", "bundled:chute", "--quiet"]) == app.EXIT_INTERNAL
    assert "internal error: ImportError" in capsys.readouterr().err


def _ending_script(second_ctrl_c: bool) -> str:
    """A process whose command 'returned 130' while a factorisation that a Ctrl-C left running
    (here a thread sleeping for ``hold`` seconds) goes on; with ``second_ctrl_c`` the process
    sends itself one more SIGINT once it waits."""
    return (
        "import os, signal, sys, threading, time\n"
        "from rfverify.engines import cholmod_nogil\n"
        "import rfverify.__main__ as entry\n"
        f"hold = {60 if second_ctrl_c else 1.0}\n"
        "t = threading.Thread(target=time.sleep, args=(hold,))\n"
        "t.start()\n"
        "cholmod_nogil._left_running.add(t)\n"
        f"if {second_ctrl_c}:\n"
        "    threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()\n"
        "t0 = time.perf_counter()\n"
        "entry._ending(130)\n"
        "print('waited', round(time.perf_counter() - t0, 1), signal.getsignal(signal.SIGINT) is signal.SIG_IGN)\n"
        "sys.exit(130)\n")


def test_the_process_waits_for_a_factorisation_a_ctrl_c_left_running_and_says_so():
    """Ending under a CHOLMOD factorisation that is still running crashes the process (its BLAS
    is torn down at exit): the entry point waits for it, saying why, and then ignores Ctrl-C
    during the teardown, where Python would otherwise end the process by the signal."""
    done = subprocess.run([sys.executable, "-c", _ending_script(False)], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 130, done.stderr
    assert done.stderr == ("rfverify: waiting for a CHOLMOD factorisation that cannot be stopped to finish; "
                           "Ctrl-C again to leave at once\n")
    waited, ignored = done.stdout.split()[1:]
    assert float(waited) >= 0.5 and ignored == "True"


def test_a_second_ctrl_c_leaves_at_once_with_the_commands_code():
    done = subprocess.run([sys.executable, "-c", _ending_script(True)], capture_output=True, text=True,
                          timeout=50)  # the thread holds for 60 s: only leaving at once passes
    assert done.returncode == 130 and "waited" not in done.stdout, (done.stdout, done.stderr)
    assert "Traceback" not in done.stderr
