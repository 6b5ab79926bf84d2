"""Lockstep diagnosis: double iterations agree with the exact step to ~15 digits while the
problem is well conditioned, and a forced failure is located and explained."""

from __future__ import annotations

import json

import rfverify
from rfverify.cli import main
from rfverify.diagnosis import diagnose


def test_lockstep_agreement_on_a_healthy_run():
    d = diagnose(rfverify.load("bundled:cube"), tol=1e-10)
    assert d["status"] == "Solved" and d["failure"] is None
    # Every double step is the exact step up to rounding (extended precision on).
    for rec in d["iterations"]:
        assert min(rec["digits_v"], rec["digits_r_t"], rec["digits_z"]) > 12, rec
        assert not rec["flags"]


def test_forced_failure_names_iteration_and_cause():
    d = diagnose(rfverify.load("bundled:chute"), tol=1e-25, max_iter=40)
    assert d["status"] != "Solved"
    assert "iteration" in d["failure"]
    flagged = [r for r in d["iterations"] if r["flags"]]
    assert flagged, "the breakdown must be flagged"
    rec = flagged[0]
    assert "≤ 0 in double while exact is" in rec["flags"][0] or "underflowed" in rec["flags"][0]
    # Before the breakdown the agreement degrades as cond(Q_p) grows.
    assert rec["max_cond_Qp"] > 1e15
    early = d["iterations"][2]
    assert min(early["digits_v"], early["digits_z"]) > 12


def test_cli_diagnose(capsys):
    assert main(["diagnose", "bundled:chute", "--tol", "1e-25", "--max-iter", "40"]) == 0
    out = capsys.readouterr().out
    assert "failure: iteration" in out and "first flagged iteration" in out
    assert main(["diagnose", "bundled:sphere", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["status"] == "Solved" and s["iterations"]
