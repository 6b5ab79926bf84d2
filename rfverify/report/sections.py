"""The sections of the report below its first screen (:mod:`.glance`), each written into a
:class:`~.document.Doc` from the numbers of :mod:`.aggregates`: the title and context, the
machine and missing records, robustness, refuted claims, speed on common solved sets, the
performance profiles, how far double precision gets, one hard problem per family, what k proven
digits cost, the lockstep diagnoses and the failures with their causes.
"""

from __future__ import annotations

import math
from pathlib import Path

from . import figures
from .aggregates import (SGM_SHIFT, digits_cost, double_limit, double_limit_summary, failures, hard_per_family,
                         mixed_precision, proven_by_method, refuted_groups)
from .data import RunData
from .document import Doc, add_figure, dig, fmt, sec, short


def title_section(doc: Doc, data: RunData, out: Path) -> None:
    """The title, a warning while a bench still runs, and what was benched."""
    doc.h(1, f"rfverify benchmark report — {out.resolve().name}")
    if data.running:
        doc.p("Warning: a bench is still running in this directory; this report shows the runs "
              "finished so far.")
    colls = {c: sum(p["collection"] == c for p in data.problems.values()) for c in data.collections}
    sizes = [p["n_contacts"] for p in data.problems.values()]
    if not data.solves:
        doc.p(f"{len(data.problems)} problems ({', '.join(f'{c}: {k}' for c, k in colls.items())}; "
              f"{min(sizes)}–{max(sizes)} contacts); the physical problem only (`bench --problem coulomb`: "
              "no runs of the convex relaxation in this directory).", cls="context")
        return
    doc.p(f"{len(data.problems)} problems ({', '.join(f'{c}: {k}' for c, k in colls.items())}; "
          f"{min(sizes)}–{max(sizes)} contacts); methods {', '.join(data.methods)}; tolerances "
          f"{', '.join(f'{t:g}' for t in data.tols)}. Solved means verified: the criterion of DESIGN §4.5 "
          "recomputed in 30-digit arithmetic from the saved solution meets the tolerance, never the "
          "solver's word.", cls="context")


def machine_section(doc: Doc, data: RunData) -> None:
    """The machine and libraries, the command that regenerates the run, and the records that are
    missing or damaged."""
    machine = data.manifest.get("machine", {})
    libraries = ", ".join(f"{name} {version}" for name, version in machine.items()
                          if name not in ("python", "platform", "cpus"))
    doc.p(f"Machine: {machine.get('platform', '?')}, {machine.get('cpus', '?')} CPUs, Python "
          f"{machine.get('python', '?')}{f' ({libraries})' if libraries else ''}, "
          f"{data.manifest.get('jobs', '?')} parallel job(s); times are "
          "wall-clock per run (compare ratios, not absolute values, on a shared machine). Medians are "
          "numpy's (mean of the two middle values) everywhere in this report. Correct digits of v are "
          "counted against the proven extended-precision point of each problem's k-digit path "
          "(DESIGN §6), capped at 16 (shown 16+).", cls="context")
    if data.manifest.get("command"):
        doc.p(f"Regenerate: {data.manifest['command']}", cls="context")

    if data.issues:
        doc.h(2, "Missing or damaged records")
        doc.p(f"{len(data.issues)} file(s) of this run directory are missing or cannot be read. A "
              "planned solve without a usable record is counted as a run that did not solve "
              "(status Missing or Damaged), so no method loses runs silently.")
        doc.bullets(data.issues)


