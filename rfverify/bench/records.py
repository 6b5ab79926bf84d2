"""The bench record: one JSON object per task, ``RUN_DIR/runs/<problem>/<stem>.json``, beside
its arrays ``<stem>.npz``.  This module is the record's schema: the fields (:data:`FIELDS`),
the format version written into every record (:data:`FORMAT_VERSION`, key ``"schema"``), the
file names (:func:`task_stem`), and the one reader that checks them (:func:`load_record`).
:mod:`rfverify.bench.tasks` and :mod:`rfverify.bench.runner` write records through it; the
resume of :mod:`rfverify.bench.runner` and :mod:`rfverify.report` read them through it.

A record that cannot be used — unreadable, not a JSON object, of a format version this
rfverify does not read, a required field missing or of the wrong type, or a file name that does
not match its contents — raises :class:`RecordError`, an input error (``rfverify`` exits 2)
that names the file, the field and the fix.  The report turns one unusable record among good
ones into a listed issue (the run counts as not solved); a run directory with no usable solve
record is an error.

Fields (``kinds``: the task kinds that carry the field; ``finished``: checked only when the
status is not one of :data:`FAILED_STATUSES`):

==================  ======================  ========  ========  ==============================
field               kinds                   required  finished  what
==================  ======================  ========  ========  ==============================
schema              all                     yes       no        :data:`FORMAT_VERSION`
problem             all                     yes       no        ``<collection>/<name>`` key
kind                all                     yes       no        solve, trajectory, digits, coulomb
status              all                     yes       no        outcome (Solved, Timeout, ...)
solved              all                     yes       no        the independent recheck passed
message             all                     no        no        the solver's or failure's words
method, tol         solve, trajectory       yes       no        what ran
method              coulomb                 yes       no        inner solver, or siconos (GFC3D)
tol                 coulomb                 no        no        the peer's own tolerance
digits              digits, coulomb         yes       no        digits asked of the path
time                all                     yes       yes       seconds of the task
nit                 solve                   no        yes       iterations
verified            solve                   yes       yes       recheck, ``{"max": ..., ...}``
max_cond_Qp         solve                   no        yes       largest cond(Q_p) of the trace
min_lam2            solve                   no        yes       smallest λ2 of z and s
solver_claims_...   solve                   no        yes       the solver said Solved
iterates            trajectory              yes       yes       ``[{time, verified_max}, ...]``
best_verified_max   trajectory              no        yes       best rechecked criterion
certified           digits, coulomb         yes       yes       the certificate proves K digits
certified_digits    digits, coulomb         no        yes       proven digits per quantity
certified_modes     digits                  no        yes       relative / absolute / information
has_reference       digits                  no        yes       the .npz holds ``ref_v/u/r``
time_certify        digits, coulomb         no        yes       seconds of the proof
backward_error      coulomb                 yes       yes       proven relative bound on δ, or null
outer_evaluations   coulomb                 no        yes       convex solves of the fixed point
==================  ======================  ========  ========  ==============================

Every record also carries ``rfverify_version``, ``task_key`` (what resume compares, see
:func:`rfverify.bench.tasks.task_key`), the task's own entries (``sha256``, ``max_iter``,
``dps``, ``attempt``, ...) and ``complete``; the kinds add further measurements that the report
reads where present (see :mod:`rfverify.bench.tasks`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..errors import BenchInputError
from ..io.output import dumps
from ..model.measures import CRITERION

FORMAT_VERSION = 2
"""Version of the record layout, written as ``"schema"``.  2: strict JSON (null for non-finite
numbers), ``task_key``, exact tolerance stems.  Resume reuses only records of this version."""

READABLE_VERSIONS = (1, 2)
"""Versions :func:`load_record` reads (1 differs only by what resume needs)."""

VERSION_FIELD = "schema"

KINDS = ("solve", "trajectory", "digits", "coulomb")

FAILED_STATUSES = ("Timeout", "Crashed", "Error")
"""Run outcomes that ``bench --retry-failed`` runs again; their records carry no measurements."""

FIX_RERUN = "re-run the same bench command (it redoes missing and damaged runs)"
"""How to regenerate a run directory's missing or unusable records."""


class RecordError(BenchInputError):
    """A bench record that cannot be used.  ``path`` is the file, ``field`` the offending field
    (None when the file as a whole is unusable), ``reason`` what is wrong (a phrase naming the
    field), ``fix`` what to do."""

    def __init__(self, path, reason: str, *, field: str | None = None, fix: str = ""):
        self.path = str(path)
        self.field = field
        self.reason = reason
        self.fix = fix or f"delete it and {FIX_RERUN}"
        super().__init__(f"{self.path}: {reason}; fix: {self.fix}")


