"""What the report shows, derived from a read run directory (:class:`~.data.RunData`): the
one median, the shifted geometric mean and the digits cap every table, figure and glance line
uses; success counts and speed on common solved sets; performance profiles; failures and their
causes; refuted claims, grouped; how far double precision gets; what k proven digits cost; the
proven digits of every answer per method; the worst cases to diagnose in lockstep; one hard
problem per family.

Nothing here trusts a solver: "solved" is the bench's independent recheck, and a refuted
claim is a solver's own claim that recheck failed.
"""

from __future__ import annotations

import math
from collections import defaultdict

import numpy as np

from ..bench.records import refuted_label, worst_measure
from ..model.measures import CRITERION
from ..solver.result import ALGORITHM1_METHODS
from .data import UNUSABLE, RunData, is_number, certified_mode

SGM_SHIFT = 0.01
"""Shift (seconds) of the shifted geometric mean of times: keeps runs of a few milliseconds
from dominating the mean through their logarithm."""

DIGITS_CAP = 16.0
"""Digits are counted up to 16 (shown "16+"): beyond that two float64 vectors agree to the
last bit, so more "digits" would only measure the rounding of the reference."""

DIGITS_BASE_TOL = 1e-10
"""The k-digit path starts with a double jqinv solve to 1e-10; its cost is compared with the
bench's jqinv solve at the loosest bench tolerance ≤ this (:func:`digits_baseline_tol`)."""


