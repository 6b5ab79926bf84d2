"""Scheduling of benchmark tasks: one process per task, K at a time, a wall-time limit per
task, and resume (a task whose valid record exists is not run again).  The processes are
local (a pool of forked processes), or, with ``scheduler=``, subprocesses on the workers of
a Dask distributed cluster (:mod:`rfverify.bench.distributed`); the records are the same.

Layout of a run directory::

    RUN_DIR/.lock                            held (flock) by the bench working in it
    RUN_DIR/manifest.json                    schema, problems (key, path, sha256, sizes),
                                             methods, tolerances, planned tasks, options
    RUN_DIR/runs/<collection>/<problem>/     one directory per problem (records: .records)
        <method>@<tol>.json / .npz           a timed solve and its independent recheck
        trajectory-<method>@<tol>.json/.npz  every iterate, rechecked (work–precision data)
        digits<K>.json / .npz                mixed-precision path, certificate, reference

Resume reuses a record only when its schema and its ``task_key`` — a hash of the problem
file's content, the method, tolerance, iteration limit, recheck precision, every solver
setting and rfverify's version — match the task, and its arrays are intact.  ``retry_failed``
also re-runs records whose status is Timeout, Crashed or Error.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
import os
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from ..errors import BenchInputError
from ..progress import Progress
from ..solver.result import ALGORITHM1_METHODS, METHODS, OPTIONAL_METHODS, PORTFOLIO_METHODS, method_unavailable
from . import records
from .records import FAILED_STATUSES, task_stem, write_json
from .execution import (crash_message, die_with_parent, npz_intact, outcome, problem_dir, read_record,
                        record_failure, record_path, timeout_message)
from .coulomb import check_coulomb_methods, coulomb_summary, plan_coulomb
from .tasks import run_task, task_key, task_label

PROBLEM_SUFFIXES = (".hdf5", ".h5", ".dat")
DEFAULT_METHODS = tuple(m for m in METHODS if m not in ("reduced_factored", "schur") and m not in PORTFOLIO_METHODS
                        and m not in OPTIONAL_METHODS)
"""What ``bench`` runs unless told otherwise: every method but (16), the factored twin of (15),
and schur (form (16)'s iterates by another engine: ``--methods schur`` asks for it), auto (it runs
the forms in turn) and the methods that need an optional module (the Siconos peer)."""
DEFAULT_TOLS = (1e-8, 1e-9, 1e-10)
MANIFEST_SCHEMA = 2
"""2: adds ``schema``, ``rfverify_version`` and the planned ``tasks`` (what report expects)."""

_FIX_MANIFEST = ("delete it and re-run the bench command: finished records under runs/ are "
                 "checked and reused")


@dataclass(frozen=True)
class ProblemEntry:
    key: str          # "<collection>/<name>", unique within a run
    collection: str
    path: str         # absolute path, for the workers of this invocation
    sha256: str
    spec: str = ""    # how to find it again: "bundled:NAME" or the path as given


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
    except OSError as exc:
        raise BenchInputError(f"{path}: cannot be read ({exc.strerror or type(exc).__name__}); "
                              "fix: make it readable or leave it out") from None
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
            try:
                files = sorted(q for q in p.iterdir() if q.suffix.lower() in PROBLEM_SUFFIXES and q.is_file())
            except OSError as exc:
                raise BenchInputError(f"{p}: directory cannot be listed ({exc.strerror or exc}); "
                                      "fix: make it readable or name its files") from None
            if not files:
                raise BenchInputError(f"{p}: directory holds no problem files ({', '.join(PROBLEM_SUFFIXES)}); "
                                      "fix: name a directory of .hdf5/.dat problems")
            coll = p.resolve().name
            found += [ProblemEntry(f"{coll}/{q.stem}", coll, str(q.resolve()), _sha256(q), str(q)) for q in files]
        elif p.is_file():
            coll = p.resolve().parent.name
            found.append(ProblemEntry(f"{coll}/{p.stem}", coll, str(p.resolve()), _sha256(p), str(p)))
        else:
            raise BenchInputError(f"{p}: no such file or directory; fix: give problem files, "
                                  "directories of them, 'bundled' or 'bundled:NAME'")
    keys = [e.key for e in found]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise BenchInputError(f"two inputs give the same problem key(s) {sorted(dup)}; fix: rename "
                              "them or pass each collection once")
    if not found:
        raise BenchInputError("no problems given; fix: name problem files or directories")
    return found


def plan_tasks(problems, methods, tols, *, trajectory_tol=1e-14, trajectories=True,
               digits=10, reference_max_contacts=60, sizes=None, max_iter=100, dps=30,
               as_stored: bool = False, time_limit: float | None = None,
               problem_kind: str = "relaxation", load_options: dict | None = None) -> list[dict]:
    """The task list: a timed solve per (problem, method, tol), a trajectory per (problem,
    Algorithm 1 method), and the mixed-precision path per problem small enough for the
    reference (``n ≤ reference_max_contacts``; 0 disables it).  With ``problem_kind``
    "coulomb" instead: rfverify's Coulomb path per (problem, method) and Siconos's GFC3D_IPM
    per (problem, tol) when ``siconos`` is among ``methods``, each at ``digits``."""
    if problem_kind == "coulomb":
        return plan_coulomb(problems, methods, tols, digits=digits, max_iter=max_iter, as_stored=as_stored,
                            time_limit=time_limit, load_options=load_options)
    tasks = []
    sizes = sizes or {}
    for e in problems:
        base = {"problem": e.key, "collection": e.collection, "path": e.path, "sha256": e.sha256,
                "max_iter": max_iter, "dps": dps}
        if as_stored:
            base["as_stored"] = True
        if load_options:
            base["load"] = dict(load_options)
        if time_limit:  # not part of the task key: the same task with more time is the same task
            base["time_limit"] = float(time_limit)
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


def is_done(run_dir: Path, task: dict, *, retry_failed: bool = False) -> bool:
    """A task is done when its record is intact, of this schema, has this task's key (same
    problem content, settings, tolerance and rfverify version) and its arrays are intact;
    with ``retry_failed`` a Timeout/Crashed/Error record — or one its solver ended at the time
    limit (MaxTime) — does not count as done."""
    path = record_path(run_dir, task)
    rec = records.is_current(path, task_key(task))
    if rec is None:
        return False
    status = rec.get("status")
    if status in FAILED_STATUSES or status == "MaxTime":
        return not retry_failed
    return npz_intact(path.with_suffix(".npz"))


def _context():
    methods = mp.get_all_start_methods()
    return mp.get_context("fork" if "fork" in methods else "spawn")


# ---------------------------------------------------------------------- the run directory
class RunLock:
    """An exclusive ``flock`` on ``RUN_DIR/.lock`` for the life of a bench: a second bench on
    the same directory is refused.  The kernel drops the lock when its holders die, so a
    killed bench never leaves a stale lock."""

    def __init__(self, run_dir: Path):
        self.path = Path(run_dir) / ".lock"
        self.fd = None

    def __enter__(self):
        try:
            import fcntl
        except ImportError:  # pragma: no cover - no flock on this platform: no lock
            return self
        self.fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self.fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.pread(self.fd, 64, 0).decode(errors="replace").strip() or "?"
            os.close(self.fd)
            self.fd = None
            raise BenchInputError(f"{self.path.parent}: RUN_DIR is in use by another rfverify bench "
                                  f"(pid {holder}); fix: wait for it to finish, or give another "
                                  "--out directory") from None
        os.ftruncate(self.fd, 0)
        os.pwrite(self.fd, f"{os.getpid()}\n".encode(), 0)
        return self

    def __exit__(self, *exc):
        if self.fd is not None:
            os.close(self.fd)  # closing the last descriptor releases the lock
            self.fd = None
        return False


def bench_running(run_dir: Path) -> bool:
    """Whether a bench holds the lock of ``run_dir`` right now."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover
        return False
    path = Path(run_dir) / ".lock"
    if not path.exists():
        return False
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)
    return False


