"""``rfverify report RUN_DIR``: ``report.html`` (self-contained page, PNG figures beside it) and
``summary.md`` from a bench run directory (:mod:`rfverify.bench`).

The first screen ("At a glance") has one figure — the proven digits of every answer of every
method against its time (:mod:`rfverify.report.proven`: the bound of DESIGN §6 at each problem's
proven point) — and answers which method reaches k proven digits, how fast, where double
precision breaks (the proven digits of the best double answer, and cond(Q_p) and λ₂ along the
trajectories) and what the k-digit path costs; then which method is fastest and most robust,
how far double precision gets per form, and the refuted claims, grouped — with numbers that
are those of the tables below it (one median, one shifted geometric mean, the same sets).

Counts come from the bench's independent high-precision recheck of each saved solution;
correct digits from the proven extended-precision point of each problem's k-digit path;
per-iteration diagnostics from a lockstep run (:func:`rfverify.diagnosis.diagnose`) of the
worst cases — failures first, each diagnosed as the bench ran it (components included,
:mod:`rfverify.report.lockstep`) — cached in ``RUN_DIR/diagnostics/``.
"""

from __future__ import annotations

import html
import json
import math
import warnings
from datetime import datetime, timezone
from pathlib import Path

from .._version import __version__
from ..bench.records import tol_text
from ..io.output import tag_floats, untag_floats, write_text_atomic
from . import figures
from .data import (DIGITS_CAP, SGM_SHIFT, RunData, algorithm1_methods, digits_cost, double_breaks, double_limit,
                   double_limit_summary, failures, hard_per_family, load_run, mixed_precision, proven_by_method,
                   refuted_groups, refuted_runs, success_table, worst_cases)
from .proven import prove_runs

__all__ = ["make_report", "load_run", "RunData"]

DIAGNOSIS_CACHE_VERSION = 2
"""Layout of a cached lockstep diagnosis (2: diagnosed as the bench ran it, with its scope)."""


def _fmt(x, spec=".2f", none="–"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return none
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float) and math.isinf(x):
        return "∞"
    return format(x, spec)


def _dig(x):
    """Digits for display: at ≥ 16 the two values are the same double (or closer)."""
    if x is not None and not (isinstance(x, float) and math.isnan(x)) and x >= DIGITS_CAP:
        return "16+"
    return _fmt(x, ".1f")


def _sec(x):
    """Seconds, the same text in the glance and in the tables (three significant digits)."""
    return _fmt(x, ".3g")


def _cell(c) -> str:
    """A table cell: booleans as words, a missing value as a dash."""
    if c is None:
        return "–"
    if isinstance(c, bool):
        return "yes" if c else "no"
    return str(c)


