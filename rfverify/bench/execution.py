"""What a bench worker leaves behind and how its end is recorded, shared by both executors (the
local pool of :mod:`rfverify.bench.runner` and the Dask one of :mod:`rfverify.bench.distributed`):
where a task's record lives, whether it is intact, the record of a task that ended without
writing one (timeout, crash), the one-line outcome the progress bar shows, and a worker that
dies with its bench."""

from __future__ import annotations

import os
import signal
import threading
import time
import zipfile
from pathlib import Path

from . import records
from .records import refuted_label, task_stem, write_json
from .tasks import base_record


def problem_dir(run_dir: Path, key: str) -> Path:
    return run_dir / "runs" / key


def record_path(run_dir: Path, task: dict) -> Path:
    return problem_dir(run_dir, task["problem"]) / f"{task_stem(task)}.json"


read_record = records.read_json
"""A record as a dict, unchecked, or None when it is missing, truncated or not a JSON object."""


def npz_intact(path: Path) -> bool:
    """The arrays of a record are present and every member passes its CRC check."""
    try:
        with zipfile.ZipFile(path) as z:
            return bool(z.namelist()) and z.testzip() is None
    except (OSError, zipfile.BadZipFile, ValueError, EOFError):
        return False


def timeout_message(time_limit: float) -> str:
    return f"killed after the per-task time limit of {time_limit:g} s"


def crash_message(exitcode) -> str:
    return f"worker process exited with code {exitcode} without a record"


def record_failure(run_dir, task, status, message):
    rec = {**base_record(task), "status": status, "message": message, "solved": False}
    write_json(record_path(run_dir, task), rec)


def outcome(run_dir, task) -> str:
    rec = read_record(record_path(run_dir, task))
    if rec is None:
        return "no record"
    verdict = "verified" if rec.get("solved") is True else "not verified"
    if task["kind"] == "coulomb":
        verdict = "certified" if rec.get("certified") is True else "not certified"
    if task["kind"] == "trajectory":
        best = rec.get("best_verified_max")
        verdict = f"best verified {best:.1e}" if isinstance(best, (int, float)) else "no verified iterate"
    t = rec.get("time")
    # A claim the recheck refuted is shown as the claim and what refuted it, not as rfverify's status.
    status = refuted_label(rec) if rec.get("refuted") else rec.get("status")
    return f"{status} ({verdict}{f', {t:.2f} s' if isinstance(t, (int, float)) else ''})"


def die_with_parent(parent: int) -> None:
    """Kill this worker when the bench process dies, however it dies (even SIGKILL): Linux's
    PR_SET_PDEATHSIG where available, and a thread watching the parent id everywhere."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG = 1
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:  # the bench died before prctl took effect
        os._exit(1)

    def watch():
        while True:
            time.sleep(0.5)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, daemon=True, name="rfverify-parent-watch").start()
