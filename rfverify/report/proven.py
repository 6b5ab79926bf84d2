"""Proven digits of every saved answer of a bench run (issue 28 item 3).

Each problem's ``digits`` task leaves a proven extended-precision point (its k-digit path,
DESIGN §6.5).  The rigorous bound of DESIGN §6, evaluated exactly at that point and carried to an
answer by the triangle inequality (what ``rfverify certify`` does with a stored point), gives
every saved (v, u, r) — of every method, peers included, at every tolerance — its *proven*
digits, whatever its size: the proof costs O(nnz) exact operations per answer (0.05–0.2 s at
800–1400 contacts, docs/DECISIONS.md), no reference solve.  Where the problem has no valid proven
point (the k-digit path timed out, crashed, or found none) its answers have no proven digits and
the report says so.

Results are cached in ``RUN_DIR/proven/`` per problem, keyed by each record's ``task_key`` and
the point's checksum, so a second report costs nothing.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
import warnings
import zipfile
from pathlib import Path

import numpy as np

from .. import __version__
from ..io.output import write_text_atomic

CACHE_LAYOUT = 1
"""Layout of a cached ``RUN_DIR/proven/<problem>.json``."""

ANSWER_QUANTITIES = ("v", "u", "Hr")
"""The quantities whose proven digits make an answer's digits: the smallest of them, over those
the certificate judges in the relative sense (r is left out: it is often not unique, and Hr is
what the bodies feel).  A local file's proof is about its own u and r (DESIGN §6.1b): there they
are the quantities."""

LOCAL_QUANTITIES = ("u", "r")


def answer_digits(digits: dict, modes: dict):
    """The proven digits of an answer: the smallest relative digits of v, u, Hr (of u, r for a
    local file's proof, which has no v); None when none is judged in the relative sense."""
    names = ANSWER_QUANTITIES if "v" in digits or "v" in modes else LOCAL_QUANTITIES
    vals = [digits.get(q) for q in names if modes.get(q) == "relative"]
    vals = [float(d) for d in vals if d is not None]
    return min(vals) if vals else None


def _point(npz: str):
    """The proven point saved by a digits task, and a checksum of its arrays; None when absent."""
    from ..proof import Point

    try:
        with np.load(npz) as z:
            arrays = {k: np.asarray(z[k]) for k in ("ref_v", "point_v_lo", "ref_r", "point_r_lo")}
            more = {k: np.asarray(z[k]) for k in ("point_v_more", "point_r_more") if k in z.files}
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None, None
    digest = hashlib.sha256()
    for k in sorted(arrays) + sorted(more):
        digest.update((arrays | more)[k].tobytes())
    point = Point(arrays["ref_v"], arrays["point_v_lo"], arrays["ref_r"], arrays["point_r_lo"],
                  more.get("point_v_more"), more.get("point_r_more"))
    return point, digest.hexdigest()


def prove_runs(data, quiet: bool = True) -> dict:
    """Give every solve record of ``data`` (a :class:`~rfverify.report.data.RunData`) its proven
    digits: ``rec["proven"]`` = {"digits": {q: d}, "modes": {q: mode}, "answer": d or None,
    "valid": bool, "failure": str, "seconds": s}, or None where the problem has no proven point.
    Returns {"n_proven": answers with proven digits, "n_runs": answers, "seconds": proof time,
    "no_point": problems without a proven point}."""
    from ..bench.runner import resolve_spec
    from ..bench.tasks import load_for_bench
    from ..progress import Progress
    from ..proof import ProofContext

    k = int(data.manifest.get("digits") or 10)
    by_problem = {}
    for rec in data.solves:
        rec["proven"] = None
        if not rec.get("_placeholder") and not rec.get("_npz_damaged") and Path(rec["_npz"]).exists():
            by_problem.setdefault(rec["problem"], []).append(rec)
    cache_dir = data.run_dir / "proven"
    stats = {"n_proven": 0, "n_runs": sum(len(v) for v in by_problem.values()), "seconds": 0.0, "no_point": []}
    bar = Progress(len(by_problem), "report: proven digits of every answer", quiet=quiet)
    for key, recs in sorted(by_problem.items()):
        d = data.digits.get(key)
        point, digest = _point(d["_npz"]) if d and d.get("has_reference") and not d.get("_npz_damaged") \
            else (None, None)
        if point is None:
            stats["no_point"].append(key)
            bar.advance(key)
            continue
        path = cache_dir / f"{key.replace('/', '__')}.json"
        ident = {"layout": CACHE_LAYOUT, "version": __version__, "point": digest, "digits": k}
        cached = {}
        if path.exists():
            try:
                got = json.loads(path.read_text(encoding="utf-8"))
                if isinstance(got, dict) and all(got.get(f) == v for f, v in ident.items()):
                    cached = got.get("runs") or {}
            except (OSError, ValueError):
                cached = {}  # a damaged cache is recomputed
        ctx, runs, changed = None, {}, False
        for rec in recs:
            stem = Path(rec["_npz"]).stem
            hit = cached.get(stem)
            if not (isinstance(hit, dict) and hit.get("task_key") == rec.get("task_key")):
                if ctx is None:
                    problem = load_for_bench(resolve_spec(data.problems[key]["spec"], data.run_dir),
                                     data.manifest.get("load_options"))
                    ctx = ProofContext(problem)
                hit = _prove_one(ctx, point, rec["_npz"], k)
                hit["task_key"] = rec.get("task_key")
                changed = True
            runs[stem] = hit
            rec["proven"] = hit
            stats["seconds"] += hit.get("seconds") or 0.0
            stats["n_proven"] += hit.get("answer") is not None
        if changed or set(runs) != set(cached):
            cache_dir.mkdir(exist_ok=True)
            write_text_atomic(path, json.dumps({**ident, "runs": runs}, indent=1, allow_nan=False,
                                               default=_json_default))
        bar.advance(key)
    bar.close()
    return stats


def _json_default(x):
    x = float(x)
    return x if math.isfinite(x) else None


def _prove_one(ctx, point, npz: str, k: int) -> dict:
    t0 = time.perf_counter()
    try:
        with np.load(npz) as z:
            v, u, r = (np.asarray(z[q], dtype=np.float64) for q in ("v", "u", "r"))
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        return {"digits": {}, "modes": {}, "answer": None, "valid": False,
                "failure": f"arrays unreadable: {exc}", "seconds": 0.0}
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        return {"digits": {}, "modes": {}, "answer": None, "valid": False,
                "failure": "the answer contains NaN or Inf", "seconds": 0.0}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        proof = ctx.prove(point, v, u, r, k)
    digits = {q: (None if x.digits is None else float(x.digits)) for q, x in proof.quantities.items()}
    modes = {q: x.mode for q, x in proof.quantities.items()}
    valid = bool(proof.valid)
    return {"digits": digits if valid else {}, "modes": modes if valid else {},
            "answer": answer_digits(digits, modes) if valid else None, "valid": valid,
            "failure": proof.failure or "", "seconds": time.perf_counter() - t0}