class _Doc:
    """Writes the same content as Markdown and as HTML."""

    def __init__(self):
        self.md: list[str] = []
        self.html: list[str] = []

    def h(self, level: int, text: str, anchor: str | None = None):
        self.md.append(f"{'#' * level} {text}\n")
        ident = f" id='{html.escape(anchor)}'" if anchor else ""
        self.html.append(f"<h{level}{ident}>{html.escape(text)}</h{level}>")

    def p(self, text: str, cls: str | None = None):
        self.md.append(text + "\n")
        attr = f" class='{cls}'" if cls else ""
        self.html.append(f"<p{attr}>{html.escape(text)}</p>")

    def bullets(self, items):
        """Items are text, or (lead, text) — the lead in bold — or (lead, text, [sub-items])."""
        md, out = [], []
        for item in items:
            lead, text, subs = (None, item, []) if isinstance(item, str) else (tuple(item) + ([],))[:3]
            md.append(f"- {f'**{lead}** ' if lead else ''}{text}")
            md += [f"  - {s}" for s in subs]
            sub_html = ("<ul>" + "".join(f"<li>{html.escape(s)}</li>" for s in subs) + "</ul>") if subs else ""
            out.append(f"<li>{f'<b>{html.escape(lead)}</b> ' if lead else ''}{html.escape(text)}{sub_html}</li>")
        self.md.append("\n".join(md) + "\n")
        self.html.append("<ul class='glance'>" + "".join(out) + "</ul>")

    def table(self, header, rows, fold: str | None = None):
        """A table; ``fold`` puts it (in HTML) inside a closed <details> with that summary."""
        if not rows:
            self.p("(none)")
            return
        rows = [[_cell(c) for c in r] for r in rows]
        self.md.append("| " + " | ".join(header) + " |")
        self.md.append("|" + "---|" * len(header))
        for r in rows:
            self.md.append("| " + " | ".join(c.replace("|", "\\|") for c in r) + " |")
        self.md.append("")
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td class='n'>{html.escape(c)}</td>" if len(c) <= 40
                                        else f"<td>{html.escape(c)}</td>" for c in r) + "</tr>" for r in rows)
        tab = f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
        if fold:
            tab = f"<details><summary>{html.escape(fold)}</summary>{tab}</details>"
        self.html.append(tab)

    def image(self, path: Path | None, alt: str):
        if path is None:
            return
        self.md.append(f"![{alt}]({path.name})\n")
        self.html.append(f'<figure><img src="{html.escape(path.name)}" alt="{html.escape(alt)}">'
                         f"<figcaption>{html.escape(alt)}</figcaption></figure>")


_CSS = """body{font-family:system-ui,sans-serif;max-width:1250px;margin:1.2em auto;padding:0 1em;color:#222;line-height:1.35}
h1{font-size:1.45em;margin:0.2em 0 0.4em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:0.6em 0 1.4em;font-size:0.85em}th,td{border:1px solid #ccc;padding:3px 7px;text-align:left}
th{background:#f0f0f0}td.n{white-space:nowrap}img{max-width:100%}figure{margin:1em 0}figcaption{font-size:0.85em;color:#555}
ul.glance{padding-left:1.2em}ul.glance>li{margin:0.35em 0}ul.glance ul{margin:0.15em 0}
p.context{font-size:0.85em;color:#444}details{margin:0.4em 0 1.2em}summary{cursor:pointer;color:#235}
code{background:#f5f5f5;padding:0 3px}"""