def read_manifest(run_dir: Path, *, required: bool) -> dict:
    """``RUN_DIR/manifest.json`` checked: a JSON object whose problems are a list of entries with
    the right types.  Missing → {} (or an error when ``required``); damaged → BenchInputError
    naming what is wrong and the fix."""
    path = Path(run_dir) / "manifest.json"
    if not path.exists():
        if required:
            raise BenchInputError(f"{run_dir}: not a bench run directory (no manifest.json); fix: "
                                  "create one with `rfverify bench ... --out DIR`")
        return {}
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise BenchInputError(f"{path}: cannot be read ({exc}); fix: {_FIX_MANIFEST}") from None
    if not text.strip():
        raise BenchInputError(f"{path}: manifest: is empty; fix: {_FIX_MANIFEST}")
    try:
        manifest = json.loads(text)
    except ValueError as exc:
        raise BenchInputError(f"{path}: manifest: is truncated or not JSON ({exc}); fix: "
                              f"{_FIX_MANIFEST}") from None
    if not isinstance(manifest, dict):
        raise BenchInputError(f"{path}: manifest: is a JSON {type(manifest).__name__}, expected an "
                              f"object; fix: {_FIX_MANIFEST}")
    schema = manifest.get("schema", 1)
    if schema not in (1, MANIFEST_SCHEMA):
        raise BenchInputError(f"{path}: schema: is {schema!r}, this rfverify reads 1 and "
                              f"{MANIFEST_SCHEMA}; fix: use the rfverify that wrote it, or "
                              "re-run the bench into a new directory")
    problems = manifest.get("problems")
    types = {"key": str, "collection": str, "spec": str, "sha256": str, "n_contacts": int, "n_dofs": int}
    if not isinstance(problems, list):
        raise BenchInputError(f"{path}: problems: is missing or not a list; fix: {_FIX_MANIFEST}")
    for k, entry in enumerate(problems):
        bad = [f for f, t in types.items()
               if not isinstance(entry, dict) or not isinstance(entry.get(f), t) or isinstance(entry.get(f), bool)]
        if bad:
            raise BenchInputError(f"{path}: problems[{k}].{bad[0]}: is missing or of the wrong type; "
                                  f"fix: {_FIX_MANIFEST}")
    for field in ("methods", "tols", "tasks"):
        if field in manifest and not isinstance(manifest[field], list):
            raise BenchInputError(f"{path}: {field}: is not a list; fix: {_FIX_MANIFEST}")
    return manifest


