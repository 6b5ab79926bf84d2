"""Issue 17, output hygiene: strict JSON (null for non-finite numbers), no Python warnings on
stderr (they become messages), a closed stdout pipe exits quietly."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

import rfverify
from rfverify.cli import EXIT_BROKEN_PIPE, main
from rfverify.io import write_fclib
from rfverify.io.output import dumps, json_safe
from rfverify.scenes.random_problems import random_problem


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def strict_loads(text):
    def refuse(constant):
        raise ValueError(f"non-standard JSON constant {constant}")

    return json.loads(text, parse_constant=refuse)


def test_dumps_turns_non_finite_numbers_into_null():
    obj = {"a": float("nan"), "b": [np.inf, -np.inf, 1.5], "c": np.float64("nan"),
           "d": np.array([1.0, np.nan]), "e": (np.int32(3), None), 4: "key"}
    text = dumps(obj)
    assert strict_loads(text) == {"a": None, "b": [None, None, 1.5], "c": None, "d": [1.0, None],
                                  "e": [3, None], "4": "key"}
    assert json_safe(2.5) == 2.5


@pytest.fixture(scope="module")
def overflowing(tmp_path_factory):
    """A valid problem whose 1e308 mass and 1e200-scaled H would overflow the solver's
    arithmetic and that no exact power-of-two change of units brings into range (M spans
    0.04 … 1e308): readable (info), refused by the solvers with one line (issue 37)."""
    p = random_problem(2, 3, seed=2)
    M = p.M.toarray()
    M[0, 0] = 1e308
    path = tmp_path_factory.mktemp("big") / "big.hdf5"
    write_fclib(rfverify.Problem.from_arrays(M, p.H * 1e200, p.f, p.w, p.mu, p.mu_r), path)
    return path


@pytest.mark.parametrize("argv", [
    ["info", "{big}", "--json"],
    ["solve", "{big}", "--json"],
    ["diagnose", "{big}", "--json", "--dps", "34"],
    ["diagnose", "bundled:chute", "--tol", "1e-25", "--json", "--dps", "34"],
])
def test_json_output_is_strict_and_warnings_do_not_leak(capsys, overflowing, argv):
    argv = [str(overflowing) if a == "{big}" else a for a in argv]
    code, out, err = run(capsys, *argv)
    if argv[0] in ("solve", "diagnose") and argv[1] == str(overflowing):
        # out of float64's range even after exact rescaling: one line naming the field, exit 2
        assert code == 2 and out == "" and err.count("\n") == 1 and "M: entries span" in err and "fix:" in err
        return
    assert code in (0, 1), err
    assert err == ""  # no RuntimeWarning text, no traceback
    data = strict_loads(out)
    assert isinstance(data, dict)


def _overflow_in_the_solve(monkeypatch):
    """A float64 overflow warning raised inside the solve (the data that used to cause one are
    now rescaled or refused): the reporting of warnings is what is tested."""
    from rfverify.solver import ipm

    real = ipm._float64_safe

    def overflowing_check(*arrays):
        np.float64(1e308) * np.float64(10.0)  # RuntimeWarning: overflow encountered
        return real(*arrays)

    monkeypatch.setattr(ipm, "_float64_safe", overflowing_check)


def test_numerical_warnings_become_a_message_in_text_output(capsys, monkeypatch):
    _overflow_in_the_solve(monkeypatch)
    code, out, err = run(capsys, "solve", "bundled:chute")
    assert err == ""
    assert "numerical warnings during the solve" in out and "overflow" in out
    code, out, err = run(capsys, "solve", "bundled:chute", "--json")
    data = strict_loads(out)
    assert err == "" and data["numerical_warnings"] and "overflow" in data["numerical_warnings"][0]


def _command():
    exe = shutil.which("rfverify")
    return [exe] if exe else [sys.executable, "-m", "rfverify"]


def test_closed_stdout_pipe_exits_quietly():
    proc = subprocess.Popen(_command() + ["info", "bundled:chute"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before rfverify writes its first line
    err = proc.stderr.read().decode()
    proc.stderr.close()
    code = proc.wait(timeout=120)
    assert err == "", err
    assert code == EXIT_BROKEN_PIPE


def test_pipe_into_head_is_quiet():
    shell = f"{' '.join(_command())} info bundled:chute --json | head -1"
    proc = subprocess.run(["bash", "-c", shell], capture_output=True, text=True, timeout=120)
    assert proc.stdout == "{\n" and proc.stderr == ""