def make_report(run_dir, *, diagnose_count: int = 3, diagnose_max_contacts: int = 40,
                diagnose_dps: int = 40, quiet: bool = True) -> dict:
    """Write ``report.html``, ``summary.md`` and the PNG figures into ``run_dir``; returns a
    dict with their paths and the success counts."""
    data = load_run(run_dir)
    out = Path(run_dir)
    if not any(not r.get("_placeholder") for r in data.solves):
        from ..errors import BenchInputError

        first = data.issues[0].split("; fix:")[0] if data.issues else ""
        damage = f" ({len(data.issues)} records missing or damaged, e.g. {first})" if data.issues else ""
        raise BenchInputError(f"{out}: the run directory holds no usable finished solve runs yet"
                              f"{damage}; fix: run or re-run `rfverify bench ... --out {out}`")
    proven = prove_runs(data, quiet)
    diags = _diagnostics(data, diagnose_count, diagnose_max_contacts, diagnose_dps, quiet)
    table = success_table(data)

    doc = _Doc()
    doc.h(1, f"rfverify benchmark report — {out.resolve().name}")
    if data.running:
        doc.p("Warning: a bench is still running in this directory; this report shows the runs "
              "finished so far.")
    colls = {c: sum(p["collection"] == c for p in data.problems.values()) for c in data.collections}
    sizes = [p["n_contacts"] for p in data.problems.values()]
    doc.p(f"{len(data.problems)} problems ({', '.join(f'{c}: {k}' for c, k in colls.items())}; "
          f"{min(sizes)}–{max(sizes)} contacts); methods {', '.join(data.methods)}; tolerances "
          f"{', '.join(f'{t:g}' for t in data.tols)}. Solved means verified: the criterion of DESIGN §4.5 "
          "recomputed in 30-digit arithmetic from the saved solution meets the tolerance, never the "
          "solver's word.", cls="context")

    doc.h(2, "At a glance", anchor="glance")
    _figure(doc, "Proven digits against time: every answer of every method, proven at its problem's proven "
                 "point (DESIGN §6), and each problem's k-digit path", figures.proven_digits_time, data, out)
    doc.bullets(_answers(data, proven) + _glance(data, table, diags))

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

    doc.h(2, "Robustness: solved per collection, method and tolerance")
    doc.p("solved = verified runs / runs. 'refuted claims' = runs whose solver itself said Solved (or "
          "AlmostSolved, by its own definition) and the independent recheck found the criterion above the "
          "tolerance that claim asserts. 'median digits of v' = over the runs of problems with a proven "
          "reference where v* is not ≈ 0 (n digits).")
    header = ["collection", "method", "tol", "solved", "refuted claims", "median digits of v", "n digits"]

    def robust_row(r):
        return [r["collection"], r["method"], f"{r['tol']:g}", f"{r['solved']}/{r['total']}", r["false_claims"],
                _dig(r["median_digits_v"]), r["n_digits"]]

    doc.table(header, [robust_row(r) for r in table if r["collection"] == "all"])
    if len(data.collections) > 1:
        doc.table(header, [robust_row(r) for r in table if r["collection"] != "all"],
                  fold=f"Per collection ({', '.join(data.collections)})")

    _refuted_section(doc, data)
    _speed_section(doc, data, table)

    doc.h(2, "Performance profiles")
    _figure(doc, "Dolan–Moré profiles of run time per tolerance (all problems; a run not verified solved never "
                 "counts)", figures.profiles, data, out, "time")
    _figure(doc, "Dolan–Moré profiles of iterations per tolerance", figures.profiles, data, out, "iterations")

    _double_section(doc, data, out)
    _hard_section(doc, data, out)
    _digits_section(doc, data, proven)

    doc.h(2, "Per-iteration diagnostics, double against reference", anchor="lockstep")
    doc.p("Lockstep (DESIGN §5): from each double iterate the reference takes the exact step; digits of "
          "agreement measure the error of that iteration: rounding, and the solver's default inexact "
          "linear solves (refinement stops at residuals of 1e-4 of the right-hand side, so healthy "
          "iterations agree to 10–12 digits rather than 15–16). Failures first — refuted claims, then "
          "runs not solved — each diagnosed as the bench ran it (same method, settings, tolerance, "
          "iteration limit and components).")
    if not diags:
        doc.p("No run was selected (no Algorithm 1 run on a problem small enough for the lockstep reference).")
    for i, (case, diag) in enumerate(diags):
        doc.h(3, f"{case['problem']} — {case['method']} at {case['tol']:g}: {case['why']}")
        doc.p(f"How it was diagnosed: {diag['scope']['text']}.")
        doc.p(_diag_summary(diag))
        _figure(doc, f"Lockstep diagnosis of {case['problem']} ({_diag_title(case, diag)})", figures.diagnostics,
                diag, case["problem"], out, i, _diag_title(case, diag))

    doc.h(2, "Failures and their diagnosed causes", anchor="failures")
    fails = failures(data)
    diag_by = {(c["problem"], c["method"], c["tol"]): d for c, d in diags if c["kind"] == "solve"}
    doc.p("Runs not verified solved whose solver did not claim they were (refuted claims are in 'Refuted "
          "claims', once).")
    doc.table(["problem", "method", "tol", "status", "cause"],
              [[f["problem"], f["method"], f"{f['tol']:g}", f["status"],
                f["cause"] + (f" — lockstep: {_diag_summary(diag_by[(f['problem'], f['method'], f['tol'])])}"
                              if (f["problem"], f["method"], f["tol"]) in diag_by else "")]
               for f in fails])

    summary = out / "summary.md"
    write_text_atomic(summary, "\n".join(doc.md) + "\n")
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    page = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>rfverify report</title>"
            f"<style>{_CSS}</style></head><body>{''.join(doc.html)}"
            f"<p style='color:#888;font-size:0.8em'>generated {stamp}</p></body></html>")
    report = out / "report.html"
    write_text_atomic(report, page)
    counts = {(r["collection"], r["method"], r["tol"]): (r["solved"], r["total"]) for r in table}
    return {"report": str(report), "summary": str(summary), "counts": counts, "issues": list(data.issues),
            "running": data.running}


