"""Reading a bench run directory and deriving what the report shows.

Nothing here trusts a solver: "solved" is the bench's independent high-precision recheck
(``record["solved"]``), forward errors are computed here from the saved arrays against the
certified reference solution of the problem (the independent mpmath run of its ``digits``
task), and a failure's cause is the solver's own diagnosis plus the recheck's verdict.
"""

from __future__ import annotations

import json
import math
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bench.verify import forward_digits

SGM_SHIFT = 0.01
"""Shift (seconds) of the shifted geometric mean of times: keeps runs of a few milliseconds
from dominating the mean through their logarithm."""


@dataclass
class RunData:
    run_dir: Path
    manifest: dict
    problems: dict                      # key -> manifest entry
    solves: list = field(default_factory=list)
    trajectories: list = field(default_factory=list)
    digits: dict = field(default_factory=dict)      # problem key -> record
    references: dict = field(default_factory=dict)  # problem key -> {"v","u","r"}

    @property
    def methods(self) -> list:
        order = ["jqinv", "qp2", "reduced", "reduced_factored", "noscaling", "clarabel"]
        present = {r["method"] for r in self.solves}
        return [m for m in order if m in present]

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


def load_run(run_dir) -> RunData:
    """Read every record of a run directory (see :mod:`rfverify.bench.runner`)."""
    run_dir = Path(run_dir)
    manifest_path = run_dir / "manifest.json"
    if not manifest_path.exists():
        from ..bench.runner import BenchInputError

        raise BenchInputError(f"{run_dir}: not a bench run directory (no manifest.json); "
                              "create one with `rfverify bench ... --out DIR`")
    manifest = json.loads(manifest_path.read_text())
    data = RunData(run_dir, manifest, {p["key"]: p for p in manifest["problems"]})
    for path in sorted((run_dir / "runs").rglob("*.json")):
        rec = json.loads(path.read_text())
        if rec.get("problem") not in data.problems:
            continue
        rec["_npz"] = str(path.with_suffix(".npz"))
        kind = rec.get("kind")
        if kind == "solve":
            data.solves.append(rec)
        elif kind == "trajectory":
            data.trajectories.append(rec)
        elif kind == "digits":
            data.digits[rec["problem"]] = rec
            if rec.get("has_reference") and Path(rec["_npz"]).exists():
                with np.load(rec["_npz"]) as z:
                    data.references[rec["problem"]] = {k: z[f"ref_{k}"] for k in ("v", "u", "r")}
    data.build_index()
    _add_forward_errors(data)
    return data


def _add_forward_errors(data: RunData) -> None:
    """Digits of v (and u) against the problem's reference, for every saved solution/iterate."""
    for rec in data.solves:
        ref = data.references.get(rec["problem"])
        rec["digits_v"] = rec["digits_u"] = None
        if ref is None or not Path(rec["_npz"]).exists():
            continue
        with np.load(rec["_npz"]) as z:
            if "v" in z:
                rec["digits_v"] = forward_digits(z["v"], ref["v"])
                rec["digits_u"] = forward_digits(z["u"], ref["u"])
    for rec in data.trajectories:
        ref = data.references.get(rec["problem"])
        rec["digits_v_iterates"] = None
        if ref is None or not Path(rec["_npz"]).exists():
            continue
        with np.load(rec["_npz"]) as z:
            if "v" in z:
                rec["digits_v_iterates"] = [forward_digits(v, ref["v"]) for v in z["v"]]


# ----------------------------------------------------------------------- aggregates
def sgm(values, shift: float = SGM_SHIFT) -> float:
    """Shifted geometric mean exp(mean(log(t + s))) − s."""
    values = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if values.size == 0:
        return math.nan
    return float(np.exp(np.mean(np.log(values + shift))) - shift)


