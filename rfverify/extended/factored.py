"""What every Newton-system back end that factors one matrix per iteration reports about it."""

from __future__ import annotations

import numpy as np


class FactoredBackend:
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
