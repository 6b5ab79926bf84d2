"""Result objects in the ecosystem's conventions: statuses compare with their printed names
and reprs fit in a few lines (no array dumps)."""

from __future__ import annotations

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
