"""Scheduling of benchmark tasks: one process per task, K at a time, a wall-time limit per
task, and resume (a task whose record exists is not run again).

Layout of a run directory::

    RUN_DIR/manifest.json                    problems (key, path, sha256, sizes), methods,
                                             tolerances, options of the last invocation
    RUN_DIR/runs/<collection>/<problem>/     one directory per problem
        <method>@<tol>.json / .npz           a timed solve and its independent recheck
        trajectory-<method>@<tol>.json/.npz  every iterate, rechecked (work–precision data)
        digits<K>.json / .npz                mixed-precision path, certificate, reference
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import RfverifyError
from ..progress import Progress
from .tasks import run_task, task_label, task_stem, write_json

PROBLEM_SUFFIXES = (".hdf5", ".h5", ".dat")
ALGORITHM1_METHODS = ("jqinv", "qp2", "reduced", "reduced_factored", "noscaling")


class BenchInputError(RfverifyError):
    """Bad benchmark input (no problems found, unknown method, bad run directory)."""


@dataclass(frozen=True)
class ProblemEntry:
    key: str          # "<collection>/<name>", unique within a run
    collection: str
    path: str         # absolute path, for the workers of this invocation
    sha256: str
    spec: str = ""    # how to find it again: "bundled:NAME" or the path as given


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def discover_problems(inputs) -> list[ProblemEntry]:
    """Problems named by ``inputs``: files, directories (their problem files, sorted; the
    collection is the directory's name), ``bundled:NAME`` or ``bundled`` (every bundled
    problem, collection "bundled")."""
    from ..io import bundled_problems, resolve_path

    found: list[ProblemEntry] = []
    for spec in inputs:
        text = str(spec)
        if text == "bundled":
            found += [ProblemEntry(f"bundled/{name}", "bundled", str(p), _sha256(p), f"bundled:{name}")
                      for name, p in sorted(bundled_problems().items())]
            continue
        if text.startswith("bundled:"):
            p = resolve_path(text)
            found.append(ProblemEntry(f"bundled/{text.split(':', 1)[1]}", "bundled", str(p), _sha256(p), text))
            continue
        p = Path(text)
        if p.is_dir():
            files = sorted(q for q in p.iterdir() if q.suffix.lower() in PROBLEM_SUFFIXES and q.is_file())
            if not files:
                raise BenchInputError(f"{p}: directory holds no problem files ({', '.join(PROBLEM_SUFFIXES)})")
            coll = p.resolve().name
            found += [ProblemEntry(f"{coll}/{q.stem}", coll, str(q.resolve()), _sha256(q), str(q)) for q in files]
        elif p.is_file():
            coll = p.resolve().parent.name
            found.append(ProblemEntry(f"{coll}/{p.stem}", coll, str(p.resolve()), _sha256(p), str(p)))
        else:
            raise BenchInputError(f"{p}: no such file or directory (give problem files, directories "
                                  "of them, 'bundled' or 'bundled:NAME')")
    keys = [e.key for e in found]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise BenchInputError(f"two inputs give the same problem key(s) {sorted(dup)}; rename or "
                              "pass each collection once")
    if not found:
        raise BenchInputError("no problems given")
    return found


def plan_tasks(problems, methods, tols, *, trajectory_tol=1e-14, trajectories=True,
               digits=10, reference_max_contacts=60, sizes=None, max_iter=100, dps=30) -> list[dict]:
    """The task list: a timed solve per (problem, method, tol), a trajectory per (problem,
    Algorithm 1 method), and the mixed-precision path per problem small enough for the
    reference (``n ≤ reference_max_contacts``; 0 disables it)."""
    tasks = []
    sizes = sizes or {}
    for e in problems:
        base = {"problem": e.key, "collection": e.collection, "path": e.path, "sha256": e.sha256,
                "max_iter": max_iter, "dps": dps}
        for method in methods:
            for tol in tols:
                tasks.append({**base, "kind": "solve", "method": method, "tol": float(tol)})
        if trajectories:
            for method in methods:
                if method in ALGORITHM1_METHODS:
                    tasks.append({**base, "kind": "trajectory", "method": method, "tol": float(trajectory_tol)})
        n = sizes.get(e.key)
        if digits and reference_max_contacts and n is not None and 0 < n <= reference_max_contacts:
            tasks.append({**base, "kind": "digits", "digits": int(digits)})
    return tasks


def problem_dir(run_dir: Path, key: str) -> Path:
    return run_dir / "runs" / key


def is_done(run_dir: Path, task: dict) -> bool:
    """A task is done when its record exists for the same problem file content."""
    path = problem_dir(run_dir, task["problem"]) / f"{task_stem(task)}.json"
    if not path.exists():
        return False
    try:
        rec = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return False
    return bool(rec.get("complete")) and rec.get("sha256") == task["sha256"]


def _context():
    methods = mp.get_all_start_methods()
    return mp.get_context("fork" if "fork" in methods else "spawn")


def run_bench(inputs, out_dir, *, methods=("jqinv", "qp2", "noscaling", "reduced", "clarabel"),
              tols=(1e-8, 1e-9, 1e-10), jobs: int = 1, time_limit: float = 600.0,
              trajectory_tol: float = 1e-14, trajectories: bool = True, digits: int = 10,
              reference_max_contacts: int = 60, max_iter: int = 100, quiet: bool = False,
              command: str | None = None) -> dict:
    """Run (or resume) a benchmark.  Returns ``{"ran", "skipped", "timeouts", "total",
    "run_dir", "counts"}`` with ``counts[(method, tol)] = (verified solved, runs)`` over the
    problems of this invocation.  ``command`` (the CLI line) is recorded in the manifest so the
    report can say how to regenerate it.

    Every task runs in a fresh process; a task that exceeds ``time_limit`` seconds is killed
    and recorded with status ``Timeout``; one that dies is recorded as ``Crashed``.
    """
    from ..io import load
    from ..solver.result import METHODS

    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise BenchInputError(f"unknown method(s) {', '.join(unknown)}; choose from {', '.join(METHODS)}")
    if not methods:
        raise BenchInputError("no methods given")
    if not tols or any(not (t > 0) for t in tols):
        raise BenchInputError("tolerances must be positive numbers")
    if jobs < 1 or time_limit <= 0:
        raise BenchInputError("--jobs must be ≥ 1 and --time-limit > 0")
    run_dir = Path(out_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise BenchInputError(f"{run_dir}: exists and is not a directory")
    problems = discover_problems(inputs)
    # Validate every problem up front (a bad file is an input error, not 15 failed runs).
    sizes = {}
    for e in problems:
        p = load(e.path)
        sizes[e.key] = (p.n_contacts, p.n_dofs)
    tasks = plan_tasks(problems, methods, sorted(tols, reverse=True), trajectory_tol=trajectory_tol,
                       trajectories=trajectories, digits=digits,
                       reference_max_contacts=reference_max_contacts,
                       sizes={k: v[0] for k, v in sizes.items()}, max_iter=max_iter)
    run_dir.mkdir(parents=True, exist_ok=True)
    manifest_path = run_dir / "manifest.json"
    old = json.loads(manifest_path.read_text()) if manifest_path.exists() else {}
    known = {p["key"]: p for p in old.get("problems", [])}
    for e in problems:
        known[e.key] = {"key": e.key, "collection": e.collection, "spec": _portable(e, run_dir), "sha256": e.sha256,
                        "n_contacts": sizes[e.key][0], "n_dofs": sizes[e.key][1]}
    manifest = {
        "problems": sorted(known.values(), key=lambda p: p["key"]),
        "methods": sorted(set(old.get("methods", [])) | set(methods), key=list(METHODS).index),
        "tols": sorted(set(old.get("tols", [])) | {float(t) for t in tols}, reverse=True),
        "trajectory_tol": trajectory_tol, "digits": digits,
        "reference_max_contacts": reference_max_contacts, "time_limit": time_limit, "jobs": jobs,
        "machine": _machine(),
        "command": command or old.get("command"),
    }
    write_json(manifest_path, manifest)

    todo = [t for t in tasks if not is_done(run_dir, t)]
    # Largest problems first: the pool then ends on short tasks (less idle time at the end).
    todo.sort(key=lambda t: -sizes[t["problem"]][0])
    bar = Progress(len(todo), "bench", quiet=quiet)
    ctx = _context()
    running = {}
    timeouts = 0
    pending = list(todo)
    while pending or running:
        while pending and len(running) < jobs:
            task = pending.pop(0)
            out = problem_dir(run_dir, task["problem"])
            out.mkdir(parents=True, exist_ok=True)
            proc = ctx.Process(target=run_task, args=(task, str(out)), daemon=True)
            proc.start()
            running[proc] = (task, time.monotonic())
        time.sleep(0.02)
        for proc in list(running):
            task, started = running[proc]
            elapsed = time.monotonic() - started
            if proc.is_alive() and elapsed <= time_limit:
                continue
            if proc.is_alive():
                proc.kill()
                proc.join()
                timeouts += 1
                _record_failure(run_dir, task, "Timeout",
                                f"killed after the per-task time limit of {time_limit:g} s")
            else:
                proc.join()
                if not is_done(run_dir, task):
                    _record_failure(run_dir, task, "Crashed",
                                    f"worker process exited with code {proc.exitcode} without a record")
            del running[proc]
            bar.advance(f"{task_label(task)}: {_outcome(run_dir, task)}")
    bar.close()
    counts = {}
    for t in tasks:
        if t["kind"] != "solve":
            continue
        rec = json.loads((problem_dir(run_dir, t["problem"]) / f"{task_stem(t)}.json").read_text())
        solved, total = counts.get((t["method"], t["tol"]), (0, 0))
        counts[(t["method"], t["tol"])] = (solved + bool(rec.get("solved")), total + 1)
    return {"ran": len(todo), "skipped": len(tasks) - len(todo), "timeouts": timeouts, "total": len(tasks),
            "run_dir": str(run_dir), "counts": counts}


def _portable(entry: ProblemEntry, run_dir: Path) -> str:
    """The problem's location as the report will look for it: ``bundled:NAME``, or the path
    relative to the run directory (so a committed run directory stays valid in any clone)."""
    import os

    if entry.spec.startswith("bundled:"):
        return entry.spec
    return os.path.relpath(entry.path, run_dir.resolve())


def resolve_spec(spec: str, run_dir) -> str:
    """Inverse of :func:`_portable`."""
    if spec.startswith("bundled:"):
        return spec
    p = Path(spec)
    return str(p if p.is_absolute() else (Path(run_dir) / p).resolve())


def _record_failure(run_dir, task, status, message):
    rec = {"format": 1, **{k: v for k, v in task.items() if k != "path"}, "complete": True,
           "status": status, "message": message, "solved": False}
    write_json(problem_dir(run_dir, task["problem"]) / f"{task_stem(task)}.json", rec)


def _outcome(run_dir, task) -> str:
    try:
        rec = json.loads((problem_dir(run_dir, task["problem"]) / f"{task_stem(task)}.json").read_text())
    except (OSError, json.JSONDecodeError):
        return "no record"
    verdict = "verified" if rec.get("solved") else "not verified"
    if task["kind"] == "trajectory":
        verdict = f"best verified {rec.get('best_verified_max', float('nan')):.1e}"
    t = rec.get("time")
    return f"{rec.get('status')} ({verdict}{'' if t is None else f', {t:.2f} s'})"


def _machine() -> dict:
    import os
    import platform

    import numpy

    return {"python": platform.python_version(), "numpy": numpy.__version__,
            "platform": platform.platform(), "cpus": os.cpu_count()}
