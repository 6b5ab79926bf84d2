"""``rfverify bench --scheduler``: the bench on a real Dask scheduler with two worker processes
on loopback gives the same records (verdicts, arrays) as a local run, kills a run on the worker
at the time limit, resumes and retries like a local bench, and leaves no task running on the
workers when the bench is killed.

Dask is in the ``test`` extra, so CI has it; only outside CI is a missing Dask a skip."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rfverify.bench import run_bench
from rfverify.cli import main
from rfverify.io import save
from rfverify.scenes.random_problems import random_problem

IN_CI = os.environ.get("CI", "").lower() in {"1", "true", "yes"}
try:
    import distributed
except ImportError:  # pragma: no cover - CI installs it (the test extra)
    if IN_CI:
        raise
    pytest.skip("dask[distributed] not installed (pip install -e '.[distributed]')",
                allow_module_level=True)

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc")

TIMING_FIELDS = {"attempt", "time", "time_double", "time_warm", "time_certify"}


def _dask(*args, cwd, log):
    return subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=cwd, stdin=subprocess.DEVNULL,
                            stdout=log, stderr=subprocess.STDOUT, start_new_session=True)


class Cluster:
    """`dask scheduler` and `dask worker ADDRESS --nworkers K --nthreads 1` on 127.0.0.1, started
    as a user would start them; ``stop()`` ends exactly these processes (and their children)."""

    def __init__(self, where: Path, workers: int):
        where.mkdir(parents=True, exist_ok=True)
        self.log = open(where / "cluster.log", "wb")
        self.procs = [_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                            "--scheduler-file", str(where / "scheduler.json"), cwd=where, log=self.log)]
        try:
            deadline = time.monotonic() + 60
            while not (where / "scheduler.json").exists():
                assert time.monotonic() < deadline and self.procs[0].poll() is None, \
                    (where / "cluster.log").read_text()
                time.sleep(0.1)
            time.sleep(0.2)  # the file is written in one go, but let it land
            self.address = json.loads((where / "scheduler.json").read_text())["address"]
            self.procs.append(_dask("worker", self.address, "--nworkers", str(workers), "--nthreads", "1",
                                    "--no-dashboard", "--host", "127.0.0.1", "--local-directory",
                                    str(where / "scratch"), cwd=where, log=self.log))
            with distributed.Client(self.address, timeout=30) as client:
                client.wait_for_workers(workers, timeout=60)
                assert len(client.scheduler_info()["workers"]) == workers
        except BaseException:
            self.stop()
            raise

    def stop(self):
        for proc in reversed(self.procs):
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        for proc in self.procs:
            try:
                proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        self.log.close()


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two worker processes (one thread each) on 127.0.0.1."""
    c = Cluster(tmp_path_factory.mktemp("dask"), workers=2)
    try:
        yield c.address
    finally:
        c.stop()


def _executed_per_worker(address) -> list[int]:
    with distributed.Client(address, timeout=30) as client:
        counts = client.run(lambda dask_worker: dask_worker.state.executed_count)
    return sorted(counts.values())


def _task_processes() -> list[int]:
    """Pids of the task subprocesses Dask workers start (their program imports
    rfverify.bench.distributed), zombies excluded."""
    pids = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                cmd = Path(f"/proc/{entry}/cmdline").read_bytes()
                state = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if b"rfverify.bench.distributed" in cmd and state != "Z":
                pids.append(int(entry))
    return pids


def _comparable(record: dict) -> dict:
    """A record without what legitimately differs between two runs (timings, attempt id)."""
    out = {k: v for k, v in record.items() if k not in TIMING_FIELDS}
    # The proven digits are −log10 of a bound (rounded upward, rigorous either way) whose
    # float64 value was not reproducible to the last ulp across processes: r 10.374701307529964
    # against …966 on the bundled cube in 2 of 8 runs at fe5e239 and at later commits alike
    # (cause not found; DECISIONS).  Twelve significant digits are compared.
    if isinstance(out.get("certified_digits"), dict):
        out["certified_digits"] = {k: float(f"{v:.12g}") if isinstance(v, float) else v
                                   for k, v in out["certified_digits"].items()}
    if "iterates" in out:
        out["iterates"] = [{k: v for k, v in it.items() if k != "time"} for it in out["iterates"]]
    return out