def median(values) -> float | None:
    """The report's one median, used by the glance, every table and every figure: numpy's
    (the mean of the two middle values for an even count) over the values that are numbers —
    None and NaN are left out, ±inf kept (they sort to the ends).  None when none is left."""
    vals = [float(v) for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return float(np.median(vals)) if vals else None


def capped(d):
    """Digits capped at :data:`DIGITS_CAP` (None stays None)."""
    return None if d is None else min(float(d), DIGITS_CAP)


def sgm(values, shift: float = SGM_SHIFT) -> float:
    """Shifted geometric mean exp(mean(log(t + s))) − s."""
    values = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if values.size == 0:
        return math.nan
    return float(np.exp(np.mean(np.log(values + shift))) - shift)


def _refuted(rec: dict) -> bool:
    """The solver's own claim (Solved, or AlmostSolved by its own definition) was refuted by
    the recheck; records written before claims were recorded fall back to Solved claims."""
    if "refuted" in rec:
        return bool(rec["refuted"])
    return bool(rec.get("solver_claims_solved")) and not rec.get("solved")


def refuted_runs(data: RunData) -> list[dict]:
    """Every counted solve whose solver claimed Solved or AlmostSolved (its ``claim``) and
    whose independent recheck failed the tolerance that claim asserts (``refuted``)."""
    return [r for r in data.solves if _refuted(r)]


def algorithm1_methods(data: RunData) -> list:

    return [m for m in data.methods if m in ALGORITHM1_METHODS]


def _keys(data: RunData, coll: str) -> list:
    return [k for k, p in data.problems.items() if coll == "all" or p["collection"] == coll]


def common_solved(data: RunData, keys, methods, tol) -> list:
    """The problems of ``keys`` that every one of ``methods`` solved (verified) at ``tol``."""
    if not methods:
        return []
    return [k for k in keys if all((r := data.solve_record(k, m, tol)) and r.get("solved") for m in methods)]


def success_table(data: RunData) -> list[dict]:
    """Rows (collection incl. "all", tol, method): solved/total, refuted claims, median digits
    of v; and speed on two common solved sets — the problems every Algorithm 1 form solved at
    that tolerance (``*_a1``; Algorithm 1 forms only) and the problems every method solved
    (``*_all``) — as shifted geometric means of time and iterations over the set."""
    rows = []
    a1 = algorithm1_methods(data)
    for coll in data.collections + ["all"]:
        keys = _keys(data, coll)
        for tol in data.tols:
            common_a1 = common_solved(data, keys, a1, tol)
            common_all = common_solved(data, keys, data.methods, tol)
            for m in data.methods:
                recs = [r for r in (data.solve_record(k, m, tol) for k in keys) if r is not None]
                digs = [capped(r.get("digits_v")) for r in recs if r.get("digits_v") is not None]
                rows.append({
                    "collection": coll, "method": m, "tol": tol,
                    "solved": sum(bool(r.get("solved")) for r in recs), "total": len(recs),
                    "false_claims": sum(_refuted(r) for r in recs),
                    "median_digits_v": median(digs), "n_digits": len(digs),
                    "n_common_a1": len(common_a1),
                    "sgm_time_a1": sgm([data.solve_record(k, m, tol)["time"] for k in common_a1])
                    if m in a1 else None,
                    "sgm_iter_a1": sgm([data.solve_record(k, m, tol).get("nit") for k in common_a1], shift=1.0)
                    if m in a1 else None,
                    "n_common_all": len(common_all),
                    "sgm_time_all": sgm([data.solve_record(k, m, tol)["time"] for k in common_all]),
                    "sgm_iter_all": sgm([data.solve_record(k, m, tol).get("nit") for k in common_all], shift=1.0),
                })
    return rows


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
    """Every counted run that is not verified solved and whose solver did not claim it was (the
    refuted claims are grouped apart, :func:`refuted_groups`), with its diagnosed cause."""
    out = []
    for r in sorted(data.solves, key=lambda r: (r["problem"], r["method"], -r["tol"])):
        if r.get("solved") or _refuted(r):  # a refuted claim is shown once, in refuted_groups
            continue
        out.append({"problem": r["problem"], "method": r["method"], "tol": r["tol"],
                    "status": r.get("status"), "refuted": _refuted(r), "cause": failure_cause(r)})
    return out


def failure_cause(rec: dict) -> str:
    status = rec.get("status")
    msg = rec.get("message", "")
    ver = rec.get("verified") or {}
    if status in ("Timeout", "Crashed", "Error") + UNUSABLE:
        return f"{status}: {msg}"
    if not ver.get("finite", True):
        return f"non-finite iterate returned ({status}: {msg})"
    measures = [k for k in CRITERION if is_number(ver.get(k)) and not math.isnan(ver[k])]
    worst = max(measures, key=lambda k: ver[k]) if measures else None
    recheck = (f"recheck: {worst} = {ver[worst]:.2e} > tol {rec['tol']:g}" if worst else "no recheck")
    if _refuted(rec):
        claim = rec.get("claim") or "Solved"
        tol = rec.get("claim_tol", rec["tol"])
        return (f"solver claimed {claim} (at {tol:g}) but the independent {recheck} "
                f"({status}: {msg})")
    return f"{status}: {msg}; {recheck}"


def double_limit(data: RunData) -> list[dict]:
    """How far double precision gets: per (problem, method) the best verified criterion and
    the best digits of v along the trajectory, and how the trajectory ended."""
    rows = []
    for t in sorted(data.trajectories, key=lambda r: (r["problem"], r["method"])):
        digs = [capped(d) for d in (t.get("digits_v_iterates") or []) if d is not None]
        rows.append({"problem": t["problem"], "method": t["method"], "tol": t["tol"],
                     "status": t.get("status"), "message": t.get("message", ""),
                     "best_verified": t.get("best_verified_max"),
                     "best_digits_v": max(digs) if digs else None,
                     "final_digits_v": digs[-1] if digs else None, "nit": t.get("nit")})
    return rows


def double_limit_summary(data: RunData) -> dict:
    """Per Algorithm 1 form, over the same problems for every form: the median (and worst)
    best verified criterion along its trajectory (problems every form has a trajectory of),
    and the median (and worst) best correct digits of v (problems every form has digits for:
    a reference, and v* not ≈ 0), and how many reach the k-digit target."""
    per = double_limit(data)
    forms = [m for m in algorithm1_methods(data) if any(r["method"] == m for r in per)]
    by = {(r["problem"], r["method"]): r for r in per}
    probs = sorted({r["problem"] for r in per})
    with_traj = [k for k in probs if all((k, m) in by for m in forms)]
    with_digs = [k for k in with_traj if all(by[(k, m)]["best_digits_v"] is not None for m in forms)]
    target = int(data.manifest.get("digits") or 10)
    rows = []
    for m in forms:
        crit = [by[(k, m)]["best_verified"] for k in with_traj]
        digs = [by[(k, m)]["best_digits_v"] for k in with_digs]
        rows.append({"method": m, "median_best_verified": median(crit),
                     "worst_best_verified": max(crit) if crit else None,
                     "median_best_digits_v": median(digs), "worst_best_digits_v": min(digs) if digs else None,
                     "reach_target": sum(d >= target for d in digs)})
    return {"rows": rows, "n_problems": len(with_traj), "n_digits": len(with_digs), "target": target,
            "tol": data.manifest.get("trajectory_tol"),
            "n_absolute": len([k for k in with_traj if k in data.absolute_v])}


def digits_baseline_tol(data: RunData):
    """The loosest bench tolerance ≤ 1e-10 (the k-digit path's own double phase stops at
    1e-10); None when the bench ran none."""
    tols = [t for t in data.tols if t <= DIGITS_BASE_TOL * (1 + 1e-9)]
    return max(tols) if tols else None


def mixed_precision(data: RunData, method: str = "jqinv") -> list[dict]:
    """Per problem with a k-digit path: its proven digits, its total time (double solve,
    double-double phase and proof: what the proven digits cost), and that time against the
    bench's double ``method`` solve at :func:`digits_baseline_tol` (ratio = path time /
    double solve time)."""
    tol = digits_baseline_tol(data)
    rows = []
    for key, d in sorted(data.digits.items()):
        if d.get("status") in ("Timeout", "Crashed", "Error"):
            rows.append({"problem": key, "certified": False, "status": d.get("status"),
                         "message": d.get("message", ""), "digits": {}, "modes": {}, "time_path": None,
                         "time_double": None, "time_warm": None, "time_certify": None,
                         "base_tol": tol, "base_time": None, "base_solved": None, "ratio": None})
            continue
        base = data.solve_record(key, method, tol) if tol is not None else None
        base_time = base.get("time") if base else None
        ratio = d["time"] / base_time if base_time and d.get("time") is not None else None
        rows.append({"problem": key, "certified": bool(d.get("certified")), "status": d.get("status"),
                     "message": d.get("message", ""), "digits": dict(d.get("certified_digits") or {}),
                     "modes": {q: certified_mode(d, q) for q in ("v", "u", "Hr", "r")},
                     "time_path": d.get("time"), "time_double": d.get("time_double"),
                     "time_warm": d.get("time_warm"), "time_certify": d.get("time_certify"),
                     "base_tol": tol, "base_time": base_time,
                     "base_solved": base.get("solved") if base else None, "ratio": ratio})
    return rows


def digits_cost(data: RunData) -> dict:
    """What k proven digits cost, over the problems whose path certified them: the median
    total path time and the median of the per-problem ratios path time / double solve."""
    rows = mixed_precision(data)
    cert = [r for r in rows if r["certified"]]
    ratios = [r["ratio"] for r in cert if r["ratio"] is not None]
    return {"digits": int(data.manifest.get("digits") or 10), "n": len(rows), "n_certified": len(cert),
            "median_time": median([r["time_path"] for r in cert]), "median_ratio": median(ratios),
            "n_ratio": len(ratios), "base_tol": digits_baseline_tol(data),
            "median_base_time": median([r["base_time"] for r in cert if r["ratio"] is not None])}


_DIAGNOSABLE_FAILURE = lambda r: r.get("status") not in ("Timeout", "Crashed", "Error") + UNUSABLE  # noqa: E731


def worst_cases(data: RunData, count: int, max_contacts: int) -> list[dict]:
    """Runs to diagnose in lockstep, at most one per problem, failures first: Algorithm 1
    runs whose own claim the recheck refuted, then the other runs that were not solved
    (tightest tolerance first, then largest cond(Q_p)); only when there are fewer failures
    than ``count``, trajectories that ended without meeting their tight tolerance (jqinv
    first), then the solved runs with the largest cond(Q_p).  Only problems with ≤
    ``max_contacts`` contacts (each iteration costs a reference step); runs that timed out,
    crashed or have no record are not rerun.  Each entry says why it was chosen."""

    small = {k for k, p in data.problems.items() if 0 < p["n_contacts"] <= max_contacts}
    a1 = [r for r in data.solves if r["method"] in ALGORITHM1_METHODS and r["problem"] in small
          and not r.get("_placeholder")]
    cond = lambda r: -(r.get("max_cond_Qp") or 0)  # noqa: E731
    refuted = sorted((r for r in a1 if _refuted(r) and _DIAGNOSABLE_FAILURE(r)), key=lambda r: (r["tol"], cond(r)))
    failed = sorted((r for r in a1 if not r.get("solved") and not _refuted(r) and _DIAGNOSABLE_FAILURE(r)),
                    key=lambda r: (r["tol"], cond(r)))
    broke = [t for t in data.trajectories if t["problem"] in small and t.get("status") != "Solved"
             and _DIAGNOSABLE_FAILURE(t)]
    broke.sort(key=lambda t: (t["method"] != "jqinv", -max((it.get("max_cond_Qp") or 0)
                                                            for it in t.get("iterates") or [{}])))
    hard = sorted((r for r in a1 if r.get("solved")), key=cond)
    why = ([(r, "solve", "its own claim refuted by the recheck") for r in refuted]
           + [(r, "solve", f"not verified solved, {r.get('status')}") for r in failed]
           + [(t, "trajectory", f"no failed run left; its trajectory at {t['tol']:g} ended {t.get('status')}")
              for t in broke]
           + [(r, "solve", "no failed run left; solved, largest cond(Q_p)") for r in hard])
    chosen, seen = [], set()
    for r, kind, reason in why:
        if r["problem"] in seen:
            continue
        seen.add(r["problem"])
        chosen.append({"problem": r["problem"], "method": r["method"], "tol": r["tol"], "kind": kind,
                       "why": reason, "record": r})
        if len(chosen) >= count:
            break
    return chosen


def per_problem_counts(data: RunData) -> dict:
    out = defaultdict(lambda: [0, 0])
    for r in data.solves:
        out[r["problem"]][1] += 1
        out[r["problem"]][0] += bool(r.get("solved"))
    return dict(out)


# ----------------------------------------------------------------------- refuted claims, grouped
def refuted_groups(data: RunData) -> list[dict]:
    """Refuted claims grouped by (method, claim, measure that refuted it): how many runs, on how
    many problems, at which tolerances, the smallest and largest refuting value, a few examples
    (each with its label).  Every refuted run is in exactly one group."""
    groups = {}
    for r in refuted_runs(data):
        name, value = worst_measure(r)
        g = groups.setdefault((r["method"], r.get("claim") or "Solved", name),
                              {"method": r["method"], "claim": r.get("claim") or "Solved", "measure": name,
                               "runs": []})
        g["runs"].append(r)
    out = []
    for g in groups.values():
        runs = sorted(g["runs"], key=lambda r: -(worst_measure(r)[1] or 0))
        vals = [worst_measure(r)[1] for r in runs if worst_measure(r)[1] is not None]
        out.append({**g, "n": len(runs), "problems": sorted({r["problem"] for r in runs}),
                    "tols": sorted({r["tol"] for r in runs}, reverse=True),
                    "min": min(vals) if vals else None, "max": max(vals) if vals else None,
                    "label": (f"{g['claim']} (refuted: {g['measure']} {min(vals):.1e}–{max(vals):.1e})"
                              if vals and len(vals) > 1 else refuted_label(runs[0])),
                    "examples": [(r["problem"], r["tol"], refuted_label(r)) for r in runs[:3]]})
    return sorted(out, key=lambda g: (-g["n"], g["method"]))


# ----------------------------------------------------------------------- proven digits of every run
def proven_by_method(data: RunData) -> list[dict]:
    """Per method (the k-digit path as "k-digit path" last): its answers (``runs``) and the
    ``problems`` they are of, the answers with proven digits, how many
    reach the bench's k digits, the median proven digits and the median time of those that do
    (:mod:`rfverify.report.proven`; an answer's digits = the smallest relative digits of v, u, Hr)."""
    k = int(data.manifest.get("digits") or 10)
    rows = []
    for m in data.methods:
        recs = [r for r in data.solves if r["method"] == m and not r.get("_placeholder")]
        proven = [r for r in recs if (r.get("proven") or {}).get("answer") is not None]
        reach = [r for r in proven if r["proven"]["answer"] >= k - 1e-9]
        rows.append({"method": m, "runs": len(recs), "problems": len({r["problem"] for r in recs}),
                     "n_proven": len(proven), "reach": len(reach),
                     "median_digits": median([r["proven"]["answer"] for r in proven]),
                     "best_digits": max((r["proven"]["answer"] for r in proven), default=None),
                     "median_time_reach": median([r["time"] for r in reach])})
    paths = [d for d in data.digits.values() if d.get("status") not in ("Timeout", "Crashed", "Error")]
    cert = [d for d in paths if d.get("certified")]
    if data.digits:
        rows.append({"method": f"{k}-digit path", "runs": len(data.digits), "problems": len(data.digits),
                     "n_proven": len(paths),
                     "reach": len(cert), "median_digits": median([path_answer_digits(d) for d in paths]),
                     "best_digits": max((x for x in (path_answer_digits(d) for d in paths) if x is not None),
                                        default=None),
                     "median_time_reach": median([d["time"] for d in cert])})
    return rows


def path_answer_digits(d: dict):
    """A k-digit path's proven digits of its answer, as :func:`rfverify.report.proven.answer_digits`."""
    from .proven import answer_digits

    digs = d.get("certified_digits") or {}
    return answer_digits(digs, {q: certified_mode(d, q) for q in digs})


def double_breaks(data: RunData) -> dict:
    """Where double precision breaks: per problem with proven digits, the best proven digits of
    any double answer (every method and tolerance) — median and largest over problems, and how
    many reach k — and, along the jqinv trajectories (every iterate kept to the trajectory
    tolerance), the median over problems of the largest cond(Q_p) and of the smallest λ₂ of z
    and Jᵀr̃, and how many trajectories had a λ₂ below 1e-300 (underflow) or cond(Q_p) ≥ 1e15."""
    k = int(data.manifest.get("digits") or 10)
    best = {}
    for r in data.solves:
        d = (r.get("proven") or {}).get("answer")
        if d is not None:
            best[r["problem"]] = max(best.get(r["problem"], -math.inf), d)
    traj = [t for t in data.trajectories if t["method"] == "jqinv" and t.get("iterates")]
    conds, lams, under, big = [], [], 0, 0
    for t in traj:
        c = [it.get("max_cond_Qp") for it in t["iterates"] if it.get("max_cond_Qp") is not None]
        lz = [min(x for x in (it.get("min_lam2_z"), it.get("min_lam2_s")) if x is not None)
              for it in t["iterates"] if it.get("min_lam2_z") is not None or it.get("min_lam2_s") is not None]
        if c:
            conds.append(max(c))
            big += max(c) >= 1e15
        if lz:
            lams.append(min(lz))
            under += min(lz) < 1e-300
    return {"n": len(best), "median_best": median(list(best.values())),
            "max_best": max(best.values()) if best else None,
            "reach": sum(v >= k - 1e-9 for v in best.values()), "digits": k,
            "n_traj": len(traj), "median_max_cond": median(conds), "median_min_lam2": median(lams),
            "n_underflow": under, "n_cond15": big, "traj_tol": data.manifest.get("trajectory_tol")}


def family(key: str) -> str:
    """The family of a problem: a generated scene's name (before "-ndof"), else its collection."""
    name = key.rsplit("/", 1)[-1]
    return name.split("-ndof")[0] if "-ndof" in name else key.split("/", 1)[0]


def hard_per_family(data: RunData, method: str = "jqinv") -> list[dict]:
    """One representative hard problem per family: the one whose ``method`` trajectory reached
    the largest cond(Q_p) (ties: more contacts), with its per-iteration cond(Q_p) and λ₂."""
    picks = {}
    for t in data.trajectories:
        if t["method"] != method or not t.get("iterates"):
            continue
        c = max((it.get("max_cond_Qp") or 0 for it in t["iterates"]), default=0)
        fam = family(t["problem"])
        score = (c, data.problems[t["problem"]]["n_contacts"])
        if fam not in picks or score > picks[fam]["score"]:
            picks[fam] = {"family": fam, "problem": t["problem"], "score": score, "trajectory": t,
                          "max_cond": c}
    return [picks[f] for f in sorted(picks)]
