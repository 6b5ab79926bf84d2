"""The physical (Coulomb / rolling-resistance) problem through De Saxcé's shift.

Per contact i, with u = Hᵀv + w (or W r + q for a local file) and
Φ_i(u) = μ_i‖u_T,i‖ + μr_i‖u_R,i‖ (De Saxcé's term; Acary and Bourrier 2021 for rolling):

    M v = H r + f,   r_i ∈ K_i,   ũ_i = u_i + Φ_i(u) e_N ∈ K*_i,   r_iᵀũ_i = 0.

For a fixed shift s ∈ R^n this is the convex relaxation rfverify solves and proves, with w_N
replaced by w_N + s (q_N by q_N + s for a local file): its u' = u + s e_N plays ũ.  A solution
of the physical problem is a fixed point s = Φ(u(s)).  Φ reads only the tangential and rolling
components, which the shift leaves alone, so Φ(u') = Φ(u).

This module holds the data side: the shifted problem (exactly the file's data but the normal
rows of w or q), Φ in long double, the physical u of a (v, r), the problem's data scale of u,
and the physical conditions measured (information, not a proof: :mod:`.backward` proves).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..model.problem import SPACEDIM, LocalForm, Problem

PROBLEMS = ("relaxation", "coulomb")
"""The problems a file can pose: its convex relaxation (DESIGN §1, the default) or the physical
problem with De Saxcé's term (this package)."""


def _frozen(a: np.ndarray) -> np.ndarray:
    """``a`` made read-only, as a Problem's vectors are."""
    a.setflags(write=False)
    return a


def offsets(problem: Problem) -> np.ndarray:
    """The data vector the shift acts on: q of a local file, else w (5n,)."""
    return np.asarray(problem.local.q if problem.local is not None else problem.w, dtype=np.float64)


def physical_of_inner(problem: Problem, shifted: Problem, u_inner) -> np.ndarray:
    """The physical u of an inner answer: u_inner − ŝ e_N exactly (ŝ = w'_N − w_N), rounded once
    to float64 (5n,).  Closer to u* than :func:`physical_velocity` of the rounded r or v, whose
    rounding W·(r − r̂) is of order u·‖W‖‖r‖ where u itself may be many orders smaller."""
    from ..proof.dyadic import Dyadic

    return (Dyadic.from_float(u_inner) - Dyadic.from_float(offsets(shifted))
            + Dyadic.from_float(offsets(problem))).nearest()


def shifted_problem(problem: Problem, s) -> Problem:
    """``problem`` with w_N + s (and q_N + s for a local file), each sum rounded once to float64;
    every other datum, the equations posed and the provenance are the problem's own.  The
    shift actually applied is ``applied_shift(problem, shifted)`` (exactly w'_N − w_N)."""
    s = np.asarray(s, dtype=np.float64)
    w = np.array(problem.w, dtype=np.float64)
    w[0::SPACEDIM] = w[0::SPACEDIM] + s
    out = dataclasses.replace(problem, w=_frozen(w), solution=None, guesses=())
    if problem.local is not None:
        q = np.array(problem.local.q, dtype=np.float64)
        q[0::SPACEDIM] = q[0::SPACEDIM] + s
        out = dataclasses.replace(out, local=LocalForm(W=problem.local.W, q=_frozen(q),
                                                       significant_digits=problem.local.significant_digits))
    object.__setattr__(out, "M_sym", problem.M_sym)  # the same matrix: no second symmetrisation
    return out


def friction_scaled(problem: Problem, factor: float) -> Problem:
    """``problem`` with μ and μr multiplied by ``factor`` (0 < factor ≤ 1), every other datum its
    own: the homotopy the friction continuation walks (:func:`.outer.find_shift`).  At 1 the
    problem itself."""
    if factor == 1.0:
        return problem
    mu = _frozen(np.asarray(problem.mu, dtype=np.float64) * factor)
    mu_r = _frozen(np.asarray(problem.mu_r, dtype=np.float64) * factor)
    out = dataclasses.replace(problem, mu=mu, mu_r=mu_r, solution=None, guesses=())
    object.__setattr__(out, "M_sym", problem.M_sym)
    return out