def _speed_section(doc: _Doc, data: RunData, table) -> None:
    doc.h(2, "Speed on common solved sets", anchor="speed")
    doc.p(f"Shifted geometric mean (shift {SGM_SHIFT} s) of the wall time per run, over two sets of problems per "
          "tolerance: those every Algorithm 1 form solved ('A1 common': Algorithm 1 forms only) and those every "
          "method solved ('all common'). Within a column every method is timed on the same problems; n = how many.")
    rows = [r for r in table if r["collection"] == "all"]
    for what, a1_key, all_key, fmt in (("time (s)", "sgm_time_a1", "sgm_time_all", _sec),
                                       ("iterations", "sgm_iter_a1", "sgm_iter_all", lambda x: _fmt(x, ".1f"))):
        header = ["method"]
        for tol in data.tols:
            at = [r for r in rows if r["tol"] == tol]
            header += [f"{tol:g} A1 common (n={at[0]['n_common_a1']})", f"{tol:g} all common (n={at[0]['n_common_all']})"]
        body = []
        for m in data.methods:
            line = [m]
            for tol in data.tols:
                r = next(r for r in rows if r["tol"] == tol and r["method"] == m)
                line += [fmt(r[a1_key]), fmt(r[all_key])]
            body.append(line)
        doc.p(f"SGM {what}, all problems:")
        doc.table(header, body)
    if len(data.collections) > 1:
        doc.table(["collection", "tol", "method", "A1 common n", "SGM time on A1 common (s)",
                   "SGM iterations on A1 common", "all common n", "SGM time on all common (s)",
                   "SGM iterations on all common"],
                  [[r["collection"], f"{r['tol']:g}", r["method"], r["n_common_a1"], _sec(r["sgm_time_a1"]),
                    _fmt(r["sgm_iter_a1"], ".1f"), r["n_common_all"], _sec(r["sgm_time_all"]),
                    _fmt(r["sgm_iter_all"], ".1f")]
                   for r in sorted(table, key=lambda r: (r["collection"], -r["tol"])) if r["collection"] != "all"],
                  fold=f"Per collection ({', '.join(data.collections)})")


def _double_section(doc: _Doc, data: RunData, out: Path) -> None:
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
              [[r["method"], _fmt(r["median_best_verified"], ".1e"), _fmt(r["worst_best_verified"], ".1e"),
                _dig(r["median_best_digits_v"]), _dig(r["worst_best_digits_v"]),
                f"{r['reach_target']}/{lim['n_digits']}"] for r in lim["rows"]])
    if data.absolute_v:
        doc.p(f"{len(data.absolute_v)} problem(s) have v* ≈ 0 (the certificate judges v in the absolute "
              f"sense, DESIGN §6.3), so v has no relative digits there and they are left out of every "
              f"digits-of-v statistic: {', '.join(sorted(data.absolute_v))}.")
    _figure(doc, "Correct digits of v against time: median over problems of the best digits reached by each "
                 "time (left) and share of problems reaching k digits (right)",
            figures.work_precision_aggregate, data, out)
    _figure(doc, "Per problem: every iterate against elapsed time — correct digits of v where a proven reference "
                 "exists, otherwise −log10 of the verified criterion",
            figures.work_precision_problems, data, out, _wp_problems(data))
    rows = double_limit(data)
    doc.table(["problem", "method", "end status", "iterations", "best verified criterion", "best digits of v",
               "digits of v at end", "how it ended"],
              [[r["problem"], r["method"], r["status"], r["nit"], _fmt(r["best_verified"], ".1e"),
                _dig(r["best_digits_v"]), _dig(r["final_digits_v"]), _short(r["message"])] for r in rows],
              fold=f"Per problem and form ({len(rows)} trajectories)")


