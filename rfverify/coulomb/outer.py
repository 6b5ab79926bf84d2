"""The outer iteration on De Saxcé's shift: find s with s = Φ(u(s)) (:mod:`.model`).

Each evaluation of the map is a double solve of the convex problem with w_N + s
(:func:`rfverify.solve`, Algorithm 1 from its standard start: the interior-point method has
no warm start, and one from the previous solve's answer — on the boundary of the cones — would
not be interior).  Two outer methods (docs/DECISIONS.md, "The physical problem"):

* ``"picard"`` — Cadoux's fixed point s ← Φ(u(s)) (Acary, Cadoux, Lemaréchal, Malick 2011);
* ``"anderson"`` (default) — Anderson acceleration of that map (Walker and Ni 2011, type II,
  memory ``memory``), restarted whenever a step does not improve on the best residual: the
  chute's Picard iteration contracts by 0.86 per step for twenty steps where the active set
  changes, which Anderson crosses in a few.

The residual is max_i |Φ_i(u(s)) − s_i| relative to the data scale of u; the loop stops when it
is at most ``outer_tol``, when it has not fallen below 0.9 of its best for ``stall``
evaluations (the inner solves' own accuracy is reached), or after ``outer_max_iter``
evaluations.  The best evaluation is returned.  Where an Anderson step does not lower the best
residual its history is dropped (the next step is a plain one): across an active-set change
the secant model is wrong, and a small generated Chute oscillated at 6e-4 without the reset
and a 12-evaluation stall window (it converges in 25 with them; memory 2: 15, but 38 against 28
on a 168-contact SpheresPile and 100 against 71 on a 176-contact Chute, so 5 is kept).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InvalidArgumentError
from ..model.problem import Problem
from .model import applied_shift, friction_scaled, phi, shifted_problem, u_scale

OUTER_METHODS = ("anderson", "picard")

INNER_TOL = 1e-12
"""Tolerance of each inner double solve: two decades below the default ``tol`` so that the
fixed point is found to the accuracy the proof then needs (the chute's double solves meet it in
14 iterations)."""

OUTER_TOL = 1e-13
"""Default target of the relative fixed-point residual (three decades below 1e-10: the proven
stage then starts where the backward error is already below a 10-digit target)."""


@dataclass
class OuterRun:
    """What :func:`fixed_point` did: ``shift`` (n,) the shift of the best evaluation, exactly as
    applied to the data (``shifted`` is that problem), ``inner`` its double solve, ``residuals``
    the relative fixed-point residual of every evaluation, ``inner_iterations`` and
    ``inner_status`` per evaluation, ``converged`` (best residual ≤ ``outer_tol``), ``message``
    (why it stopped), ``method``, ``seconds``, ``scale`` (the data scale of u used), ``started``
    (True when it started from a given shift, not from 0)."""

    shift: np.ndarray
    shifted: Problem
    inner: object
    residuals: list = field(default_factory=list)
    inner_iterations: list = field(default_factory=list)
    inner_status: list = field(default_factory=list)
    converged: bool = False
    message: str = ""
    method: str = "anderson"
    seconds: float = 0.0
    scale: float = 0.0
    best: int = 0
    max_evaluations: int = 0
    started: bool = False  # from a given shift (``start``), not from 0
    timed_out: bool = False  # stopped by ``deadline``
    refused: bool = False  # an inner solve refused the shifted problem (status InvalidInput)
    stages: list = field(default_factory=list)  # the friction continuation's, when it ran (find_shift)

    @property
    def residual(self) -> float:
        """The best relative fixed-point residual reached."""
        return self.residuals[self.best] if self.residuals else math.inf

    @property
    def evaluations(self) -> int:
        """Evaluations of the map for the problem itself: those of the run returned."""
        return len(self.residuals)

    @property
    def total_evaluations(self) -> int:
        """Every convex solve the search made, the continuation's stages included."""
        return sum(st["evaluations"] for st in self.stages) if self.stages else self.evaluations

    @property
    def total_inner_iterations(self) -> int:
        """Interior-point iterations of every convex solve the search made."""
        return sum(st["inner_iterations"] for st in self.stages) if self.stages else int(sum(self.inner_iterations))

    def as_dict(self) -> dict:
        return {"method": self.method, "evaluations": self.evaluations, "converged": self.converged,
                "residual": self.residual, "residuals": list(self.residuals),
                "inner_iterations": list(self.inner_iterations), "inner_status": list(self.inner_status),
                "message": self.message, "seconds": self.seconds, "scale": self.scale,
                "start": "given shift" if self.started else "zero",
                "total_evaluations": self.total_evaluations, "stages": [dict(st) for st in self.stages]}


def check_outer(outer: str) -> str:
    if outer not in OUTER_METHODS:
        raise InvalidArgumentError("outer", f"{outer!r} is not one of {', '.join(OUTER_METHODS)}",
                                   fix="use outer='anderson' (default) or 'picard'")
    return outer


