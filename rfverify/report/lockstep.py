"""Lockstep diagnosis of exactly what the bench ran (:func:`rfverify.verify.diagnosis.diagnose`).

The bench's timed solves split a problem into its independent components (presolve, DESIGN
§2.1) and solve each one by itself; a lockstep run keeps every iterate and therefore never
splits.  Diagnosing the whole problem unsplit would show a different run — one that may even
succeed where the bench's failed.  So for a split solve this module first solves the problem
again exactly as the bench did, finds the component that did not reach the tolerance, and
diagnoses that component alone, as the sub-problem the solver handed to Algorithm 1 (its own
M, H, f, w, μ, μr: the same matrices, scales and starting point).  It checks that the
component alone ends as it did inside the bench's run (status and iterations) and says so.

:func:`diagnose_worst` runs it on the report's worst cases and caches each diagnosis in
``RUN_DIR/diagnostics/``.
"""

from __future__ import annotations

import json
import warnings

import numpy as np

from .._version import __version__
from ..bench.records import tol_text
from ..io.output import tag_floats, untag_floats, write_text_atomic
from ..model.problem import SPACEDIM, Problem
from ..solver.result import Settings
from .aggregates import worst_cases
from .data import RunData


def solve_groups(problem: Problem, settings):
    """The independent components the solver splits ``problem`` into with ``settings``
    (exactly its own computation), or None when it solves the problem as one system."""
    from ..model.lifting import lift
    from ..solver.presolve import independent_components

    if not settings.split_components:
        return None
    lp = lift(problem, reduce_cones=settings.reduce_cones)
    groups = independent_components(problem, lp, problem.contact_free_dofs)
    if len(groups) <= 1 or len(groups) > settings.max_components:
        return None
    return lp, groups