def _refuted_section(doc: _Doc, data: RunData) -> None:
    groups = refuted_groups(data)
    doc.h(2, "Refuted claims", anchor="refuted")
    doc.p(f"{sum(g['n'] for g in groups)} run(s) whose solver said Solved or AlmostSolved (by its own definition) "
          "and whose criterion, recomputed in 30-digit arithmetic from the saved answer, exceeds the tolerance "
          "that claim asserts. Grouped by method, claim and the measure that refuted it; each run is counted "
          "once, here, and not again among the failures.")
    doc.table(["method", "shown as", "runs", "problems", "tolerances", "examples"],
              [[g["method"], g["label"], g["n"], len(g["problems"]), ", ".join(f"{t:g}" for t in g["tols"]),
                "; ".join(f"{p} at {t:g}: {lab}" for p, t, lab in g["examples"])] for g in groups])


def _hard_section(doc: _Doc, data: RunData, out: Path) -> None:
    picks = hard_per_family(data)
    doc.h(2, "cond(Q_p) and λ2 per iteration, one hard problem per family", anchor="hard")
    doc.p("For each family of problems (a generated scene, else the collection), the problem whose jqinv "
          "trajectory reached the largest cond(Q_p); every iterate of that trajectory, solved or not. "
          "cond(Q_p) ≥ 1e15 leaves a double-precision step no correct digit; a λ2 at or below 1e-300 has "
          "underflowed (or lost its sign) in double while the exact one is positive.")
    if not picks:
        doc.p("No jqinv trajectory in this run (trajectories disabled, or jqinv not benched).")
        return
    _figure(doc, "cond(Q_p) and the smallest λ2 per iteration, one representative hard problem per family",
            figures.hard_iterations, picks, out)
    doc.table(["family", "problem", "contacts", "iterations", "end status", "max cond(Q_p)", "min λ2"],
              [[p["family"], p["problem"], data.problems[p["problem"]]["n_contacts"],
                len(p["trajectory"]["iterates"]), p["trajectory"].get("status"), _fmt(p["max_cond"], ".1e"),
                _fmt(min((x for it in p["trajectory"]["iterates"] for x in (it.get("min_lam2_z"),
                                                                             it.get("min_lam2_s"))
                          if x is not None), default=None), ".1e")] for p in picks])


def _digits_section(doc: _Doc, data: RunData, proven: dict | None = None) -> None:
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
              f"{proven['n_runs']} saved answers, {_sec(proven['seconds'])} s of proofs in all"
              + (f"; no proven point (k-digit path not certified or not run) on {len(proven['no_point'])} "
                 f"problem(s): {', '.join(proven['no_point'][:8])}" if proven["no_point"] else "") + ".")
        doc.table(["method", "answers", "with proven digits", f"≥ {k} digits", "median proven digits",
                   "best", f"median time of those ≥ {k} (s)"],
                  [[r["method"], r["runs"], r["n_proven"], r["reach"], _dig(r["median_digits"]),
                    _dig(r["best_digits"]), _sec(r["median_time_reach"])] for r in proven_by_method(data)])
    rows = mixed_precision(data)
    if cost["n_certified"]:
        doc.p(f"Median over the {cost['n_certified']} of {cost['n']} problems proven to {k} digits: path time "
              f"{_sec(cost['median_time'])} s; ratio {_fmt(cost['median_ratio'], '.1f')}× (over {cost['n_ratio']} "
              f"with a double solve; its median time {_sec(cost['median_base_time'])} s).")

    def dq(r, q):
        mode = r["modes"].get(q)
        if mode is None:
            return "–"
        return {"information": "info", "absolute": "abs."}.get(mode) or _dig(r["digits"].get(q))

    doc.table(["problem", f"proven to {k}", "v", "u", "Hr", "r", "path time (s)", "double part (s)",
               "extended part (s)", "proof (s)", "double solve (s)", "ratio"],
              [[r["problem"], r["certified"] if r["status"] not in ("Timeout", "Crashed", "Error") else r["status"],
                dq(r, "v"), dq(r, "u"), dq(r, "Hr"), dq(r, "r"), _sec(r["time_path"]), _sec(r["time_double"]),
                _sec(r["time_warm"]), _sec(r["time_certify"]), _sec(r["base_time"]), _fmt(r["ratio"], ".1f")]
               for r in rows],
              fold=f"Per problem ({len(rows)} k-digit paths)")