class Anderson:
    """Anderson acceleration (type II) of x ← G(x): from the last ``memory`` differences of
    x and of f = G(x) − x, the next x is G(x) − ΔG·γ with γ the least-squares fit of f by ΔF."""

    def __init__(self, memory: int = 5):
        self.memory = memory
        self.xs, self.gs = [], []

    def reset(self):
        self.xs, self.gs = self.xs[-1:], self.gs[-1:]

    def next(self, x: np.ndarray, g: np.ndarray) -> np.ndarray:
        self.xs = (self.xs + [x])[-(self.memory + 1):]
        self.gs = (self.gs + [g])[-(self.memory + 1):]
        if len(self.xs) < 2:
            return g
        F = np.array([gk - xk for xk, gk in zip(self.xs, self.gs)])
        dF = np.diff(F, axis=0).T
        dG = np.diff(np.array(self.gs), axis=0).T
        big = np.max(np.abs(dF), axis=0)
        if not np.all(big > 0):
            return g
        colscale = np.linalg.norm(dF / big, axis=0) * big  # the 2-norms, without squares that overflow
        gamma = np.linalg.lstsq(dF / colscale, F[-1], rcond=1e-12)[0] / colscale
        out = g - dG @ gamma
        return out if np.all(np.isfinite(out)) else g


def fixed_point(problem: Problem, *, method: str = "auto", max_iter: int = 100, outer: str = "anderson",
                outer_tol: float = OUTER_TOL, outer_max_iter: int = 100, inner_tol: float = INNER_TOL,
                memory: int = 5, stall: int = 12, start=None, progress=None, deadline: float | None = None,
                evaluate=None, done=None, label: str = "outer iteration", **options) -> OuterRun:
    """Iterate on the shift s (n,) from ``start`` (default 0: the relaxation) until
    max_i |Φ_i(u(s)) − s_i| ≤ ``outer_tol``·(data scale of u), a stall, ``outer_max_iter``
    evaluations, ``deadline`` (a ``time.perf_counter()`` value) or ``done(inner)`` is True.
    ``evaluate(shifted)`` gives (inner result, its u of the shifted problem); by default the
    double solve :func:`rfverify.solve` with ``method``, ``max_iter``, ``inner_tol`` and
    ``options``."""
    from ..solver import solve

    if evaluate is None:
        def evaluate(shifted):
            inner = solve(shifted, method=method, tol=inner_tol, max_iter=max_iter, **options)
            return inner, inner.u

    check_outer(outer)
    t0 = time.perf_counter()
    say = progress or (lambda msg: None)
    scale = u_scale(problem)
    den = scale if scale > 0 else 1.0
    x = np.zeros(problem.n_contacts) if start is None else np.maximum(np.asarray(start, dtype=np.float64), 0.0)
    acc = Anderson(memory) if outer == "anderson" else None
    run = OuterRun(shift=x, shifted=problem, inner=None, method=outer, scale=scale, max_evaluations=outer_max_iter,
                   started=start is not None)
    best_res, since = math.inf, 0
    for k in range(outer_max_iter):
        shifted = shifted_problem(problem, x)
        s = applied_shift(problem, shifted)
        inner, u_inner = evaluate(shifted)
        if str(getattr(inner, "status", "")) == "InvalidInput":  # refused: no u to iterate on
            run.message = f"the inner solve refused the shifted problem: {inner.message}"
            run.refused = True
            break
        g = phi(problem, u_inner)
        res = float(np.max(np.abs(g - s), initial=0.0)) / den
        run.residuals.append(res)
        run.inner_iterations.append(int(inner.nit))
        run.inner_status.append(str(inner.status))
        say(f"{label} {k}: fixed-point residual {res:.2e} (inner {inner.status}, {inner.nit} iterations)")
        if not math.isfinite(res):
            run.message = f"the inner solve at evaluation {k} returned a non-finite answer ({inner.status})"
            break
        if res < best_res:
            run.best, run.shift, run.shifted, run.inner = k, s, shifted, inner
        if res <= outer_tol:
            run.converged = True
            run.message = f"fixed-point residual {res:.2e} ≤ {outer_tol:.0e} after {k + 1} evaluations"
            break
        if done is not None and done(inner):
            run.message = f"accepted after {k + 1} evaluations (residual {res:.2e})"
            break
        if res < 0.9 * best_res:
            since = 0
        else:
            since += 1
        if res >= best_res and acc is not None:
            acc.reset()  # the secant model failed (an active-set change): a plain step next
        best_res = min(best_res, res)
        if since >= stall:
            run.message = (f"stalled: the fixed-point residual has not fallen below 0.9 of its best "
                           f"({best_res:.2e}) for {stall} evaluations")
            break
        if deadline is not None and time.perf_counter() > deadline:
            run.message = f"time limit reached after {k + 1} evaluations (best residual {best_res:.2e})"
            run.timed_out = True
            break
        x = g if acc is None else acc.next(s, g)
        x = np.maximum(x, 0.0)  # Φ ≥ 0: a fixed point has s ≥ 0
    else:
        run.message = f"{outer_max_iter} evaluations without reaching {outer_tol:.0e} (best {best_res:.2e})"
    run.seconds = time.perf_counter() - t0
    return run


