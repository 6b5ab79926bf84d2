"""Issue 49, the first hour with rfverify: `solve` says which method ran and why, a long run
shows its iterations on stderr (--quiet silences them); a numba compilation is named by the kernel
it compiles, on any run (tests/test_everyday.py)."""

from __future__ import annotations

import re

import pytest

import rfverify
from rfverify.cli import main
from rfverify.cli.common import PROGRESS_AFTER_ENV, IterationProgress
from rfverify.scenes.random_problems import random_local_problem
from rfverify.solver.result import IterationInfo

ITERATION_LINE = re.compile(r"^rfverify solve:   (\w+) iteration (\d+)(?: \(component \d+\))?: "
                            r"μ = \S+, criterion = \S+, [\d.]+ s"
                            r"(?:; full step|; step [\d.]+, held by contact \d+'s (?:friction|rolling|normal) "
                            r"cone \((?:velocity|reaction)\))?$")


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------------- the method line
def test_solve_text_names_the_form_auto_ran_and_why(capsys):
    code, out, err = run(capsys, "solve", "bundled:sphere")
    assert code == 0
    assert ("method jqinv (auto: jqinv first, as 1 contact < 500; next reduced, then noscaling, then jqinv (σ rule paper), had it stalled)"
            in out.splitlines()), out
    code, out, err = run(capsys, "solve", "bundled:sphere", "--sigma-rule", "hybrid")  # a chosen rule: no last resort
    assert code == 0 and ("method jqinv (auto: jqinv first, as 1 contact < 500; next reduced, then noscaling, had it "
                          "stalled)" in out.splitlines()), out


def test_solve_text_names_a_requested_method(capsys):
    code, out, err = run(capsys, "solve", "bundled:sphere", "--method", "qp2")
    assert code == 0 and "method qp2 (as requested)" in out.splitlines(), out


def test_solve_text_says_what_auto_tried_before_the_form_it_returns(capsys, tmp_path):
    """jqinv stalls on this lifted local problem and reduced solves it (tests/test_solver.py):
    the method line names both runs, in order, with how each ended."""
    path = tmp_path / "local.h5"
    rfverify.save(random_local_problem(60, seed=0), path)
    code, out, err = run(capsys, "solve", path)
    line = next(x for x in out.splitlines() if x.startswith("method "))
    assert code == 0
    assert re.fullmatch(r"method reduced \(auto: jqinv first, as 60 contacts < 500; jqinv InsufficientProgress "
                        r"at criterion \S+ after \d+ iterations \([\d.]+ s\), then reduced Solved at criterion \S+ "
                        r"after \d+ iterations \([\d.]+ s\)\)", line), line


def test_solve_digits_text_names_the_double_solve_form(capsys):
    code, out, err = run(capsys, "solve", "bundled:sphere", "--digits", "6", "--quiet")
    assert code == 0 and out.startswith("double solve (jqinv by auto): Solved in "), out


# ------------------------------------------------------------------------ progress on stderr
def test_a_run_past_the_threshold_shows_its_iterations_on_stderr(capsys, monkeypatch):
    monkeypatch.setenv(PROGRESS_AFTER_ENV, "0")
    code, out, err = run(capsys, "solve", "bundled:chute")
    lines = [x for x in err.splitlines() if "iteration" in x]
    assert code == 0 and lines, err
    assert all(ITERATION_LINE.match(x) for x in lines), lines
    assert ITERATION_LINE.match(lines[0]).group(1) == "jqinv" and ITERATION_LINE.match(lines[0]).group(2) == "0"
    assert not any(ITERATION_LINE.match(x) for x in out.splitlines())  # stdout holds the result only


def test_quiet_and_json_silence_the_iterations(capsys, monkeypatch):
    monkeypatch.setenv(PROGRESS_AFTER_ENV, "0")
    code, out, err = run(capsys, "solve", "bundled:chute", "--quiet")
    assert code == 0 and err == "" and out.startswith("status Solved")
    code, out, err = run(capsys, "solve", "bundled:chute", "--json")
    assert code == 0 and err == ""