def robustness_section(doc: Doc, data: RunData, table) -> None:
    """Solved (verified) per method and tolerance, all problems and per collection."""
    doc.h(2, "Robustness: solved per collection, method and tolerance")
    doc.p("solved = verified runs / runs. 'refuted claims' = runs whose solver itself said Solved (or "
          "AlmostSolved, by its own definition) and the independent recheck found the criterion above the "
          "tolerance that claim asserts. 'median digits of v' = over the runs of problems with a proven "
          "reference where v* is not ≈ 0 (n digits).")
    header = ["collection", "method", "tol", "solved", "refuted claims", "median digits of v", "n digits"]

    def robust_row(r):
        return [r["collection"], r["method"], f"{r['tol']:g}", f"{r['solved']}/{r['total']}", r["false_claims"],
                dig(r["median_digits_v"]), r["n_digits"]]

    doc.table(header, [robust_row(r) for r in table if r["collection"] == "all"])
    if len(data.collections) > 1:
        doc.table(header, [robust_row(r) for r in table if r["collection"] != "all"],
                  fold=f"Per collection ({', '.join(data.collections)})")


def refuted_section(doc: Doc, data: RunData) -> None:
    groups = refuted_groups(data)
    doc.h(2, "Refuted claims", anchor="refuted")
    doc.p(f"{sum(g['n'] for g in groups)} run(s) whose solver said Solved or AlmostSolved (by its own definition) "
          "and whose criterion, recomputed in 30-digit arithmetic from the saved answer, exceeds the tolerance "
          "that claim asserts. Grouped by method, claim and the measure that refuted it; each run is counted "
          "once, here, and not again among the failures.")
    doc.table(["method", "shown as", "runs", "problems", "tolerances", "examples"],
              [[g["method"], g["label"], g["n"], len(g["problems"]), ", ".join(f"{t:g}" for t in g["tols"]),
                "; ".join(f"{p} at {t:g}: {lab}" for p, t, lab in g["examples"])] for g in groups])


def speed_section(doc: Doc, data: RunData, table) -> None:
    doc.h(2, "Speed on common solved sets", anchor="speed")
    doc.p(f"Shifted geometric mean (shift {SGM_SHIFT} s) of the wall time per run, over two sets of problems per "
          "tolerance: those every Algorithm 1 form solved ('A1 common': Algorithm 1 forms only) and those every "
          "method solved ('all common'). Within a column every method is timed on the same problems; n = how many.")
    rows = [r for r in table if r["collection"] == "all"]
    for what, a1_key, all_key, show in (("time (s)", "sgm_time_a1", "sgm_time_all", sec),
                                        ("iterations", "sgm_iter_a1", "sgm_iter_all", lambda x: fmt(x, ".1f"))):
        header = ["method"]
        for tol in data.tols:
            at = [r for r in rows if r["tol"] == tol]
            header += [f"{tol:g} A1 common (n={at[0]['n_common_a1']})", f"{tol:g} all common (n={at[0]['n_common_all']})"]
        body = []
        for m in data.methods:
            line = [m]
            for tol in data.tols:
                r = next(r for r in rows if r["tol"] == tol and r["method"] == m)
                line += [show(r[a1_key]), show(r[all_key])]
            body.append(line)
        doc.p(f"SGM {what}, all problems:")
        doc.table(header, body)
    if len(data.collections) > 1:
        doc.table(["collection", "tol", "method", "A1 common n", "SGM time on A1 common (s)",
                   "SGM iterations on A1 common", "all common n", "SGM time on all common (s)",
                   "SGM iterations on all common"],
                  [[r["collection"], f"{r['tol']:g}", r["method"], r["n_common_a1"], sec(r["sgm_time_a1"]),
                    fmt(r["sgm_iter_a1"], ".1f"), r["n_common_all"], sec(r["sgm_time_all"]),
                    fmt(r["sgm_iter_all"], ".1f")]
                   for r in sorted(table, key=lambda r: (r["collection"], -r["tol"])) if r["collection"] != "all"],
                  fold=f"Per collection ({', '.join(data.collections)})")


def profiles_section(doc: Doc, data: RunData, out: Path) -> None:
    """Dolan–Moré profiles of time and of iterations."""
    doc.h(2, "Performance profiles")
    add_figure(doc, "Dolan–Moré profiles of run time per tolerance (all problems; a run not verified solved "
                    "never counts)", figures.profiles, data, out, "time")
    add_figure(doc, "Dolan–Moré profiles of iterations per tolerance", figures.profiles, data, out, "iterations")


