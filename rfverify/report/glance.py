"""The report's first screen, "At a glance": one figure (the proven digits of every answer of
every method against its time) and the answers — which method reaches k proven digits, how
fast, where double precision breaks, which method is fastest and most robust, how far double
precision gets, what k proven digits cost, the refuted claims and the failures — each with the
numbers of the table below that it names (the same functions of :mod:`.aggregates`, the same
sets, the same formatting).
"""

from __future__ import annotations

import math
from pathlib import Path

from . import figures
from .aggregates import (algorithm1_methods, digits_cost, double_breaks, double_limit_summary, proven_by_method,
                         refuted_groups, refuted_runs)
from .data import RunData
from .document import Doc, add_figure, counted, dig, fmt, problems, resting_on, sec, too_few


def glance_section(doc: Doc, data: RunData, out: Path, proven: dict, table, diags) -> None:
    """The heading, the answer in plain words, the figure and the detailed answers."""
    doc.h(2, "At a glance", anchor="glance")
    doc.p(" ".join(in_words(data, proven)))
    add_figure(doc, "Proven digits against time: every answer of every method, proven at its problem's proven "
                    "point (DESIGN §6), and each problem's k-digit path", figures.proven_digits_time, data, out)
    doc.bullets(_answers(data, proven) + _glance(data, table, diags))


def in_words(data: RunData, proven: dict) -> list:
    """The first screen's answer in sentences a newcomer can act on: which method gives k proven
    digits on which problems and at what cost, where double precision stops and why, and what
    the solvers' own claims are worth here (every number is one the bullets below give)."""
    k = int(data.manifest.get("digits") or 10)
    rows = {r["method"]: r for r in proven_by_method(data)}
    path = rows.get(f"{k}-digit path")
    cost = digits_cost(data)
    out = []
    if path is not None and path["runs"]:
        text = (f"In short: for {k} proven digits use the {k}-digit path (`rfverify solve --digits {k}`): it proved "
                f"{path['reach']} of {path['runs']} problems")
        if cost["n_certified"] and cost["median_ratio"] is not None:
            text += (f", in a median {sec(cost['median_time'])} s (per problem, a median {fmt(cost['median_ratio'], '.1f')}× "
                     f"the time of the bench's jqinv solve at {fmt(cost['base_tol'], 'g')})")
        out.append(text + ".")
        missed = sorted((key, _why_not(d)) for key, d in data.digits.items() if not d.get("certified"))
        if missed:
            out.append(f"The {len(missed)} it did not: " + "; ".join(f"{key}, {why}" for key, why in missed[:4])
                       + ("; …" if len(missed) > 4 else "") + f" (table 'The {k}-digit path').")
    doubles = [r for m, r in rows.items() if not m.endswith("path") and r["runs"]]
    if doubles:
        best = max(doubles, key=lambda r: r["reach"])
        out.append(f"Double precision alone rarely gets there provably: the best method, {best['method']}, gives {k} "
                   f"proven digits on {best['reach']} of {best['runs']} answers ({problems(best['problems'])}"
                   + (", too few to rank by" if too_few(best["problems"]) else "") + "; a run pushed to 1e-14 may "
                   "pass through "
                   "an iterate with more correct digits, table 'How far double precision gets', but nothing tells "
                   "which iterate without a proof).")
    br = double_breaks(data)
    if br["n"]:
        why = ""
        if br["n_traj"]:
            why = (f" Why: near the solution the Nesterov–Todd scaling grows ill-conditioned (largest cond(Q_p): "
                   f"median {fmt(br['median_max_cond'], '.1e')}) and an iterate's rounding of 1e-16 becomes a "
                   "relative error that many times larger in the answer; the extended precision of the path "
                   "removes exactly that.")
        out.append(f"Where it stops: the best double answer of a problem is proven to a median of "
                   f"{dig(br['median_best'])} digits (over {problems(br['n'])}).{why}")
    out.append("Terms: v are the bodies' velocities, u the contact velocities, r the contact reactions and Hr "
               "the forces they put on the bodies (a proven digit is a correct significant digit, proven by a "
               "rigorous error bound); jqinv, qp2, reduced and noscaling are Algorithm 1 with different linear "
               "systems, the k-digit path is Algorithm 1 continued in extended precision until the proof succeeds.")
    refuted = refuted_runs(data)
    if refuted:
        by = {}
        for r in refuted:
            by[r["method"]] = by.get(r["method"], 0) + 1
        out.append("A solver's own 'Solved' is not evidence here: "
                   + ", ".join(f"{m}'s claim failed the independent recheck on {n} runs" for m, n in by.items())
                   + " (table 'Refuted claims').")
    return out


