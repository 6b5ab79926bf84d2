"""``rfverify report RUN_DIR``: ``report.html`` (self-contained page, PNG figures beside it) and
``summary.md`` from a bench run directory (:mod:`rfverify.bench`).

Counts come from the bench's independent high-precision recheck of each saved solution;
forward errors from the certified reference solution of each problem small enough to have
one; per-iteration diagnostics from a lockstep run (:func:`rfverify.diagnosis.diagnose`) of
the worst cases, cached in ``RUN_DIR/diagnostics/``.
"""

from __future__ import annotations

import html
import json
import math
import warnings
from datetime import datetime, timezone
from pathlib import Path

from .. import __version__
from ..bench.tasks import tol_text
from ..io.output import tag_floats, untag_floats, write_text_atomic
from . import figures
from .data import (SGM_SHIFT, RunData, double_limit, failures, load_run, mixed_precision,
                   success_table, worst_cases)

__all__ = ["make_report", "load_run", "RunData"]


def _fmt(x, spec=".2f", none="–"):
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return none
    if isinstance(x, float) and math.isinf(x):
        return "∞"
    return format(x, spec)


def _dig(x):
    """Digits for display: at ≥ 16 the two values are the same double (or closer)."""
    if x is not None and not (isinstance(x, float) and math.isnan(x)) and x >= 16:
        return "16+"
    return _fmt(x, ".1f")