# ---------------------------------------------------------------------- workers
def _worker(task: dict, out_dir: str, parent: int) -> None:
    """Process target: ignore Ctrl-C (the bench decides, and kills its workers), die with the
    bench (never an orphan), then run the task."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent(parent)
    run_task(task, out_dir)


class _Interrupts:
    """Ctrl-C noted as a flag and acted on at one safe point of the pool's loop.  A
    KeyboardInterrupt raised wherever the signal lands (inside a lock's release, a finaliser,
    a fork) can be swallowed there ("Exception ignored in ...") and the bench would carry on.
    Forked workers inherit this handler until they ignore SIGINT, so a Ctrl-C that reaches one
    while it starts only sets a flag in the child instead of printing its traceback."""

    def __init__(self):
        self.seen = False
        self.previous = None

    def __enter__(self):
        self.previous = signal.signal(signal.SIGINT, self._note)
        return self

    def _note(self, signum, frame):
        self.seen = True

    def check(self):
        """Raise KeyboardInterrupt here if Ctrl-C came since the last check."""
        if self.seen:
            raise KeyboardInterrupt

    def __exit__(self, *exc):
        signal.signal(signal.SIGINT, self.previous)
        return False


def _stop(procs, run_dir: Path | None = None) -> None:
    """Kill the workers still running and remove the temporary files they were writing (a
    record is written to ``.<name>.<pid>.tmp`` and renamed: a killed writer leaves its
    temporary behind, never a half record under the final name)."""
    killed = [proc for proc in procs if proc.is_alive()]
    for proc in killed:
        proc.kill()
    for proc in procs:
        proc.join(timeout=5)
    if run_dir is not None:
        for proc in killed:
            for tmp in Path(run_dir).rglob(f".*.{proc.pid}.tmp"):
                tmp.unlink(missing_ok=True)


def run_bench(inputs, out_dir, *, methods=DEFAULT_METHODS,
              tols=DEFAULT_TOLS, jobs: int | None = None, time_limit: float = 600.0,
              trajectory_tol: float = 1e-14, trajectories: bool = True, digits: int = 10,
              reference_max_contacts: int = 60, max_iter: int = 100, quiet: bool = False,
              command: str | None = None, retry_failed: bool = False,
              scheduler: str | None = None, as_stored: bool = False, problem_kind: str = "relaxation",
              load_options: dict | None = None) -> dict:
    """Run (or resume) a benchmark.  Returns ``{"ran", "skipped", "timeouts", "total",
    "run_dir", "counts"}`` with ``counts[(method, tol)] = (verified solved, runs)`` over the
    problems of this invocation.  ``command`` (the CLI line) is recorded in the manifest so the
    report can say how to regenerate it.

    Every task runs in a fresh process; a task that exceeds ``time_limit`` seconds is killed
    and recorded with status ``Timeout``; one that dies is recorded as ``Crashed``.  Workers
    die with the bench.  ``retry_failed`` re-runs Timeout/Crashed/Error records (e.g. with a
    longer ``time_limit``).

    ``scheduler`` (a Dask scheduler address, ``tcp://host:8786``) runs the tasks on a Dask
    distributed cluster instead of local processes (:mod:`rfverify.bench.distributed`): the
    same task entry point in a subprocess on the worker machine, killed there at
    ``time_limit``; this process writes the records as a local run does.  ``jobs`` is the
    number of local processes (default 1), or with ``scheduler`` the most tasks in flight at
    once (default: twice the cluster's worker threads).

    ``as_stored`` solves, rechecks and proves every problem's equations with M exactly as
    stored instead of (M + Mᵀ)/2 (DESIGN §6.1); a run directory holds one choice.  The peers
    (clarabel, siconos) solve (M + Mᵀ)/2 only and are refused with it when a problem's M is
    unsymmetric.

    ``load_options`` ``{"max_asymmetry": X, "psd_shift": True}`` load every problem as ``solve``
    does (:func:`.tasks.load_for_bench`); one choice per run directory, kept in its manifest.

    ``problem_kind`` "coulomb" runs the physical problem instead (issue 51): per problem
    rfverify's Coulomb path at ``digits`` (each method of ``methods`` but ``siconos`` as its
    inner solver) and, with ``siconos`` in ``methods``, Siconos's GFC3D_IPM at each tolerance,
    its answer certified; no trajectories or digits tasks.  The result then also holds
    ``"coulomb"``: one summary per Coulomb record (:func:`rfverify.bench.coulomb.coulomb_summary`).
    """
    import math

    from ..coulomb import check_problem_kind
    from .tasks import check_one_choice, load_for_bench

    check_problem_kind(problem_kind)
    coulomb = problem_kind == "coulomb"
    if coulomb:
        check_coulomb_methods(methods)

    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise BenchInputError(f"unknown method(s) {', '.join(unknown)}; fix: choose from {', '.join(METHODS)}")
    if not methods:
        raise BenchInputError("no methods given; fix: pass --methods jqinv,...")
    missing = [method_unavailable(m) for m in methods if method_unavailable(m) is not None]
    if missing:  # refused before any task: every one of its records would be an Error
        raise BenchInputError(f"--methods: {missing[0]}, or leave it out of --methods")
    if not tols or any(not (isinstance(t, (int, float)) and math.isfinite(t) and t > 0) for t in tols):
        raise BenchInputError(f"tolerances {list(tols)}: must be finite numbers > 0; fix: pass e.g. "
                              "--tol 1e-8,1e-10")
    if not math.isfinite(trajectory_tol) or not trajectory_tol > 0:
        raise BenchInputError(f"trajectory tolerance {trajectory_tol!r}: must be a finite number > 0; "
                              "fix: pass e.g. --trajectory-tol 1e-14")
    if (jobs is not None and jobs < 1) or not time_limit > 0:
        raise BenchInputError("--jobs must be ≥ 1 and --time-limit > 0; fix: pass e.g. --jobs 2 --time-limit 600")
    if jobs is None and scheduler is None:
        jobs = 1
    if scheduler is not None:
        from .distributed import check_available

        check_available(scheduler)
    run_dir = Path(out_dir)
    if run_dir.exists() and not run_dir.is_dir():
        raise BenchInputError(f"{run_dir}: exists and is not a directory; fix: give a new or "
                              "existing directory to --out")
    problems = discover_problems(inputs)
    # Validate every problem up front (a bad file is an input error, not 15 failed runs).
    sizes = {}
    for e in problems:
        p = load_for_bench(e.path, load_options)
        sizes[e.key] = (p.n_contacts, p.n_dofs)
        peers = [m for m in methods if m in ("clarabel", "siconos")]
        if as_stored and peers and not p.matrix_is_symmetric:
            raise BenchInputError(f"--as-stored: {e.key} has an unsymmetric M, and {', '.join(peers)} "
                                  f"{'solve' if len(peers) > 1 else 'solves'} (M + Mᵀ)/2 only; fix: leave them out of --methods, or drop --as-stored")
    old = read_manifest(run_dir, required=False) if run_dir.is_dir() else {}
    load_options = check_one_choice(run_dir, old, as_stored, load_options)
    tasks = plan_tasks(problems, methods, sorted(tols, reverse=True), trajectory_tol=trajectory_tol,
                       trajectories=trajectories, digits=digits,
                       reference_max_contacts=reference_max_contacts,
                       sizes={k: v[0] for k, v in sizes.items()}, max_iter=max_iter, as_stored=as_stored,
                       time_limit=time_limit, problem_kind=problem_kind, load_options=load_options)
    run_dir.mkdir(parents=True, exist_ok=True)
    with RunLock(run_dir):
        return _run_locked(run_dir, problems, sizes, tasks, methods, tols, jobs, time_limit,
                           trajectory_tol, digits, reference_max_contacts, quiet, command,
                           retry_failed, scheduler, as_stored, coulomb, load_options)


def _run_locked(run_dir, problems, sizes, tasks, methods, tols, jobs, time_limit, trajectory_tol,
                digits, reference_max_contacts, quiet, command, retry_failed, scheduler,
                as_stored: bool = False, coulomb: bool = False, load_options: dict | None = None) -> dict:
    from .._version import __version__

    old = read_manifest(run_dir, required=False)
    if coulomb:  # the relaxation's settings stay as they were; the Coulomb run's are kept apart
        coulomb_settings = {"methods": list(methods), "tols": sorted({float(t) for t in tols}, reverse=True),
                            "digits": digits, "time_limit": time_limit, "command": command}
        methods, tols = [], []
        trajectory_tol = old.get("trajectory_tol", trajectory_tol)
        digits = old.get("digits", digits)
        reference_max_contacts = old.get("reference_max_contacts", reference_max_contacts)
        command = None
    known = {p["key"]: p for p in old.get("problems", [])}
    for e in problems:
        known[e.key] = {"key": e.key, "collection": e.collection, "spec": _portable(e, run_dir), "sha256": e.sha256,
                        "n_contacts": sizes[e.key][0], "n_dofs": sizes[e.key][1]}
    planned = {(t.get("problem"), t.get("stem")): t for t in old.get("tasks", []) if isinstance(t, dict)}
    for t in tasks:
        entry = {"problem": t["problem"], "kind": t["kind"], "stem": task_stem(t)}
        entry.update({k: t[k] for k in ("method", "tol", "digits") if k in t})
        planned[(t["problem"], entry["stem"])] = entry
    manifest = {
        "schema": MANIFEST_SCHEMA, "rfverify_version": __version__,
        "problems": sorted(known.values(), key=lambda p: p["key"]),
        "methods": sorted({m for m in old.get("methods", []) if m in METHODS} | set(methods),
                          key=list(METHODS).index),
        "tols": sorted({t for t in old.get("tols", []) if isinstance(t, float)} | {float(t) for t in tols},
                       reverse=True),
        "tasks": sorted(planned.values(), key=lambda t: (t["problem"], t["stem"])),
        "trajectory_tol": trajectory_tol, "digits": digits,
        "reference_max_contacts": reference_max_contacts, "time_limit": time_limit, "jobs": jobs,
        "machine": _machine(), "scheduler": scheduler,
        "command": command or old.get("command"),
        "as_stored": bool(as_stored),
        "load_options": dict(load_options or {}),
    }
    if coulomb:
        manifest["coulomb"] = coulomb_settings
    elif isinstance(old.get("coulomb"), dict):
        manifest["coulomb"] = old["coulomb"]
    write_json(run_dir / "manifest.json", manifest)

    todo = [t for t in tasks if not is_done(run_dir, t, retry_failed=retry_failed)]
    # Largest problems first: the pool then ends on short tasks (less idle time at the end).
    todo.sort(key=lambda t: -sizes[t["problem"]][0])
    bar = Progress(len(todo), "bench", quiet=quiet)
    previous = _terminate_on_sigterm()
    try:
        if scheduler:
            from .distributed import run_on_cluster

            timeouts = run_on_cluster(scheduler, run_dir, todo, time_limit, bar, jobs=jobs,
                                      priority={k: v[0] for k, v in sizes.items()})
        else:
            timeouts = _run_local(run_dir, todo, jobs, time_limit, bar)
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
        bar.close()
    counts = {}
    for t in tasks:
        if t["kind"] != "solve":
            continue
        rec = read_record(record_path(run_dir, t)) or {}
        solved, total = counts.get((t["method"], t["tol"]), (0, 0))
        counts[(t["method"], t["tol"])] = (solved + (rec.get("solved") is True), total + 1)
    out = {"ran": len(todo), "skipped": len(tasks) - len(todo), "timeouts": timeouts, "total": len(tasks),
           "run_dir": str(run_dir), "counts": counts}
    if coulomb:
        out["coulomb"] = [coulomb_summary(t["problem"], read_record(record_path(run_dir, t)) or {}, t)
                          for t in tasks]
    return out


def _run_local(run_dir: Path, todo: list, jobs: int, time_limit: float, bar) -> int:
    """The local process pool: each task in a fresh (forked) process, ``jobs`` at a time, killed
    after ``time_limit`` seconds.  Returns the number of timeouts."""
    ctx = _context()
    if any(t["kind"] != "digits" for t in todo):
        from ..solver import kernels

        kernels.warm_up()  # once here: forked tasks inherit the loaded kernels
    running = {}
    timeouts = 0
    pending = list(todo)
    with _Interrupts() as interrupts:
        try:
            while pending or running:
                interrupts.check()
                while pending and len(running) < jobs:
                    task = pending.pop(0)
                    out = problem_dir(run_dir, task["problem"])
                    out.mkdir(parents=True, exist_ok=True)
                    # The attempt id tells this run's record from an outdated one left in place.
                    task = {**task, "attempt": os.urandom(8).hex()}
                    proc = ctx.Process(target=_worker, args=(task, str(out), os.getpid()), daemon=True)
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
                        record_failure(run_dir, task, "Timeout", timeout_message(time_limit))
                    else:
                        proc.join()
                        rec = read_record(record_path(run_dir, task))
                        if rec is None or rec.get("attempt") != task["attempt"]:
                            record_failure(run_dir, task, "Crashed", crash_message(proc.exitcode))
                    del running[proc]
                    bar.advance(f"{task_label(task)}: {outcome(run_dir, task)}")
            interrupts.check()  # a Ctrl-C during the last runs still ends the bench with 130
        finally:
            _stop(list(running), run_dir)  # interrupted or killed by SIGTERM: no worker outlives the bench
    return timeouts


def _terminate_on_sigterm():
    """SIGTERM (kill, a CI timeout) raises SystemExit in the main loop, so its ``finally`` stops
    the workers; returns the previous handler (None when not in the main thread)."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        raise SystemExit(128 + signum)

    return signal.signal(signal.SIGTERM, handler)


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


def _machine() -> dict:
    import os
    import platform

    from importlib import metadata

    def version(dist: str) -> str:
        try:
            return metadata.version(dist)
        except metadata.PackageNotFoundError:
            return "not installed"

    # The numerical libraries whose builds change results in the last bits (the scene files
    # are simulated with the solver, so they differ with these; see `generate --help`).
    return {"python": platform.python_version(),
            **{name: version(name) for name in ("numpy", "scipy", "qdldl", "clarabel", "numba", "mpmath")},
            "platform": platform.platform(), "cpus": os.cpu_count()}
