"""The interface of the extended phase's Newton-system back ends (:class:`NewtonBackend`), and
what every one that factors one matrix per iteration reports about it (:class:`FactoredBackend`)."""

from __future__ import annotations

from typing import Protocol

import numpy as np


class NewtonBackend(Protocol):
    """A back end of the double-double phase (:mod:`.system`): it solves

        [ M    −H̃ᵀ ] [dv ]   [a]
        [ H̃     G  ] [dr̃] = [t],      G = J Q_{p⁻²} Jᵀ,

    with double-double vectors given as (hi, lo) pairs of float64 arrays.  A back end
    subclasses this protocol and so has its default hooks: :meth:`observe` and :meth:`prepare`
    do nothing, :meth:`retry_solve` has nothing more accurate to try, :meth:`stats` reports
    nothing.  :class:`.ipm.DDBackend` shows one to :class:`rfverify.algorithm.newton.ReducedNewton`."""

    name: str
    factorisations: int

    def update(self, ph, pl, pih, pil, spec) -> bool:
        """Factor at the NT point p, p⁻¹ and p's spectral data (:func:`.cones.nt_scaling`); False
        when the matrix is not positive definite or a contact block is singular."""

    def solve(self, a: tuple, t: tuple) -> tuple:
        """((dv_hi, dv_lo), (dr_hi, dr_lo)) from a, t given as (hi, lo) pairs."""

    def observe(self, k: int, mu: float, solve_residual: float | None) -> None:
        """Once per iteration, before the update (the hybrid switches forms here)."""
        return None

    def set_accuracy(self, residual_norm: float | None) -> None:
        """The error ‖·‖∞ the coming solves may leave in the complementarity row (after the
        primal projection), at which their inner iterations (conjugate gradients on a shifted
        float64 factor) may stop; None: their own targets.
        Nothing here (a back end without such iterations): :meth:`.contactspace.ContactSpace.set_accuracy`."""
        return None

    def retry_solve(self, residual: float) -> bool:
        """After a Newton solve that refined badly: True when the solves were made more accurate."""
        return False

    def prepare(self) -> None:
        """What the first update needs no iterate for, done ahead (the k-digit path runs it beside
        the double solve)."""
        return None

    def stats(self) -> dict:
        """What the factorisation costs (for benchmarks); {} where there is no single factor."""
        return {}

    def describe_cost(self) -> str:
        """Which factorisations ran and what they cost, for the time line ("" where not known)."""
        return ""


class FactoredBackend(NewtonBackend):
    """Base of the Newton-system back ends (:mod:`.system`): the cost of the one matrix
    ``self.chol`` a back end factors.  :class:`.system.Hybrid`, which holds two, has no
    ``chol``: its ``flops`` and ``stats`` raise AttributeError."""

    name = ""
    factorisations = 0

    def describe_cost(self) -> str:
        """The factorisations that ran, for the time line (a back end with a float64 engine
        says which precision ran and why: :meth:`.contactspace.ContactSpace.describe_cost`)."""
        n = int(self.factorisations)
        return f"{n} double-double factorisation{'s' if n != 1 else ''}"

    def flops(self) -> float:
        cc = np.diff(self.chol.Lp).astype(float)
        return float(np.sum(cc * cc) + self.chol.nnz_upper)

    def stats(self) -> dict:
        """What the factorisation costs (for benchmarks): order, stored upper entries, nnz(L)
        and Σ c_j² (column counts of L in the engine's order), factorisations, solves and
        refinement steps of the float64 engines."""
        ch = self.chol
        cc = np.diff(ch.Lp).astype(float)
        return {"engine": getattr(self, "engine", "ldl"), "precision": getattr(ch, "precision", "double-double"),
                "order": int(ch.n), "nnz_upper": int(ch.nnz_upper), "nnz_L": int(cc.sum()),
                "sum_c2": float(np.sum(cc * cc)), "factorisations": int(self.factorisations),
                "solves": int(getattr(ch, "solves", 0)), "refinement_steps": int(getattr(ch, "refinement_steps", 0))}