def _why_not(record: dict) -> str:
    """Why a k-digit path did not certify, in a few words, from its verdict."""
    msg = str(record.get("message") or record.get("status") or "")
    if "not positive semidefinite" in msg:
        return ("its W is indefinite as stored, so the file's problem is not convex (certify the global problem it "
                "was made from instead)")
    if "not in the cones" in msg:
        return ("no point strictly inside the cones was found (the feasible set may have no interior; an exact "
                "answer can still be certified with rfverify certify)")
    if "not proven to" in msg:
        return "fewer digits proven"
    if record.get("status") in ("Timeout", "Crashed", "Error"):
        return str(record["status"]).lower()
    return msg[:60]


def _names(methods) -> str:
    return ", ".join(methods)


def _answers(data: RunData, proven: dict) -> list:
    """The first screen's four answers, from the proven digits of every answer (the figure above
    them and the tables 'What k proven digits cost' and 'cond(Q_p) and λ2 per iteration')."""
    rows = proven_by_method(data)
    k = int(data.manifest.get("digits") or 10)
    items = []
    reach = [f"{r['method']} {r['reach']}/{r['runs']}" + (" problems" if r["method"].endswith("path") else "")
             for r in rows]
    items.append((f"Which method reaches {k} proven digits:", f"answers proven to ≥ {k} digits of v, u and Hr: "
                  + ", ".join(reach) + f" ({proven['n_proven']} of {proven['n_runs']} answers have proven digits; "
                                       "table 'Proven digits of every answer')"))
    fast = [r for r in rows if r["median_time_reach"] is not None]
    if fast:
        items.append(("How fast:", "; ".join(
            f"{r['method']} {sec(r['median_time_reach'])} s "
            f"({counted(r['reach'], 'problem' if r['method'].endswith('path') else 'run')})" for r in fast)
                      + f" (median wall time of the runs that reached {k} proven digits, and how many did)"))
    br = double_breaks(data)
    if br["n"]:
        text = (f"the best double answer of each problem (any method, any tolerance) is proven to a median of "
                f"{dig(br['median_best'])} digits (at most {dig(br['max_best'])}; {br['reach']} of {br['n']} "
                f"problems reach {k})")
        if br["n_traj"]:
            text += (f"; along the jqinv trajectories to {fmt(br['traj_tol'], 'g')}, the largest cond(Q_p) has a "
                     f"median of {fmt(br['median_max_cond'], '.1e')} ({br['n_cond15']} of {br['n_traj']} reach "
                     f"1e15) and the smallest λ2 a median of {fmt(br['median_min_lam2'], '.1e')} ({br['n_underflow']}"
                     f" below 1e-300); figure 'cond(Q_p) and λ2 per iteration'")
        items.append(("Where double precision breaks:", text))
    return items


