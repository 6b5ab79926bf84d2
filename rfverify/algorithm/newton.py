"""The Newton solve of the extended precisions, written once: dz eliminated through
Q_{p⁻¹}, the (dv, dr̃) system solved by a back end, every solve refined against the
unreduced three-block system (:func:`.rules.refined_newton`)."""

from __future__ import annotations

import math

from .interfaces import Breakdown, Direction, ReducedBackend
from .rules import refined_newton

NEWTON_ENOUGH = 1e-8
"""η of the inexact Newton solves of both extended precisions (:func:`.rules.refined_newton`):
refinement of a Newton solve stops once each block's residual is at most η times its right-hand
side.  The step is taken along the corrector, so its residual changes the next iterate's
residuals by a relative η; the precision's floor (1e-31 relative in double-double) is not needed
for that."""
PREDICTOR_ENOUGH = 1e-2
"""η of the predictor solve: its direction only sets σ (through α_aff and μ_aff) and the
second-order term of the corrector's right-hand side, and the corrector is solved to
:data:`NEWTON_ENOUGH` for whatever right-hand side it gets.  Same iterations, steps and proven
digits as with 1e-8 on the beds measured, 16% fewer float64 solves (docs/DECISIONS.md)."""

INNER_FRACTION = 0.1
"""A Newton solve with η asks the back end's inner iterative solves (conjugate gradients on a
shifted float64 factor) only for a reduced solve that leaves the complementarity row, after the
primal projection, within ``INNER_FRACTION``·η·‖c‖∞
(:meth:`~.interfaces.ReducedBackend.set_accuracy`), not for double-double accuracy: that row
keeps B r', r' the reduced solve's scaled residual and B with orthonormal columns
(:meth:`ReducedNewton._project_primal`), and the driver's refinement checks every block anyway
(docs/DECISIONS.md, "An exact lift")."""

RETRIES = 2
"""Times a Newton system is solved again after the back end made its solves more accurate: the
contact-space form steps up to checked solves, then, where its checked conjugate-gradient solves
are not enough, to the next shifted factor or the double-double factor
(:meth:`rfverify.extended.contactspace.ContactSpace.retry_solve`)."""


