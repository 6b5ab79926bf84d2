"""Independent check of a candidate solution (v, u, r) of a :class:`~rfverify.problem.Problem`.

Nothing a file or a solver says about its own solution is trusted: the residuals are
recomputed from the problem data.  This is the cheap, double-precision check used by
``rfverify info`` on a file's ``/solution``; certification in high precision lives elsewhere.

Measures (all relative, dimensionless; 0 is exact):

``dynamics``        ‖M v − H r − f‖∞ / max(‖M v‖∞, ‖H r‖∞, ‖f‖∞)
``velocity``        ‖u − Hᵀ v − w‖∞ / max(‖u‖∞, ‖Hᵀ v‖∞, ‖w‖∞)
``primal_cone``     max_i max(‖r_T‖ − μ r_N, ‖r_R‖ − μr r_N, −r_N, 0) / ‖r‖∞      (r ∈ K)
``dual_cone``       max_i max(μ‖u_T‖ + μr‖u_R‖ − u_N, −u_N, 0) / U∞             (u ∈ K*)
``complementarity`` |rᵀu| / (‖r‖₂ U₂)

with U = max(‖u‖, ‖Hᵀv‖, ‖w‖): u is a difference of Hᵀv and −w and is ~0 at sticking
contacts, so its own norm is no scale for its errors; the terms it is computed from are.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .problem import SPACEDIM, Problem, StoredSolution

_TINY = np.finfo(float).tiny


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
    """Recompute the residuals of ``solution`` for ``problem`` (see module docstring).

    Missing u is recomputed as Hᵀv + w (its residual is then 0 by construction); a missing
    v or r makes the check incomplete (the residual measures involving it are reported NaN).
    """
    v, u, r = solution.v, solution.u, solution.r
    missing = tuple(k for k, a in (("v", v), ("r", r)) if a is None)
    zero = tuple(k for k, a in (("v", v), ("u", u), ("r", r)) if a is not None and not np.any(a))
    nan = float("nan")
    if missing:
        return SolutionCheck(missing, zero, nan, nan, nan, nan, nan)
    Mv = problem.M_sym @ v
    Hr = problem.H @ r
    dyn = _rel(Mv - Hr - problem.f, Mv, Hr, problem.f)
    HTv = problem.H.T @ v
    if u is None:
        u = HTv + problem.w
    vel = _rel(u - HTv - problem.w, u, HTv, problem.w)
    rc = r.reshape(-1, SPACEDIM)
    uc = u.reshape(-1, SPACEDIM)
    mu, mu_r = problem.mu, problem.mu_r
    rT = np.hypot(rc[:, 1], rc[:, 2])
    rR = np.hypot(rc[:, 3], rc[:, 4])
    primal = np.maximum.reduce([rT - mu * rc[:, 0], rR - mu_r * rc[:, 0], np.zeros(len(mu))])
    uT = np.hypot(uc[:, 1], uc[:, 2])
    uR = np.hypot(uc[:, 3], uc[:, 4])
    dual = np.maximum(mu * uT + mu_r * uR - uc[:, 0], 0.0)
    # With μ = μr = 0 the norm conditions no longer force r_N ≥ 0 (nor u_N ≥ 0): check signs.
    primal = np.maximum(primal, -rc[:, 0])
    dual = np.maximum(dual, -uc[:, 0])
    rmax = max(np.abs(r).max(initial=0.0), _TINY)
    umax = max(np.abs(u).max(initial=0.0), np.abs(HTv).max(initial=0.0),
               np.abs(problem.w).max(initial=0.0), _TINY)
    u2 = max(np.linalg.norm(u), np.linalg.norm(HTv), np.linalg.norm(problem.w))
    comp = abs(float(r @ u)) / max(np.linalg.norm(r) * u2, _TINY)
    return SolutionCheck(
        missing=(), zero=zero, dynamics=dyn, velocity=vel,
        primal_cone=float(max(primal.max(initial=0.0), 0.0) / rmax),
        dual_cone=float(max(dual.max(initial=0.0), 0.0) / umax), complementarity=float(comp),
    )


def _rel(residual, *terms) -> float:
    scale = max(max(np.abs(t).max(initial=0.0) for t in terms), _TINY)
    return float(np.abs(residual).max(initial=0.0) / scale)


def criterion(problem: Problem, v, u, r, dtype=np.longdouble) -> dict:
    """The stopping criterion of Algorithm 1 recomputed from (v, u, r) in the original
    variables, in ``dtype`` (default longdouble), from the problem data only.

    Returns relative measures ``dinfeas`` = ‖Mv − f − Hr‖₂/max(‖Mv‖, ‖f‖, ‖Hr‖) (H̃ᵀr̃ = Hr),
    ``velocity`` (u = Hᵀv + w), ``mu`` = |uᵀr|/n (= zᵀJᵀr̃/n when Jz = ũ), ``cone`` = the
    larger of the K and K* violations (in place of pinfeas: the split of u0 between the two
    lifted cones is not part of a stored solution), and ``max`` of all four.
    """
    M = problem.M_sym.astype(dtype)
    H = problem.H.astype(dtype)
    v, u, r = (np.asarray(x, dtype=dtype) for x in (v, u, r))
    f, w = problem.f.astype(dtype), problem.w.astype(dtype)
    Mv, Hr, HTv = M @ v, H @ r, H.T @ v

    def nrm(x):
        s = np.abs(x).max(initial=0)
        return s * np.sqrt(np.sum((x / s) ** 2)) if s > 0 else s

    tiny = np.finfo(dtype).tiny
    dinf = nrm(Mv - f - Hr) / max(nrm(Mv), nrm(f), nrm(Hr), tiny)
    vel = nrm(u - HTv - w) / max(nrm(u), nrm(HTv), nrm(w), tiny)
    mu_gap = abs(u @ r) / problem.n_contacts
    rc, uc = r.reshape(-1, SPACEDIM), u.reshape(-1, SPACEDIM)
    mu, mu_r = problem.mu.astype(dtype), problem.mu_r.astype(dtype)
    primal = np.maximum.reduce([np.hypot(rc[:, 1], rc[:, 2]) - mu * rc[:, 0],
                                np.hypot(rc[:, 3], rc[:, 4]) - mu_r * rc[:, 0], -rc[:, 0],
                                np.zeros(len(mu), dtype)])
    dual = np.maximum.reduce([mu * np.hypot(uc[:, 1], uc[:, 2]) + mu_r * np.hypot(uc[:, 3], uc[:, 4])
                              - uc[:, 0], -uc[:, 0], np.zeros(len(mu), dtype)])
    u_scale = max(np.abs(u).max(initial=0), np.abs(HTv).max(initial=0), np.abs(w).max(initial=0), tiny)
    # r shares units with M v and f; at an all-open solution r is noise and no scale itself.
    r_scale = max(np.abs(r).max(initial=0), np.abs(Mv).max(initial=0), np.abs(f).max(initial=0), tiny)
    cone = max(primal.max() / r_scale, dual.max() / u_scale)
    out = {"dinfeas": float(dinf), "velocity": float(vel), "mu": float(mu_gap), "cone": float(cone)}
    out["max"] = max(out.values())
    return out