def double_section(doc: Doc, data: RunData, out: Path) -> None:
    lim = double_limit_summary(data)
    tol = lim["tol"] if lim["tol"] is not None else data.manifest.get("trajectory_tol", 1e-14)
    doc.h(2, "How far double precision gets", anchor="double")
    doc.p(f"Each Algorithm 1 form run once more at tol {tol:g} with every iterate rechecked (the bench's "
          "trajectories). Per form: the best verified criterion along the run (median and worst over the "
          f"{lim['n_problems']} problems every form has a trajectory of) and the best correct digits of v "
          f"along the run (median and worst over the {lim['n_digits']} problems with a proven reference where "
          f"v* is not ≈ 0; 'reach {lim['target']}' counts those reaching {lim['target']} digits).")
    doc.table(["method", "median best verified criterion", "worst best verified criterion",
               "median best digits of v", "worst best digits of v", f"reach {lim['target']} digits"],
              [[r["method"], fmt(r["median_best_verified"], ".1e"), fmt(r["worst_best_verified"], ".1e"),
                dig(r["median_best_digits_v"]), dig(r["worst_best_digits_v"]),
                f"{r['reach_target']}/{lim['n_digits']}"] for r in lim["rows"]])
    if data.absolute_v:
        doc.p(f"{len(data.absolute_v)} problem(s) have v* ≈ 0 (the certificate judges v in the absolute "
              f"sense, DESIGN §6.3), so v has no relative digits there and they are left out of every "
              f"digits-of-v statistic: {', '.join(sorted(data.absolute_v))}.")
    add_figure(doc, "Correct digits of v against time: median over problems of the best digits reached by "
                    "each time (left) and share of problems reaching k digits (right)",
               figures.work_precision_aggregate, data, out)
    add_figure(doc, "Per problem: every iterate against elapsed time — correct digits of v where a proven "
                    "reference exists, otherwise −log10 of the verified criterion",
               figures.work_precision_problems, data, out, _wp_problems(data))
    rows = double_limit(data)
    doc.table(["problem", "method", "end status", "iterations", "best verified criterion", "best digits of v",
               "digits of v at end", "how it ended"],
              [[r["problem"], r["method"], r["status"], r["nit"], fmt(r["best_verified"], ".1e"),
                dig(r["best_digits_v"]), dig(r["final_digits_v"]), short(r["message"])] for r in rows],
              fold=f"Per problem and form ({len(rows)} trajectories)")


def hard_section(doc: Doc, data: RunData, out: Path) -> None:
    picks = hard_per_family(data)
    doc.h(2, "cond(Q_p) and λ2 per iteration, one hard problem per family", anchor="hard")
    doc.p("For each family of problems (a generated scene, else the collection), the problem whose jqinv "
          "trajectory reached the largest cond(Q_p); every iterate of that trajectory, solved or not. "
          "cond(Q_p) ≥ 1e15 leaves a double-precision step no correct digit; a λ2 at or below 1e-300 has "
          "underflowed (or lost its sign) in double while the exact one is positive.")
    if not picks:
        doc.p("No jqinv trajectory in this run (trajectories disabled, or jqinv not benched).")
        return
    add_figure(doc, "cond(Q_p) and the smallest λ2 per iteration, one representative hard problem per family",
               figures.hard_iterations, picks, out)
    doc.table(["family", "problem", "contacts", "iterations", "end status", "max cond(Q_p)", "min λ2"],
              [[p["family"], p["problem"], data.problems[p["problem"]]["n_contacts"],
                p["trajectory"].get("nit", len(p["trajectory"]["iterates"]) - 1),  # the iterates include the start
                p["trajectory"].get("status"), fmt(p["max_cond"], ".1e"),
                fmt(min((x for it in p["trajectory"]["iterates"] for x in (it.get("min_lam2_z"),
                                                                             it.get("min_lam2_s"))
                          if x is not None), default=None), ".1e")] for p in picks])