def success_table(data: RunData) -> list[dict]:
    """Rows (collection incl. "all", method, tol): solved/total, SGM time over the problems
    every method solved at that tolerance, SGM iterations, solver's false claims."""
    rows = []
    for coll in data.collections + ["all"]:
        keys = [k for k, p in data.problems.items() if coll == "all" or p["collection"] == coll]
        for tol in data.tols:
            common = [k for k in keys if all((r := data.solve_record(k, m, tol)) and r.get("solved")
                                             for m in data.methods)]
            for m in data.methods:
                recs = [data.solve_record(k, m, tol) for k in keys]
                recs = [r for r in recs if r is not None]
                solved = [r for r in recs if r.get("solved")]
                false_claims = [r for r in recs if r.get("solver_claims_solved") and not r.get("solved")]
                rows.append({
                    "collection": coll, "method": m, "tol": tol, "solved": len(solved), "total": len(recs),
                    "sgm_time_common": sgm([data.solve_record(k, m, tol)["time"] for k in common]),
                    "n_common": len(common),
                    "sgm_iter_common": sgm([data.solve_record(k, m, tol).get("nit") for k in common], shift=1.0),
                    "false_claims": len(false_claims),
                    "median_digits_v": _median([r.get("digits_v") for r in recs]),
                })
    return rows


def _median(values):
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.median(vals)) if vals else None


def performance_profile(data: RunData, tol: float, measure: str = "time"):
    """Dolan–Moré profile at ``tol``: returns (taus, {method: ρ(τ)}), ρ_s(τ) = share of ALL
    problems with t_{p,s} ≤ τ · min_s t_{p,s}.  A run that is not verified solved has t = ∞;
    a problem no method solves stays in the denominator (no curve reaches 1 then)."""
    keys = sorted(data.problems)
    methods = data.methods
    T = np.full((len(keys), len(methods)), np.inf)
    for i, k in enumerate(keys):
        for j, m in enumerate(methods):
            r = data.solve_record(k, m, tol)
            if r and r.get("solved"):
                val = r["time"] if measure == "time" else r.get("nit")
                if val is not None:
                    T[i, j] = max(float(val), 1e-9 if measure == "time" else 1.0)
    best = T.min(axis=1, keepdims=True)
    with np.errstate(invalid="ignore"):
        ratio = np.where(np.isfinite(best), T / best, np.inf)
    finite = ratio[np.isfinite(ratio)]
    tau_max = max(2.0, float(finite.max()) * 1.05) if finite.size else 2.0
    taus = np.unique(np.concatenate(([1.0], np.sort(finite), [tau_max])))
    prof = {m: np.array([(ratio[:, j] <= t).sum() / max(len(keys), 1) for t in taus])
            for j, m in enumerate(methods)}
    return taus, prof


def failures(data: RunData) -> list[dict]:
    """Every counted run that is not verified solved, with its diagnosed cause."""
    out = []
    for r in sorted(data.solves, key=lambda r: (r["problem"], r["method"], -r["tol"])):
        if r.get("solved"):
            continue
        out.append({"problem": r["problem"], "method": r["method"], "tol": r["tol"],
                    "status": r.get("status"), "cause": failure_cause(r)})
    return out


def failure_cause(rec: dict) -> str:
    status = rec.get("status")
    msg = rec.get("message", "")
    ver = rec.get("verified") or {}
    if status in ("Timeout", "Crashed", "Error"):
        return f"{status}: {msg}"
    if not ver.get("finite", True):
        return f"non-finite iterate returned ({status}: {msg})"
    worst = max(("dinfeas", "velocity", "mu", "cone"), key=lambda k: ver.get(k, -1.0)) if ver else None
    recheck = (f"recheck: {worst} = {ver[worst]:.2e} > tol {rec['tol']:.0e}" if worst else "no recheck")
    if status == "Solved":
        return f"solver claimed Solved but the independent {recheck} ({msg})"
    return f"{status}: {msg}; {recheck}"


