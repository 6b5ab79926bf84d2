"""Reading a bench run directory: every record, with the runs that are missing or damaged kept
as runs that did not solve, and the forward errors of every saved answer (what the report
derives from them is :mod:`.aggregates`).

Nothing here trusts a solver: "solved" is the bench's independent high-precision recheck
(``record["solved"]``), and forward errors are computed here from the saved arrays against the
certified reference solution of the problem (the independent mpmath run of its ``digits``
task).
"""

from __future__ import annotations

import math
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bench.records import FIX_RERUN as _FIX_RERUN
from ..bench.verify import forward_digits
from ..model.measures import CRITERION
from ..solver.result import METHODS


@dataclass
class RunData:
    run_dir: Path
    manifest: dict
    problems: dict                      # key -> manifest entry
    solves: list = field(default_factory=list)
    trajectories: list = field(default_factory=list)
    digits: dict = field(default_factory=dict)      # problem key -> record
    references: dict = field(default_factory=dict)  # problem key -> {"v","u","r"}
    issues: list = field(default_factory=list)      # one line per missing or damaged file
    coulomb: list = field(default_factory=list)     # records of bench --problem coulomb
    absolute_v: set = field(default_factory=set)    # problems whose v* ≈ 0: no relative digits of v
    running: bool = False                           # a bench holds the run directory's lock

    @property
    def methods(self) -> list:
        present = {r["method"] for r in self.solves}
        return [m for m in METHODS if m in present]

    @property
    def tols(self) -> list:
        return sorted({r["tol"] for r in self.solves}, reverse=True)

    @property
    def collections(self) -> list:
        return sorted({p["collection"] for p in self.problems.values()})

    def solve_record(self, key, method, tol):
        return self._index.get((key, method, tol))

    def build_index(self):
        self._index = {(r["problem"], r["method"], r["tol"]): r for r in self.solves}


UNUSABLE = ("Missing", "Damaged")
"""Statuses the report gives a planned solve whose record is absent or unreadable: it is
counted as a run that did not solve, never silently left out."""

def is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _normalise(rec: dict) -> None:
    """Strict JSON stores non-finite numbers as null: give them back the values the report's
    arithmetic expects (an unverifiable criterion is +inf, an unknown measure NaN)."""
    ver = rec.get("verified")
    if isinstance(ver, dict):
        if ver.get("max") is None:
            ver["max"] = math.inf
        for k in CRITERION + ("primal_cone", "dual_cone", "paper_dinfeas", "paper_mu"):
            if k in ver and ver[k] is None:
                ver[k] = math.nan
    if rec.get("kind") == "trajectory":
        if rec.get("best_verified_max") is None:
            rec["best_verified_max"] = math.inf
        for it in rec.get("iterates") or []:
            if it.get("verified_max") is None:
                it["verified_max"] = math.inf
    # certified_digits: None means "no relative digits" (x* ≈ 0, judged in the absolute sense,
    # DESIGN §6.3), never +inf: proven digits are capped at 15.95, so no record holds inf there.


def _stem_task(stem: str) -> dict | None:
    """(kind, method, tol) read back from a file stem, for records that cannot be read."""
    kind = "solve"
    if stem.startswith("coulomb-"):
        return {"kind": "coulomb"}
    if stem.startswith("trajectory-"):
        kind, stem = "trajectory", stem[len("trajectory-"):]
    if stem.startswith("digits"):
        return {"kind": "digits"}
    method, sep, tol = stem.partition("@")
    try:
        return {"kind": kind, "method": method, "tol": float(tol)} if sep else None
    except ValueError:
        return None


def _placeholder(key: str, task: dict, status: str, message: str, npz: Path) -> dict:
    return {"problem": key, "kind": "solve", "method": task["method"], "tol": task["tol"],
            "status": status, "message": message, "solved": False, "time": None, "nit": None,
            "verified": None, "_npz": str(npz), "_placeholder": True}


