"""Issue 14 item 3, layering: the method names are declared once."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_method_names_are_declared_once():
    """METHODS in rfverify/solver/result.py is the one list of method names; the rest derive from it."""
    from rfverify.bench.runner import DEFAULT_METHODS
    from rfverify.report.data import RunData
    from rfverify.solver.result import ALGORITHM1_METHODS, METHODS, PEER_METHODS

    assert METHODS == ALGORITHM1_METHODS + PEER_METHODS
    assert set(DEFAULT_METHODS) < set(METHODS)
    data = RunData(Path("."), {}, {}, solves=[{"method": m} for m in reversed(METHODS)])
    assert data.methods == list(METHODS)
    from rfverify.report.figures import _LINE, _STYLE  # per-method styles: one for every method

    assert set(METHODS) <= set(_STYLE) and set(METHODS) <= set(_LINE)
    # No other source spells out a list of three or more method names.
    listing = re.compile(r"""[\[(]\s*(["'](%s)["']\s*,\s*){2,}""" % "|".join(METHODS))
    where = [p.relative_to(ROOT).as_posix() for d in ("rfverify", "benchmarks")
             for p in sorted((ROOT / d).rglob("*.py")) if listing.search(p.read_text(encoding="utf-8"))]
    assert where == ["rfverify/solver/result.py"]
