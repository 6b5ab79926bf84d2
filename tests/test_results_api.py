"""Result objects in the ecosystem's conventions: statuses compare with their printed names
and reprs fit in a few lines (no array dumps)."""

from __future__ import annotations

import pytest

import rfverify
from rfverify.solver.result import Status


def _short(text: str) -> bool:
    return text.count("\n") <= 3 and len(text) <= 400 and "array(" not in text


def test_status_equals_its_printed_name():
    res = rfverify.solve(rfverify.load("bundled:chute"))
    assert res.status == "Solved" and str(res.status) == "Solved" and f"{res.status}" == "Solved"
    assert res.status is Status.SOLVED and res.status != "AlmostSolved"
    assert {s.value for s in Status} >= {"Solved", "AlmostSolved", "MaxIterations", "NumericalError"}
    assert _short(repr(res))


def test_digits_solution_and_certificate_are_typed_and_short():
    out = rfverify.solve_to_digits(rfverify.load("bundled:chute"), digits=10)
    assert out.status == "Certified" and out.message.startswith("proven to 10 digits")
    assert out.nit == out.double.nit + out.extended.nit
    assert _short(repr(out)) and _short(repr(out.certificate))
    assert out.certificate.status == "Certified" and out.certificate.message == out.certificate.verdict


def test_aliases_agree_with_the_fields_they_name():
    """Clarabel's ``iterations``/``solve_time`` and SciPy's ``success`` are the same numbers as
    ``nit``/``timings["total"]``/the status, on every result that has them (docs/RESULTS.md)."""
    p = rfverify.load("bundled:chute")
    res = rfverify.solve(p)
    cert = rfverify.certify(p, res, digits=6)
    diag = rfverify.diagnose(rfverify.load("bundled:sphere"), max_iter=3)
    ten = rfverify.solve_to_digits(p, digits=10)
    for obj in (res, cert, diag, ten):
        assert obj.iterations == obj.nit and isinstance(obj.nit, int)
        assert obj.solve_time == obj.timings["total"] > 0
        assert obj.success == (obj.status in ("Solved", "Certified"))
        assert isinstance(obj.message, str) and obj.message
        assert _short(repr(obj)), repr(obj)
    assert res.success and res["nit"] == res.nit
    assert cert.success is cert.certified


def test_diagnosis_is_typed_and_its_dict_is_the_cli_json():
    import json

    diag = rfverify.diagnose(rfverify.load("bundled:sphere"), max_iter=3)
    assert diag.status == "MaxIterations" and not diag.success and diag.nit == 3 == len(diag.steps)
    assert diag.failure == diag.message
    assert set(diag.timings) == {"double", "setup", "steps", "exact", "witness", "remedies", "total"}
    assert diag.cause == "iterations" and diag.remedy["status"] == "Solved" and diag["cause"] == diag.cause
    d = json.loads(json.dumps(diag.to_dict()))
    # (a local file has no v: its digits_v is NaN, which == cannot compare)
    assert d["status"] == "MaxIterations" and d["nit"] == 3 and json.dumps(d["iterations"]) == json.dumps(diag.steps)
    assert repr(diag).startswith("Diagnosis(method='jqinv', status=MaxIterations, nit=3, cause='iterations'")
    assert d["cause"] == "iterations" and d["remedy"] == diag.remedy and d["evidence"]["text"]


def _results_table():
    """docs/RESULTS.md's table: {field: {class name: cell text}}."""
    from pathlib import Path

    text = (Path(__file__).resolve().parent.parent / "docs" / "RESULTS.md").read_text(encoding="utf-8")
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    head = [c.strip() for c in rows[0].strip("|").split("|")]
    classes = [c.split()[0].strip("`") for c in head[1:5]]
    table = {}
    for line in rows[1:]:  # (the |---| line is not among them)
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        table[cells[0]] = dict(zip(classes, cells[1:5]))
    return table


