"""Issue 17, benchmarks: one bench per run directory (lock), records keyed on everything that
determines them, --retry-failed, exact tolerance stems, no orphaned worker, and a report that
names what is missing or damaged instead of crashing or silently dropping runs."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rfverify.bench import run_bench
from rfverify.bench.records import FORMAT_VERSION as RECORD_SCHEMA
from rfverify.bench.records import task_stem
from rfverify.bench.runner import BenchInputError, RunLock
from rfverify.cli import main
from rfverify.io import save
from rfverify.scenes.random_problems import random_problem
from rfverify.report import load_run, make_report

QUICK = dict(methods=("jqinv", "clarabel"), tols=(1e-8,), trajectories=False, digits=0, quiet=True)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A small finished run directory (2 problems × 2 methods × 1 tolerance)."""
    run_dir = tmp_path_factory.mktemp("finished") / "run"
    out = run_bench(["bundled:sphere", "bundled:cube"], run_dir, **QUICK)
    assert out["ran"] == 4
    return run_dir


@pytest.fixture
def copy(finished, tmp_path):
    target = tmp_path / "run"
    shutil.copytree(finished, target)
    return target


def records(run_dir):
    return sorted(p for p in (run_dir / "runs").rglob("*.json") if not p.name.startswith("."))


# ---------------------------------------------------------------------- lock
def test_second_bench_on_the_same_directory_is_refused(capsys, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with RunLock(run_dir):
        code, out, err = run(capsys, "bench", "bundled:sphere", "--out", run_dir, "--methods", "jqinv",
                             "--tol", "1e-8", "--digits", "0", "--no-trajectories", "--quiet")
    assert code == 2 and err.count("\n") == 1
    assert "in use by another rfverify bench" in err and f"pid {os.getpid()}" in err and "fix:" in err
    assert not (run_dir / "runs").exists()
    # The lock goes with its holder: the same command now runs.
    code, _, err = run(capsys, "bench", "bundled:sphere", "--out", run_dir, "--methods", "jqinv",
                       "--tol", "1e-8", "--digits", "0", "--no-trajectories", "--quiet")
    assert code == 0, err


# ---------------------------------------------------------------------- what resume reuses
def test_resume_reuses_only_records_of_the_same_task(tmp_path, monkeypatch):
    run_dir = tmp_path / "run"
    kw = dict(methods=("jqinv",), tols=(1e-8,), trajectories=False, digits=0, quiet=True)
    assert run_bench(["bundled:sphere"], run_dir, **kw)["ran"] == 1
    assert run_bench(["bundled:sphere"], run_dir, **kw)["ran"] == 0
    (rec_path,) = records(run_dir)
    rec = json.loads(rec_path.read_text())
    assert rec["schema"] == RECORD_SCHEMA and len(rec["task_key"]) == 64
    # another iteration limit is another task
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 1
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 0
    # a record of an older schema is not reused
    rec = json.loads(rec_path.read_text())
    rec["schema"] = 1
    rec_path.write_text(json.dumps(rec))
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 1
    # nor one written by another rfverify version
    import rfverify

    monkeypatch.setattr(rfverify, "__version__", "99.0")
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 1
    monkeypatch.undo()
    # nor one whose arrays are damaged
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 1
    npz = rec_path.with_suffix(".npz")
    npz.write_bytes(npz.read_bytes()[:40])
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 1
    assert run_bench(["bundled:sphere"], run_dir, max_iter=50, **kw)["ran"] == 0


def test_retry_failed_reruns_timeouts_with_a_longer_limit(capsys, tmp_path):
    run_dir = tmp_path / "run"
    argv = ["bench", "bundled:sphere", "--out", run_dir, "--methods", "jqinv", "--tol", "1e-8",
            "--digits", "0", "--no-trajectories", "--quiet", "--json"]
    code, out, err = run(capsys, *argv, "--time-limit", "1e-4")
    assert code == 0, err and json.loads(out)["timeouts"] == 1
    (rec_path,) = records(run_dir)
    assert json.loads(rec_path.read_text())["status"] == "Timeout"
    code, out, _ = run(capsys, *argv, "--time-limit", "600")
    assert json.loads(out)["ran"] == 0  # without --retry-failed a timeout is a finished run
    code, out, _ = run(capsys, *argv, "--time-limit", "600", "--retry-failed")
    assert json.loads(out)["ran"] == 1
    rec = json.loads(rec_path.read_text())
    assert rec["status"] == "Solved" and rec["solved"] is True
    code, out, _ = run(capsys, *argv, "--time-limit", "600", "--retry-failed")
    assert json.loads(out)["ran"] == 0  # a solved run is not retried


def test_close_tolerances_get_distinct_records(tmp_path):
    run_dir = tmp_path / "run"
    out = run_bench(["bundled:sphere"], run_dir, methods=("jqinv",), tols=(1.5e-10, 2e-10),
                    trajectories=False, digits=0, quiet=True)
    assert out["ran"] == 2 and len(out["counts"]) == 2
    names = sorted(p.name for p in records(run_dir))
    assert names == ["jqinv@1.5e-10.json", "jqinv@2e-10.json"]
    assert {json.loads((p)).get("tol") for p in map(Path.read_text, records(run_dir))} == {1.5e-10, 2e-10}
    assert task_stem({"kind": "solve", "method": "qp2", "tol": 1e-8}) == "qp2@1e-08"


def test_records_are_strict_json(finished):
    def refuse(constant):
        raise ValueError(constant)

    for path in records(finished) + [finished / "manifest.json"]:
        json.loads(path.read_text(), parse_constant=refuse)


# ---------------------------------------------------------------------- no orphans
def _children(pid: int) -> list[int]:
    kids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                stat = Path(f"/proc/{entry}/stat").read_text()
            except OSError:
                continue
            fields = stat.rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                kids.append(int(entry))
    return kids


def _alive(pid: int) -> bool:
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has finished running


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_killing_the_bench_leaves_no_worker(tmp_path, sig):
    coll = tmp_path / "c"
    coll.mkdir()
    # Its trajectory task (every iterate rechecked in 30 digits) runs for seconds.
    save(random_problem(200, 600, seed=3), coll / "big.hdf5")
    cmd = [sys.executable, "-m", "rfverify", "bench", str(coll), "--out", str(tmp_path / "run"),
           "--methods", "jqinv", "--tol", "1e-8", "--digits", "0", "--jobs", "2", "--quiet"]
    parent = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    workers = []
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(workers) < 2:
        workers = [p for p in _children(parent.pid) if _alive(p)]
        time.sleep(0.02)
    time.sleep(0.3)
    workers = [p for p in _children(parent.pid) if _alive(p)]
    assert workers and parent.poll() is None, "no worker running to orphan"
    parent.send_signal(sig)
    parent.wait(timeout=30)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline and any(_alive(p) for p in workers):
        time.sleep(0.05)
    left = [p for p in workers if _alive(p)]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert not left, f"orphaned worker(s) {left} after {signal.Signals(sig).name} to the bench"
    assert b"Traceback" not in parent.stderr.read()
    if sig == signal.SIGTERM:
        assert parent.returncode == 128 + signal.SIGTERM  # stopped its workers, then exited


# ---------------------------------------------------------------------- damaged run directories
@pytest.mark.parametrize("content, expect", [
    ('{"problems": [', "truncated or not JSON"),
    ("", "is empty"),
    ("[1, 2]", "JSON list, expected an object"),
    ('{"problems": "all"}', "problems"),
    ('{"problems": [{"key": 3}]}', "problems[0].key"),
    ('{"schema": 7, "problems": []}', "schema"),
])
def test_damaged_manifest_is_one_line_exit_2(capsys, copy, content, expect):
    (copy / "manifest.json").write_text(content)
    for argv in (["report", copy, "--diagnose", "0", "--quiet"],
                 ["bench", "bundled:sphere", "--out", copy, "--methods", "jqinv", "--tol", "1e-8",
                  "--digits", "0", "--no-trajectories", "--quiet"]):
        code, out, err = run(capsys, *argv)
        assert code == 2, err
        assert err.count("\n") == 1 and expect in err and "manifest.json" in err and "fix:" in err, err
    assert (copy / "manifest.json").read_text() == content  # left for the user to look at


def _damage(run_dir, how):
    recs = records(run_dir)
    victim = next(p for p in recs if p.name.startswith("clarabel") and "cube" in str(p))
    if how == "truncated record":
        victim.write_text(victim.read_text()[:50])
    elif how == "non-object record":
        victim.write_text("[]")
    elif how == "wrong-typed field":
        rec = json.loads(victim.read_text())
        rec["time"] = "fast"
        victim.write_text(json.dumps(rec))
    elif how == "wrong-typed solved":
        rec = json.loads(victim.read_text())
        rec["solved"] = "yes"
        victim.write_text(json.dumps(rec))
    elif how == "unknown schema":
        rec = json.loads(victim.read_text())
        rec["schema"] = 99
        victim.write_text(json.dumps(rec))
    elif how == "deleted record":
        victim.unlink()
    elif how == "truncated npz":
        npz = victim.with_suffix(".npz")
        npz.write_bytes(npz.read_bytes()[:100])
    return victim.relative_to(run_dir).as_posix()


@pytest.mark.parametrize("how, status", [
    ("truncated record", "Damaged"), ("non-object record", "Damaged"),
    ("wrong-typed field", "Damaged"), ("wrong-typed solved", "Damaged"),
    ("unknown schema", "Damaged"), ("deleted record", "Missing"), ("truncated npz", None),
])
def test_report_names_what_is_missing_or_damaged(capsys, copy, how, status):
    rel = _damage(copy, how)
    code, out, err = run(capsys, "report", copy, "--diagnose", "0", "--quiet")
    assert code == 0, err
    assert err.count("\n") == 1 and err.startswith("rfverify report: warning: "), err
    name = rel if how != "truncated npz" else rel[:-5] + ".npz"
    assert name in err
    summary = (copy / "summary.md").read_text()
    assert "## Missing or damaged records" in summary and name in summary
    # clarabel is not dropped: its damaged or missing cube run still counts as a run
    assert "| all | clarabel | 1e-08 |" in summary
    row = next(line for line in summary.splitlines() if line.startswith("| all | clarabel | 1e-08 |"))
    assert row.split("|")[4].strip().endswith("/2"), row
    if status is not None:
        assert f"| bundled/cube | clarabel | 1e-08 | {status} |" in summary
    data = load_run(copy)
    assert len(data.issues) == 1


def test_every_record_deleted_is_exit_2(capsys, copy):
    for p in records(copy):
        p.unlink()
    code, out, err = run(capsys, "report", copy, "--diagnose", "0", "--quiet")
    assert code == 2 and err.count("\n") == 1 and "missing" in err and "fix:" in err, err


def test_report_of_an_intact_run_has_no_warning(capsys, copy):
    code, out, err = run(capsys, "report", copy, "--diagnose", "0", "--quiet", "--json")
    assert code == 0 and err == ""
    assert json.loads(out)["issues"] == []
    assert "Missing or damaged" not in (copy / "summary.md").read_text()


def test_report_while_a_bench_holds_the_lock_says_so(copy):
    with RunLock(copy):
        make_report(copy, diagnose_count=0)
    assert "a bench is still running" in (copy / "summary.md").read_text()


def test_run_lock_refuses_a_second_holder(tmp_path):
    with RunLock(tmp_path):
        with pytest.raises(BenchInputError, match="in use"):
            with RunLock(tmp_path):
                pass
