"""Algorithm 1 in exact arithmetic from the iterates of a double run: what
:func:`rfverify.diagnose` compares the double run with (DESIGN §5).

"Exact" is double-double (about 32 digits; :mod:`rfverify.extended`) with every Newton solve
refined against the unreduced system down to the floor of that arithmetic (relative residual
1e-31), not to the extended phase's inexact-Newton η: its steps are those of exact arithmetic
to far more digits than a double step can keep, which is all a lockstep needs, at the cost of
a double step (0.03–0.1 s per step at 700–1400 contacts, against 3–20 s for the mpmath
reference).  Two uses:

* :meth:`ExactAlgorithm.step`: one iteration of Algorithm 1 from a given iterate with a given
  step fraction γ and σ rule — the exact step the lockstep compares the double run's next
  iterate with;
* :meth:`ExactAlgorithm.run`: Algorithm 1 continued from a given iterate, with the double
  run's own policy (σ rule, γ = 0.9 + 0.09α, criterion, stall rule and iteration limit,
  :class:`rfverify.solver.termination.Termination`) — the counterfactual: what the same
  algorithm does from there without double's rounding.

:func:`witness` runs the independent mpmath reference (:mod:`reference`, which shares none of
this code) from the same iterate on the iterations that decide a verdict, as far as a time
budget allows.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..algorithm import rules
from ..algorithm.interfaces import Breakdown
from ..algorithm.loop import Precision, iterate
from ..algorithm.newton import ReducedNewton
from ..extended import cones as C
from ..extended import dd
from ..extended import ipm as ext
from ..extended.data import ExtendedData
from ..extended.system import choose_backend
from ..solver.result import Status
from ..solver.termination import PaperPolicy, Termination, Verdict

FLOOR = 1e-31
"""Relative residual to which every Newton solve of an exact step is refined (double-double's
own floor; the extended phase stops at η = 1e-8 instead, which a lockstep could not use)."""

REFINE_MAX = 20
"""Refinement steps of one exact Newton solve at most (each stops earlier when a step no longer
halves the residual)."""


class ExactStepError(Exception):
    """No exact step exists from the given iterate (it is not interior in exact arithmetic, or
    a Newton matrix is singular there); the message says where."""


@dataclass
class ExactStep:
    """One exact iteration: the next iterate (double-double ``v``, ``r_t``, ``z``), the σ and
    α it took, and at the iterate it started from, max cond(Q_p) over the cones; at the next
    iterate, the smallest λ2 of z and of s = Jᵀr̃ (float) and their cones."""

    v: ext.V
    r_t: ext.V
    z: ext.V
    sigma: float
    alpha: float
    max_cond_Qp: float
    min_lam2_z: float
    min_lam2_z_cone: int
    min_lam2_s: float
    min_lam2_s_cone: int


@dataclass
class ExactRun:
    """Algorithm 1 continued in exact arithmetic (:meth:`ExactAlgorithm.run`): where it started
    (``start``, an iteration of the double run), how it ended (``status``, ``message``), the
    iteration at which it met the tolerance (``reached_at``, None if it did not), and one row
    per iterate (``iter``, ``mu``, ``criterion``, ``worst``: the measure deciding it,
    ``pinfeas``, ``dinfeas``, ``gamma``: the step fraction of the step from it, ``r_t_inf``:
    ‖r̃‖∞)."""

    start: int
    status: Status
    message: str
    reached_at: int | None
    rows: list = field(default_factory=list)
    seconds: float = 0.0
    kept: dict = field(default_factory=dict)  # iteration → (v, r̃, z) double-double, when asked to keep them

    @property
    def best(self) -> float:
        return min((r["criterion"] for r in self.rows), default=math.inf)

    def as_dict(self) -> dict:
        return {"start": self.start, "status": str(self.status), "message": self.message,
                "reached_at": self.reached_at, "best_criterion": self.best, "seconds": self.seconds,
                "iterations": [dict(r) for r in self.rows]}


class _ExactScaling(ext.DDScaling):
    """The double-double NT scaling, reporting max cond(Q_p) = (λ1(p)/λ2(p))² from its
    spectral data (λ1(p) and λ2(p) are computed there without cancellation)."""

    def describe(self) -> dict:
        a, b = self.spec[:, 0], self.spec[:, 2]
        with np.errstate(all="ignore"):
            cond = np.square(a / b)
        return {"max_cond_Qp": float(np.max(cond, initial=1.0))}


class _ExactCones(ext.DDCones):
    def scaling(self, z, s):
        return _ExactScaling(self.n3, self.nz, self.n_cones, self.e, z, s)


class _OneStep(PaperPolicy):
    """Policy of one exact step: γ and the σ rule given, stop at the next iterate."""

    def __init__(self, gamma: float, rule: str):
        self.gamma0, self.rule = gamma, rule
        self.record = None

    def observe(self, k, it, res, record):
        return Verdict(Status.STOPPED, "one step") if k == 1 else None

    def sigma(self, mu, mu_aff, alpha_aff):
        return rules.centring(self.rule, mu_aff, mu, alpha_aff)

    def after_direction(self, k, record, predictor, corrector):
        self.record = dict(record)

    @staticmethod
    def after_step(alpha):
        return None


class _Continuation(PaperPolicy):
    """The double run's policy in exact arithmetic: its criterion (``judge``), stall rule and
    iteration limit (:class:`Termination`, iterations counted as the double run's), its σ
    rule and γ; a deadline ends it with MaxTime."""

    def __init__(self, settings, judge, k0: int, gamma0: float, max_iter: int, deadline, progress, keep):
        self.settings = settings
        self.keep, self.kept = keep, {}
        self.term = Termination(dataclasses.replace(settings, max_iter=max_iter, time_limit=None))
        # The double run engaged its stall counter at its first long step; a continuation starts
        # from an iterate that is past it (or, from iteration 0, does as the double run did).
        self.term._engaged = k0 > 0
        self.judge, self.k0, self.gamma0 = judge, k0, gamma0
        self.gamma = gamma0  # the γ of the step from the iterate last observed
        self.deadline, self.progress = deadline, progress
        self.criterion = math.nan
        self.rows = []

    def observe(self, k, it, res, record):
        judged = self.judge(*it)
        self.criterion = judged.max
        kk = self.k0 + k
        if self.keep:
            self.kept[kk] = it
        self.rows.append({"iter": kk, "mu": res.mu, "criterion": judged.max, "worst": judged.worst(),
                          "pinfeas": res.pinfeas, "dinfeas": res.dinfeas, "gamma": self.gamma,
                          "r_t_inf": float(np.max(np.abs(it[1].h), initial=0.0))})
        if self.progress:
            self.progress(kk, res.mu, judged.max)
        verdict = self.term.observe(kk, judged, (res.pinfeas, res.dinfeas, res.mu), None)
        if verdict is None and self.deadline is not None and time.perf_counter() > self.deadline:
            verdict = Verdict(Status.MAX_TIME, f"iteration {kk}: the diagnosis's time limit was reached")
        return verdict

    def sigma(self, mu, mu_aff, alpha_aff):
        return rules.centring(rules.rule_at(self.settings.sigma_rule, self.criterion), mu_aff, mu, alpha_aff)

    @staticmethod
    def after_direction(k, record, predictor, corrector):
        return None

    def after_step(self, alpha):
        self.term.after_step(alpha)

    def next_gamma(self, alpha):
        self.gamma = rules.step_fraction(alpha, 0.09)
        return self.gamma


class ExactAlgorithm:
    """Algorithm 1 in double-double on ``problem`` (its extended data and Newton back end built
    once, :mod:`rfverify.extended`), judged as the double run with ``settings`` judges:
    ``judge(v, r̃, z)`` (double-double vectors) returns the :class:`rfverify.model.measures.Measures`
    of the answer that iterate would give."""

    def __init__(self, problem, settings, judge):
        self.problem, self.settings, self.judge = problem, settings, judge
        self.data = ExtendedData(problem)
        self.backend = choose_backend(self.data)
        self.local = self.data.local

    def point(self, v, r_t, z) -> tuple:
        """An iterate (v (m,) — ignored for a local problem, which has no dofs here —, r̃ (nk,),
        z (nz,), any float dtype, in the lifted layout of :func:`rfverify.model.lifting.lift`) as
        double-double vectors, exactly."""
        v = np.zeros(0, dtype=np.longdouble) if self.local else np.asarray(v, dtype=np.longdouble)
        return tuple(ext.V(*dd.from_longdouble(np.asarray(x, dtype=np.longdouble))) for x in (v, r_t, z))

    def _precision(self):
        space = ext.DDSpace(self.data)
        newton = ReducedNewton(space, ext.DDBackend(self.backend), refine_max=REFINE_MAX, floor=FLOOR,
                               inf=ext.V.inf, enough=None, predictor_enough=None)
        return Precision(space, _ExactCones(self.data), newton)

    def step(self, start: tuple, gamma: float, rule: str) -> ExactStep:
        """One iteration from ``start`` (double-double vectors) with step fraction ``gamma`` and
        σ rule ``rule`` ("paper", "mehrotra" or "siconos").  Raises :class:`ExactStepError`
        when there is none (the start is not interior in exact arithmetic, a Newton matrix
        lost definiteness)."""
        policy = _OneStep(gamma, rule)
        out = iterate(self._precision(), policy, start, n_contacts=self.data.n,
                      n_cones=self.data.n3 + self.data.n1, clock_origin=time.perf_counter())
        status, message = out.verdict.status, out.verdict.message
        if status is not Status.STOPPED or policy.record is None:
            raise ExactStepError(message.split(": ", 1)[-1] if message.startswith("iteration") else message)
        v, r, z = out.iterate
        lam_z = C.min_lambda2(self.data.n3, z.h, z.l)
        s = ext.V(*self.data.JT.matvec(r.h, r.l))
        lam_s = C.min_lambda2(self.data.n3, s.h, s.l)
        rec = policy.record
        return ExactStep(v, r, z, float(rec["sigma"]), float(rec["alpha"]), float(rec.get("max_cond_Qp", math.nan)),
                         float(lam_z[0]), int(lam_z[1]), float(lam_s[0]), int(lam_s[1]))

    def run(self, start: tuple, k0: int, gamma0: float, max_iter: int, deadline=None, progress=None,
            keep: bool = False) -> ExactRun:
        """Algorithm 1 from ``start`` (iteration ``k0`` of the double run, whose γ there was
        ``gamma0``) with the double run's policy, until the criterion meets ``settings.tol``,
        the run stalls or breaks down, or iteration ``max_iter`` (counted as the double run
        counts).  ``progress(k, mu, criterion)`` is called at every iterate; ``keep`` keeps
        every iterate in ``kept``."""
        t0 = time.perf_counter()
        policy = _Continuation(self.settings, self.judge, k0, gamma0, max_iter, deadline, progress, keep)
        try:
            out = iterate(self._precision(), policy, start, n_contacts=self.data.n,
                          n_cones=self.data.n3 + self.data.n1, clock_origin=t0)
        except (ArithmeticError, Breakdown) as exc:  # a back end's own failure: the run stops there
            verdict = Verdict(Status.NUMERICAL_ERROR, f"iteration {k0 + len(policy.rows) - 1}: {exc}")
            out = None
        else:
            verdict = out.verdict
        status = verdict.status
        reached = policy.rows[-1]["iter"] if status is Status.SOLVED else None
        return ExactRun(k0, status, verdict.message, reached, policy.rows, time.perf_counter() - t0, policy.kept)


def dd_difference(a: ext.V, b) -> np.ndarray:
    """a − b as float64 (the high part of the double-double difference; ``b`` any float
    array, converted exactly)."""
    bh, bl = dd.from_longdouble(np.asarray(b, dtype=np.longdouble))
    oh, ol = np.empty_like(bh), np.empty_like(bh)
    dd.vsub(a.h, a.l, bh, bl, oh, ol)
    return oh


# ---------------------------------------------------------------------- the mpmath witness
@dataclass
class Witness:
    """What the mpmath reference did from an iterate of the double run (:func:`witness`):
    ``steps`` taken, the criterion of each of its iterates (``criteria``, from iteration
    ``start``), whether it met the tolerance (``reached_at``), the fewest digits of agreement
    of its iterates with the double-double run's at the same iteration (``agreement``: v, u
    and Hr, or u for a local problem), and why it stopped (``stopped``)."""

    start: int
    steps: int
    criteria: list
    reached_at: int | None
    agreement: float
    stopped: str
    seconds: float
    dps: int

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def witness(reference_solver, start_iterate: tuple, k0: int, gamma0: float, settings, judge, compare,
            max_steps: int, deadline: float, dps: int, progress=None, step_seconds: float = 0.0) -> Witness:
    """Algorithm 1 in the mpmath reference (``reference_solver``, a :class:`reference.Solver`)
    from ``start_iterate`` (a :class:`reference.Iterate`, or (v, r̃, z cones) in the reference's
    layout), iteration ``k0`` of the double run, with the double run's σ rule (by the criterion
    ``judge(iterate)`` of each iterate) and γ rule, for at most ``max_steps`` steps, while the
    wall clock allows and until the criterion meets ``settings.tol``.  ``compare(k, iterate)``
    returns the digits of agreement of the reference's iterate k (a :class:`reference.Iterate`)
    with the double-double run's.  A step that would end past ``deadline`` is not begun
    (``step_seconds``: what one is expected to take, before the first is timed)."""
    from reference import jordan as RJ

    t0 = time.perf_counter()
    it = start_iterate if hasattr(start_iterate, "r_t") else reference_solver.iterate(*start_iterate)
    gamma = gamma0
    criteria, agreement, reached, stopped = [], math.inf, None, ""
    steps = 0
    k = k0
    last = step_seconds  # seconds of the last step: a step that would end past the deadline is not begun
    while True:
        crit = judge(it).max
        criteria.append(crit)
        if k > k0:
            agreement = min(agreement, compare(k, it))
        if crit <= settings.tol:
            reached, stopped = k, "met the tolerance"
            break
        if steps >= max_steps:
            stopped = f"{steps} steps, as many as the double-double run took"
            break
        if time.perf_counter() + last > deadline:
            stopped = f"its time budget was spent after {steps} steps"
            break
        if progress:
            progress(k, crit)
        t_step = time.perf_counter()
        try:
            step = reference_solver.step(it, gamma, rules.rule_at(settings.sigma_rule, crit))
        except RJ.ReferenceDomainError as exc:
            stopped = f"no step from iteration {k}: {exc}"
            break
        except ArithmeticError as exc:  # its own linear algebra, at its precision: the run it checks stands
            stopped = f"its linear algebra broke down at iteration {k} ({exc}) at {dps} digits"
            break
        last = time.perf_counter() - t_step
        it = step.iterate
        gamma = rules.step_fraction(float(step.alpha), 0.09)
        steps += 1
        k += 1
    return Witness(k0, steps, criteria, reached, agreement, stopped, time.perf_counter() - t0, dps)