def test_docs_results_table_matches_the_code():
    import re

    p = rfverify.load("bundled:chute")
    objs = {"SolveResult": rfverify.solve(p), "DigitsSolution": rfverify.solve_to_digits(p, digits=6),
            "Certificate": None, "Diagnosis": rfverify.diagnose(rfverify.load("bundled:sphere"), max_iter=3)}
    objs["Certificate"] = rfverify.certify(p, objs["SolveResult"], digits=6)
    table = _results_table()
    # every field named as `name` in its own row exists on every result whose cell is not "—"
    for field, cells in table.items():
        name = re.fullmatch(r"`(\w+)`", field)
        if not name:
            continue
        for cls, cell in cells.items():
            if cell != "—":
                assert hasattr(objs[cls], name.group(1)), (cls, field)
    for cls, cell in table["`status`"].items():  # every status listed is a Status, and the object's is one
        assert cell.startswith("`Status`"), cls
        for s in re.findall(r'`"(\w+)"`', cell):
            assert Status(s).value == s
        assert isinstance(objs[cls].status, Status)
    for cls, obj in objs.items():
        assert isinstance(obj.as_dict(), dict) and obj["nit"] == obj.nit and obj.time == obj.timings["total"]
        assert obj.solve_time == obj.time
    # nit of a solve split into components is the most any component needed, as the table says
    res = objs["SolveResult"]
    runs = res.extras.get("component_runs") or []
    assert "the most any independent component needed" in table["`nit`"]["SolveResult"]
    if runs:
        assert res.nit == max(r["nit"] for r in runs)
    assert objs["DigitsSolution"].digits == objs["DigitsSolution"].certificate.digits


@pytest.fixture(scope="module")
def four_results():
    """One result of each kind, from the small bundled problems."""
    p = rfverify.load("bundled:chute")
    res = rfverify.solve(p)
    return {"SolveResult": res, "DigitsSolution": rfverify.solve_to_digits(p, digits=6),
            "Certificate": rfverify.certify(p, res, digits=6),
            "Diagnosis": rfverify.diagnose(rfverify.load("bundled:sphere"), max_iter=3)}


@pytest.mark.parametrize("kind", ["SolveResult", "DigitsSolution", "Certificate", "Diagnosis"])
def test_every_result_is_a_mapping_like_optimize_result(four_results, kind):
    """Issue 49: ``"status" in res``, ``dict(res)``, ``res.keys()``, ``items()``, ``values()``,
    ``len`` and iteration work on every result, as on SciPy's OptimizeResult; the keys are its
    fields and properties (the common ones first, the aliases last), never its methods; attribute
    access is unchanged."""
    import dataclasses
    from collections.abc import Mapping

    res = four_results[kind]
    assert type(res).__name__ == kind and isinstance(res, Mapping)
    keys = list(res.keys())
    assert keys[:6] == ["status", "success", "message", "nit", "time", "timings"]
    assert keys[-2:] == ["iterations", "solve_time"]
    assert "status" in res and "nit" in res and "as_dict" not in res and "__class__" not in res
    assert {f.name for f in dataclasses.fields(res)} <= set(keys)
    assert len(keys) == len(set(keys)) == len(res) and list(res) == keys
    d = dict(res)
    assert list(d) == keys and d["status"] is res.status and d["nit"] == res.nit == res["iterations"]
    assert [k for k, _ in res.items()] == keys and len(list(res.values())) == len(keys)
    for k in ("status", "message", "timings"):
        assert res[k] is getattr(res, k) or res[k] == getattr(res, k)
    assert res.get("x") is None and res.get("status") is res.status
    with pytest.raises(KeyError):
        res["x"]  # noqa: B018  (SciPy's x: the unknowns are v, u, r here, docs/RESULTS.md)
    with pytest.raises(KeyError):
        res["as_dict"]  # noqa: B018  (a method, not a key)
    assert res.status == d["status"] and res.as_dict()["status"] == str(res.status)
