"""The report's text: number formatting shared by every table and the glance (one way to show
digits, seconds and missing values), and :class:`Doc`, which writes the same content as
Markdown (``summary.md``) and as HTML (``report.html``, with :data:`CSS`)."""

from __future__ import annotations

import base64
import html
import math
import warnings
from pathlib import Path

from .aggregates import DIGITS_CAP


def fmt(x, spec=".2f", none="–"):
    """A number in ``spec``; a missing one (None, NaN) as ``none``, a boolean as yes/no."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return none
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float) and math.isinf(x):
        return "∞"
    return format(x, spec)


def dig(x):
    """Digits for display: at ≥ 16 the two values are the same double (or closer)."""
    if x is not None and not (isinstance(x, float) and math.isnan(x)) and x >= DIGITS_CAP:
        return "16+"
    return fmt(x, ".1f")


def sec(x):
    """Seconds, the same text in the glance and in the tables (three significant digits)."""
    return fmt(x, ".3g")


FEW_PROBLEMS = 5
"""A ranking ("fastest", "most robust", "the best method") that rests on fewer problems than this
says it is too few to rank by."""


def counted(n: int, noun: str) -> str:
    """``n`` and ``noun`` in the number it takes: "1 problem", "21 problems"."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def problems(n: int) -> str:
    """``n`` problem(s), in words: "1 problem", "21 problems"."""
    return counted(n, "problem")


def resting_on(n: int, which: str = "") -> str:
    """What a ranking rests on: "on the 21 problems every form solved" (``which`` = "every form
    solved"), with ", too few to rank by" when ``n`` < :data:`FEW_PROBLEMS`."""
    text = f"on the {problems(n)}{f' {which}' if which else ''}"
    return text + (", too few to rank by" if too_few(n) else "")


def too_few(n: int) -> bool:
    """Whether a ranking on ``n`` problems must say it is too few to rank by."""
    return n < FEW_PROBLEMS


def _cell(c) -> str:
    """A table cell: booleans as words, a missing value as a dash."""
    if c is None:
        return "–"
    if isinstance(c, bool):
        return "yes" if c else "no"
    return str(c)


class Doc:
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

    def markdown(self) -> str:
        """``summary.md``."""
        return "\n".join(self.md) + "\n"

    def page(self, stamp: str) -> str:
        """``report.html``: the self-contained page (its figures embedded, it needs no other file),
        ``stamp`` (when it was generated) at its foot."""
        return (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>rfverify report</title>"
                f"<style>{CSS}</style></head><body>{''.join(self.html)}"
                f"<p style='color:#888;font-size:0.8em'>generated {stamp}</p></body></html>")

    def image(self, path: Path | None, alt: str):
        """A figure: Markdown links the PNG file beside it; the HTML page carries the PNG itself
        (a base64 ``data:`` URI), so that report.html stands alone when mailed or moved."""
        if path is None:
            return
        self.md.append(f"![{alt}]({path.name})\n")
        data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
        self.html.append(f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(alt)}">'
                         f"<figcaption>{html.escape(alt)}</figcaption></figure>")


CSS = """body{font-family:system-ui,sans-serif;max-width:1250px;margin:1.2em auto;padding:0 1em;color:#222;line-height:1.35}
h1{font-size:1.45em;margin:0.2em 0 0.4em}h2{font-size:1.2em;margin-top:1.6em;border-bottom:1px solid #ddd}
table{border-collapse:collapse;margin:0.6em 0 1.4em;font-size:0.85em}th,td{border:1px solid #ccc;padding:3px 7px;text-align:left}
th{background:#f0f0f0}td.n{white-space:nowrap}img{max-width:100%}figure{margin:1em 0}figcaption{font-size:0.85em;color:#555}
ul.glance{padding-left:1.2em}ul.glance>li{margin:0.35em 0}ul.glance ul{margin:0.15em 0}
p.context{font-size:0.85em;color:#444}details{margin:0.4em 0 1.2em}summary{cursor:pointer;color:#235}
code{background:#f5f5f5;padding:0 3px}"""


def add_figure(doc: Doc, alt: str, make, *args) -> None:
    """Draw a figure with its warnings recorded; a warning (an empty log axis, ...) becomes a
    note under the figure instead of text on stderr."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = make(*args)
    doc.image(path, alt)
    notes = sorted({" ".join(str(w.message).split()) for w in caught})
    if notes and path is not None:
        doc.p("Figure note: " + "; ".join(notes))


def short(text, n=110):
    """``text`` on one line, cut to ``n`` characters (an ellipsis marks the cut)."""
    text = " ".join(str(text).split())
    return text if len(text) <= n else text[: n - 1] + "…"