STAGE_TOL = 1e-9
"""Relative fixed-point residual at which a stage of the friction continuation (μ, μr scaled by
λ < 1) is done: the next stage only needs a start in its basin, not the last digits."""

MAX_STAGES = 12
"""Stages of the friction continuation at most (each at most ``outer_max_iter`` evaluations)."""

CONTINUE_ABOVE = 1e-8
"""The continuation runs only where the iteration stopped above this relative residual.  Below
it the stall is the double solves' own accuracy (their forward error in u, 1e-10 to 1e-9 on the
piles measured), which no start improves and the proven rounds close: on fresh files of seed
9411 a Millimetre stopped at 7e-11 and a SpheresPile at 2e-10, and ten stages of continuation
each ended at the same residual (6 s and 11 s for nothing)."""

SMALLEST_STEP = 1 / 32
"""The continuation gives up when a stage fails with a step in λ below this."""


def find_shift(problem: Problem, *, continuation: bool = True, start=None, progress=None,
               deadline: float | None = None, outer_tol: float = OUTER_TOL, **options) -> OuterRun:
    """:func:`fixed_point` from ``start``; where it stops above :data:`CONTINUE_ABOVE`, the friction continuation
    (``continuation``, default on): the same iteration on the problem with μ and μr scaled by λ
    (:func:`.model.friction_scaled`), λ = 0.5, 0.75, 1 (adaptive: a stage that fails halves the
    step and is tried again from the last λ reached), each stage started from the last one's
    shift times the ratio of the λs (Φ is linear in μ at fixed u), λ < 1 to
    :data:`STAGE_TOL`, λ = 1 to ``outer_tol``.  At λ → 0 the problem is frictionless, s = 0 is its
    fixed point, and the map contracts; the continuation follows that branch.  It exists for
    problems where the iteration from 0 lands on a branch with no fixed point (a generated
    181-contact Chute: a sliding contact whose Φ grows by 1.057 per unit of its own shift;
    docs/DECISIONS.md, "The physical problem").  Returns the better run on the problem itself
    (converged first, then the smaller residual); ``stages`` records every stage."""
    say = progress or (lambda msg: None)
    first = fixed_point(problem, start=start, progress=progress, deadline=deadline, outer_tol=outer_tol, **options)
    if (first.converged or not continuation or first.inner is None or first.timed_out or first.refused
            or not first.residual > CONTINUE_ABOVE):
        return first
    stages = [_stage(1.0, first, "from the given shift" if first.started else "from 0")]
    say(f"the fixed point from {'the given shift' if first.started else '0'} stopped at residual "
        f"{first.residual:.1e}: friction continuation (μ and μr scaled by λ, up to 1)")
    best, lam, shift, step = first, 0.0, None, 0.5
    while len(stages) < MAX_STAGES + 1 and step >= SMALLEST_STEP:
        trial = min(1.0, lam + step)
        begin = None if shift is None else shift * (trial / lam)
        run = fixed_point(friction_scaled(problem, trial), start=begin, deadline=deadline,
                          outer_tol=outer_tol if trial == 1.0 else max(outer_tol, STAGE_TOL),
                          label=f"continuation λ={trial:.4g}", progress=progress, **options)
        stages.append(_stage(trial, run, f"from λ={lam:.4g}"))
        if trial == 1.0 and run.inner is not None and (run.converged or run.residual < best.residual):
            best = run
        if run.timed_out or run.inner is None or run.refused or (trial == 1.0 and run.converged):
            break
        if run.converged:
            lam, shift = trial, run.shift
        else:
            step /= 2
    best.stages = stages
    best.started = first.started  # the run's start is the user's, not the last stage's scaled shift
    if best is not first:
        best.message = (f"friction continuation ({len(stages) - 1} stages after the iteration "
                        f"{stages[0]['from']} stopped at {first.residual:.1e}): {best.message}")
    elif not first.converged:
        best.message = (f"{first.message}; the friction continuation ({len(stages) - 1} stages) reached λ = "
                        f"{lam:.4g} and no better residual on the problem itself")
    best.seconds = sum(st["seconds"] for st in stages)
    return best


def _stage(friction: float, run: OuterRun, origin: str) -> dict:
    return {"friction": friction, "from": origin, "evaluations": run.evaluations,
            "inner_iterations": int(sum(run.inner_iterations)), "residual": run.residual,
            "converged": run.converged, "seconds": run.seconds, "message": run.message}