def _figure(doc: _Doc, alt: str, make, *args) -> None:
    """Draw a figure with its warnings recorded; a warning (an empty log axis, ...) becomes a
    note under the figure instead of text on stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = make(*args)
    doc.image(path, alt)
    notes = sorted({" ".join(str(w.message).split()) for w in caught})
    if notes and path is not None:
        doc.p("Figure note: " + "; ".join(notes))


def _short(text, n=110):
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[: n - 1] + "…"


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
        items.append(("How fast:", "; ".join(f"{r['method']} {_sec(r['median_time_reach'])} s" for r in fast)
                      + f" (median wall time of the runs that reached {k} proven digits)"))
    br = double_breaks(data)
    if br["n"]:
        text = (f"the best double answer of each problem (any method, any tolerance) is proven to a median of "
                f"{_dig(br['median_best'])} digits (at most {_dig(br['max_best'])}; {br['reach']} of {br['n']} "
                f"problems reach {k})")
        if br["n_traj"]:
            text += (f"; along the jqinv trajectories to {_fmt(br['traj_tol'], 'g')}, the largest cond(Q_p) has a "
                     f"median of {_fmt(br['median_max_cond'], '.1e')} ({br['n_cond15']} of {br['n_traj']} reach "
                     f"1e15) and the smallest λ2 a median of {_fmt(br['median_min_lam2'], '.1e')} ({br['n_underflow']}"
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
            others = ", ".join(f"{r['method']} {_sec(r['sgm_time_a1'])} s" for r in timed_a1 if r is not best)
            parts.append(f"Algorithm 1 form {best['method']}, {_sec(best['sgm_time_a1'])} s on the "
                         f"{best['n_common_a1']} problems every form solved" + (f" ({others})" if others else ""))
        elif a1:
            parts.append("no problem was solved by every Algorithm 1 form")
        if set(data.methods) != set(a1):
            timed = [r for r in at.values() if not math.isnan(r["sgm_time_all"])]
            if timed:
                best = min(timed, key=lambda r: r["sgm_time_all"])
                text = (f"overall {best['method']}, {_sec(best['sgm_time_all'])} s on the "
                        f"{best['n_common_all']} problems every method solved")
                a1_there = [r for r in timed if r["method"] in a1]
                if best["method"] not in a1 and a1_there:
                    b1 = min(a1_there, key=lambda r: r["sgm_time_all"])
                    text += (f" (fastest form there: {b1['method']} {_sec(b1['sgm_time_all'])} s, "
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
                      + (f"; {rest}" if rest else ""))
    items.append(("Most robust", "(verified solved runs per tolerance; table 'Robustness'):", robust))

    lim = double_limit_summary(data)
    if lim["rows"]:
        order = sorted(lim["rows"], key=lambda r: -(r["median_best_digits_v"] if r["median_best_digits_v"]
                                                    is not None else -1))
        per = [f"{r['method']}: {_dig(r['median_best_digits_v'])} digits of v ({lim['target']} reached on "
               f"{r['reach_target']}/{lim['n_digits']}), best criterion {_fmt(r['median_best_verified'], '.1e')}"
               for r in order]
        items.append(("How far double precision gets",
                      f"(each form run to {lim['tol']:g} with every iterate rechecked; median over problems of the "
                      f"best along the run — digits over the {lim['n_digits']} problems with a proven reference, "
                      f"criterion over {lim['n_problems']}; table 'How far double precision gets'):", per))
    cost = digits_cost(data)
    k = cost["digits"]
    if cost["n"]:
        if cost["n_certified"]:
            text = (f"{_sec(cost['median_time'])} s" + (f" ({_fmt(cost['median_ratio'], '.1f')}× the double solve)"
                                                         if cost["median_ratio"] is not None else ""))
            text += (f" — median over the {cost['n_certified']} of {cost['n']} problems proven to {k} digits of "
                     "v, u, Hr (and r where unique); time of the whole path (double solve to 1e-10, double-double "
                     "continuation and, where needed, the 320-bit tail; proof) in a fresh process; ratio = path time / the bench's jqinv solve at "
                     f"{_fmt(cost['base_tol'], 'g')}, per problem (median of {cost['n_ratio']} ratios)")
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
        text += (f"; {len(diags)} diagnosed in lockstep: "
                 + ", ".join(f"{c['problem']} {c['method']} at {c['tol']:g} ({c['why']})" for c, _ in diags))
    items.append(("Failures:", text))
    return items


def _wp_problems(data: RunData, count: int = 6) -> list:
    with_ref = sorted((k for k in data.references if k not in data.absolute_v),
                      key=lambda k: -data.problems[k]["n_contacts"])
    rest = sorted((k for k in data.problems if k not in with_ref), key=lambda k: -data.problems[k]["n_contacts"])
    return (with_ref + rest)[:count]


def _diagnostics(data: RunData, count, max_contacts, dps, quiet) -> list:
    from ..bench.runner import resolve_spec
    from ..io import load
    from ..progress import Progress
    from .lockstep import diagnose_as_run

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
            problem = load(resolve_spec(data.problems[key]["spec"], data.run_dir))
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


def _diag_title(case: dict, diag: dict) -> str:
    scope = diag.get("scope", {})
    where = (f", component {scope['index'] + 1} of {scope['count']}" if scope.get("mode") == "component"
             else ", unsplit" if scope.get("mode") == "unsplit" else "")
    kind = "trajectory, " if case["kind"] == "trajectory" else ""
    return f"{kind}{case['method']}, tol {case['tol']:g}{where}"


def _diag_summary(diag: dict) -> str:
    its = diag["iterations"]
    if not its:
        return f"{diag['status']} after {diag['nit']} iterations (no step to compare)"
    finite = [r for r in its if r["digits_v"] is not None and not math.isnan(r["digits_v"])]
    conds = [r["max_cond_Qp"] for r in its if r["max_cond_Qp"] and math.isfinite(r["max_cond_Qp"])]
    flags = [(r["iter"] + 1, f) for r in its for f in r["flags"]]
    text = f"{diag['status']} after {diag['nit']} iterations"
    if finite:
        worst = min(finite, key=lambda r: r["digits_v"])
        shown = _dig(worst["digits_v"]) if worst["digits_v"] > 0 else "none (error larger than v)"
        text += f"; fewest digits of agreement in v: {shown} at iteration {worst['iter'] + 1}"
    if conds:
        text += f"; max cond(Q_p) {max(conds):.1e}"
    if flags:
        text += f"; first λ2 event at iteration {flags[0][0]}: {flags[0][1]}"
    else:
        text += "; no λ2 underflow"
    if diag.get("failure"):
        text += f"; stop: {diag['failure']}"
    return text
