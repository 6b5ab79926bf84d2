"""``bench --problem coulomb`` and the report's section on the physical problem (issue 51), and
Siconos's GFC3D_IPM as the Coulomb peer whose answers rfverify certifies (the peer tests build
the peer as tests/test_siconos_peer.py does, and skip only when its sources are absent)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.cli import main

from test_siconos_peer import siconos_prefix  # noqa: F401  (the session fixture that builds the peer)


def _records(run):
    return {p.stem: json.loads(p.read_text()) for p in (run / "runs").rglob("coulomb-*.json")}


def test_bench_problem_coulomb_certifies_a_bundled_problem_and_the_report_shows_it(tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["bench", "bundled:sphere", "--problem", "coulomb", "--out", str(run), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "bundled/sphere:" in out
    recs = _records(run)
    assert list(recs) == ["coulomb-auto-digits10"], recs  # no relaxation tasks, no peer without --methods siconos
    rec = recs["coulomb-auto-digits10"]
    assert rec["kind"] == "coulomb" and rec["certified"] is True and rec["solved"] is True
    assert 0 < rec["backward_error"] <= 1e-10
    assert rec["outer_evaluations"] >= 1 and rec["proven_rounds"] >= 1
    assert f"rfverify (auto)" in out and f"certified to 10 digits: backward error {rec['backward_error']:.1e}" in out
    with np.load(run / "runs" / "bundled" / "sphere" / "coulomb-auto-digits10.npz") as z:
        v, r, shift = z["v"], z["r"], z["shift"]
    # The saved answer is the physical one: its certificate, made again from the arrays, agrees.
    p = rfverify.load("bundled:sphere")
    again = rfverify.certify(p, v, None, r, problem="coulomb", shift=shift)
    assert again.certified and again.backward_error <= 1e-10

    assert main(["report", str(run), "--quiet"]) == 0
    summary = (run / "summary.md").read_text()
    assert "## The physical problem (--problem coulomb)" in summary
    assert "rfverify: 1/1 certified" in summary
    row = next(line for line in summary.splitlines() if line.startswith("| bundled/sphere | rfverify (auto)"))
    assert f"| yes | {rec['backward_error']:.1e} |" in row
    assert "the physical problem only" in summary  # no relaxation runs: that section alone


def test_bench_problem_coulomb_refuses_methods_it_has_no_use_for(tmp_path, capsys):
    assert main(["bench", "bundled:sphere", "--problem", "coulomb", "--methods", "clarabel",
                 "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err
    assert "--methods clarabel: not a method of --problem coulomb" in err and "fix:" in err
    assert main(["bench", "bundled:sphere", "--problem", "coulomb", "--digits", "0",
                 "--out", str(tmp_path / "r")]) == 2


def test_the_peer_missing_is_refused_before_any_task(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("RFVERIFY_SICONOS", str(tmp_path / "nowhere"))
    assert main(["bench", "bundled:sphere", "--problem", "coulomb", "--methods", "auto,siconos",
                 "--out", str(tmp_path / "r")]) == 2
    assert "build.sh" in capsys.readouterr().err
    assert not (tmp_path / "r" / "runs").exists()


def _chute_3d():
    """The bundled chute's 3-D problem (rolling columns and rows dropped, μr = 0)."""
    p = rfverify.load("bundled:chute")
    n = p.n_contacts
    keep = np.ones(5 * n)
    keep[3::5] = keep[4::5] = 0
    return rfverify.Problem.from_arrays(p.M, sp.csc_matrix(p.H @ sp.diags(keep)), p.f, np.asarray(p.w) * keep,
                                        p.mu, np.zeros(n), title="chute (3-D)", max_asymmetry=np.inf,
                                        provenance={"format": "fclib_global", "spacedim": 3})


def test_gfc3d_answers_the_physical_problem_and_is_certified_by_its_backward_error(siconos_prefix):
    from rfverify.solver.siconos_peer import solve_gfc3d

    p = _chute_3d()
    ans = solve_gfc3d(p, tol=1e-10, max_iter=100)
    assert ans.answered and ans.info == 0 and ans.status == "Solved", ans.failure
    u = p.H.T @ ans.v + np.asarray(p.w)
    U, S = u.reshape(-1, 5), ans.u_siconos.reshape(-1, 5)
    # Its velocity is De Saxcé's: u_N + μ‖u_T‖ (it updates the shift inside its iterations).
    np.testing.assert_allclose(S[:, 0], U[:, 0] + p.mu * np.hypot(U[:, 1], U[:, 2]), rtol=0, atol=1e-8)
    cert = rfverify.certify(p, ans.v, None, ans.r, problem="coulomb")
    assert cert.backward.proven and 0 < cert.backward_error <= 1e-9  # measured 5.6e-11
    # Judged as the convex relaxation instead, the same answer is far from a solution.
    relaxed = rfverify.certify(p, ans.v, None, ans.r, digits=3, polish_max_iter=0)
    assert not relaxed.certified


def test_bench_certifies_the_peer_beside_ours_and_says_why_it_did_not_run(siconos_prefix, tmp_path, capsys):
    path = rfverify.save(_chute_3d(), tmp_path / "chute-3d.hdf5")
    run = tmp_path / "run"
    assert main(["bench", str(path), "bundled:sphere", "--problem", "coulomb", "--methods", "auto,siconos",
                 "--tol", "1e-10", "--out", str(run), "--quiet"]) == 0
    out = capsys.readouterr().out
    recs = _records(run)
    peer = recs["coulomb-siconos@1e-10-digits10"]
    assert set(recs) == {"coulomb-auto-digits10", "coulomb-siconos@1e-10-digits10"}
    assert peer["peer_status"] == "Solved" and peer["peer_iterations"] > 0
    assert isinstance(peer["backward_error"], float) and peer["backward_error"] <= 1e-9
    line = next(x for x in out.splitlines() if "Siconos GFC3D_IPM (tol 1e-10)" in x and "backward error" in x)
    assert f"backward error {peer['backward_error']:.1e}" in line and "GFC3D says Solved" in line
    # The rolling sphere: GFC3D is not run, and the output says why.
    assert "NotRun: a rolling problem" in out and "GFC3D_IPM solves 3-D Coulomb friction only" in out
    assert main(["report", str(run), "--quiet"]) == 0
    summary = (run / "summary.md").read_text()
    assert "Siconos GFC3D_IPM (tol 1e-10)" in summary and f"{peer['backward_error']:.1e}" in summary


def test_a_gfc3d_crash_is_a_record_with_its_reason(siconos_prefix, tmp_path, monkeypatch):
    from rfverify.solver.siconos_peer import solve_gfc3d

    monkeypatch.setenv("RFVERIFY_SICONOS_FAULT", "sigsegv")
    ans = solve_gfc3d(_chute_3d(), tol=1e-8)
    assert not ans.answered and "siconos crashed (signal 11)" in ans.failure and "GFC3D_IPM" in ans.failure
    assert os.environ["RFVERIFY_SICONOS"] == siconos_prefix
