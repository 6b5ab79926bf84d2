"""Bench tasks on a Dask distributed cluster: ``rfverify bench ... --scheduler ADDRESS``.

Needs the optional extra ``distributed`` (``pip install 'rfverify[distributed]'``, which
installs ``dask[distributed]``) on the machine that runs the bench and on every worker, with
the same rfverify.  See ``docs/DISTRIBUTED.md`` for starting a scheduler and workers.

How a task runs (the guarantees of a local bench carry over):

* **Problem files travel with the task.**  The bench reads each problem file, checks it
  against the sha256 it planned with, and puts its bytes into the task's arguments (not
  ``Client.scatter``: scattered data lives on one worker, and when that worker dies every task
  that needs it is lost; task arguments are kept by the scheduler, so a task whose worker died
  is retried elsewhere).  The worker writes them into a private scratch directory, checks the
  sha256 again, and solves that copy.  No shared filesystem is needed, and a worker can never
  solve a file that differs from the one the task key names.
* **Time limits are enforced on the worker.**  The Dask task starts the same entry point a
  local bench forks (:func:`rfverify.bench.tasks.run_task`) in a subprocess of the worker
  (``python -m rfverify.bench.distributed``, its own process group), and kills the group when
  it runs longer than ``time_limit`` seconds — a hung solve is killed on the machine where it
  hangs, and the worker thread is free for the next task.  The subprocess dies with its
  worker (``PR_SET_PDEATHSIG``, set before anything is imported, and a parent watch); Dask
  then runs the task again on another worker (``distributed.scheduler.allowed-failures``,
  3 by default, after which it is recorded as ``Crashed``).  It is killed when the bench
  cancels the task or disappears (the scheduler then releases the bench's tasks, which the
  watch loop sees).
* **The bench writes the records.**  The subprocess writes ``<stem>.json``/``<stem>.npz``
  into the scratch directory exactly as a local worker writes them into the run directory;
  the Dask task returns their bytes, and the bench, after checking that the record is this
  attempt's and carries the task key it computed itself, writes them into ``RUN_DIR/runs/``
  (arrays first, record last, each atomically).  Timeouts and crashes are recorded by the
  bench with the same status and message as locally (plus the worker's host name).  So a
  record is byte-for-byte what a local run writes, apart from the timings it measures;
  resume, ``--retry-failed`` and ``rfverify report`` cannot tell the two apart.
* **Workers must run the same rfverify.**  Before submitting anything the bench asks every
  connected worker to compute the task key of the first task: a worker with another rfverify
  version or other solver defaults (which would change results) is refused with the fix; a
  result whose key still differs (a worker that joined later) is recorded as ``Error``.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from ..errors import RfverifyError

INSTALL_FIX = "install the extra on this machine and on every worker: pip install 'rfverify[distributed]'"
CONNECT_TIMEOUT = 20.0
"""Seconds to wait for the scheduler to answer."""
WORKER_WAIT = 60.0
"""Seconds to wait for the first worker to join the scheduler."""
_POLL = 0.05


class ClusterError(RfverifyError):
    """The Dask cluster cannot be used (not installed, unreachable, no or mismatched workers,
    connection lost).  Exit code 2 in the CLI, with the fix."""


def check_available(scheduler: str) -> None:
    """Refuse ``--scheduler`` early (before any work) when Dask is missing or the address is
    empty."""
    if not isinstance(scheduler, str) or not scheduler.strip():
        raise ClusterError("--scheduler: is empty; fix: give the scheduler's address, e.g. "
                           "--scheduler tcp://HOST:8786")
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise ClusterError(f"--scheduler {scheduler}: Dask distributed is not installed; fix: "
                           f"{INSTALL_FIX}") from None


# ---------------------------------------------------------------------- the bench's side
def run_on_cluster(scheduler: str, run_dir: Path, todo: list, time_limit: float, bar, *,
                   jobs: int | None = None, priority: dict | None = None) -> int:
    """Run the tasks ``todo`` (planned by :mod:`.runner`, largest first) on the cluster whose
    scheduler listens at ``scheduler``; write every record into ``run_dir``; advance ``bar``
    once per finished task.  At most ``jobs`` tasks are in flight (default: twice the
    cluster's worker threads, so the queue stays short and the order is kept).  Returns the
    number of timeouts."""
    from distributed import Client

    quiet = _QuietLogs()  # the cluster's own log lines (reconnects, tracebacks) are not for stderr
    client = None
    try:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there "
                               f"({type(exc).__name__}: {' '.join(str(exc).split())[:200]}); fix: "
                               "start one with `dask scheduler` and pass the address it prints "
                               "(tcp://HOST:8786)") from None
        if todo:
            _check_workers(client, scheduler, todo[0])
        return _run(client, run_dir, todo, time_limit, bar, jobs, priority or {})
    finally:
        if client is not None:
            try:
                client.close(timeout=10)
            except Exception:  # noqa: BLE001 - closing a dead connection is not an error
                pass
        quiet.restore()


class _QuietLogs:
    """Silence the ``distributed``/``tornado`` loggers (and the handlers Dask attaches) for the
    life of the bench; the bench reports what matters in its own one-line errors and records."""

    def __init__(self):
        import logging

        manager = logging.Logger.manager
        names = ["distributed", "tornado"] + [n for n in list(manager.loggerDict)
                                             if n.startswith(("distributed.", "tornado."))]
        self.saved = []
        for name in names:
            lg = logging.getLogger(name)
            self.saved.append((lg, lg.level))
            lg.setLevel(logging.CRITICAL + 1)
            for h in lg.handlers:
                self.saved.append((h, h.level))
                h.setLevel(logging.CRITICAL + 1)

    def restore(self):
        for obj, level in reversed(self.saved):
            obj.setLevel(level)


def _check_workers(client, scheduler: str, sample: dict) -> None:
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT)
    except TimeoutError:
        raise ClusterError(f"--scheduler {scheduler}: no worker joined within {WORKER_WAIT:g} s; "
                           f"fix: start workers with `dask worker {scheduler} --nworkers K "
                           "--nthreads 1`") from None
    from .tasks import task_key

    want = task_key(sample)
    facts = client.run(worker_facts, sample, on_error="return")
    bad = []
    for addr, got in sorted(facts.items()):
        if isinstance(got, BaseException):
            bad.append(f"{addr} cannot run rfverify ({type(got).__name__}: {' '.join(str(got).split())[:120]})")
        elif got.get("task_key") != want:
            bad.append(f"{addr} on {got.get('host')} computes other task keys (its rfverify "
                       f"{got.get('rfverify')} differs in version or solver defaults)")
    if bad:
        from .._version import __version__

        raise ClusterError(f"--scheduler {scheduler}: worker(s) {'; '.join(bad)}; this bench runs "
                           f"rfverify {__version__}; fix: install the same rfverify (with the "
                           "distributed extra) on every worker and restart the workers (a running "
                           "worker keeps the code it imported), or stop those workers")


def worker_facts(sample: dict) -> dict:
    """Run on each worker by :func:`_check_workers`: who it is and the task key it computes."""
    import platform

    from .._version import __version__
    from .tasks import task_key

    return {"host": socket.gethostname(), "rfverify": __version__, "python": platform.python_version(),
            "task_key": task_key(sample)}


def _run(client, run_dir: Path, todo: list, time_limit: float, bar, jobs, priority) -> int:
    from distributed import KilledWorker

    from .execution import outcome, problem_dir, record_failure
    from .tasks import task_label

    pending = list(todo)
    running = {}            # future -> task
    timeouts = 0
    cap_checked, cap = 0.0, 1
    try:
        while pending or running:
            if jobs is None and time.monotonic() - cap_checked > 2.0:
                try:
                    cap = max(1, 2 * sum(client.nthreads().values()))
                except Exception:  # noqa: BLE001 - a lost scheduler shows in the futures below
                    pass
                cap_checked = time.monotonic()
            limit = jobs if jobs is not None else cap
            while pending and len(running) < limit:
                task = {**pending.pop(0), "attempt": os.urandom(8).hex()}
                problem_dir(run_dir, task["problem"]).mkdir(parents=True, exist_ok=True)
                fut = client.submit(run_remote, task, _problem_bytes(task), time_limit, pure=False,
                                    key=f"rfverify-bench-{task['attempt']}",
                                    priority=int(priority.get(task["problem"], 0)))
                running[fut] = task
            time.sleep(_POLL)
            for fut in [f for f in running if f.done()]:
                task = running.pop(fut)
                if fut.status == "finished":
                    timeouts += _store(run_dir, task, fut.result(), time_limit)
                elif fut.status == "error":
                    exc = fut.exception()
                    if isinstance(exc, KilledWorker):
                        msg = ("the Dask worker running it died each time it was tried "
                               f"(KilledWorker: {' '.join(str(exc).split())[:300]})")
                    else:
                        msg = f"the Dask task failed: {type(exc).__name__}: {' '.join(str(exc).split())[:300]}"
                    record_failure(run_dir, task, "Crashed", msg)
                else:  # cancelled or lost: the connection to the scheduler is gone
                    raise ClusterError("lost the connection to the Dask scheduler (task "
                                       f"{task_label(task)}: {fut.status}); fix: check the "
                                       "scheduler and re-run the same command (finished runs are "
                                       "reused)")
                bar.advance(f"{task_label(task)}: {outcome(run_dir, task)}")
    finally:
        if running:  # interrupted, SIGTERM or an error: the workers kill the subprocesses
            try:
                client.cancel(list(running), force=True)
            except Exception:  # noqa: BLE001 - the connection may be gone already
                pass
    return timeouts


def _problem_bytes(task: dict) -> bytes:
    from ..errors import BenchInputError

    try:
        data = Path(task["path"]).read_bytes()
    except OSError as exc:
        raise BenchInputError(f"{task['path']}: cannot be read ({exc.strerror or exc}); fix: make "
                              "it readable") from None
    if hashlib.sha256(data).hexdigest() != task["sha256"]:
        raise BenchInputError(f"{task['path']}: changed while the bench runs; fix: leave the "
                              "problem files alone during a bench and re-run it")
    return data


def _store(run_dir: Path, task: dict, result: dict, time_limit: float) -> int:
    """Write what the worker returned as a local worker would have written it; returns 1 for a
    timeout, else 0."""
    from .execution import crash_message, problem_dir, record_failure, timeout_message
    from .records import task_stem
    from .tasks import task_key

    where = f" (on worker {result.get('host', '?')})"
    if result.get("outcome") == "timeout":
        record_failure(run_dir, task, "Timeout", timeout_message(time_limit) + where)
        return 1
    if result.get("outcome") == "refused":
        record_failure(run_dir, task, "Error", result.get("message", "refused") + where)
        return 0
    files = result.get("files") or {}
    try:
        rec = json.loads(files["json"].decode("utf-8")) if files.get("json") else None
    except ValueError:
        rec = None
    if not isinstance(rec, dict) or rec.get("attempt") != task["attempt"]:
        last = [line for line in str(result.get("stderr") or "").splitlines() if line.strip()]
        said = f"; its last words: {last[-1].strip()[:300]}" if last else ""
        record_failure(run_dir, task, "Crashed", crash_message(result.get("exitcode")) + where + said)
        return 0
    if rec.get("task_key") != task_key(task):
        record_failure(run_dir, task, "Error",
                        f"the worker{where} computed another task key: its rfverify version or "
                        "solver defaults differ from the bench's; fix: install the same rfverify "
                        "on every worker, then re-run with --retry-failed")
        return 0
    out = problem_dir(run_dir, task["problem"])
    stem = task_stem(task)
    if files.get("npz") is not None:
        _write_bytes(out / f"{stem}.npz", files["npz"])
    _write_bytes(out / f"{stem}.json", files["json"])  # last: its presence means finished
    return 0


def _write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


# ---------------------------------------------------------------------- the worker's side
def run_remote(task: dict, problem: bytes, time_limit: float) -> dict:
    """The Dask task: run ``task`` in a subprocess of this worker on a private copy of the
    problem file, kill it after ``time_limit`` seconds (or when the task is cancelled), and
    return ``{"outcome", "exitcode", "host", "files": {"json", "npz"}}`` with the bytes of the
    record and arrays it wrote."""
    from .records import task_stem

    host = socket.gethostname()
    worker, key = _current_task()
    base = getattr(worker, "local_directory", None)
    work = Path(tempfile.mkdtemp(prefix="rfverify-task-", dir=base if base and os.path.isdir(base) else None))
    try:
        if hashlib.sha256(problem).hexdigest() != task["sha256"]:
            return {"outcome": "refused", "host": host,
                    "message": "the problem file's bytes arrived damaged (sha256 differs)"}
        path = work / Path(task["path"]).name
        path.write_bytes(problem)
        out = work / "out"
        out.mkdir()
        spec = work / "task.json"
        spec.write_text(json.dumps({**task, "path": str(path)}), encoding="utf-8")
        cmd = [sys.executable, "-c", _BOOTSTRAP, str(spec), str(out), str(os.getpid())]
        with open(work / "stderr.txt", "wb") as err:
            proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                    stderr=err, start_new_session=True, cwd=work)
        started = time.monotonic()
        outcome = None
        try:
            while proc.poll() is None:
                if time.monotonic() - started > time_limit:
                    outcome = "timeout"
                    break
                if _cancelled(worker, key):
                    outcome = "cancelled"
                    break
                time.sleep(_POLL)
        finally:
            if proc.poll() is None:
                _kill_group(proc)
        if outcome is not None:
            return {"outcome": outcome, "host": host, "exitcode": proc.returncode}
        stem = task_stem(task)
        files = {ext: (out / f"{stem}.{ext}").read_bytes() if (out / f"{stem}.{ext}").is_file() else None
                 for ext in ("json", "npz")}
        err_tail = (work / "stderr.txt").read_bytes()[-2000:].decode("utf-8", "replace")
        return {"outcome": "exited", "host": host, "exitcode": proc.returncode, "files": files,
                "stderr": err_tail}
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _current_task():
    try:
        from distributed import get_worker

        worker = get_worker()
        return worker, worker.get_current_task()
    except (ImportError, ValueError):  # not on a Dask worker (called directly)
        return None, None


def _cancelled(worker, key) -> bool:
    """The scheduler no longer wants this task (the bench cancelled it or went away)."""
    if worker is None or key is None:
        return False
    try:
        ts = worker.state.tasks.get(key)
    except Exception:  # noqa: BLE001 - worker internals changed: never kill on a guess
        return False
    return ts is None or ts.state in ("cancelled", "released", "forgotten")


def _kill_group(proc) -> None:
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        proc.kill()
    proc.wait()


_BOOTSTRAP = """\
import os, sys
try:  # die with the Dask worker from the first instant (imports take a second)
    import ctypes, signal
    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG
except (OSError, AttributeError):
    pass
if os.getppid() != int(sys.argv[3]):
    os._exit(1)
from rfverify.bench.distributed import _child_main
sys.exit(_child_main(sys.argv[1:]))
"""
"""The subprocess's program (``python -c``): PR_SET_PDEATHSIG before the imports, then
:func:`_child_main`."""


def _child_main(argv) -> int:
    """``TASK_JSON OUT_DIR PARENT_PID``: the subprocess a Dask task starts; dies with its
    parent, then runs the task exactly as a local worker."""
    spec, out_dir, parent = argv
    from .execution import die_with_parent
    from .tasks import run_task

    die_with_parent(int(parent))
    task = json.loads(Path(spec).read_text(encoding="utf-8"))
    run_task(task, out_dir)
    return 0

