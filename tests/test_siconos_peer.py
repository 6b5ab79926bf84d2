"""The Siconos peer (issue 30): the paper's own GRFC3D_IPM, built from ../shared/peers/siconos.

The session fixture builds it with benchmarks/peers/siconos/build.sh (cached: seconds when built
before; ~3 min from scratch on 2 cores).  The tests skip only when the sources are absent; when
they are present, a failing build fails the tests.
"""

from __future__ import annotations

import glob
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest

import rfverify
from rfverify.errors import InvalidArgumentError
from rfverify.io import load
from rfverify.model.measures import measures
from rfverify.solver import Status
from rfverify.solver.result import method_unavailable

from conftest import REPO_ROOT
from test_docs import console_steps, run_steps

SOURCES = REPO_ROOT.parent / "shared" / "peers" / "siconos"
BUILD = REPO_ROOT / "benchmarks" / "peers" / "siconos" / "build.sh"


@pytest.fixture(scope="session")
def siconos_prefix():
    """The prefix of a built peer (RFVERIFY_SICONOS set to it for the session)."""
    if not SOURCES.is_dir():
        pytest.skip(f"Siconos sources absent ({SOURCES}): the peer cannot be built here")
    proc = subprocess.run(["bash", str(BUILD)], capture_output=True, text=True, timeout=1800, check=False)
    if proc.returncode != 0:
        pytest.fail(f"build.sh failed (exit {proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    prefix = proc.stdout.strip().splitlines()[-1]
    old = os.environ.get("RFVERIFY_SICONOS")
    os.environ["RFVERIFY_SICONOS"] = prefix
    yield prefix
    if old is None:
        os.environ.pop("RFVERIFY_SICONOS", None)
    else:
        os.environ["RFVERIFY_SICONOS"] = old


def _P(problem):
    """P = diag(1, μ, μ, μr, μr) per contact, as a vector."""
    P = np.ones((problem.n_contacts, 5))
    P[:, 1:3] = problem.mu[:, None]
    P[:, 3:5] = problem.mu_r[:, None]
    return P.ravel()


@pytest.mark.parametrize("name", ["chute", "cube"])
def test_answer_unscaled_meets_the_criterion_and_agrees_with_rfverify(siconos_prefix, name):
    problem = load(f"bundled:{name}")
    res = rfverify.solve(problem, method="siconos", tol=1e-10)
    assert res.method == "siconos" and res.extras["siconos_info"] == 0, res.message
    assert res.status is Status.SOLVED, res.message
    # The driver's unscaling is exactly r = P r_s, u = P⁻¹ u_s ...
    P = _P(problem)
    u = res.extras["u_s"] / P
    np.testing.assert_array_equal(res.r, res.extras["r_s"] * P)
    if problem.local is None:  # a local file's answer gets u = W r + q of the file (judged_on_the_file)
        np.testing.assert_array_equal(res.u, u)
    # ... and it is what makes the answer right: on the global problem (for the local cube: its
    # lifting, which Siconos solved), the unscaled triple meets rfverify's criterion, the scaled
    # one does not.
    on_lifting = measures(problem, res.v, u, res.r, "longdouble")
    assert on_lifting.max <= 1e-9, on_lifting
    scaled = measures(problem, res.v, res.extras["u_s"], res.extras["r_s"], "longdouble")
    assert scaled.max > 1e-3, scaled
    # Its v (unique: M is positive definite) agrees with Algorithm 1's to the accuracy both claim.
    ours = rfverify.solve(problem, method="jqinv", tol=1e-10)
    assert ours.status is Status.SOLVED
    scale = max(1.0, float(np.max(np.abs(ours.v))))
    assert float(np.max(np.abs(res.v - ours.v))) <= 1e-4 * scale
    assert res.timings["siconos_solve"] > 0 and res.nit > 0 and res.extras["siconos_residual"] <= 1e-10


def test_a_crash_is_a_recorded_failure(siconos_prefix, monkeypatch):
    """RFVERIFY_SICONOS_FAULT=sigsegv (test-only, driver.c) makes the child raise SIGSEGV."""
    monkeypatch.setenv("RFVERIFY_SICONOS_FAULT", "sigsegv")
    problem = load("bundled:chute")
    res = rfverify.solve(problem, method="siconos", tol=1e-8)
    assert res.status is Status.NUMERICAL_ERROR
    assert res.message.startswith("siconos crashed (signal 11)"), res.message
    assert res.extras["siconos_status"] == "Crashed (signal 11)" and res.extras["no_answer"]
    assert not res.success and res.nit == 0


def test_a_real_zero_pivot_crash_is_a_recorded_failure(siconos_prefix):
    """A committed Chute (240 contacts) on which GRFC3D_IPM's LDLᵀ meets a zero pivot, ignores the
    return code and segfaults in the next triangular solve (ldl_l_lsolve, seen in gdb)."""
    problem = load(str(REPO_ROOT / "tests" / "data" / "hard" / "Chute-ndof-1200-nc-240-3.hdf5"))
    res = rfverify.solve(problem, method="siconos", tol=1e-10)
    assert res.status is Status.NUMERICAL_ERROR, res.message
    assert res.message.startswith("siconos crashed (signal 11)"), res.message
    # Algorithm 1 solves the same problem (the crash is Siconos's, not the problem's).
    assert rfverify.solve(problem, method="jqinv", tol=1e-10).status is Status.SOLVED


def test_a_crash_in_the_bench_is_a_record_not_the_bench_s_death(siconos_prefix, tmp_path):
    env = {**os.environ, "RFVERIFY_SICONOS_FAULT": "sigsegv", "OPENBLAS_NUM_THREADS": "1"}
    out = tmp_path / "run"
    proc = subprocess.run([sys.executable, "-m", "rfverify", "bench", "bundled:chute", "--out", str(out),
                           "--methods", "siconos", "--tol", "1e-8", "--no-trajectories", "--digits", "0", "--quiet"],
                          capture_output=True, text=True, env=env, timeout=600, check=False)
    assert proc.returncode == 0, proc.stderr
    records = [json.loads(open(p).read()) for p in glob.glob(str(out / "runs" / "**" / "*.json"), recursive=True)]
    solves = [r for r in records if r.get("kind") == "solve"]
    assert len(solves) == 1, records
    assert solves[0]["status"] == "NumericalError" and not solves[0]["solved"]
    assert "siconos crashed (signal 11)" in solves[0]["message"]


def test_time_limit_kills_the_child(siconos_prefix):
    res = rfverify.solve(load("bundled:chute"), method="siconos", tol=1e-10, time_limit=1e-4)
    assert res.status is Status.MAX_TIME and "time limit" in res.message


def test_zero_rolling_coefficient_is_refused_not_divided_by(siconos_prefix):
    import dataclasses

    problem = load("bundled:chute")
    mu_r = problem.mu_r.copy()
    mu_r[1] = 0.0
    res = rfverify.solve(dataclasses.replace(problem, mu_r=mu_r), method="siconos", tol=1e-8)
    assert res.status is Status.INVALID_INPUT and "contact 1" in res.message


def test_missing_build_is_one_clear_error(monkeypatch, tmp_path):
    monkeypatch.setenv("RFVERIFY_SICONOS", str(tmp_path / "nowhere"))
    why = method_unavailable("siconos")
    assert why is not None and "build.sh" in why and "RFVERIFY_SICONOS" in why
    with pytest.raises(InvalidArgumentError, match="Siconos peer driver"):
        rfverify.solve(load("bundled:chute"), method="siconos")
    proc = subprocess.run([sys.executable, "-m", "rfverify", "solve", "bundled:chute", "--method", "siconos"],
                          capture_output=True, text=True, env={**os.environ}, timeout=300, check=False)
    assert proc.returncode == 2
    assert len(proc.stderr.strip().splitlines()) == 1 and "build.sh" in proc.stderr


# --- the TUTORIAL's Siconos section: its commands print what it quotes ------------------------

def test_tutorial_siconos_section_prints_what_it_quotes(siconos_prefix, tmp_path):
    text = (REPO_ROOT / "docs" / "TUTORIAL.md").read_text(encoding="utf-8")
    section = text[text.index("## Certify a Siconos solution"):]
    steps = console_steps(re.search(r"```sh-session\n(.*?)```", section, re.S).group(1))
    assert len(steps) >= 6
    problems = run_steps(tmp_path, steps, env={"OPENBLAS_NUM_THREADS": "1"}, timeout=600)
    assert not problems, "docs/TUTORIAL.md (Siconos section) disagrees with the program:\n" + "\n".join(problems)


def test_bench_task_key_follows_the_peer_build(monkeypatch, tmp_path):
    """A rebuilt peer (other sources, patches or driver: another stamp) re-runs its bench tasks;
    other methods' keys do not depend on it."""
    from rfverify.bench.tasks import task_key

    exe = tmp_path / "bin" / "rfverify-siconos-driver"
    exe.parent.mkdir()
    exe.write_text("#!/bin/sh\nexit 2\n")
    exe.chmod(0o755)
    monkeypatch.setenv("RFVERIFY_SICONOS", str(tmp_path))
    task = {"sha256": "0" * 64, "kind": "solve", "method": "siconos", "tol": 1e-8, "max_iter": 100, "dps": 30}
    keys = []
    for stamp in ("aaaa-1111", "bbbb-1111"):
        (tmp_path / ".rfverify-driver-stamp").write_text(stamp + "\n")
        keys.append((task_key(task), task_key({**task, "method": "jqinv"})))
    assert keys[0][0] != keys[1][0] and keys[0][1] == keys[1][1]
