"""The path that *produces* k-digit solutions: a double (mixed-precision) solve, then warm
iterations of the mpmath reference from the double iterate, the result rounded to double and
certified against an independent reference solve (DESIGN §6).

The warm iterations continue Algorithm 1 from the last double iterate (v, r̃, z) — it is
interior and near the central path, so a handful of high-precision iterations take μ from
~1e-12 to far below 10^(−k) — and the certificate comes from a *separate*, independent
reference run, never from the run that produced the answer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .certification import Certificate, certify
from .lifting import lift
from .problem import Problem
from .solver import SolveResult, solve


@dataclass
class RefinedSolution:
    """v (m,), u (5n,), r (5n,) rounded to double; ``double`` is the double solve it started
    from, ``warm`` the reference warm run, ``certificate`` the independent check."""

    v: np.ndarray
    u: np.ndarray
    r: np.ndarray
    double: SolveResult
    warm: object
    certificate: Certificate

    @property
    def success(self) -> bool:
        return self.certificate.certified


def warm_start_from(problem: Problem, result: SolveResult) -> dict:
    """The double iterate in the reference's lifted layout (cones contact by contact)."""
    lp = lift(problem, reduce_cones=result.settings.reduce_cones)
    z = np.asarray(result.extras["z"])
    cones = [z[3 * c:3 * c + 3] for c in range(lp.n3)] + [z[3 * lp.n3 + k:3 * lp.n3 + k + 1] for k in range(lp.n1)]
    order = np.lexsort((lp.cone_part, lp.cone_contact))
    return {"v": np.asarray(result.v), "r_t": np.asarray(result.extras["r_t"]),
            "z": [cones[i] for i in order]}


def solve_to_digits(problem: Problem, digits: int = 10, method: str = "jqinv", dps: int | None = None,
                    **options) -> RefinedSolution:
    """Solve ``problem`` so that v, u, Hr (and r where unique) are right to ``digits`` digits,
    and certify it.  ``dps`` (default 2·digits + 16) is the accuracy of the reference runs.

    The warm run stops at μ ≤ 10^(−2·digits−6): near a solution without strict
    complementarity the error of an interior-point iterate behaves like √μ, so a tolerance of
    10^(−digits−6) gave only 8–9 digits (measured on the bundled Chute problem)."""
    import reference

    dps = dps or 2 * digits + 16
    double = solve(problem, method=method, tol=options.pop("tol", 1e-10), **options)
    if method == "clarabel" or "z" not in double.extras or not problem.n_contacts:
        raise ValueError("the warm path needs an Algorithm 1 iterate (not the Clarabel peer)")
    warm = reference.solve(problem, dps=dps, tol=10.0 ** (-(2 * digits + 6)),
                           warm_start=warm_start_from(problem, double))
    v, u, r = warm.as_float("v"), warm.as_float("u"), warm.as_float("r")
    cert = certify(problem, v, u, r, digits=digits, dps=dps)
    return RefinedSolution(v=v, u=u, r=r, double=double, warm=warm, certificate=cert)
