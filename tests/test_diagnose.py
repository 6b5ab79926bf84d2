"""Lockstep diagnosis: double iterations agree with the exact step to ~15 digits while the
problem is well conditioned, and a forced failure is located and explained."""

from __future__ import annotations

import json
import math

import rfverify
from rfverify.cli import main
from rfverify.diagnosis import diagnose


def test_lockstep_agreement_on_a_healthy_run():
    d = diagnose(rfverify.load("bundled:cube"), tol=1e-10)
    assert d.status == "Solved" and d.success and d.failure is None
    # Every double step is the exact step up to rounding (extended precision on).
    for rec in d.steps:
        assert min(rec["digits_v"], rec["digits_r_t"], rec["digits_z"]) > 12, rec
        assert not rec["flags"]
    # With the solver's default inexact linear solves (residuals ≤ 1e-4 of the right-hand
    # side) the steps differ from the exact ones by more than rounding, but not by much.
    d = diagnose(rfverify.load("bundled:cube"), tol=1e-10, refine_tol="adaptive")
    assert d.status == "Solved"
    worst = min(min(r["digits_v"], r["digits_r_t"], r["digits_z"]) for r in d.steps)
    assert 9 < worst < 15


def test_forced_failure_names_iteration_and_cause():
    d = diagnose(rfverify.load("bundled:chute"), tol=1e-25, max_iter=40)
    assert d.status != "Solved"
    assert "iteration" in d.failure
    flagged = [r for r in d.steps if r["flags"]]
    assert flagged, "the breakdown must be flagged"
    rec = flagged[0]
    assert "≤ 0 in double while exact is" in rec["flags"][0] or "underflowed" in rec["flags"][0]
    # Before the breakdown the agreement degrades as cond(Q_p) grows.
    assert rec["max_cond_Qp"] > 1e15
    early = d.steps[2]
    assert min(early["digits_v"], early["digits_z"]) > 12


def test_cli_diagnose_exit_code_is_the_double_runs_outcome(capsys):
    """Exit 1 when the double run did not reach --tol (the diagnosis is printed all the same),
    0 when it was Solved; --json does not change that."""
    assert main(["diagnose", "bundled:chute", "--tol", "1e-25", "--max-iter", "40"]) == 1
    out = capsys.readouterr().out
    assert "failure: iteration" in out and "first flagged iteration" in out
    assert main(["diagnose", "bundled:sphere", "--json", "--max-iter", "3"]) == 1
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "MaxIterations" and len(s["iterations"]) == 3
    assert main(["diagnose", "bundled:sphere", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "Solved" and s["iterations"]


def test_lockstep_builds_the_reference_once(monkeypatch):
    """One reference.Solver (one build of W̃, the block inverses and the ordering) serves every
    lockstep step."""
    import reference

    built, steps = [], []

    class Counting(reference.Solver):
        def __init__(self, *a, **k):
            built.append(1)
            super().__init__(*a, **k)

        def step(self, *a, **k):
            steps.append(1)
            return super().step(*a, **k)

    monkeypatch.setattr(reference, "Solver", Counting)
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-10)
    assert len(built) == 1 and len(steps) == len(d.steps) > 3


def test_iterate_without_an_exact_step_is_reported(monkeypatch):
    """Where the reference cannot step from the double iterate (not interior in exact
    arithmetic), that iteration has no digits (NaN, null in JSON) and a flag says why; the
    other iterations are diagnosed as usual."""
    import reference
    from reference import jordan as RJ

    real_step = reference.Solver.step
    calls = []

    def step(self, it, gamma, sigma_rule="paper", residuals=None):
        calls.append(1)
        if len(calls) == 2:
            raise RJ.ReferenceDomainError("nt_scaling", "'z' not interior")
        return real_step(self, it, gamma, sigma_rule, residuals)

    monkeypatch.setattr(reference.Solver, "step", step)
    d = diagnose(rfverify.load("bundled:sphere"), tol=1e-10)
    bad, good = d.steps[1], d.steps[2]
    assert all(math.isnan(bad[k]) for k in ("digits_v", "digits_r_t", "digits_z"))
    assert math.isnan(bad["min_lam2_z"]["reference"]) and bad["min_lam2_z"]["double"] > 0
    assert bad["flags"] == ["no exact step from the double iterate: nt_scaling: 'z' not interior"]
    assert min(good["digits_v"], good["digits_z"]) > 12 and not good["flags"]


def test_cli_diagnose_reports_progress_on_stderr_only(capsys):
    """Long lockstep runs are not silent: one stderr line for the double run and one per exact
    step; --json keeps stderr quiet and stdout pure JSON."""
    assert main(["diagnose", "bundled:sphere", "--max-iter", "3"]) == 1
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert lines[0].startswith("rfverify diagnose: double run (jqinv): MaxIterations after 3 iterations")
    assert [ln for ln in lines if "exact step" in ln] == [f"rfverify diagnose: exact step {k} of 3" for k in (1, 2, 3)]
    assert "rfverify diagnose:" not in captured.out  # progress stays off stdout
    assert main(["diagnose", "bundled:sphere", "--max-iter", "3", "--json"]) == 1
    captured = capsys.readouterr()
    assert captured.err == "" and json.loads(captured.out)["status"] == "MaxIterations"
