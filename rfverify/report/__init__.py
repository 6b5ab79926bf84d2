"""``rfverify report RUN_DIR``: ``report.html`` (a self-contained page: its figures are embedded
in it) and ``summary.md`` (whose figures are the PNG files written beside it) from a bench run
directory (:mod:`rfverify.bench`).

The first screen ("At a glance") has one figure — the proven digits of every answer of every
method against its time (:mod:`rfverify.report.proven`: the bound of DESIGN §6 at each problem's
proven point) — and answers which method reaches k proven digits, how fast, where double
precision breaks (the proven digits of the best double answer, and cond(Q_p) and λ₂ along the
trajectories) and what the k-digit path costs; then which method is fastest and most robust,
how far double precision gets per form, and the refuted claims, grouped — with numbers that
are those of the tables below it (one median, one shifted geometric mean, the same sets).

A run directory that holds ``bench --problem coulomb`` records also gets a section on the
physical problem (:func:`.sections.coulomb_section`): per problem, rfverify's and Siconos
GFC3D_IPM's answers, certified or not, their proven backward errors and proven digits, right
after the first screen; one that holds only those gets a report of that section alone.

Counts come from the bench's independent high-precision recheck of each saved solution;
correct digits from the proven extended-precision point of each problem's k-digit path;
per-iteration diagnostics from a lockstep run (:func:`rfverify.verify.diagnosis.diagnose`) of the
worst cases — failures first, each diagnosed as the bench ran it (components included,
:mod:`rfverify.report.lockstep`) — cached in ``RUN_DIR/diagnostics/``.

By job: :mod:`.data` reads the run directory, :mod:`.aggregates` derives every number shown,
:mod:`.proven` proves the digits of every answer, :mod:`.lockstep` diagnoses the worst cases,
:mod:`.figures` draws, :mod:`.document` writes Markdown and HTML, :mod:`.glance` the first
screen and :mod:`.sections` the rest; :func:`make_report` puts them in order.
"""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path

from ..io.output import write_text_atomic
from . import sections
from .aggregates import success_table
from .data import RunData, load_run
from .document import Doc
from .glance import glance_section
from .lockstep import DIAGNOSIS_CACHE_VERSION, diagnose_worst  # noqa: F401  (its old home)
from .proven import prove_runs

__all__ = ["make_report", "load_run", "RunData"]


def make_report(run_dir, *, diagnose_count: int = 3, diagnose_max_contacts: int = 40,
                diagnose_dps: int = 40, quiet: bool = True) -> dict:
    """Write ``report.html``, ``summary.md`` and the PNG figures into ``run_dir``; returns a
    dict with their paths and the success counts."""
    data = load_run(run_dir)
    out = Path(run_dir)
    if data.coulomb and not data.solves:  # bench --problem coulomb only: its section alone
        return _coulomb_only(data, out)
    if not any(not r.get("_placeholder") for r in data.solves):
        from ..errors import BenchInputError

        first = data.issues[0].split("; fix:")[0] if data.issues else ""
        damage = f" ({len(data.issues)} records missing or damaged, e.g. {first})" if data.issues else ""
        raise BenchInputError(f"{out}: the run directory holds no usable finished solve runs yet"
                              f"{damage}; fix: run or re-run `rfverify bench ... --out {out}`")
    proven = prove_runs(data, quiet)
    diags = diagnose_worst(data, diagnose_count, diagnose_max_contacts, diagnose_dps, quiet)
    table = success_table(data)
    doc = Doc()
    sections.title_section(doc, data, out)
    glance_section(doc, data, out, proven, table, diags)
    sections.coulomb_section(doc, data)
    sections.machine_section(doc, data)
    sections.robustness_section(doc, data, table)
    sections.refuted_section(doc, data)
    sections.speed_section(doc, data, table)
    sections.profiles_section(doc, data, out)
    sections.double_section(doc, data, out)
    sections.hard_section(doc, data, out)
    sections.digits_section(doc, data, proven)
    sections.lockstep_section(doc, diags, out)
    sections.failures_section(doc, data, diags)

    counts = {(r["collection"], r["method"], r["tol"]): (r["solved"], r["total"]) for r in table}
    return _write(doc, data, out, counts)


def _write(doc: Doc, data: RunData, out: Path, counts: dict) -> dict:
    summary = out / "summary.md"
    write_text_atomic(summary, doc.markdown())
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    report = out / "report.html"
    write_text_atomic(report, doc.page(stamp))
    return {"report": str(report), "summary": str(summary), "counts": counts, "issues": list(data.issues),
            "running": data.running, "coulomb": sections.coulomb_rows(data)}


def _coulomb_only(data: RunData, out: Path) -> dict:
    """The report of a run directory with Coulomb records and no relaxation runs."""
    doc = Doc()
    sections.title_section(doc, data, out)
    sections.coulomb_section(doc, data)
    sections.machine_section(doc, data)
    return _write(doc, data, out, {})
