"""The double-precision (mixed-precision) production solver: :func:`solve`."""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..lifting import KIND_NAMES, lift
from ..problem import Problem
from .cones import ProductCone
from .result import METHODS, Settings, SolveResult, Status

__all__ = ["solve", "Settings", "SolveResult", "Status", "METHODS"]


def solve(problem: Problem, method: str = "jqinv", tol: float = 1e-10, max_iter: int = 100,
          **options) -> SolveResult:
    """Solve a rolling-friction problem with Algorithm 1 (or the Clarabel peer).

    Parameters
    ----------
    problem : Problem
    method : {"jqinv", "qp2", "reduced", "noscaling", "clarabel"}
        Linear-system form (DESIGN §4); ``clarabel`` hands the same convex problem to Clarabel.
    tol : float
        Stop when max(pinfeas, dinfeas, μ) ≤ tol.
    max_iter : int
    **options
        Any other :class:`Settings` field (``sigma_rule``, ``extended_jordan``, ``refine_max``,
        ``reduce_cones``, ``drop_free_bodies``, ...).

    Returns
    -------
    SolveResult
        v (m,), u = Hᵀv + w (5n,), r (5n,) in the original variables, with status, message,
        trace and timings.
    """
    if method not in METHODS:
        raise ValueError(f"method {method!r} is not one of {', '.join(METHODS)}")
    unknown = set(options) - set(Settings.names())
    if unknown:
        raise TypeError(f"unknown solver option(s): {', '.join(sorted(unknown))}; "
                        f"valid: {', '.join(Settings.names())}")
    settings = Settings(tol=tol, max_iter=max_iter, **options)
    t0 = time.perf_counter()
    if method == "clarabel":
        from .clarabel_peer import solve_clarabel

        return solve_clarabel(problem, settings)

    lp = lift(problem, reduce_cones=settings.reduce_cones)
    M = problem.M_sym
    m = problem.n_dofs
    presolve = {"cone_kinds": lp.reduction_counts()}

    # Bodies no contact touches decouple: v = M⁻¹ f on their dofs (whole blocks of M).
    v = np.zeros(m)
    active = np.arange(m)
    if settings.drop_free_bodies:
        free = problem.contact_free_dofs
        if free.size:
            active = np.setdiff1d(np.arange(m), free)
            v[free] = splu(M[free][:, free].tocsc()).solve(problem.f[free])
        presolve["free_dofs"] = int(free.size)
    t_pre = time.perf_counter() - t0

    from . import ipm

    M_a = M[active][:, active].tocsc()
    H_a = lp.H_t[:, active].tocsr()
    cones = ProductCone(lp.n3, lp.n1)

    def describe(k):
        part = ("friction (N,T) cone", "rolling (N,R) cone", "normal cone")[lp.cone_part[k]]
        c = lp.cone_contact[k]
        return f"contact {c} {part} [{KIND_NAMES[lp.kinds[c]]} contact]"

    out = ipm.run(M_a, problem.f[active], H_a, lp.w_t, lp.J, cones, problem.n_contacts, method,
                  settings, describe_cone=describe)
    v[active] = np.asarray(out["v"], dtype=np.float64)
    r = lp.r_from_lifted(np.asarray(out["r_t"], dtype=np.float64))
    u = lp.u_from_v(v)
    timings = dict(out["timings"])
    timings["presolve"] = t_pre
    timings["total"] = time.perf_counter() - t0
    return SolveResult(
        v=v, u=u, r=r, status=out["status"], message=out["message"], nit=out["nit"],
        pinfeas=out["pinfeas"], dinfeas=out["dinfeas"], mu=out["mu"], trace=out["trace"],
        timings=timings, method=method, settings=settings, presolve=presolve,
        extras={"factorisations": out["factorisations"], "r_t": out["r_t"], "z": out["z"],
                "n_cones": {"L3": lp.n3, "L1": lp.n1}},
    )
