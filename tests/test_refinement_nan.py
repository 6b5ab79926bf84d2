"""A refinement step that makes a Newton direction worse, or not finite, is undone; a run whose
solve breaks down never steps to a NaN iterate (tests/data/hard/README.md,
Lattice-ndof-360-nc-274-0)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import rfverify
from rfverify.algorithm.rules import refined_newton

HARD = Path(__file__).parent / "data" / "hard"


def _inf(x):
    return float(np.max(np.abs(x), initial=0.0))


def _refine(corrections, refine_max=4):
    """refined_newton on x = b with 'solves' that return the given corrections in turn (the first
    solve x0 = 0.9 b, so the first residual is 0.1 b)."""
    b = np.array([1.0, 2.0])
    calls = iter([0.9 * b] + corrections)

    def core(a, bb, c):
        d = next(calls)
        return d, d.copy(), d.copy()

    def residual(a, bb, c, dv, dr, dz):
        return bb - dv, bb - dr, bb - dz

    return refined_newton(core, residual, b, b, b, inf=_inf, refine_max=refine_max, floor=1e-30)


def test_a_nan_correction_is_undone_and_the_residual_returned_is_the_directions():
    dv, dr, dz, steps, res, settled = _refine([np.array([np.nan, 0.0])])
    assert np.all(np.isfinite(dv)) and np.allclose(dv, [0.9, 1.8])
    assert steps == 0 and math.isclose(res, 0.1) and not settled


def test_a_correction_that_makes_the_residual_worse_is_undone():
    dv, *_, steps, res, settled = _refine([np.array([5.0, 5.0])])
    assert np.allclose(dv, [0.9, 1.8]) and steps == 0 and math.isclose(res, 0.1)


def test_a_helpful_correction_is_kept_and_a_last_unevaluated_nan_one_is_not():
    helpful = np.array([0.075, 0.15])  # the residual falls from 0.1 b to 0.025 b
    dv, *_, res, _ = _refine([helpful, np.zeros(2)], refine_max=4)
    assert np.allclose(dv, [0.975, 1.95]) and math.isclose(res, 0.025)
    # refine_max = 2: the second correction is never evaluated; a NaN one is undone all the same
    dv, *_, steps, res, _ = _refine([helpful, np.array([np.nan, 1.0])], refine_max=2)
    assert steps == 1 and np.all(np.isfinite(dv)) and np.allclose(dv, [0.975, 1.95])


def test_the_lattice_whose_refinement_returned_nan_is_proven():
    problem = rfverify.load(HARD / "Lattice-ndof-360-nc-274-0.hdf5")
    sol = rfverify.solve_to_digits(problem, digits=10)
    assert sol.certificate.certified, sol.message
    assert min(sol.digits[q] for q in ("v", "u", "Hr")) >= 10
    assert all(np.all(np.isfinite(x)) for x in (sol.v, sol.u, sol.r))
    # its proof point is the multiple-precision tail's predictor point (tests/test_predicted_point.py
    # covers the double-double phase's)
    at = sol.certificate.extra["proven_at"]
    assert at["phase"] == "multiple-precision" and at["predicted"], at