class _Doc:
    """Writes the same content as Markdown and as HTML."""

    def __init__(self):
        self.md: list[str] = []
        self.html: list[str] = []

    def h(self, level: int, text: str):
        self.md.append(f"{'#' * level} {text}\n")
        self.html.append(f"<h{level}>{html.escape(text)}</h{level}>")

    def p(self, text: str):
        self.md.append(text + "\n")
        self.html.append(f"<p>{html.escape(text)}</p>")

    def bullets(self, items):
        self.md.append("\n".join(f"- {i}" for i in items) + "\n")
        self.html.append("<ul>" + "".join(f"<li>{html.escape(i)}</li>" for i in items) + "</ul>")

    def table(self, header, rows):
        if not rows:
            self.p("(none)")
            return
        self.md.append("| " + " | ".join(header) + " |")
        self.md.append("|" + "---|" * len(header))
        for r in rows:
            self.md.append("| " + " | ".join(str(c).replace("|", "\\|") for c in r) + " |")
        self.md.append("")
        head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
        body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
        self.html.append(f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>")

    def image(self, path: Path | None, alt: str):
        if path is None:
            return
        self.md.append(f"![{alt}]({path.name})\n")
        self.html.append(f'<figure><img src="{html.escape(path.name)}" alt="{html.escape(alt)}">'
                         f"<figcaption>{html.escape(alt)}</figcaption></figure>")


_CSS = """body{font-family:system-ui,sans-serif;max-width:1250px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:0.6em 0 1.4em;font-size:0.85em}th,td{border:1px solid #ccc;padding:3px 7px;text-align:left}
th{background:#f0f0f0}img{max-width:100%}figure{margin:1em 0}figcaption{font-size:0.85em;color:#555}
code{background:#f5f5f5;padding:0 3px}"""


def make_report(run_dir, *, diagnose_count: int = 3, diagnose_max_contacts: int = 40,
                diagnose_dps: int = 40, quiet: bool = True) -> dict:
    """Write ``report.html``, ``summary.md`` and the PNG figures into ``run_dir``; returns a
    dict with their paths and the success counts."""
    data = load_run(run_dir)
    out = Path(run_dir)
    if not any(not r.get("_placeholder") for r in data.solves):
        from ..bench.runner import BenchInputError

        first = data.issues[0].split("; fix:")[0] if data.issues else ""
        damage = f" ({len(data.issues)} records missing or damaged, e.g. {first})" if data.issues else ""
        raise BenchInputError(f"{out}: the run directory holds no usable finished solve runs yet"
                              f"{damage}; fix: run or re-run `rfverify bench ... --out {out}`")
    diags = _diagnostics(data, diagnose_count, diagnose_max_contacts, diagnose_dps, quiet)

    doc = _Doc()
    doc.h(1, f"rfverify benchmark report — {out.resolve().name}")
    if data.running:
        doc.p("Warning: a bench is still running in this directory; this report shows the runs "
              "finished so far.")
    if data.issues:
        doc.h(2, "Missing or damaged records")
        doc.p(f"{len(data.issues)} file(s) of this run directory are missing or cannot be read. A "
              "planned solve without a usable record is counted as a run that did not solve "
              "(status Missing or Damaged), so no method loses runs silently.")
        doc.bullets(data.issues)
    machine = data.manifest.get("machine", {})
    colls = {c: sum(p["collection"] == c for p in data.problems.values()) for c in data.collections}
    sizes = [p["n_contacts"] for p in data.problems.values()]
    doc.p(f"{len(data.problems)} problems ({', '.join(f'{c}: {k}' for c, k in colls.items())}; "
          f"{min(sizes)}–{max(sizes)} contacts), methods {', '.join(data.methods)}, tolerances "
          f"{', '.join(f'{t:g}' for t in data.tols)}. Machine: {machine.get('platform', '?')}, "
          f"{machine.get('cpus', '?')} CPUs, Python {machine.get('python', '?')}, "
          f"{data.manifest.get('jobs', '?')} parallel job(s) (times are wall-clock per run; compare "
          "ratios, not absolute values, on a shared machine).")
    doc.p("A run counts as solved only when an independent recomputation of the stopping criterion "
          "max(dinfeas, velocity, μ = |uᵀr|/n, cone violation) in 30-digit arithmetic from the saved "
          "solution meets the tolerance — never on the solver's word. Correct digits of v are against "
          "the certified reference solution (independent mpmath run) where the problem is small enough "
          "to have one.")
    if data.manifest.get("command"):
        doc.p(f"Regenerate: {data.manifest['command']}")

    table = success_table(data)
    doc.h(2, "At a glance")
    doc.bullets(_glance(data, table))

    doc.h(2, "Performance profiles")
    _figure(doc, "Dolan–Moré profiles of run time per tolerance", figures.profiles, data, out, "time")
    _figure(doc, "Dolan–Moré profiles of iterations per tolerance", figures.profiles, data, out, "iterations")

    doc.h(2, "Success per collection, method and tolerance")
    doc.p(f"solved = verified runs / runs. Times are shifted geometric means (shift {SGM_SHIFT} s) over "
          "the problems every method solved at that tolerance (n common), so methods are compared "
          "on the same problems. 'false claims' = runs whose solver itself said Solved (or AlmostSolved, by its "
          "own definition) and the independent recheck refuted it.")
    doc.table(["collection", "method", "tol", "solved", "SGM time (s)", "n common", "SGM iterations",
               "median digits of v", "false claims"],
              [[r["collection"], r["method"], f"{r['tol']:g}", f"{r['solved']}/{r['total']}",
                _fmt(r["sgm_time_common"], ".4f"), r["n_common"], _fmt(r["sgm_iter_common"], ".1f"),
                _dig(r["median_digits_v"]), r["false_claims"]] for r in table])

    doc.h(2, "Error against run time")
    _figure(doc, "Correct digits of v against elapsed time (left) and share of problems reaching k "
                 "digits (right)", figures.work_precision_aggregate, data, out)
    wp_keys = _wp_problems(data)
    _figure(doc, "Per problem: verified error of every iterate against elapsed time",
            figures.work_precision_problems, data, out, wp_keys)

    doc.h(2, "How far double precision gets")
    doc.p(f"Each Algorithm 1 method run at tol {data.manifest.get('trajectory_tol', 1e-14):g} with every "
          "iterate rechecked: the best verified criterion and the best digits of v along the run.")
    doc.table(["problem", "method", "end status", "iterations", "best verified criterion", "best digits of v",
               "digits of v at end", "how it ended"],
              [[r["problem"], r["method"], r["status"], r["nit"], _fmt(r["best_verified"], ".1e"),
                _dig(r["best_digits_v"]), _dig(r["final_digits_v"]), _short(r["message"])]
               for r in double_limit(data)])

    doc.h(2, "The mixed-precision path")
    doc.p("rfverify solve --digits K: the double jqinv solve at 1e-10, warm mpmath iterations, then an "
          "independent reference run certifies it. 'path time' excludes the certificate; 'per digit' = "
          "(path time − double time) / (digits of v gained over the double run).")
    doc.table(["problem", "certified", "min certified digits", "digits of v", "path time (s)",
               "certificate time (s)", "double run digits of v", "double time (s)", "s per extra digit"],
              [[r["problem"], r["certified"], _dig(r["digits_min"]), _dig(r["digits_v"]),
                _fmt(r["time_path"], ".2f"), _fmt(r["time_certify"], ".2f"), _dig(r["double_digits_v"]),
                _fmt(r["double_time"], ".3f"), _fmt(r["per_digit"], ".3f")] for r in mixed_precision(data)])

    doc.h(2, "Per-iteration diagnostics, double against reference")
    if not diags:
        doc.p("No problem was selected (none small enough for the lockstep reference).")
    for i, (key, method, tol, diag) in enumerate(diags):
        doc.h(3, f"{key} — {method} at {tol:g}")
        doc.p(_diag_summary(diag))
        _figure(doc, f"Lockstep diagnosis of {key} ({method}, tol {tol:g})", figures.diagnostics,
                diag, key, out, i)

    doc.h(2, "Failures and their diagnosed causes")
    fails = failures(data)
    diag_by = {(k, m, t): d for k, m, t, d in diags}
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


def _glance(data: RunData, table) -> list[str]:
    lines = []
    if data.issues:
        lines.append(f"{len(data.issues)} record(s) or array file(s) missing or damaged: planned solves "
                     "without a usable record count as not solved (see 'Missing or damaged records')")
    rows = [r for r in table if r["collection"] == "all"]
    for tol in data.tols:
        at = [r for r in rows if r["tol"] == tol]
        timed = [r for r in at if not math.isnan(r["sgm_time_common"])]
        best_solved = max(r["solved"] for r in at)
        robust = [r["method"] for r in at if r["solved"] == best_solved]
        line = (f"tol {tol:g}: most robust {', '.join(robust)} ({best_solved}/{at[0]['total']} verified)")
        if timed:
            fastest = min(timed, key=lambda r: r["sgm_time_common"])
            line += (f"; fastest {fastest['method']} (SGM {fastest['sgm_time_common']:.4f} s over "
                     f"{fastest['n_common']} common problems")
            peer = next((r for r in timed if r["method"] == "clarabel"), None)
            if peer and fastest["method"] != "clarabel" and peer["sgm_time_common"] > 0:
                line += f", {fastest['sgm_time_common'] / peer['sgm_time_common']:.2f}× Clarabel's"
            jq = next((r for r in timed if r["method"] == "jqinv"), None)
            if jq and peer and jq is not fastest:
                line += f"; jqinv {jq['sgm_time_common'] / peer['sgm_time_common']:.2f}× Clarabel's"
            line += ")"
        else:
            line += "; no problem was solved by every method, so no common-set timing"
        lines.append(line)
    lim = [r for r in double_limit(data) if r["method"] == "jqinv" and r["best_digits_v"] is not None]
    if lim:
        best = sorted(r["best_digits_v"] for r in lim)
        lines.append(f"Double precision (jqinv, every iterate checked): best digits of v median "
                     f"{best[len(best) // 2]:.1f}, worst {best[0]:.1f} over {len(best)} problems with a reference")
    tight = min(data.tols) if data.tols else None
    at_tight = [r for r in data.solves if r["method"] == "jqinv" and r["tol"] == tight and r.get("digits_v") is not None]
    if at_tight:
        d = sorted(r["digits_v"] for r in at_tight)
        lines.append(f"jqinv stopped at {tight:g} gives median {d[len(d) // 2]:.1f}, worst {d[0]:.1f} "
                     "correct digits of v")
    mp = mixed_precision(data)
    if mp:
        cert = [r for r in mp if r["certified"]]
        per = sorted(r["per_digit"] for r in mp if r["per_digit"] is not None)
        msg = f"Mixed-precision path: {len(cert)}/{len(mp)} problems certified to {data.manifest.get('digits', 10)} digits"
        if per:
            msg += f"; it costs a median {per[len(per) // 2]:.3f} s per extra digit of v over the double run"
        lines.append(msg)
    claims = sum(r["false_claims"] for r in rows)
    lines.append(f"Solver claims (Solved, or AlmostSolved by the solver's own definition) refuted by the recheck: {claims}")
    return lines


def _wp_problems(data: RunData, count: int = 6) -> list:
    with_ref = sorted(data.references, key=lambda k: -data.problems[k]["n_contacts"])
    rest = sorted((k for k in data.problems if k not in data.references),
                  key=lambda k: -data.problems[k]["n_contacts"])
    return (with_ref + rest)[:count]


def _diagnostics(data: RunData, count, max_contacts, dps, quiet) -> list:
    from ..bench.runner import resolve_spec
    from ..diagnosis import diagnose
    from ..io import load
    from ..progress import Progress

    chosen = worst_cases(data, count, max_contacts)
    cache = data.run_dir / "diagnostics"
    if chosen:
        cache.mkdir(exist_ok=True)
    out = []
    bar = Progress(len(chosen), "report: lockstep diagnosis", quiet=quiet)
    for key, method, tol in chosen:
        sha = data.problems[key]["sha256"]
        path = cache / f"{key.replace('/', '__')}__{method}@{tol_text(tol)}.json"
        diag = None
        if path.exists():
            try:
                cached = untag_floats(json.loads(path.read_text(encoding="utf-8")))
            except (OSError, ValueError):
                cached = None  # a damaged cache entry is recomputed
            if isinstance(cached, dict) and cached.get("sha256") == sha and cached.get("dps") == dps \
                    and cached.get("version") == __version__:
                diag = cached
        if diag is None:
            problem = load(resolve_spec(data.problems[key]["spec"], data.run_dir))
            with warnings.catch_warnings(record=True):
                warnings.simplefilter("always")  # the double run's warnings: not for stderr
                diag = diagnose(problem, method=method, tol=tol, dps=dps)
            diag.update(sha256=sha, dps=dps, tol=tol, problem=key, version=__version__)
            # Tagged, so NaN/inf survive strict JSON (null would lose which one it was).
            write_text_atomic(path, json.dumps(tag_floats(diag), indent=1, allow_nan=False, default=float))
        out.append((key, method, tol, diag))
        bar.advance(key)
    bar.close()
    return out


def _diag_summary(diag: dict) -> str:
    its = diag["iterations"]
    if not its:
        return f"{diag['status']} after {diag['nit']} iterations (no step to compare)"
    worst = min(its, key=lambda r: r["digits_v"])
    conds = [r["max_cond_Qp"] for r in its if r["max_cond_Qp"] and math.isfinite(r["max_cond_Qp"])]
    flags = [(r["iter"] + 1, f) for r in its for f in r["flags"]]
    text = (f"{diag['status']} after {diag['nit']} iterations; fewest digits of agreement in v: "
            f"{worst['digits_v']:.1f} at iteration {worst['iter'] + 1}")
    if conds:
        text += f"; max cond(Q_p) {max(conds):.1e}"
    if flags:
        text += f"; first λ2 event at iteration {flags[0][0]}: {flags[0][1]}"
    else:
        text += "; no λ2 underflow"
    if diag.get("failure"):
        text += f"; stop: {diag['failure']}"
    return text
