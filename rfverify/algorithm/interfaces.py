"""The four interfaces Algorithm 1 is written against (see the package docstring), and the
few values that pass between the loop and them."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol


class Breakdown(Exception):
    """The iteration cannot go on at this iterate: a cone is not strictly interior, a
    factorisation lost definiteness, a solve is not finite.  The message says what failed,
    without the iteration (the loop prefixes "iteration k: ")."""


class OutOfTime(Exception):
    """The time limit was reached inside a long computation of an iteration (a double-double
    factorisation stopped by :func:`rfverify.extended.stoppable.run_stoppable` or not started, a
    conjugate-gradient solve): the run ends with the best iterate so far, the message saying
    what was stopped."""


PROMOTE = "promote"
"""What :meth:`Policy.observe` returns to continue in the next, wider precision."""


@dataclass
class Residuals:
    """The iterate's residuals in its precision: s = Jᵀr̃, r_d = Mv − H̃ᵀr̃ − f,
    r_p = H̃v + w̃ − Jz, the terms of each (``dual_terms`` = (Mv, f, H̃ᵀr̃),
    ``primal_terms`` = (H̃v, w̃, Jz)), the gap zᵀs in the precision's scalar type, μ = zᵀs / n
    (n contacts) as a float, and the paper's relative infeasibilities (DESIGN §4)."""

    s: Any
    r_d: Any
    r_p: Any
    dual_terms: tuple
    primal_terms: tuple
    gap: Any
    mu: float
    pinfeas: float
    dinfeas: float


@dataclass
class Direction:
    """A solved Newton direction (dv, dr̃, dz) in the precision's vectors, the refinement
    steps it took, its relative residual, and the solver's own report (``info``)."""

    dv: Any
    dr: Any
    dz: Any
    steps: int
    residual: float
    info: Any = None


class Space(Protocol):
    """The lifted problem in one precision.  ``M``, ``H``, ``HT``, ``J``, ``JT`` apply the data
    by ``@``; ``f``, ``w`` are the right-hand sides; vectors support ``+`` and ``-``."""

    M: Any
    H: Any
    HT: Any
    J: Any
    JT: Any
    f: Any
    w: Any
    tiny: float  # the floor of a norm in a denominator

    def velocity(self, v, r):
        """H̃v — the lifted contact velocity without w̃ (W̃r̃ on a local problem)."""

    def dot(self, x, y):
        """xᵀy in the precision's scalar type."""

    def norm2(self, x) -> float: ...

    def axpy(self, x, a: float, y):
        """x + a·y, a trial point (μ of the affine step)."""

    def move(self, x, a: float, y):
        """x + a·y in the iterate's precision: the step."""


class Scaling(Protocol):
    """The NT scaling at one iterate (z, s) and the cone operations that depend on it."""

    def describe(self) -> dict:
        """Per-iteration figures for the trace (e.g. max cond(Q_p), centrality)."""

    def affine_rhs(self):
        """The complementarity right-hand side of the predictor (σ = 0)."""

    def corrector_rhs(self, target, dz_aff, ds_aff):
        """The corrector's complementarity right-hand side for the centring target σμ_c·e and
        Mehrotra's second-order term from the predictor's (dz, ds)."""

    def max_step(self, dz, ds) -> float:
        """The largest α with z + α dz and s + α ds in the cones (inf when unbounded).  A
        scaling may also set ``limit`` = (cone index, "z" or "s"), the cone that sets it (None
        when unbounded); the loop records it for the corrector's step."""


class Cones(Protocol):
    def scaling(self, z, s) -> Scaling:
        """The NT scaling of (z, s); raises :class:`Breakdown` if a cone is not interior."""


class Newton(Protocol):
    name: str

    def update(self, scaling: Scaling, k: int, mu: float) -> None:
        """Build and factor the Newton matrix at ``scaling``; :class:`Breakdown` on failure."""

    def solve(self, a, b, c, phase: str) -> Direction:
        """The direction with M dv − H̃ᵀ dr̃ = a, H̃ dv − J dz = b (so b = −r_p solves the primal
        residual) and the complementarity rows = c, refined; ``phase`` is "predictor" or
        "corrector".  :class:`Breakdown` when it is not finite."""


class Policy(Protocol):
    gamma0: float

    def observe(self, k: int, iterate: tuple, residuals: Residuals, record: dict):
        """Iterate k before its step: None to go on, :data:`PROMOTE` to go on in the wider
        precision, or a verdict to stop.  May add columns to ``record``."""

    def sigma(self, mu: float, mu_aff: float, alpha_aff: float) -> float: ...

    def after_predictor(self, k: int, alpha_aff: float, point_at):
        """The predictor's direction is known, the corrector's not yet: None to go on (this
        default), or (verdict, (v, r̃, z)) to stop at that point instead of iterate k — one of
        ``point_at(α)`` = ((v, r̃, z) + α·predictor, its μ), for an α ≤ ``alpha_aff`` (the
        largest step the cones allow), that the policy accepted (the extended phases: proven)."""
        return None

    def after_direction(self, k: int, record: dict, predictor: Direction, corrector: Direction):
        """The step is computed, not taken: None to take it, or a verdict to stop."""

    def after_step(self, alpha: float) -> None: ...

    def next_gamma(self, alpha: float) -> float:
        """The step-to-boundary fraction of the next iteration after a step α."""

    def breakdown(self, message: str):
        """The verdict of a :class:`Breakdown` (message already prefixed)."""

    def interrupted(self, k: int):
        """Ctrl-C during iteration k: a verdict that returns the best iterate so far, or None (this
        default) to let the KeyboardInterrupt go on to the caller."""
        return None

    def out_of_time(self, message: str):
        """The verdict of an :class:`OutOfTime` (message already prefixed), or None (this
        default) to let it go on to the caller."""
        return None


class ReducedBackend(Protocol):
    """What :class:`.newton.ReducedNewton` solves with: the reduced system

        M dv − H̃ᵀ dr̃ = a,   H̃ dv + G dr̃ = t,   G = J Q_{p⁻²} Jᵀ,

    in a precision's vectors.  A back end subclasses this protocol and so has its default hooks:
    :meth:`observe` does nothing, :meth:`retry_solve` has nothing more accurate to try, and
    ``projects_primal`` is False: the reduced solve's primal residual is not projected away (where
    it is True, the space's ``lift(e, scaling)`` does it: :meth:`.newton.ReducedNewton._project_primal`)."""

    name: str
    projects_primal: bool = False

    def update(self, scaling: Scaling) -> bool:
        """Factor at the scaling; False when the matrix is not positive definite."""

    def solve(self, a, t) -> tuple:
        """(dv, dr̃) of the reduced system."""

    def observe(self, k: int, mu: float, solve_residual: float | None) -> None:
        """Once per iteration, before :meth:`update`, with the largest relative residual of the
        previous iteration's solves (None at the first)."""
        return None

    def retry_solve(self, residual: float) -> bool:
        """Asked after a solve whose refinement stalled at ``residual``: True when the back end
        has made its solves more accurate (the system is then solved again)."""
        return False

    def set_accuracy(self, residual_norm: float | None) -> None:
        """Before each Newton solve: the error ‖·‖∞ the reduced solve may leave in the
        complementarity row after the primal projection; the back end's inner iterative solves
        may stop there (None: at their own targets).  Nothing here."""
        return None