def digits_section(doc: Doc, data: RunData, proven: dict | None = None) -> None:
    cost = digits_cost(data)
    k = cost["digits"]
    doc.h(2, f"What {k} proven digits cost", anchor="digits")
    base = (f"the bench's double jqinv solve at {cost['base_tol']:g} (the loosest bench tolerance ≤ 1e-10)"
            if cost["base_tol"] is not None else "no double solve (the bench ran no tolerance ≤ 1e-10)")
    doc.p(f"rfverify solve --digits {k} (DESIGN §6.5): a double jqinv solve to 1e-10, Algorithm 1 continued in "
          f"double-double arithmetic from its last iterate (then in 320-bit arithmetic where double-double "
          f"stalls), and a rigorous error bound evaluated exactly, until "
          f"v, u, Hr (and r where unique) are proven to {k} digits. 'path time' is the whole of it (what the "
          f"proven digits cost) in the bench's fresh process per run, so it includes loading the compiled "
          f"double-double kernels once (numba's cache; a second path in the same process skips it); 'ratio' = "
          f"path time / {base}, per problem. Proven digits are lower bounds; "
          "'abs.' = x* ≈ 0, proven in the absolute sense against a data scale (DESIGN §6.3); 'info' = r is not "
          "unique, so not certified (information only).")
    if proven is not None:
        doc.h(3, "Proven digits of every answer")
        doc.p(f"Proven digits of every answer (DESIGN §6, evaluated exactly at the problem's proven point and "
              f"carried to the answer, as certify does with a stored point): {proven['n_proven']} of "
              f"{proven['n_runs']} saved answers, {sec(proven['seconds'])} s of proofs in all"
              + (f"; no proven point (k-digit path not certified or not run) on {len(proven['no_point'])} "
                 f"problem(s): {', '.join(proven['no_point'][:8])}" if proven["no_point"] else "") + ".")
        doc.table(["method", "answers", "with proven digits", f"≥ {k} digits", "median proven digits",
                   "best", f"median time of those ≥ {k} (s)"],
                  [[r["method"], r["runs"], r["n_proven"], r["reach"], dig(r["median_digits"]),
                    dig(r["best_digits"]), sec(r["median_time_reach"])] for r in proven_by_method(data)])
    rows = mixed_precision(data)
    if cost["n_certified"]:
        doc.p(f"Median over the {cost['n_certified']} of {cost['n']} problems proven to {k} digits: path time "
              f"{sec(cost['median_time'])} s; ratio {fmt(cost['median_ratio'], '.1f')}× (over {cost['n_ratio']} "
              f"with a double solve; its median time {sec(cost['median_base_time'])} s).")

    def dq(r, q):
        mode = r["modes"].get(q)
        if mode is None:
            return "–"
        return {"information": "info", "absolute": "abs."}.get(mode) or dig(r["digits"].get(q))

    doc.table(["problem", f"proven to {k}", "v", "u", "Hr", "r", "path time (s)", "double part (s)",
               "extended part (s)", "proof (s)", "double solve (s)", "ratio"],
              [[r["problem"], r["certified"] if r["status"] not in ("Timeout", "Crashed", "Error") else r["status"],
                dq(r, "v"), dq(r, "u"), dq(r, "Hr"), dq(r, "r"), sec(r["time_path"]), sec(r["time_double"]),
                sec(r["time_warm"]), sec(r["time_certify"]), sec(r["base_time"]), fmt(r["ratio"], ".1f")]
               for r in rows],
              fold=f"Per problem ({len(rows)} k-digit paths)")