def component_problem(problem: Problem, lp, group) -> tuple[Problem, np.ndarray]:
    """The sub-problem of one component (its dofs and contacts, in the problem's order) and
    the problem's contact numbers of its contacts."""
    dofs, rows = group[0], group[1]
    contacts = np.unique(lp.keep[rows] // SPACEDIM)
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    sub = Problem.from_arrays(problem.M_sym[dofs][:, dofs], problem.H[dofs][:, cols], problem.f[dofs],
                              problem.w[cols], problem.mu[contacts], problem.mu_r[contacts],
                              max_asymmetry=np.inf, title=f"component of {problem.title}".strip())
    return sub, contacts


# The bench runs the solver with its default settings; the diagnosis repeats that run
# (diagnose alone would refine every solve to 4·eps and start in longdouble arithmetic, see
# rfverify.verify.diagnosis.diagnose).  The mpmath witness gets a shorter budget than the command's:
# a report diagnoses several runs.
AS_BENCHED = {"refine_tol": Settings.refine_tol, "longdouble_below": Settings.longdouble_below, "witness_time": 20.0}


def diagnose_as_run(problem: Problem, method: str, tol: float, *, max_iter: int = 100, dps: int = 40,
                    kind: str = "solve", bench_status: str | None = None) -> dict:
    """Lockstep diagnosis of the run the bench made (``kind`` "solve": a timed solve, split
    into components as the solver does; "trajectory": one system, as trajectories run).

    Returns the :meth:`~rfverify.verify.diagnosis.Diagnosis.to_dict` dict with a ``scope`` entry: ``mode``
    ("whole", "component" or "unsplit"), ``text`` (one sentence for the reader), and for a
    component its ``index``, ``count``, ``contacts``, ``n_dofs``, the ``status`` and ``nit``
    it had inside the bench's run and whether the diagnosed run ``reproduced`` them."""
    from ..verify.diagnosis import diagnose
    from ..solver import Status, solve

    if kind == "trajectory":
        diag = diagnose(problem, method=method, tol=tol, max_iter=max_iter, dps=dps, **AS_BENCHED).to_dict()
        diag["scope"] = {"mode": "whole", "text": "the trajectory run solves the problem as one system "
                                                  "(it keeps every iterate, so it never splits components); "
                                                  "diagnosed the same way"}
        return diag
    split = solve_groups(problem, Settings(tol=tol, max_iter=max_iter))
    if split is None:
        diag = diagnose(problem, method=method, tol=tol, max_iter=max_iter, dps=dps, **AS_BENCHED).to_dict()
        diag["scope"] = {"mode": "whole", "text": "the bench solved the problem as one system; so does the "
                                                  "diagnosis"}
        return _compare_status(diag, bench_status)
    lp, groups = split
    rerun = solve(problem, method=method, tol=tol, max_iter=max_iter)
    comps = rerun.extras.get("component_runs") or []
    bad = [i for i, c in enumerate(comps) if c["status"] is not Status.SOLVED]
    if len(comps) != len(groups) or not bad:
        diag = diagnose(problem, method=method, tol=tol, max_iter=max_iter, dps=dps, **AS_BENCHED).to_dict()
        why = (f"every one of its {len(groups)} independent components met the tolerance on its own"
               if not bad else f"its {len(groups)} components could not be matched to the solver's runs")
        diag["scope"] = {"mode": "unsplit", "count": len(groups),
                         "text": f"the bench solved the problem as {len(groups)} independent components and "
                                 f"{why}; diagnosed without splitting (one system), which is not the run "
                                 "the bench made"}
        return _compare_status(diag, bench_status, rerun)
    i = bad[0]
    sub, contacts = component_problem(problem, lp, groups[i])
    diag = diagnose(sub, method=method, tol=tol, max_iter=max_iter, dps=dps, **AS_BENCHED).to_dict()
    inside = comps[i]
    reproduced = diag["status"] == str(inside["status"]) and diag["nit"] == inside["nit"]
    shown = ", ".join(map(str, contacts[:12])) + (", …" if contacts.size > 12 else "")
    text = (f"the bench solved the problem as {len(groups)} independent components; {len(bad)} did not "
            f"reach the tolerance. Diagnosed: component {i + 1} of {len(groups)} alone ({contacts.size} "
            f"contacts — the problem's contacts {shown} — and {sub.n_dofs} dofs), which ended "
            f"{inside['status']} after {inside['nit']} iterations inside the bench's run")
    text += ("; alone it ends the same way" if reproduced else
             f"; alone it ends {diag['status']} after {diag['nit']} iterations (not the same run)")
    text += "; contact numbers in its messages are the problem's"
    _renumber_contacts(diag, contacts)
    diag["scope"] = {"mode": "component", "index": i, "count": len(groups), "contacts": contacts.tolist(),
                     "n_dofs": sub.n_dofs, "status": str(inside["status"]), "nit": int(inside["nit"]),
                     "reproduced": bool(reproduced), "text": text}
    return _compare_status(diag, bench_status, rerun)


def _renumber_contacts(diag: dict, contacts: np.ndarray) -> None:
    """Messages of a component's run name its own contact k; give them the problem's number."""
    import re

    def fix(text):
        if not isinstance(text, str):
            return text
        return re.sub(r"\bcontact (\d+)\b",
                      lambda m: f"contact {contacts[int(m.group(1))]}" if int(m.group(1)) < contacts.size
                      else m.group(0), text)

    for key in ("message", "failure", "conclusion"):
        diag[key] = fix(diag.get(key))
    for it in diag.get("iterations", []):
        it["flags"] = [fix(f) for f in it.get("flags", [])]
    evidence = diag.get("evidence") or {}
    evidence["text"] = [fix(t) for t in evidence.get("text", [])]
    for key in ("departure",):
        if evidence.get(key):
            evidence[key]["through"] = fix(evidence[key].get("through"))


def _compare_status(diag: dict, bench_status, rerun=None) -> dict:
    """Say so when solving again today does not end as the bench's record says."""
    if bench_status is None:
        return diag
    if rerun is None:
        now = diag["status"]
    else:
        now = str(rerun.status)
    if now != bench_status:
        diag["scope"]["text"] += (f" (note: solved again now, the problem ends {now}, the bench recorded "
                                  f"{bench_status}: the solver or its settings changed since the bench ran)")
    return diag


# ---------------------------------------------------------------------- the report's worst cases, cached
DIAGNOSIS_CACHE_VERSION = 3
"""Layout of a cached lockstep diagnosis (2: diagnosed as the bench ran it, with its scope; 3: exact
steps in double-double, with the cause, its evidence and a remedy)."""


def diagnose_worst(data: RunData, count, max_contacts, dps, quiet) -> list:
    """(case, diagnosis) of the worst cases of a run (:func:`.aggregates.worst_cases`), each
    diagnosed as the bench ran it (:func:`diagnose_as_run`) and cached in
    ``RUN_DIR/diagnostics/`` under the problem's content, the digits, the rfverify version and
    the cache layout."""
    from ..bench.runner import resolve_spec
    from ..bench.tasks import load_for_bench
    from ..progress import Progress

    chosen = worst_cases(data, count, max_contacts)
    cache = data.run_dir / "diagnostics"
    if chosen:
        cache.mkdir(exist_ok=True)
    out = []
    bar = Progress(len(chosen), "report: lockstep diagnosis", quiet=quiet)
    for case in chosen:
        key, method, tol, kind = case["problem"], case["method"], case["tol"], case["kind"]
        rec = case["record"]
        max_iter = int(rec.get("max_iter") or data.manifest.get("max_iter") or 100)
        sha = data.problems[key]["sha256"]
        prefix = "trajectory-" if kind == "trajectory" else ""
        path = cache / f"{key.replace('/', '__')}__{prefix}{method}@{tol_text(tol)}.json"
        ident = {"sha256": sha, "dps": dps, "version": __version__, "layout": DIAGNOSIS_CACHE_VERSION,
                 "kind": kind, "max_iter": max_iter, "bench_status": rec.get("status")}
        diag = None
        if path.exists():
            try:
                cached = untag_floats(json.loads(path.read_text(encoding="utf-8")))
            except (OSError, ValueError):
                cached = None  # a damaged cache entry is recomputed
            if isinstance(cached, dict) and all(cached.get(k) == v for k, v in ident.items()):
                diag = cached
        if diag is None:
            problem = load_for_bench(resolve_spec(data.problems[key]["spec"], data.run_dir),
                                     data.manifest.get("load_options"))
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("always")  # the double run's warnings: not for stderr
                diag = diagnose_as_run(problem, method, tol, max_iter=max_iter, dps=dps, kind=kind,
                                       bench_status=rec.get("status") if kind == "solve" else None)
            diag.update(ident, tol=tol, problem=key)
            # Tagged, so NaN/inf survive strict JSON (null would lose which one it was).
            write_text_atomic(path, json.dumps(tag_floats(diag), indent=1, allow_nan=False, default=float))
        out.append((case, diag))
        bar.advance(key)
    bar.close()
    return out