def load_run(run_dir) -> RunData:
    """Read every record of a run directory (see :mod:`rfverify.bench.runner`).

    A damaged manifest is an error (BenchInputError, one line with the fix).  A record that is
    missing, truncated, not an object, of an unknown schema or with a wrong-typed field, and
    arrays that cannot be read, are listed in ``RunData.issues``; such a planned solve is kept
    as a run with status Missing or Damaged (not solved), so no method silently loses runs."""
    from ..bench.records import FAILED_STATUSES, RecordError, load_record
    from ..bench.runner import bench_running, npz_intact, read_manifest

    run_dir = Path(run_dir)
    manifest = read_manifest(run_dir, required=True)
    data = RunData(run_dir, manifest, {p["key"]: p for p in manifest["problems"]})
    data.running = bench_running(run_dir)
    runs = run_dir / "runs"
    found = set()
    for path in sorted(runs.rglob("*.json")) if runs.is_dir() else []:
        if path.name.startswith("."):
            continue  # a record being written
        key = path.parent.relative_to(runs).as_posix()
        rel = path.relative_to(run_dir).as_posix()
        stem = path.stem
        found.add((key, stem))
        if key not in data.problems:
            data.issues.append(f"{rel}: its problem {key!r} is not listed in manifest.json, so it is "
                               f"not shown; fix: {_FIX_RERUN}")
            continue
        try:
            rec = load_record(path, key=key, stem=stem, name=rel)
        except RecordError as exc:  # one unusable record: listed, and its run counts as not solved
            data.issues.append(str(exc))
            task = _stem_task(stem)
            if task and task["kind"] == "solve":
                data.solves.append(_placeholder(key, task, "Damaged", f"record {exc.reason}",
                                                path.with_suffix(".npz")))
            continue
        _normalise(rec)
        rec["_npz"] = str(path.with_suffix(".npz"))
        if rec["status"] not in FAILED_STATUSES and not npz_intact(Path(rec["_npz"])):
            rec["_npz_damaged"] = True
            data.issues.append(f"{rel[:-5]}.npz: missing or damaged; the record's verdict stands but "
                               f"its arrays (correct digits, references) are not used; fix: {_FIX_RERUN}")
        kind = rec["kind"]
        if kind == "solve":
            data.solves.append(rec)
        elif kind == "trajectory":
            data.trajectories.append(rec)
        elif kind == "coulomb":
            data.coulomb.append(rec)
        else:
            data.digits[rec["problem"]] = rec
            if rec.get("has_reference") and not rec.get("_npz_damaged"):
                ref = _load_reference(rec["_npz"])
                if ref is None:
                    data.issues.append(f"{rel[:-5]}.npz: holds no readable reference solution; "
                                       f"fix: {_FIX_RERUN}")
                else:
                    data.references[rec["problem"]] = ref
    for key, stem, task in _expected(data):
        if (key, stem) in found:
            continue
        data.issues.append(f"runs/{key}/{stem}.json: missing (planned, never written or deleted); "
                           f"counted as not solved; fix: {_FIX_RERUN}")
        if task["kind"] == "solve":
            data.solves.append(_placeholder(key, task, "Missing", "record missing",
                                            runs / key / f"{stem}.npz"))
    data.build_index()
    _add_forward_errors(data)
    return data


def _expected(data: RunData):
    """(problem, stem, task) of every run the manifest planned.  Manifests before schema 2 did
    not list their tasks: then every problem × method × tolerance solve is expected."""
    from ..bench.records import task_stem

    planned = data.manifest.get("tasks")
    if isinstance(planned, list):
        for t in planned:
            if isinstance(t, dict) and t.get("problem") in data.problems and isinstance(t.get("stem"), str):
                task = _stem_task(t["stem"]) or {"kind": "other"}
                yield t["problem"], t["stem"], task
        return
    methods = [m for m in data.manifest.get("methods", []) if isinstance(m, str)]
    tols = [t for t in data.manifest.get("tols", []) if is_number(t)]
    for key in data.problems:
        for m in methods:
            for t in tols:
                task = {"kind": "solve", "method": m, "tol": float(t)}
                yield key, task_stem(task), task


def _load_reference(npz: str):
    try:
        with np.load(npz) as z:
            return {k: np.asarray(z[f"ref_{k}"]) for k in ("v", "u", "r")}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None


def _saved(npz: str, keys):
    """Arrays ``keys`` of a saved run, or None when they cannot be read."""
    try:
        with np.load(npz) as z:
            return {k: np.asarray(z[k]) for k in keys}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None


def certified_mode(rec: dict, quantity: str) -> str | None:
    """How the certificate of a digits record judged ``quantity``: "relative", "absolute"
    (x* ≈ 0, against a data scale) or "information"; None when the record does not say.
    Records written before modes were recorded: no relative digits (None) means absolute."""
    modes = rec.get("certified_modes")
    if isinstance(modes, dict) and quantity in modes:
        return modes[quantity]
    digs = rec.get("certified_digits")
    if isinstance(digs, dict) and quantity in digs:
        return "absolute" if digs[quantity] is None else "relative"
    return None


def _add_forward_errors(data: RunData) -> None:
    """Digits of v (and u) against the problem's reference, for every saved solution/iterate.

    Where the certificate judged v in the absolute sense (v* ≈ 0, DESIGN §6.3) v has no
    relative digits: such a problem is listed in
    ``data.absolute_v`` and gets no digits of v, so no statistic mixes it in."""
    for key, d in data.digits.items():
        if key in data.references and certified_mode(d, "v") == "absolute":
            data.absolute_v.add(key)
    for rec in data.solves:
        ref = data.references.get(rec["problem"])
        rec["digits_v"] = rec["digits_u"] = None
        if ref is None or rec.get("_placeholder") or rec.get("_npz_damaged") or not Path(rec["_npz"]).exists():
            continue
        z = _saved(rec["_npz"], ("v", "u"))
        if z is not None:
            if rec["problem"] not in data.absolute_v:
                rec["digits_v"] = forward_digits(z["v"], ref["v"])
            rec["digits_u"] = forward_digits(z["u"], ref["u"])
    for rec in data.trajectories:
        ref = data.references.get(rec["problem"])
        rec["digits_v_iterates"] = None
        if ref is None or rec["problem"] in data.absolute_v or rec.get("_npz_damaged") \
                or not Path(rec["_npz"]).exists():
            continue
        z = _saved(rec["_npz"], ("v",))
        if z is not None:
            rec["digits_v_iterates"] = [forward_digits(v, ref["v"]) for v in z["v"]]
