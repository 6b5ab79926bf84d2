"""Check of a candidate solution (v, u, r) of a :class:`~rfverify.model.problem.Problem`, e.g. a
file's ``/solution``: nothing a file or a solver says about its own solution is trusted.

The measures are those of :mod:`rfverify.model.measures` (the one definition of "solved" in
rfverify), in float64; see there for their definitions and scales.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .problem import Problem, StoredSolution


@dataclass(frozen=True)
class SolutionCheck:
    """Result of :func:`check_solution`; ``missing`` lists absent vectors, ``zero`` the stored
    vectors that are identically zero (placeholders some generators store: the Siconos Chute
    file has v = 0 and r = 0)."""

    missing: tuple
    zero: tuple
    dynamics: float
    velocity: float
    primal_cone: float
    dual_cone: float
    complementarity: float

    @property
    def max_error(self) -> float:
        return max(self.dynamics, self.velocity, self.primal_cone, self.dual_cone,
                   self.complementarity)

    def ok(self, tol: float) -> bool:
        return not self.missing and self.max_error <= tol

    def verdict(self, tol: float) -> str:
        if self.missing:
            return f"incomplete: {', '.join(self.missing)} missing"
        worst = max(("dynamics", "velocity", "primal_cone", "dual_cone", "complementarity"),
                    key=lambda k: getattr(self, k))
        zero = f"{', '.join(self.zero)} all zero; " if self.zero else ""
        if self.max_error <= tol:
            return f"{zero}consistent to {self.max_error:.2e} (≤ {tol:g})"
        return f"{zero}NOT a solution to {tol:g}: {worst} residual {getattr(self, worst):.2e}"

    def as_dict(self) -> dict:
        d = asdict(self)
        d["missing"] = list(self.missing)
        d["zero"] = list(self.zero)
        d["max_error"] = self.max_error
        return d


def check_solution(problem: Problem, solution: StoredSolution) -> SolutionCheck:
    """Recompute the measures of ``solution`` for ``problem`` (float64).

    Missing u is recomputed as Hᵀv + w (its residual is then 0 by construction); a missing
    v or r makes the check incomplete (the measures involving it are reported NaN).
    """
    from .measures import measures

    if not all(hasattr(solution, name) for name in ("v", "u", "r")):
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("solution", f"is a {type(solution).__name__}, not a solution with v, u and r",
                                   fix="pass a StoredSolution(v=…, u=…, r=…), a result of rfverify.solve, "
                                       "or problem.solution")
    v, u, r = solution.v, solution.u, solution.r
    missing = tuple(k for k, a in (("v", v), ("r", r)) if a is None)
    zero = tuple(k for k, a in (("v", v), ("u", u), ("r", r)) if a is not None and not np.any(a))
    nan = float("nan")
    if missing:
        return SolutionCheck(missing, zero, nan, nan, nan, nan, nan)
    m = measures(problem, v, u, r, "float64")
    return SolutionCheck(missing=(), zero=zero, dynamics=m.dynamics, velocity=m.velocity,
                         primal_cone=m.primal_cone, dual_cone=m.dual_cone, complementarity=m.complementarity)