def test_cluster_run_matches_a_local_run(cluster, tmp_path):
    kw = dict(methods=("jqinv", "clarabel"), tols=(1e-8, 1e-10), digits=10,
              reference_max_contacts=2, quiet=True)
    inputs = ["bundled:sphere", "bundled:cube"]
    before = sum(_executed_per_worker(cluster))
    local = run_bench(inputs, tmp_path / "local", jobs=2, **kw)
    remote = run_bench(inputs, tmp_path / "remote", scheduler=cluster, **kw)
    # 2 problems × (2 methods × 2 tols + 1 trajectory + 1 digits path)
    assert local["total"] == remote["total"] == remote["ran"] == 12
    assert remote["counts"] == local["counts"] and remote["timeouts"] == 0
    done = _executed_per_worker(cluster)
    assert sum(done) - before >= 12 and len(done) == 2

    names = sorted(p.relative_to(tmp_path / "local") for p in (tmp_path / "local" / "runs").rglob("*.json"))
    assert names == sorted(p.relative_to(tmp_path / "remote")
                           for p in (tmp_path / "remote" / "runs").rglob("*.json"))
    assert len(names) == 12
    statuses = set()
    for name in names:
        a = json.loads((tmp_path / "local" / name).read_text())
        b = json.loads((tmp_path / "remote" / name).read_text())
        assert _comparable(a) == _comparable(b), name
        assert list(a) == list(b), name  # the same fields in the same order
        statuses.add(b["status"])
        with np.load((tmp_path / "local" / name).with_suffix(".npz")) as za, \
                np.load((tmp_path / "remote" / name).with_suffix(".npz")) as zb:
            assert za.files == zb.files
            for key in za.files:
                if "time" not in key:
                    assert np.array_equal(za[key], zb[key], equal_nan=True), (name, key)
    assert {"Solved", "Certified"} <= statuses
    # A resumed bench on the cluster's run directory reuses every record.
    again = run_bench(inputs, tmp_path / "remote", scheduler=cluster, **kw)
    assert again["ran"] == 0 and again["skipped"] == 12
    manifest = json.loads((tmp_path / "remote" / "manifest.json").read_text())
    assert manifest["scheduler"] == cluster


def test_time_limit_kills_on_the_worker_then_retry(cluster, tmp_path, capsys):
    argv = ["bench", "bundled:sphere", "--out", tmp_path / "run", "--methods", "jqinv", "--tol", "1e-8",
            "--digits", "0", "--no-trajectories", "--quiet", "--json", "--scheduler", cluster]
    code = main([str(a) for a in argv] + ["--time-limit", "0.2"])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["timeouts"] == 1
    (path,) = (tmp_path / "run" / "runs").rglob("*.json")
    rec = json.loads(path.read_text())
    assert rec["status"] == "Timeout" and rec["solved"] is False
    assert rec["message"].startswith("killed after the per-task time limit of 0.2 s (on worker ")
    assert not _task_processes()  # killed on the worker, not left running
    assert main([str(a) for a in argv]) == 0
    assert json.loads(capsys.readouterr()[0])["ran"] == 0  # a timeout is a finished run
    assert main([str(a) for a in argv] + ["--retry-failed"]) == 0
    assert json.loads(capsys.readouterr()[0])["ran"] == 1
    rec = json.loads(path.read_text())
    assert rec["status"] == "Solved" and rec["solved"] is True


def test_killing_the_bench_stops_its_tasks_on_the_workers(cluster, tmp_path):
    bench = _bench_two_big_problems(tmp_path, cluster, running=2)
    bench.kill()
    bench.wait(timeout=30)
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and _task_processes():
        time.sleep(0.05)
    left = _task_processes()
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    assert not left, f"task process(es) {left} still running after the bench was killed"
    assert not list((tmp_path / "run" / "runs").rglob("*.json")), "a record for a killed task"


def test_a_dead_worker_takes_its_task_process_along_and_the_task_is_retried(cluster, tmp_path):
    coll = tmp_path / "c"
    coll.mkdir()
    save(random_problem(600, 1800, seed=3), coll / "big.hdf5")  # its solve takes seconds
    cmd = [sys.executable, "-m", "rfverify", "bench", str(coll), "--out", str(tmp_path / "run"),
           "--methods", "jqinv", "--tol", "1e-8", "--digits", "0", "--no-trajectories", "--quiet",
           "--json", "--scheduler", cluster]
    bench = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not _task_processes():
        time.sleep(0.02)
    time.sleep(1.0)  # past the subprocess's imports: the solve is running
    running = _task_processes()
    assert running and bench.poll() is None, "no task running"
    task = running[0]
    worker = int(Path(f"/proc/{task}/stat").read_text().rsplit(")", 1)[1].split()[1])
    os.kill(worker, signal.SIGKILL)  # the Dask worker process dies (its nanny starts a new one)
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and task in _task_processes():
        time.sleep(0.02)
    assert task not in _task_processes(), "the task process outlived its worker"
    out, err = bench.communicate(timeout=120)
    assert bench.returncode == 0, err.decode()
    assert json.loads(out)["ran"] == 1  # its one task, run twice
    for path in (tmp_path / "run" / "runs").rglob("*.json"):
        assert json.loads(path.read_text())["status"] not in ("Crashed", "Error", "Timeout"), path.name
    with distributed.Client(cluster, timeout=30) as client:
        client.wait_for_workers(2, timeout=60)  # the nanny's new worker joined: cluster intact


