"""When Algorithm 1 stops, and with which iterate: the criterion, the stall rule, the best
iterate, the iteration and time limits, and a user's callback.

The criterion is :mod:`rfverify.model.measures`' (judged on what would be returned).  A stall is
``stall_iterations`` consecutive iterations in which none of the primal (velocity, dual cone),
dual (dynamics) and gap (complementarity, primal cone) measures that is still above tol fell
below 0.9 × its own best, counted from the first step with α ≥ 0.5 — before it, a badly
scaled start can take several tiny but growing steps while μ grows 1e6-fold (see
docs/DECISIONS.md, "Solver robustness") — and counted afresh, with the bests reset, after a
step that raised μ more than :data:`RESCALED`-fold.  A run that stops otherwise returns its best iterate.

The messages state no criterion value: the run judges its iterates on its own component (the
bodies in contact, without the contact-free ones, in the iterate's arithmetic), while what
:func:`rfverify.solve` returns is judged once more on the whole problem.  That one number — the
criterion of the returned (v, u, r) — decides Solved and AlmostSolved and is the one stated
(:func:`rfverify.solver.returned_verdict`), so that a point is never given two criterion values.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..algorithm import rules
from ..algorithm.interfaces import Policy
from .result import Status


RESCALED = 100.0
"""A step after which μ is this many times larger restarts the stall count, as the first long
step does: the iterate has moved to another scale (on MassRatio piles with a mass ratio of 1e9,
a reaction 1e5 times its start in one step, μ up 1e3–1e7-fold), from which its measures fall
five-fold a step but stayed above their bests from before the move for longer than
``stall_iterations`` (18 of 24 such problems ended InsufficientProgress; docs/DECISIONS.md)."""


@dataclass
class Verdict:
    """A decision to stop: the status and why."""

    status: Status
    message: str


class PaperPolicy(Policy):
    """What the double run's policy (:mod:`.ipm`) and its continuations in exact arithmetic
    (:mod:`rfverify.verify.exact`) answer alike: the next step-to-boundary fraction by the paper's
    rule, γ = 0.9 + 0.09α, and a breakdown ends the run NumericalError."""

    @staticmethod
    def next_gamma(alpha):
        return rules.step_fraction(alpha, 0.09)

    @staticmethod
    def breakdown(message):
        return Verdict(Status.NUMERICAL_ERROR, message)

    @staticmethod
    def out_of_time(message):
        return Verdict(Status.MAX_TIME, message)


class Termination:
    """The stopping rules of one run (see the module docstring)."""

    def __init__(self, settings, callback=None, t0: float | None = None):
        self.settings = settings
        self.callback = callback
        self.t0 = time.perf_counter() if t0 is None else t0
        self.best = None  # (merit, k, state, measures, paper)
        self._best_each = [np.inf, np.inf, np.inf]
        self._since = 0
        self._engaged = False
        self._last_k = -1
        self._last_mu = np.inf

    def observe(self, k: int, judged, paper: tuple, state) -> Verdict | None:
        """Record iterate k (its measures, the paper's (pinfeas, dinfeas, μ), and ``state``,
        whatever the driver needs to return it); a Verdict when the run must stop here."""
        tol = self.settings.tol
        merit = judged.max
        self._last_k = k
        if np.isnan(merit) or not np.all(np.isfinite(paper)):
            return Verdict(Status.NUMERICAL_ERROR, f"iteration {k}: residuals are not finite")
        if self.best is None or merit < self.best[0]:
            self.best = (merit, k, (state, judged, paper))
        if merit <= tol:
            return Verdict(Status.SOLVED, f"paper's max(pinfeas, dinfeas, mu) = {max(paper):.2e}")
        mu = paper[2]
        if self._engaged and mu > RESCALED * self._last_mu:  # the iterate moved to another scale: count afresh
            self._count_afresh()
        self._last_mu = mu
        improved = False
        for i, val in enumerate((max(judged.velocity, judged.dual_cone), judged.dynamics,
                                 max(judged.complementarity, judged.primal_cone))):
            if val > tol and val < 0.9 * self._best_each[i]:
                improved = True
            self._best_each[i] = min(self._best_each[i], val)
        self._since = 0 if improved or not self._engaged else self._since + 1
        if k == self.settings.max_iter:
            return Verdict(Status.MAX_ITERATIONS, f"reached max_iter = {self.settings.max_iter}")
        if self._since >= self.settings.stall_iterations:
            return Verdict(Status.INSUFFICIENT_PROGRESS,
                           f"iteration {k}: none of the primal, dual and gap measures above tol improved by 10% "
                           f"in {self._since} iterations")
        limit = self.settings.time_limit
        if limit is not None and time.perf_counter() - self.t0 > limit:
            return Verdict(Status.MAX_TIME, f"iteration {k}: time limit of {limit:g} s reached")
        return None

    def after_step(self, alpha: float):
        """Stall counting starts at the first step with α ≥ 0.5, with the bests reset there."""
        if not self._engaged and alpha >= 0.5:
            self._engaged = True
            self._count_afresh()

    def _count_afresh(self):
        """Each measure's best forgotten and the stall count at 0: from the first long step, and after
        a step to another scale (:data:`RESCALED`)."""
        self._best_each, self._since = [np.inf, np.inf, np.inf], 0

    def ask_callback(self, info) -> Verdict | None:
        if self.callback is not None and self.callback(info):
            return Verdict(Status.STOPPED, f"stopped by the callback at iteration {info.iteration}")
        return None

    def final(self, verdict: Verdict, current):
        """(status, message, bundle, k) to return, bundle = (state, measures, paper) as given to
        :meth:`observe` for iteration k: the current iterate when Solved or stopped by the
        callback, else the best one, named in the message when it is not the last.  The status
        is the verdict's: whether the returned point is AlmostSolved is decided on it by
        :func:`rfverify.solver.returned_verdict`."""
        status, message = verdict.status, verdict.message
        if status in (Status.SOLVED, Status.STOPPED) and current is not None:
            return status, message, current, self._last_k
        if self.best is None:  # the first iterate already failed (e.g. its residuals overflowed)
            return status, message, current, self._last_k
        _, kb, bundle = self.best
        if kb != self._last_k:
            message += f"; returning the best iterate (iteration {kb})"
        return status, message, bundle, kb
