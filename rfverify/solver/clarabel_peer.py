"""The Clarabel peer: the same convex problem handed to Clarabel (not Algorithm 1).

Clarabel solves  min ½xᵀPx + qᵀx  s.t.  Ax + s = b, s ∈ K.  With x = (v, z):

    P = [[M, 0], [0, 0]],  q = (−f, 0)
    [H̃, −J] x + s = −w̃,  s ∈ {0}           (H̃ v + w̃ = J z)
    [0, −I] x + s = 0,    s ∈ L3^{n3} × R₊^{n1}   (z in the lifted cones)

Stationarity in v gives M v − f + H̃ᵀ y_eq = 0, so r̃ = −y_eq.  The status is rfverify's
criterion (:mod:`rfverify.model.measures`) recomputed from the returned (v, u, r), exactly as for
Algorithm 1; Clarabel's own status is kept verbatim in ``extras["clarabel_status"]``.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from ..model.lifting import lift
from ..model.measures import measures
from ..model.problem import Problem
from .result import Settings, SolveResult, Status

_STATUS = {
    "Solved": Status.SOLVED,
    "AlmostSolved": Status.ALMOST_SOLVED,
    "MaxIterations": Status.MAX_ITERATIONS,
    "MaxTime": Status.MAX_ITERATIONS,
    "NumericalError": Status.NUMERICAL_ERROR,
    "InsufficientProgress": Status.INSUFFICIENT_PROGRESS,
}


def lifted_measures(M, f, H_t, w_t, J, v, r_t, z, n_contacts):
    """(pinfeas, dinfeas, μ) of DESIGN §4 for a lifted iterate, in float64."""
    Mv, HTr, Hv, Jz = M @ v, H_t.T @ r_t, H_t @ v, J @ z
    tiny = np.finfo(float).tiny
    pinf = np.linalg.norm(Hv + w_t - Jz) / max(np.linalg.norm(Jz), np.linalg.norm(Hv), np.linalg.norm(w_t), tiny)
    dinf = np.linalg.norm(Mv - HTr - f) / max(np.linalg.norm(Mv), np.linalg.norm(f), np.linalg.norm(HTr), tiny)
    mu = float(z @ (J.T @ r_t)) / n_contacts
    return float(pinf), float(dinf), mu


def solve_clarabel(problem: Problem, settings: Settings) -> SolveResult:
    import clarabel

    t0 = time.perf_counter()
    lp = lift(problem, reduce_cones=settings.reduce_cones)
    M = problem.M_sym.tocsc()
    m, nk, nz = problem.n_dofs, lp.nk, lp.nz
    P = sp.block_diag((sp.triu(M), sp.csc_matrix((nz, nz))), format="csc")
    q = np.concatenate((-problem.f, np.zeros(nz)))
    A = sp.vstack((sp.hstack((lp.H_t, -lp.J)), sp.hstack((sp.csr_matrix((nz, m)), -sp.identity(nz)))),
                  format="csc")
    b = np.concatenate((-lp.w_t, np.zeros(nz)))
    cones = [clarabel.ZeroConeT(nk)]
    cones += [clarabel.SecondOrderConeT(3)] * lp.n3
    if lp.n1:
        cones.append(clarabel.NonnegativeConeT(lp.n1))
    opts = clarabel.DefaultSettings()
    opts.verbose = bool(settings.verbose)  # Clarabel's own log, not Algorithm 1's columns
    opts.max_iter = settings.max_iter
    opts.tol_gap_abs = opts.tol_gap_rel = opts.tol_feas = settings.tol
    opts.tol_ktratio = min(opts.tol_ktratio, settings.tol)
    solver = clarabel.DefaultSolver(P, q, A, b, cones, opts)
    t_setup = time.perf_counter() - t0
    sol = solver.solve()
    status_name = str(sol.status).split(".")[-1]
    x = np.asarray(sol.x)
    v, z = x[:m], x[m:]
    r_t = -np.asarray(sol.z)[:nk]
    pinf, dinf, mu = lifted_measures(M, problem.f, lp.H_t, lp.w_t, lp.J, v, r_t, z, problem.n_contacts)
    r = lp.r_from_lifted(r_t)
    u = lp.u_from_v(v)
    # Clarabel's own stopping test is not ours: its answer is judged by rfverify's criterion
    # (rfverify.model.measures), exactly like Algorithm 1's; its own status is kept verbatim in
    # extras["clarabel_status"].
    judged = measures(problem, v, u, r, "longdouble")
    merit = judged.max
    if merit <= settings.tol:
        status = Status.SOLVED
    elif merit <= settings.almost_factor * settings.tol:
        status = Status.ALMOST_SOLVED
    else:
        status = _STATUS.get(status_name, Status.NUMERICAL_ERROR)
        if status in (Status.SOLVED, Status.ALMOST_SOLVED):
            status = Status.INSUFFICIENT_PROGRESS
    message = (f"Clarabel status {status_name}; rfverify criterion {merit:.2e} "
               f"({'≤' if merit <= settings.tol else '>'} tol = {settings.tol:g}, worst: {judged.worst()})")
    total = time.perf_counter() - t0
    return SolveResult(
        v=v, u=u, r=r, status=status, message=message, nit=int(sol.iterations), measures=judged,
        pinfeas=pinf, dinfeas=dinf, mu=mu, trace={}, timings={"total": total, "setup": t_setup,
                                                                "clarabel_solve": float(sol.solve_time)},
        method="clarabel", settings=settings, presolve={"cone_kinds": lp.reduction_counts()},
        extras={"clarabel_status": status_name, "r_t": r_t, "z": z,
                "clarabel_almost_tol": float(max(opts.reduced_tol_feas, opts.reduced_tol_gap_abs,
                                                 opts.reduced_tol_gap_rel))},
    )