# ---------------------------------------------------------------------- the fields
def _is_num(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _is_int(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


def _num_or_null(x) -> bool:
    return x is None or _is_num(x)


@dataclass(frozen=True)
class Field:
    """One declared field: its name, the kinds that carry it, whether it must be present, whether
    it is checked only for finished (not failed) runs, its test and what the test expects."""

    name: str
    kinds: tuple
    required: bool
    finished: bool
    check: Callable
    expected: str


_ALL = KINDS
_RUNS = ("solve", "trajectory")

FIELDS = (
    Field("problem", _ALL, True, False, lambda x: isinstance(x, str), "a string"),
    Field("kind", _ALL, True, False, lambda x: x in KINDS, "solve, trajectory, digits or coulomb"),
    Field("status", _ALL, True, False, lambda x: isinstance(x, str), "a string"),
    Field("solved", _ALL, True, False, lambda x: isinstance(x, bool), "true or false"),
    Field("message", _ALL, False, False, lambda x: isinstance(x, str), "a string"),
    Field("method", _RUNS, True, False, lambda x: isinstance(x, str), "a method name"),
    Field("tol", _RUNS, True, False, lambda x: _is_num(x) and math.isfinite(x) and x > 0, "a number > 0"),
    Field("method", ("coulomb",), True, False, lambda x: isinstance(x, str), "a method name"),
    Field("tol", ("coulomb",), False, False, lambda x: _is_num(x) and math.isfinite(x) and x > 0, "a number > 0"),
    Field("digits", ("digits", "coulomb"), True, False, _is_int, "an integer"),
    Field("time", _ALL, True, True, _is_num, "a number"),
    Field("nit", ("solve",), False, True, lambda x: x is None or _is_int(x), "an integer"),
    Field("verified", ("solve",), True, True, lambda x: isinstance(x, dict) and _num_or_null(x.get("max")),
          "an object with a numeric 'max'"),
    Field("max_cond_Qp", ("solve",), False, True, _num_or_null, "a number or null"),
    Field("min_lam2", ("solve",), False, True, _num_or_null, "a number or null"),
    Field("solver_claims_solved", ("solve",), False, True, lambda x: isinstance(x, bool), "true or false"),
    Field("iterates", ("trajectory",), True, True,
          lambda x: isinstance(x, list) and all(isinstance(i, dict) and _is_num(i.get("time"))
                                                and _num_or_null(i.get("verified_max")) for i in x),
          "a list of {time, verified_max}"),
    Field("best_verified_max", ("trajectory",), False, True, _num_or_null, "a number or null"),
    Field("certified", ("digits",), True, True, lambda x: isinstance(x, bool), "true or false"),
    Field("certified_digits", ("digits",), False, True,
          lambda x: x is None or (isinstance(x, dict) and all(v is None or _is_num(v) for v in x.values())),
          "an object of numbers"),
    Field("certified_modes", ("digits",), False, True,
          lambda x: isinstance(x, dict) and all(isinstance(v, str) for v in x.values()), "an object of strings"),
    Field("has_reference", ("digits",), False, True, lambda x: isinstance(x, bool), "true or false"),
    Field("time_certify", ("digits", "coulomb"), False, True, _num_or_null, "a number or null"),
    Field("certified", ("coulomb",), True, True, lambda x: isinstance(x, bool), "true or false"),
    Field("backward_error", ("coulomb",), True, True, _num_or_null, "a number or null"),
    Field("certified_digits", ("coulomb",), False, True,
          lambda x: x is None or (isinstance(x, dict) and all(v is None or _is_num(v) for v in x.values())),
          "an object of numbers"),
    Field("outer_evaluations", ("coulomb",), False, True, _is_int, "an integer"),
)
"""The declared fields, in the order they are checked (the first problem found is reported)."""


# ---------------------------------------------------------------------- names
def tol_text(tol: float) -> str:
    """The shortest text that reads back as exactly ``tol`` (1e-08, 1.5e-10): distinct
    tolerances never share a file name."""
    return repr(float(tol))


def task_stem(task: dict) -> str:
    """File stem of a task's outputs (record and arrays) inside its problem directory."""
    if task["kind"] == "solve":
        return f"{task['method']}@{tol_text(task['tol'])}"
    if task["kind"] == "trajectory":
        return f"trajectory-{task['method']}@{tol_text(task['tol'])}"
    if task["kind"] == "coulomb":
        at = f"@{tol_text(task['tol'])}" if task.get("tol") is not None else ""
        return f"coulomb-{task['method']}{at}-digits{task['digits']}"
    return f"digits{task['digits']}"


# ---------------------------------------------------------------------- writing
def new_record(task: dict, task_key: str) -> dict:
    """The fields every record of ``task`` carries: the format version, rfverify's version, the
    task key and the task's entries (not its absolute path: that is this machine's business;
    the manifest keeps a portable one)."""
    from .._version import __version__

    return {VERSION_FIELD: FORMAT_VERSION, "rfverify_version": __version__, "task_key": task_key,
            **{k: v for k, v in task.items() if k != "path"}, "complete": True}


def write_json(path: Path, record: dict) -> None:
    """Strict JSON (non-finite numbers as null), written to a temporary file and renamed: a
    reader never sees half a record."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(dumps(record, indent=1, default=str))
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


write_record = write_json


# ---------------------------------------------------------------------- reading
def read_json(path: Path) -> dict | None:
    """A record file as a dict, unchecked; None when it is missing, truncated or not a JSON
    object (what the scheduler needs to tell a finished attempt from a crashed one)."""
    try:
        rec = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) else None


def check_record(rec, path, *, key: str | None = None, stem: str | None = None,
                 versions=READABLE_VERSIONS) -> dict:
    """``rec`` when it is a usable record of one of ``versions``; otherwise :class:`RecordError`
    naming ``path``, the field and the fix.  With ``key`` and ``stem`` (its problem directory and
    file stem) the record must also belong there."""
    if not isinstance(rec, dict):
        raise RecordError(path, f"is a JSON {type(rec).__name__}, expected an object")
    version = rec.get(VERSION_FIELD, rec.get("format"))
    if version not in versions:
        raise RecordError(path, f"field {VERSION_FIELD!r}: format version {version!r}; this rfverify "
                                f"reads {', '.join(map(str, versions))}", field=VERSION_FIELD,
                          fix=f"delete it and {FIX_RERUN}, or read it with the rfverify that wrote it")
    kind = rec.get("kind")
    finished = rec.get("status") not in FAILED_STATUSES
    for f in FIELDS:
        if kind in KINDS and kind not in f.kinds:
            continue
        if f.finished and not finished:
            continue
        if f.name not in rec:
            if f.required:
                raise RecordError(path, f"field {f.name!r} is missing", field=f.name)
            continue
        if not f.check(rec[f.name]):
            value = rec[f.name]
            raise RecordError(path, f"field {f.name!r} is {type(value).__name__} {str(value)[:30]!r}, "
                                    f"expected {f.expected}", field=f.name)
    if key is not None and rec["problem"] != key:
        raise RecordError(path, f"field 'problem': belongs to problem {rec['problem']!r}, not to its "
                                f"directory {key!r}", field="problem")
    if stem is not None and task_stem(rec) != stem:
        raise RecordError(path, f"holds {task_stem(rec)}, not what its file name says (an older "
                                "rfverify gave close tolerances one name)")
    return rec


def load_record(path, *, key: str | None = None, stem: str | None = None,
                versions=READABLE_VERSIONS, name=None) -> dict:
    """Read and check the record at ``path`` (see :func:`check_record`); ``name`` is how the
    error names the file (default: ``path``)."""
    shown = path if name is None else name
    try:
        rec = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise RecordError(shown, f"is truncated or not JSON ({' '.join(str(exc).split())[:80]})") from None
    return check_record(rec, shown, key=key, stem=stem, versions=versions)


def is_current(path, task_key: str) -> dict | None:
    """The record at ``path`` when resume may reuse it — complete, of :data:`FORMAT_VERSION`, with
    every declared field right and this task's key — else None."""
    try:
        rec = load_record(path, versions=(FORMAT_VERSION,))
    except RecordError:
        return None
    if rec.get("complete") is not True or rec.get("task_key") != task_key:
        return None
    return rec


def worst_measure(rec: dict):
    """(name, value) of the recheck measure that failed most (largest), or (None, None)."""
    ver = rec.get("verified") or {}
    measures = [k for k in CRITERION if _is_num(ver.get(k)) and not math.isnan(ver[k])]
    if not measures:
        return None, None
    worst = max(measures, key=lambda k: ver[k])
    return worst, float(ver[worst])


def refuted_label(rec: dict) -> str:
    """What a refuted run is shown as: its solver's claim and what refuted it, e.g.
    "Solved (refuted: complementarity 1.7e-06)"."""
    name, value = worst_measure(rec)
    claim = rec.get("claim") or "Solved"
    if name is None:
        return f"{claim} (refuted: no finite recheck)"
    return f"{claim} (refuted: {name} {value:.1e})"