def double_limit(data: RunData) -> list[dict]:
    """How far double precision gets: per (problem, method) the best verified criterion and
    the best digits of v along the trajectory, and how the trajectory ended."""
    rows = []
    for t in sorted(data.trajectories, key=lambda r: (r["problem"], r["method"])):
        digs = t.get("digits_v_iterates") or []
        digs = [d for d in digs if d is not None]
        rows.append({"problem": t["problem"], "method": t["method"], "tol": t["tol"],
                     "status": t.get("status"), "message": t.get("message", ""),
                     "best_verified": t.get("best_verified_max"),
                     "best_digits_v": max(digs) if digs else None,
                     "final_digits_v": digs[-1] if digs else None, "nit": t.get("nit")})
    return rows


def mixed_precision(data: RunData, method: str = "jqinv") -> list[dict]:
    """Cost of the mixed-precision path per problem: the double solve at the loosest counted
    tolerance ≤ 1e-10 against the certified path; seconds per extra digit of v."""
    rows = []
    tol = min(data.tols) if data.tols else 1e-10
    for key, d in sorted(data.digits.items()):
        base = data.solve_record(key, method, tol)
        digs = d.get("certified_digits") or {}
        got = min(digs.values()) if digs else None
        got_v = digs.get("v")
        row = {"problem": key, "certified": d.get("certified"), "digits_min": got, "digits_v": got_v,
               "time_path": d.get("time"), "time_certify": d.get("time_certify"),
               "double_tol": tol, "double_time": base.get("time") if base else None,
               "double_digits_v": base.get("digits_v") if base else None, "per_digit": None}
        if base and base.get("digits_v") is not None and got_v is not None:
            # Beyond ~16 digits both roundings are the same double: count 16 at most.
            extra = min(got_v, 16.0) - min(base["digits_v"], 16.0)
            if extra > 0.5:
                row["per_digit"] = (d["time"] - base["time"]) / extra
        rows.append(row)
    return rows


def worst_cases(data: RunData, count: int, max_contacts: int) -> list[tuple]:
    """(problem, method, tol) to diagnose, at most one per problem, worst first: counted
    Algorithm 1 runs that failed (tightest tolerance first), then trajectories that ended
    without meeting their tight tolerance (where double precision broke down; jqinv first),
    then the runs with the largest cond(Q_p).  Only problems with ≤ ``max_contacts`` contacts
    (each iteration costs a reference step)."""
    from ..bench.runner import ALGORITHM1_METHODS

    small = {k for k, p in data.problems.items() if 0 < p["n_contacts"] <= max_contacts}
    failed = [r for r in data.solves if not r.get("solved") and r["method"] in ALGORITHM1_METHODS
              and r["problem"] in small and r.get("status") not in ("Timeout", "Crashed", "Error")]
    failed.sort(key=lambda r: (r["tol"], -(r.get("max_cond_Qp") or 0)))
    broke = [t for t in data.trajectories if t["problem"] in small and t.get("status") != "Solved"
             and t.get("status") not in ("Timeout", "Crashed", "Error")]
    broke.sort(key=lambda t: (t["method"] != "jqinv", -max((it.get("max_cond_Qp") or 0)
                                                            for it in t.get("iterates") or [{}])))
    hard = [r for r in data.solves if r["method"] in ALGORITHM1_METHODS and r["problem"] in small]
    hard.sort(key=lambda r: -(r.get("max_cond_Qp") or 0))
    chosen, seen = [], set()
    for r in failed + broke + hard:
        if r["problem"] in seen:
            continue
        seen.add(r["problem"])
        chosen.append((r["problem"], r["method"], r["tol"]))
        if len(chosen) >= count:
            break
    return chosen


def per_problem_counts(data: RunData) -> dict:
    out = defaultdict(lambda: [0, 0])
    for r in data.solves:
        out[r["problem"]][1] += 1
        out[r["problem"]][0] += bool(r.get("solved"))
    return dict(out)