def applied_shift(problem: Problem, shifted: Problem) -> np.ndarray:
    """The shift ``shifted`` carries, w'_N − w_N (q for a local file), in long double: exact
    where long double has 11 more bits than float64 and the exponents are close, which the
    proof does not rely on (it uses w'_N and w_N themselves, :mod:`.backward`)."""
    a = offsets(shifted)[0::SPACEDIM].astype(np.longdouble)
    b = offsets(problem)[0::SPACEDIM].astype(np.longdouble)
    return np.asarray(a - b, dtype=np.float64)


def phi(problem: Problem, u) -> np.ndarray:
    """Φ_i(u) = μ_i‖u_T,i‖ + μr_i‖u_R,i‖ per contact (n,), summed in long double and rounded to
    float64; ``u`` (5n,) in the FCLIB layout (N, T1, T2, R1, R2)."""
    U = np.asarray(u, dtype=np.longdouble).reshape(-1, SPACEDIM)
    mu = np.asarray(problem.mu, dtype=np.longdouble)
    mur = np.asarray(problem.mu_r, dtype=np.longdouble)
    out = mu * np.hypot(U[:, 1], U[:, 2]) + mur * np.hypot(U[:, 3], U[:, 4])
    return np.asarray(out, dtype=np.float64)


def physical_velocity(problem: Problem, v, r) -> np.ndarray:
    """u = Hᵀv + w of the file's data (W r + q for a local file), summed in long double and
    rounded to float64 (5n,)."""
    if problem.local is not None:
        return problem.local.velocity(r)
    ld = np.longdouble
    Ht = problem.H.T.tocsr().astype(ld)
    u = Ht @ np.asarray(v, dtype=ld) + np.asarray(problem.w, dtype=ld)
    return np.asarray(u, dtype=np.float64)


def u_scale(problem: Problem) -> float:
    """The data scale of u the backward error is relative to, a float estimate for the outer
    loop's stopping test: ‖HᵀM⁻¹f + w‖∞ (‖q‖∞ for a local file), the scale the proof's
    absolute mode uses (DESIGN §6.3); the certificate uses the proven lower bound of it."""
    if problem.local is not None:
        return float(np.max(np.abs(problem.local.q), initial=0.0))
    from scipy.sparse.linalg import splu

    import scipy.sparse as sp

    x = splu(sp.csc_matrix(problem.M_sym)).solve(np.asarray(problem.f, dtype=np.float64))
    u = problem.H.T @ x + problem.w
    return float(np.max(np.abs(u), initial=0.0))