def _bench_two_big_problems(tmp_path, address, running: int = 1):
    """Start `bench --scheduler` on two problems whose trajectory tasks (every iterate rechecked
    in 30 digits) run for seconds; return once ``running`` tasks run on the workers."""
    coll = tmp_path / "c"
    coll.mkdir()
    save(random_problem(200, 600, seed=3), coll / "big.hdf5")
    save(random_problem(200, 600, seed=4), coll / "big2.hdf5")
    cmd = [sys.executable, "-m", "rfverify", "bench", str(coll), "--out", str(tmp_path / "run"),
           "--methods", "jqinv", "--tol", "1e-8", "--digits", "0", "--quiet", "--scheduler", address]
    bench = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and len(_task_processes()) < running:
        time.sleep(0.02)
    assert len(_task_processes()) >= running and bench.poll() is None, f"fewer than {running} task(s) running"
    return bench


def test_sigterm_stops_the_bench_with_143_and_its_tasks(cluster, tmp_path):
    bench = _bench_two_big_problems(tmp_path, cluster)
    bench.send_signal(signal.SIGTERM)
    bench.wait(timeout=30)
    assert bench.returncode == 128 + signal.SIGTERM
    assert bench.stderr.read() == b""
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and _task_processes():
        time.sleep(0.05)
    assert not _task_processes()


def test_losing_the_scheduler_is_one_line_exit_2(tmp_path):
    private = Cluster(tmp_path / "cluster", workers=1)
    try:
        bench = _bench_two_big_problems(tmp_path, private.address)
        os.killpg(private.procs[0].pid, signal.SIGKILL)  # the scheduler dies
        bench.wait(timeout=60)
        err = bench.stderr.read().decode()
    finally:
        private.stop()
    assert bench.returncode == 2
    assert err.count("\n") == 1 and "lost the connection to the Dask scheduler" in err, err
    assert "re-run the same command" in err


def test_unreachable_scheduler_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    import socket

    from rfverify.bench import distributed as bd

    monkeypatch.setattr(bd, "CONNECT_TIMEOUT", 2.0)
    with socket.socket() as s:  # a port on which nothing listens
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    code = main(["bench", "bundled:sphere", "--out", str(tmp_path / "run"), "--methods", "jqinv",
                 "--tol", "1e-8", "--digits", "0", "--no-trajectories", "--quiet",
                 "--scheduler", f"tcp://127.0.0.1:{port}"])
    out, err = capsys.readouterr()
    assert code == 2
    assert err.count("\n") == 1 and "cannot connect to a Dask scheduler" in err and "fix: " in err


def test_a_result_from_another_rfverify_is_not_recorded_as_a_result(tmp_path):
    """A worker whose task key differs (other version or solver defaults) gives an Error record,
    never its result; an attempt that wrote no record of its own is Crashed."""
    from rfverify.bench.distributed import _store
    from rfverify.bench.runner import discover_problems, plan_tasks, read_record, record_path

    (entry,) = discover_problems(["bundled:sphere"])
    (task,) = plan_tasks([entry], ["jqinv"], [1e-8], trajectories=False, digits=0)
    task = {**task, "attempt": "a1"}
    run_dir = tmp_path / "run"
    record_path(run_dir, task).parent.mkdir(parents=True)
    forged = {"attempt": "a1", "task_key": "0" * 64, "status": "Solved", "solved": True}
    _store(run_dir, task, {"outcome": "exited", "host": "h", "exitcode": 0,
                           "files": {"json": json.dumps(forged).encode(), "npz": b"x"}}, 10.0)
    rec = read_record(record_path(run_dir, task))
    assert rec["status"] == "Error" and rec["solved"] is False and "task key" in rec["message"]
    assert not record_path(run_dir, task).with_suffix(".npz").exists()
    stale = {**forged, "attempt": "old"}
    _store(run_dir, task, {"outcome": "exited", "host": "h", "exitcode": -9,
                           "files": {"json": json.dumps(stale).encode(), "npz": None}}, 10.0)
    rec = read_record(record_path(run_dir, task))
    assert rec["status"] == "Crashed" and "code -9" in rec["message"]
