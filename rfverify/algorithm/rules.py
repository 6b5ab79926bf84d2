"""The rules every precision's policy shares: the centring parameter σ, the step-to-boundary
fraction γ, and iterative refinement of a Newton solve against the unreduced system."""

from __future__ import annotations

import math

# sigma_rule="hybrid": Mehrotra's cubic σ, bounded below by HYBRID_SIGMA_FLOOR, while the
# iterate's criterion is above HYBRID_SWITCH; the paper's rule below it (Settings.sigma_rule).
HYBRID_SWITCH = 1e-4
HYBRID_SIGMA_FLOOR = 0.2


def rule_at(rule: str, criterion: float) -> str:
    """The σ rule one iteration uses: ``rule`` itself, or for ``hybrid`` "mehrotra" (the
    floored cube of :func:`centring`) while ``criterion`` (the iterate's, before the step) is
    above :data:`HYBRID_SWITCH` and "paper" from there on.  The diagnosis's lockstep asks the
    same question of the double run's trace."""
    if rule == "hybrid":
        return "mehrotra" if criterion > HYBRID_SWITCH else "paper"
    return rule


def centring(rule: str, mu_aff: float, mu: float, alpha_aff: float) -> float:
    """σ from the predictor's μ_aff and step α_aff at an iterate with μ, by ``rule``:
    "paper" (σ = (μ_aff/μ)^e, e = max(1, 3α_aff) once μ < 1e-5), "mehrotra" (the cube,
    floored at :data:`HYBRID_SIGMA_FLOOR`) or "siconos" (Siconos's GRFC3D_IPM)."""
    ratio = max(mu_aff, 0.0) / mu if mu > 0 else 0.0
    if rule == "paper":
        expo = max(1.0, 3 * alpha_aff) if mu < 1e-5 else 1.0
        return min(1.0, ratio ** expo)
    if rule == "mehrotra":
        # The floor: with σ far below it the FE sticking blocks ended 1.3–2.8× less accurate
        # at the same criterion than under the paper's rule (docs/DECISIONS.md, "σ rule").
        return max(HYBRID_SIGMA_FLOOR, min(1.0, ratio ** 3))
    expo = max(1.0, 3 * alpha_aff ** 2) if mu > 1e-5 else max(1.0, 3 * alpha_aff)
    return min(1.0, ratio ** expo) / 5


def step_fraction(alpha: float, slope: float, cap: float | None = None) -> float:
    """The paper's γ after a step α: 0.9 + ``slope``·α (0.09 in the double solver), capped at
    ``cap`` where a policy asks for one."""
    gamma = 0.9 + slope * alpha
    return gamma if cap is None else min(cap, gamma)


def refined_newton(core, residual, a, b, c, *, inf, refine_max: int, floor: float, enough: float | None = None):
    """(dv, dr̃, dz, steps, relative residual, settled): ``core(a, b, c)`` solves the Newton
    system (through a reduced form), then each step refines against the unreduced three-block
    system — ``residual(a, b, c, dv, dr, dz)`` returns its three residual blocks — while the
    relative residual max‖e‖∞ / max(‖a‖∞, ‖b‖∞, ‖c‖∞) at least halves and is above ``floor``.
    With ``enough`` = η it also stops once every block's residual is at most η times its own
    right-hand side (‖e_a‖ ≤ η‖a‖, ‖e_b‖ ≤ η‖b‖, ‖e_c‖ ≤ η‖c‖), or below the floor, or at the
    level at which that block's residual can be evaluated at all (:func:`_evaluation_floors`):
    an inexact Newton direction that accurate changes the next iterate's residuals, (1 − α)·rhs
    + α·e, by a relative η only.  ``settled``: the loop stopped at the floor or on that test,
    not because refinement stalled or ran out of steps.  The direction returned is the one whose
    residual is returned: a correction that made it worse, or not finite, is undone.  Any vector
    type with + and - and a norm ``inf`` works (double-double pairs, mpfr arrays)."""
    dv, dr, dz = core(a, b, c)
    sizes = (inf(a), inf(b), inf(c))
    scale = max(*sizes, 1e-300)
    best, steps, settled = math.inf, 0, False
    floors, predicted, before = (0.0, 0.0, 0.0), None, None
    for _ in range(refine_max):
        e = residual(a, b, c, dv, dr, dz)
        if predicted is not None:
            floors = _evaluation_floors(e, predicted, floors, inf)
        errors = tuple(inf(x) for x in e)
        res = max(errors) / scale
        if res < floor or (enough is not None
                           and all(err <= max(enough * s, floor * scale, 2 * f)
                                   for err, s, f in zip(errors, sizes, floors))):
            best, settled = min(best, res), True
            break
        if not res < 0.5 * best:
            if before is not None and not res <= best:  # worse, or NaN: keep the direction before it
                (dv, dr, dz), steps = before, steps - 1
            best = min(best, res) if math.isfinite(res) else best
            break
        best = res
        ddv, ddr, ddz = core(*e)
        if enough is not None:  # what the residual will be, evaluated on the correction alone
            predicted = residual(*e, ddv, ddr, ddz)
        before = (dv, dr, dz)
        dv, dr, dz = dv + ddv, dr + ddr, dz + ddz
        steps += 1
    else:
        if before is not None and not all(math.isfinite(inf(x)) for x in (dv, dr, dz)):
            (dv, dr, dz), steps = before, steps - 1  # the last correction, never evaluated, is not finite
    return dv, dr, dz, steps, best, settled


def _evaluation_floors(evaluated, predicted, floors, inf) -> tuple:
    """Per block, the largest gap seen between a residual evaluated at the refined direction x + d
    and the same residual evaluated as e − L d on the correction alone: equal in exact
    arithmetic, they differ by the rounding of the evaluation, which a further correction cannot
    remove.  (Measured on a touching pile: the dual row's rhs 5e-35 against H̃ᵀdr̃'s terms of
    4e-6 — self-stresses cancel in H̃ᵀ — so its residual is evaluated to ~4e-38 only, 1e-3 of
    the rhs; refinement chased it for three more solves and then asked for a new factor.)"""
    return tuple(max(f, inf(x - y)) for f, x, y in zip(floors, evaluated, predicted))