@dataclasses.dataclass
class PhysicalResiduals:
    """The physical conditions measured at a float64 (u, r) in long double (information; the
    proof is :mod:`.backward`): ``fixed_point`` max_i |s_i − Φ_i(u)| for the shift s the answer
    was solved with (None when not given), ``normal`` the most negative u_N (0 when u_N ≥ 0:
    ũ ∈ K* is exactly u_N ≥ 0, as Φ(ũ) = Φ(u)), both divided by ``scale`` (the data scale of
    u); ``cone`` max_i (‖r_T‖ − μ r_N)⁺ + (‖r_R‖ − μr r_N)⁺ and ``complementarity`` |rᵀũ| with
    ũ = u + Φ(u)e_N, divided by ‖r‖∞ and by ‖r‖∞·scale."""

    fixed_point: float | None
    normal: float
    cone: float
    complementarity: float
    scale: float

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def physical_residuals(problem: Problem, u, r, s=None, scale: float | None = None) -> PhysicalResiduals:
    """:class:`PhysicalResiduals` of (u, r) — the file's own u, not the shifted one."""
    scale = u_scale(problem) if scale is None else scale
    den = scale if scale > 0 else 1.0
    ld = np.longdouble
    U = np.asarray(u, dtype=ld).reshape(-1, SPACEDIM)
    R = np.asarray(r, dtype=ld).reshape(-1, SPACEDIM)
    mu, mur = np.asarray(problem.mu, dtype=ld), np.asarray(problem.mu_r, dtype=ld)
    ph = mu * np.hypot(U[:, 1], U[:, 2]) + mur * np.hypot(U[:, 3], U[:, 4])
    comp = abs(float(np.sum(R[:, 0] * (U[:, 0] + ph) + np.sum(R[:, 1:] * U[:, 1:], axis=1))))
    r_inf = float(np.max(np.abs(R), initial=0.0)) or 1.0
    # r ∈ K: r_N ≥ 0 too (with μ = μr = 0 the other two terms do not see a pulling contact)
    cone = (np.maximum(-R[:, 0], 0) + np.maximum(np.hypot(R[:, 1], R[:, 2]) - mu * R[:, 0], 0)
            + np.maximum(np.hypot(R[:, 3], R[:, 4]) - mur * R[:, 0], 0))
    normal = max(0.0, -float(np.min(U[:, 0], initial=0.0)))
    fixed = None if s is None else float(np.max(np.abs(np.asarray(s, dtype=ld) - ph), initial=0.0)) / den
    return PhysicalResiduals(fixed, normal / den, float(np.max(cone, initial=0.0)) / r_inf,
                             comp / (den * r_inf), scale)


PHYSICAL_CHECKS = ("dynamics", "velocity", "cone", "normal", "complementarity")


def check_physical_solution(problem: Problem, solution, shift, tol: float) -> dict:
    """``rfverify info``'s check of a stored /solution that answers the physical problem (a file
    written by ``solve --problem coulomb --out``, with ``shift`` (n,) read from /coulomb): the
    relative residuals of M v = H r + f and u = Hᵀv + w (:func:`rfverify.check_solution`), and the
    physical conditions of :func:`physical_residuals` — r ∈ K (``cone``), u_N ≥ 0 (``normal``),
    rᵀũ = 0 (``complementarity``) — in float64 and long double, never trusting the file; the stored
    shift's distance from Φ(u) is ``fixed_point`` (information: any shift the answer solves is one
    a certificate can use).  Keys: those, ``max_error``, ``tolerance``, ``consistent``, ``problem``
    ("coulomb"), ``missing``, ``zero``, ``verdict``."""
    from ..model.check import check_solution

    chk = check_solution(problem, solution)
    out = {"problem": "coulomb", "missing": list(chk.missing), "zero": list(chk.zero), "tolerance": tol}
    where = "answer to the physical problem (/coulomb/shift stored beside it)"
    if chk.missing:
        return {**out, "consistent": False, "verdict": f"{where}, incomplete: {', '.join(chk.missing)} missing"}
    u = solution.u if solution.u is not None else physical_velocity(problem, solution.v, solution.r)
    ph = physical_residuals(problem, u, solution.r, shift)
    values = {"dynamics": chk.dynamics, "velocity": chk.velocity, "cone": ph.cone, "normal": ph.normal,
              "complementarity": ph.complementarity}
    worst = max(PHYSICAL_CHECKS, key=lambda k: values[k])
    ok = bool(values[worst] <= tol)
    zero = f"{', '.join(chk.zero)} all zero; " if chk.zero else ""
    verdict = (f"{where}: {zero}consistent to {values[worst]:.2e} (≤ {tol:g})" if ok else
               f"{where}: {zero}NOT a solution of it to {tol:g}: {worst} residual {values[worst]:.2e}")
    return {**out, **values, "fixed_point": ph.fixed_point, "max_error": float(values[worst]),
            "consistent": ok, "verdict": verdict}
