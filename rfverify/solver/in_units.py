"""A returned answer judged (:func:`returned_verdict`: the one criterion value a result states),
and a solve's answer found in other units brought back to the problem's own and judged there:
the exact scaling of data beyond float64's safe range, and per-contact units brought together
(:mod:`rfverify.model.scaling`)."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.measures import measures
from ..model.problem import Problem
from .result import Settings, SolveResult, Status


def returned_verdict(status: Status, message: str, final, settings: Settings) -> tuple[Status, str]:
    """The status and message of a returned answer, decided by ``final`` — the measures of the
    returned (v, u, r) on the whole problem, the one criterion value a result states — from the
    run's own ending (``status``, ``message``: why it stopped, naming the returned iteration).

    A run judges its iterates on its own component (its arithmetic, its data scales), so its
    stopping test and the returned answer's criterion can differ; the answer decides: Solved
    when ``final.max ≤ tol``, AlmostSolved when ``≤ almost_factor·tol``, and the number stated
    is ``final.max``.  A user's stop (Stopped) stays Stopped."""
    tol, almost = settings.tol, settings.almost_factor * settings.tol
    x = final.max if final is not None and np.isfinite(final.max) else np.inf
    if status is Status.STOPPED or not np.isfinite(x):
        return status, message
    if x <= tol:
        if status is Status.SOLVED:
            return status, f"criterion {x:.2e} ≤ tol (worst: {final.worst()}); {message}"
        return Status.SOLVED, f"criterion of the returned (v, u, r) {x:.2e} ≤ tol (the iterations ended {status}: {message})"
    if status is Status.SOLVED:  # the run's own test passed, the returned answer's did not
        return (Status.ALMOST_SOLVED if x <= almost else Status.INSUFFICIENT_PROGRESS,
                f"the run met tol on its own iterates ({message}), but the returned (v, u, r) has criterion "
                f"{x:.2e} > tol ({final.worst()})")
    if x <= almost:
        return Status.ALMOST_SOLVED, (f"{status}: {message}; the returned (v, u, r) has criterion {x:.2e} ≤ "
                                      f"{settings.almost_factor:g}·tol")
    return status, message


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