def lockstep_section(doc: Doc, diags: list, out: Path) -> None:
    """Each diagnosed case (:func:`.lockstep.diagnose_worst`): why it was chosen, how, and its figure."""
    doc.h(2, "Per-iteration diagnostics, double against reference", anchor="lockstep")
    doc.p("Lockstep (DESIGN §5): from each double iterate the exact step (Algorithm 1 in double-double, "
          "the mpmath reference as witness on the deciding steps); digits of agreement measure the error of "
          "that iteration: rounding, and the solver's default inexact linear solves (refinement stops at "
          "residuals of 1e-4 of the right-hand side, so healthy iterations agree to 10–12 digits rather than "
          "15–16). For a run that missed its tolerance the same algorithm is continued in exact arithmetic "
          "from where the double steps departed: the cause is precision if it meets the tolerance within the "
          "run's iteration limit, iterations if later, the data if never; a remedy is tried. Failures first — "
          "refuted claims, then runs not solved — each diagnosed as the bench ran it (same method, settings, "
          "tolerance, iteration limit and components).")
    if not diags:
        doc.p("No run was selected (no Algorithm 1 run on a problem small enough for the lockstep reference).")
    for i, (case, diag) in enumerate(diags):
        doc.h(3, f"{case['problem']} — {case['method']} at {case['tol']:g}: {case['why']}")
        doc.p(f"How it was diagnosed: {diag['scope']['text']}.")
        if diag.get("conclusion"):
            doc.p(diag["conclusion"].replace("PROBLEM", case["problem"]))
        doc.p(diag_summary(diag))
        add_figure(doc, f"Lockstep diagnosis of {case['problem']} ({diag_title(case, diag)})",
                   figures.diagnostics, diag, case["problem"], out, i, diag_title(case, diag))


def failures_section(doc: Doc, data: RunData, diags: list) -> None:
    """Every run not solved whose solver did not claim it was, with its cause (and lockstep line)."""
    doc.h(2, "Failures and their diagnosed causes", anchor="failures")
    fails = failures(data)
    diag_by = {(c["problem"], c["method"], c["tol"]): d for c, d in diags if c["kind"] == "solve"}
    doc.p("Runs not verified solved whose solver did not claim they were (refuted claims are in 'Refuted "
          "claims', once).")
    doc.table(["problem", "method", "tol", "status", "cause"],
              [[f["problem"], f["method"], f"{f['tol']:g}", f["status"],
                f["cause"] + (f" — lockstep: {diag_summary(diag_by[(f['problem'], f['method'], f['tol'])])}"
                              if (f["problem"], f["method"], f["tol"]) in diag_by else "")]
               for f in fails])


def _wp_problems(data: RunData, count: int = 6) -> list:
    """The problems of the per-problem work-precision figure: the largest with a reference first."""
    with_ref = sorted((k for k in data.references if k not in data.absolute_v),
                      key=lambda k: -data.problems[k]["n_contacts"])
    rest = sorted((k for k in data.problems if k not in with_ref), key=lambda k: -data.problems[k]["n_contacts"])
    return (with_ref + rest)[:count]


def diag_title(case: dict, diag: dict) -> str:
    """What a lockstep figure shows: the run (trajectory or solve), its tolerance and its scope."""
    scope = diag.get("scope", {})
    where = (f", component {scope['index'] + 1} of {scope['count']}" if scope.get("mode") == "component"
             else ", unsplit" if scope.get("mode") == "unsplit" else "")
    kind = "trajectory, " if case["kind"] == "trajectory" else ""
    return f"{kind}{case['method']}, tol {case['tol']:g}{where}"


def diag_summary(diag: dict) -> str:
    """One line of a lockstep diagnosis: how it ended, the fewest digits of agreement, cond(Q_p), λ2."""
    its = diag["iterations"]
    if not its:
        return f"{diag['status']} after {diag['nit']} iterations (no step to compare)"
    finite = [r for r in its if r["digits_v"] is not None and not math.isnan(r["digits_v"])]
    conds = [r["max_cond_Qp"] for r in its if r["max_cond_Qp"] and math.isfinite(r["max_cond_Qp"])]
    flags = [(r["iter"] + 1, f) for r in its for f in r["flags"]]
    text = f"{diag['status']} after {diag['nit']} iterations"
    if finite:
        worst = min(finite, key=lambda r: r["digits_v"])
        shown = dig(worst["digits_v"]) if worst["digits_v"] > 0 else "none (error larger than v)"
        text += f"; fewest digits of agreement in v: {shown} at iteration {worst['iter'] + 1}"
    if conds:
        text += f"; max cond(Q_p) {max(conds):.1e}"
    if flags:
        text += f"; first λ2 event at iteration {flags[0][0]}: {flags[0][1]}"
    else:
        text += "; no λ2 underflow"
    if diag.get("failure"):
        text += f"; stop: {diag['failure']}"
    if diag.get("cause"):
        text += f"; cause: {diag['cause']}"
    return text