def _glance(data: RunData, table, diags) -> list:
    """The four questions, answered with the numbers of the tables below (same functions,
    same sets, same formatting)."""
    items = []
    if data.issues:
        items.append(("Warning:", f"{len(data.issues)} record(s) or array file(s) missing or damaged: planned "
                                  "solves without a usable record count as not solved (see 'Missing or damaged "
                                  "records')"))
    rows = [r for r in table if r["collection"] == "all"]
    a1 = algorithm1_methods(data)
    fast = []
    for tol in data.tols:
        at = {r["method"]: r for r in rows if r["tol"] == tol}
        parts = []
        timed_a1 = [at[m] for m in a1 if m in at and at[m]["sgm_time_a1"] is not None
                    and not math.isnan(at[m]["sgm_time_a1"])]
        if timed_a1:
            best = min(timed_a1, key=lambda r: r["sgm_time_a1"])
            others = ", ".join(f"{r['method']} {sec(r['sgm_time_a1'])} s" for r in timed_a1 if r is not best)
            parts.append(f"Algorithm 1 form {best['method']}, {sec(best['sgm_time_a1'])} s "
                         f"{resting_on(best['n_common_a1'], 'every form solved')}"
                         + (f" ({others})" if others else ""))
        elif a1:
            parts.append("no problem was solved by every Algorithm 1 form")
        if set(data.methods) != set(a1):
            timed = [r for r in at.values() if not math.isnan(r["sgm_time_all"])]
            if timed:
                best = min(timed, key=lambda r: r["sgm_time_all"])
                text = (f"overall {best['method']}, {sec(best['sgm_time_all'])} s "
                        f"{resting_on(best['n_common_all'], 'every method solved')}")
                a1_there = [r for r in timed if r["method"] in a1]
                if best["method"] not in a1 and a1_there:
                    b1 = min(a1_there, key=lambda r: r["sgm_time_all"])
                    text += (f" (fastest form there: {b1['method']} {sec(b1['sgm_time_all'])} s, "
                             f"{b1['sgm_time_all'] / best['sgm_time_all']:.1f}×)")
                parts.append(text)
            else:
                parts.append("no problem was solved by every method, so no overall comparison")
        fast.append(f"tol {tol:g}: " + "; ".join(parts))
    items.append(("Fastest", "(shifted geometric mean of wall time per run, each on its common solved set; "
                             "table 'Speed on common solved sets'):", fast))

    robust = []
    for tol in data.tols:
        at = [r for r in rows if r["tol"] == tol]
        top = max(r["solved"] for r in at)
        best = [r["method"] for r in at if r["solved"] == top]
        rest = ", ".join(f"{r['method']} {r['solved']}" for r in at if r["solved"] != top)
        robust.append(f"tol {tol:g}: {_names(best)} ({top}/{at[0]['total']} verified)"
                      + (f"; {rest}" if rest else "") + (f"; {resting_on(at[0]['total'])}"
                                                         if too_few(at[0]["total"]) else ""))
    items.append(("Most robust", "(verified solved runs per tolerance; table 'Robustness'):", robust))

    lim = double_limit_summary(data)
    if lim["rows"]:
        order = sorted(lim["rows"], key=lambda r: -(r["median_best_digits_v"] if r["median_best_digits_v"]
                                                    is not None else -1))
        per = [f"{r['method']}: {dig(r['median_best_digits_v'])} digits of v ({lim['target']} reached on "
               f"{r['reach_target']}/{lim['n_digits']}), best criterion {fmt(r['median_best_verified'], '.1e')}"
               for r in order]
        items.append(("How far double precision gets",
                      f"(each form run to {lim['tol']:g} with every iterate rechecked; median over problems of the "
                      f"best along the run — digits over the {lim['n_digits']} problems with a proven reference, "
                      f"criterion over {lim['n_problems']}; table 'How far double precision gets'):", per))
    cost = digits_cost(data)
    k = cost["digits"]
    if cost["n"]:
        if cost["n_certified"]:
            text = (f"{sec(cost['median_time'])} s" + (f" ({fmt(cost['median_ratio'], '.1f')}× the double solve)"
                                                         if cost["median_ratio"] is not None else ""))
            text += (f" — median over the {cost['n_certified']} of {cost['n']} problems proven to {k} digits of "
                     "v, u, Hr (and r where unique); time of the whole path (double solve to 1e-10, double-double "
                     "continuation and, where needed, the 320-bit tail; proof) in a fresh process; ratio = path time / the bench's jqinv solve at "
                     f"{fmt(cost['base_tol'], 'g')}, per problem (median of {cost['n_ratio']} ratios)")
        else:
            text = f"not measured: none of the {cost['n']} k-digit paths proved {k} digits"
        items.append((f"{k} proven digits cost", text))

    refuted = refuted_runs(data)
    by = {}
    for r in refuted:
        by[r["method"]] = by.get(r["method"], 0) + 1
    items.append(("Refuted claims:", f"{len(refuted)} run(s) whose solver said Solved or AlmostSolved failed the "
                                     "independent recheck at the tolerance claimed"
                  + (f" ({', '.join(f'{m} {n}' for m, n in by.items())})" if by else "") + "; table 'Refuted claims'",
                  [f"{g['method']}: {g['n']} × {g['label']}" for g in refuted_groups(data)]))
    fails = [r for r in data.solves if not r.get("solved")]
    text = (f"{len(fails)} of {len(data.solves)} counted runs not solved, {len(refuted)} of them refuted claims "
            "(tables 'Refuted claims' and 'Failures')")
    if diags:
        text += (f"; {len(diags)} Algorithm 1 run(s) diagnosed in lockstep (only Algorithm 1 can be replayed "
                 "step by step beside the exact reference, a peer's run cannot): "
                 + ", ".join(f"{c['problem']} {c['method']} at {c['tol']:g} ({c['why']})" for c, _ in diags))
    items.append(("Failures:", text))
    return items
