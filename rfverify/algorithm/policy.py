"""The extended phases' policy (double-double and mpfr runs share it) and the trace format
of their results."""

from __future__ import annotations

from . import rules
from .interfaces import Policy


PREDICTED_FRACTION = 0.999
"""The predictor's point offered to ``until`` lies this fraction of the way to the cones'
boundary along the predictor's direction: late in a run its μ is far below the next iterate's
(which the corrector re-centres), and a thousandth of the margin is kept so that the proof's
exact cone tests see a strict interior (docs/DECISIONS.md, "A proof at the predictor's point")."""


class UntilPolicy(Policy):
    """The extended phases' policy: stop when ``until(iterate)`` accepts an iterate (status
    "Stopped") or at ``max_iter``; the paper's σ rule; γ = min(γ_max, 0.9 + (γ_max − 0.9)α).
    ``progress(k, mu, pinfeas, dinfeas, step)`` is told of each iterate, with ``step`` = (α, limit)
    of the step that led to it (None for the first): limit is the scaling's (cone, "z" or "s")
    that set the step to the boundary, or None."""

    gamma0 = 0.9

    def __init__(self, until, progress, max_iter: int, make_iterate, gamma_max: float, stop_words: str,
                 make_predicted=None):
        self.until, self.progress, self.max_iter = until, progress, max_iter
        self.make_iterate, self.gamma_max, self.stop_words = make_iterate, gamma_max, stop_words
        self.make_predicted = make_predicted  # (k, (v, r̃, z), μ) -> the predictor's point for ``until``
        self.last_step = None  # (α, limit) of the step just taken

    def after_predictor(self, k, alpha_aff, point_at):
        """Offer ``until`` the point :data:`PREDICTED_FRACTION` of the predictor's largest step
        along its direction (where ``make_predicted`` is given); stop there if it accepts it."""
        if self.until is None or self.make_predicted is None or not alpha_aff > 0:
            return None
        alpha = PREDICTED_FRACTION * alpha_aff
        point, mu = point_at(alpha)
        if self.until(self.make_predicted(k, point, mu)):
            return ("Stopped", f"{self.stop_words} at iteration {k}'s predictor point, {alpha:.4g} along its "
                               f"direction (μ = {mu:.2e})"), point
        return None

    def observe(self, k, iterate, res, record):
        if self.progress:
            self.progress(k, res.mu, res.pinfeas, res.dinfeas, self.last_step)
        if self.until is not None and self.until(self.make_iterate(k, iterate, res)):
            return ("Stopped", f"{self.stop_words} at iteration {k} (μ = {res.mu:.2e})")
        if k == self.max_iter:
            return ("MaxIterations", f"reached max_iter = {self.max_iter}")
        return None

    @staticmethod
    def sigma(mu, mu_aff, alpha_aff):
        return rules.centring("paper", mu_aff, mu, alpha_aff)

    def after_direction(self, k, record, predictor, corrector):
        self.last_step = (record["alpha"], record.get("limit"))
        return None

    @staticmethod
    def after_step(alpha):
        return None

    def next_gamma(self, alpha):
        return rules.step_fraction(alpha, self.gamma_max - 0.9, cap=self.gamma_max)

    @staticmethod
    def breakdown(message):
        return ("NumericalError", message)

    @staticmethod
    def out_of_time(message):
        return ("MaxTime", message)


def extended_trace(records: list) -> dict:
    """The extended phases' trace from the loop's records: mu, pinfeas, dinfeas, time per
    iterate; the step columns per iteration that computed its step (``refine`` is the
    records' refine_steps) and ``limit`` (the (cone, "z" or "s") that set the step to the boundary,
    or None); "centrality" per iteration that reached its scaling."""
    trace = {key: [rec[key] for rec in records] for key in ("mu", "pinfeas", "dinfeas", "time")}
    stepped = [rec for rec in records if "sigma" in rec]
    for key in ("sigma", "alpha", "refine", "solve_residual"):
        trace[key] = [rec["refine_steps" if key == "refine" else key] for rec in stepped]
    trace["limit"] = [rec.get("limit") for rec in stepped]
    if any("centrality" in rec for rec in records):
        trace["centrality"] = [rec["centrality"] for rec in records if "centrality" in rec]
    return trace