def coulomb_rows(data: RunData) -> list:
    """One summary per Coulomb record (:func:`rfverify.bench.coulomb.coulomb_summary`), in the
    order problem, rfverify's answers, then the peer's by decreasing tolerance."""
    from ..bench.coulomb import coulomb_summary

    rows = [coulomb_summary(r["problem"], r) for r in data.coulomb]
    return sorted(rows, key=lambda s: (s["problem"], s["method"] == "siconos", -(s["tol"] or 0)))


def coulomb_section(doc: Doc, data: RunData) -> None:
    """The physical problem (``bench --problem coulomb``), when the run directory holds it:
    per answer, certified or not, its proven backward error and digits, iterations and time."""
    rows = coulomb_rows(data)
    if not rows:
        return
    settings = data.manifest.get("coulomb") if isinstance(data.manifest.get("coulomb"), dict) else {}
    k = settings.get("digits") or next((r.get("digits") for r in data.coulomb if isinstance(r.get("digits"), int)), "K")
    doc.h(2, "The physical problem (--problem coulomb)", anchor="coulomb")
    ours = [r for r in rows if r["method"] != "siconos"]
    peer = [r for r in rows if r["method"] == "siconos"]
    answered = [r for r in peer if r["backward_error"] is not None]
    line = (f"Coulomb friction and rolling resistance with De Saxcé's term (u_N + μ‖u_T‖ + μr‖u_R‖ in the dual "
            f"cone), not the convex relaxation. Each answer is certified by a proven backward error: the exact "
            f"solution it names solves the physical problem exactly for data whose w_N differs from the file's "
            f"by δ, with |δ| ≤ the bound shown (relative to the data scale of u); physical solutions need not "
            f"be unique. Certified = {k} proven digits and a backward error ≤ 1e-{k}; proven digits '–': the "
            f"exact value may be 0, so it is bounded against its data scale instead (DESIGN §6.3). rfverify: "
            f"{sum(r['certified'] for r in ours)}/{len(ours)} certified.")
    if peer:
        line += (f" Siconos GFC3D_IPM (its own 3-D Coulomb IPM, De Saxcé's shift updated inside its iterations; "
                 f"its answers certified by rfverify): {len(answered)} of {len(peer)} runs answered and were "
                 f"proven, {sum(r['certified'] for r in peer)} certified; the others are listed with the reason.")
    doc.p(line)
    if settings.get("command"):
        doc.p(f"Regenerate: {settings['command']}", cls="context")

    def cells(r):
        digs = " ".join(f"{q} {'–' if d is None else f'{d:.1f}'}" for q, d in r["digits"].items())
        be = "–" if r["backward_error"] is None else f"{r['backward_error']:.1e}"
        verdict = "yes" if r["certified"] else ("no" if r["backward_error"] is not None else r["status"])
        return [r["problem"], r["solver"], verdict, be, digs or "–", r["outer"] or "–", sec(r["time"])]

    doc.table(["problem", "answer by", "certified", "backward error", "proven digits", "iterations", "time"],
              [cells(r) for r in rows])
    why = [f"{r['problem']}, {r['solver']}: {r['status']}: {short(r['why'], 200)}" for r in rows
           if r["backward_error"] is None]
    if why:
        doc.p("Without a proven backward error (not run, failed, or the proof did not hold):")
        doc.bullets(why)