def test_a_short_run_prints_no_progress(capsys, monkeypatch):
    """Below the threshold (here an hour) the run is quiet: the lines are for long runs."""
    monkeypatch.setenv(PROGRESS_AFTER_ENV, "3600")
    code, out, err = run(capsys, "solve", "bundled:chute")
    assert code == 0 and "iteration" not in err, err


def test_the_digits_path_shows_its_double_solve_iterations(capsys, monkeypatch):
    monkeypatch.setenv(PROGRESS_AFTER_ENV, "0")
    code, out, err = run(capsys, "solve", "bundled:sphere", "--digits", "6")
    lines = err.splitlines()
    first = next(i for i, x in enumerate(lines) if ITERATION_LINE.match(x))
    stage = next(i for i, x in enumerate(lines) if x.startswith("rfverify solve: double solve (jqinv by auto)"))
    assert code == 0 and first < stage, err


def test_a_peer_run_past_the_threshold_is_named(capsys, monkeypatch):
    monkeypatch.setenv(PROGRESS_AFTER_ENV, "0")
    code, out, err = run(capsys, "solve", "bundled:sphere", "--method", "clarabel")
    assert code == 0 and err.startswith("rfverify solve: clarabel is running (a peer solver"), err
    code, out, err = run(capsys, "solve", "bundled:sphere", "--method", "clarabel", "--quiet")
    assert err == ""


@pytest.mark.parametrize("value", ["x", "-1", "nan", "inf"])
def test_a_bad_threshold_is_refused_with_the_fix(capsys, monkeypatch, value):
    monkeypatch.setenv(PROGRESS_AFTER_ENV, value)
    code, out, err = run(capsys, "solve", "bundled:sphere")
    assert code == 2 and out == ""
    assert err.startswith(f"rfverify solve: error: {PROGRESS_AFTER_ENV}: must be a number of seconds ≥ 0")
    assert "fix: set RFVERIFY_PROGRESS_AFTER=2" in err


def _info(k, method="jqinv", component=0, components=2):
    nan = float("nan")
    return IterationInfo(component=component, iteration=k, criterion=10.0 ** -k, pinfeas=nan, dinfeas=nan,
                         mu=10.0 ** -k, sigma=nan, alpha_aff=nan, alpha=nan, min_lam2_z=nan, min_lam2_s=nan,
                         max_cond_Qp=nan, solve_residual=nan, elapsed=0.0, method=method, components=components)


def test_iteration_lines_are_spaced_but_a_new_form_or_component_is_always_shown():
    lines = []
    progress = IterationProgress(lines.append, after=0.0, every=3600.0)
    for info in (_info(0), _info(1), _info(0, "reduced"), _info(1, "reduced"), _info(0, "reduced", 1)):
        assert progress(info) is False  # never stops the run
    # numbered from 0 as in the JSON, the first component named too (it was not, and the second was "2")
    assert [x.split(":")[0].strip() for x in lines] == ["jqinv iteration 0 (component 0)",
                                                        "reduced iteration 0 (component 0)",
                                                        "reduced iteration 0 (component 1)"]
    one = []
    IterationProgress(one.append, after=0.0, every=3600.0)(_info(0, components=1))
    assert one[0].split(":")[0].strip() == "jqinv iteration 0"  # a problem solved as one names none
    every = []
    progress = IterationProgress(every.append, after=0.0, every=0.0)
    for k in range(4):
        progress(_info(k))
    assert len(every) == 4
    late = []
    IterationProgress(late.append, after=3600.0)(_info(0))
    assert late == []


def test_a_split_run_names_every_component_of_its_progress_lines(capsys, monkeypatch):
    """The bundled Chute is solved as 4 independent components: every iteration line names its
    component, numbered as the JSON's component_traces are."""
    import json
    import re

    monkeypatch.setenv(PROGRESS_AFTER_ENV, "0")
    code, out, err = run(capsys, "solve", "bundled:chute")
    lines = [x for x in err.splitlines() if " iteration " in x and "μ =" in x]
    assert code == 0 and lines, err
    named = [re.search(r"\(component (\d+)\)", x) for x in lines]
    assert all(named), lines
    code, out, _ = run(capsys, "solve", "bundled:chute", "--json", "--quiet")
    traces = json.loads(out)["component_traces"]
    assert {int(m.group(1)) for m in named} == set(range(len(traces))) and len(traces) == 4
