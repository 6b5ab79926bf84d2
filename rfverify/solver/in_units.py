"""A solve's answer found in other units, brought back to the problem's own: the exact scaling
of data beyond float64's safe range, and per-contact units brought together
(:mod:`rfverify.model.scaling`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.measures import measures
from ..model.problem import Problem
from . import SolveResult, Status, returned_verdict


def unscaled_result(res: SolveResult, scaled: Problem, scaling) -> SolveResult:
    """:func:`solve`'s answer found in units scaled by exact powers of two
    (:mod:`rfverify.model.scaling`), scaled back and judged on the problem as given (longdouble
    holds its range)."""
    note = scaling.describe("solved")
    back = {name: scaling.back(name, getattr(res, name)) for name in ("v", "u", "r")}
    extras = {**res.extras, "binary_scaling": note, "lifted_units": "scaled"}
    if not all(np.all(np.isfinite(x)) for x in back.values()):
        return dataclasses.replace(res, **back, status=Status.NUMERICAL_ERROR, extras=extras,
                                   message=f"{res.message}; {note}, but the answer overflows float64 in the "
                                           "problem's own units")
    # The measures are ratios of terms that scale alike: those of the scaled run are the problem's.
    return dataclasses.replace(res, **back, message=f"{res.message} ({note})", extras=extras)


def in_own_contact_units(res: SolveResult, problem: Problem, scaled: Problem, units) -> SolveResult:
    """:func:`solve`'s answer found with per-contact units brought together
    (:func:`rfverify.model.scaling.contact_units`), in the problem's units and judged there."""
    note = units.describe()
    back = {"v": res.v, "u": units.back("u", res.u), "r": units.back("r", res.r)}
    # the lifted iterate (z, r̃) is in the scaled units: a later phase starts from (v, r) instead
    extras = {k: x for k, x in res.extras.items() if k not in ("z", "r_t")}
    extras.update(contact_units=note, lifted_units="scaled")
    final = measures(problem, back["v"], back["u"], back["r"], "longdouble")
    run = res.extras.get("run_verdict", (res.status, res.message))
    status, message = returned_verdict(*run, final, res.settings)
    # what auto (or its time limit) put before the judged message stays: only the judgement is redone
    judged_there = returned_verdict(*run, res.measures, res.settings)[1]
    before = res.message[:-len(judged_there)] if res.message.endswith(judged_there) else ""
    if res.status is Status.MAX_TIME or status is Status.MAX_TIME:
        status = res.status if res.status is Status.MAX_TIME else status
    return dataclasses.replace(res, **back, measures=final, status=status, message=f"{before}{message} ({note})",
                               extras=extras)