class ReducedNewton:
    """:class:`~.interfaces.Newton` for a ``space`` whose ``backend`` solves

        M dv − H̃ᵀ dr̃ = a,   H̃ dv + G dr̃ = t,   G = J Q_{p⁻²} Jᵀ

    (a :class:`~.interfaces.ReducedBackend`: ``update(scaling) -> bool``, ``solve(a, t) -> (dv, dr)``
    in the space's vectors, ``name``; its hooks ``observe(k, mu, last_residual)`` before each
    update, ``set_accuracy(residual_norm)`` before each Newton solve (what its inner iterative
    solves may leave in the complementarity row: :data:`INNER_FRACTION`), and
    ``retry_solve(residual) -> bool``, asked after a solve whose refinement
    stalled above ``floor`` short of ``enough``: True when the back end has made its solves more
    accurate, and the system is solved again; and ``projects_primal``: True where each reduced
    solve's primal residual is to be projected away, :meth:`_project_primal`, with the space's
    ``lift(e, scaling)`` — the double-double back ends' do, the multiple-precision tail's does
    not).  The complementarity row Q_p dz + Q_{p⁻¹} Jᵀ dr̃ = c gives
    dz = Q_{p⁻¹}(c − Q_{p⁻¹} Jᵀ dr̃), and the primal row H̃ dv − J dz = b then reads
    H̃ dv + G dr̃ = t with t = b + J Q_{p⁻¹} c.  ``scaling.quad(k, y)`` applies Q_{p^k}.
    Refinement: at most ``refine_max`` steps, down to the relative residual ``floor`` (about the
    precision's unit roundoff) or, with ``enough`` = η, until each block's residual is at most η
    times its right-hand side (:func:`.rules.refined_newton`); the predictor's solves with
    ``predictor_enough`` where given (its direction only sets σ and the corrector's second-order
    term)."""

    def __init__(self, space, backend: ReducedBackend, *, refine_max: int, floor: float, inf, enough: float | None = None,
                 predictor_enough: float | None = None):
        self.space = space
        self.backend = backend
        self.name = backend.name
        self.refine_max = refine_max
        self.floor = floor
        self.enough = enough
        # no η (refine to the floor) holds for the predictor too
        self.predictor_enough = None if enough is None else (predictor_enough or enough)
        self.inf = inf
        self.scaling = None
        self._last_residual = None  # the largest relative residual of the last iteration's solves
        self._residual = None
        self.projections = 0  # statistics: primal residuals projected away (_project_primal)

    def update(self, scaling, k: int, mu: float) -> None:
        self.backend.observe(k, mu, self._last_residual)
        self.scaling = scaling
        try:
            ok = self.backend.update(scaling)
        except ArithmeticError as exc:  # a singular contact factor
            raise Breakdown(str(exc)) from None
        if not ok:
            raise Breakdown(f"the {self.name} matrix lost definiteness")
        self._residual = None

    def _core(self, a, b, c):
        sp, q = self.space, self.scaling.quad
        dv, dr = self.backend.solve(a, b + sp.J @ q(-1, c))
        dz = q(-1, c - q(-1, sp.JT @ dr))
        if self.backend.projects_primal:
            dz = self._project_primal(b, c, dv, dr, dz)
        return dv, dr, dz

    def _project_primal(self, b, c, dv, dr, dz):
        """dz + δ with Jδ = −e_b, where e_b = b − H̃dv + J dz is the primal row's residual, and δ
        the one of least ‖Q_p δ‖ (the space's ``lift``), if that lowers the larger of the primal
        and complementarity rows' residuals relative to their right-hand sides; else dz.

        Why: t = b + J Q_{p⁻¹} c is dominated by its c part (by 1e13 and more near the end), so
        the reduced solve's error, small against t, lands in the primal row at up to 1e13 times
        ‖b‖ and more, and refinement took one to four more solves to bring it below η‖b‖.  Jδ = −e_b
        zeroes that row; the complementarity row gets Q_p δ = −B F⁻¹e_b instead, where
        B = Q_{p⁻¹}JᵀF⁻ᵀ has orthonormal columns (F Fᵀ = G = J Q_{p⁻²}Jᵀ): the scaled residual of the
        reduced solve, small against c.  The lift is exact in J to double-double rounding, however
        ill-conditioned G is; kept only where it helps, since that damage to c can exceed what it
        removes early on (docs/DECISIONS.md, "An exact lift")."""
        sp, inf = self.space, self.inf
        e_b = b - sp.velocity(dv, dr) + sp.J @ dz
        delta = sp.lift(-e_b, self.scaling)
        nb, nc = max(inf(b), 1e-300), max(inf(c), 1e-300)
        if max(inf(e_b + sp.J @ delta) / nb, inf(self.scaling.quad(1, delta)) / nc) < inf(e_b) / nb:
            self.projections += 1
            return dz + delta
        return dz

    def _unreduced_residual(self, a, b, c, dv, dr, dz):
        sp, q = self.space, self.scaling.quad
        return (a - sp.M @ dv + sp.HT @ dr, b - sp.velocity(dv, dr) + sp.J @ dz,
                c - q(1, dz) - q(-1, sp.JT @ dr))

    def _refined(self, a, b, c, enough):
        return refined_newton(self._core, self._unreduced_residual, a, b, c, inf=self.inf,
                              refine_max=self.refine_max, floor=self.floor, enough=enough)

    def solve(self, a, b, c, phase: str) -> Direction:
        enough = self.predictor_enough if phase == "predictor" else self.enough
        wanted = None if enough is None else INNER_FRACTION * enough * self.inf(c)
        self.backend.set_accuracy(wanted if wanted else None)
        dv, dr, dz, steps, res, settled = self._refined(a, b, c, enough)
        for _ in range(RETRIES):
            if settled or not self.backend.retry_solve(res):
                break
            # the back end made its solves more accurate: solve this system again
            dv, dr, dz, more, res, settled = self._refined(a, b, c, enough)
            steps += more
        if not math.isfinite(res) or not all(math.isfinite(self.inf(x)) for x in (dv, dr, dz)):
            raise Breakdown(f"the {self.name} solve failed (its direction is not finite)")
        self._residual = res if self._residual is None else max(self._residual, res)
        if phase == "corrector":
            self._last_residual = self._residual
        return Direction(dv=dv, dr=dr, dz=dz, steps=steps, residual=res)
