"""Moreau–Jean velocity-level time stepping whose one-step problems are solved by
:func:`rfverify.solve` and can be dumped (a "trace", as Siconos does for FCLIB).

One step from (q_k, v_k), step h, θ = 1:

1. contacts at q_k with gap ≤ margin (speculative contacts included);
2. M = M(q_k) (world inertia), H = H(q_k), and the one-step problem
       M v⁺ = H r + f,   f = M v_k + h (m g ⊕ −ω × I_w ω),
       u = Hᵀ v⁺ + w,    w_N = max(gap, 0)/h,  w_T = w_R = 0,
   with the rolling-friction cone of each contact (μ, μr from the scene's material tables);
3. solve it (jqinv by default); on failure keep the solver's best iterate and record it;
4. q_{k+1} = q_k + h v⁺ (orientation by the exponential map of h ω⁺, world frame).

Why θ = 1: with w_N = gap/h the condition u_N ≥ 0 says exactly that the gap predicted by
q_{k+1} = q_k + h v⁺ stays non-negative; θ = 1/2 would need w_N to depend on v_k to keep that
meaning, and FCLIB's w would then no longer be a gap.  (The Siconos Chute file in
``rfverify/data`` was also made with θ = 1.)  Restitution e = 0: a contact that is already
closed (gap ≤ 0) gets w_N = 0, so penetration is not pushed back (as in Siconos) and impacts
are perfectly inelastic.  Open contacts inside the margin give w_N > 0: they appear in the
problem and the solver finds them open (r = 0, u_N > 0) unless the bodies would close the gap
within the step.

The gyroscopic term −ω × (I_w ω) is explicit; it is exactly zero for spheres and only matters
for capsules.

De Saxcé shift.  The convex relaxation that rfverify.solve solves (DESIGN §1) lets a sliding
contact separate at u_N = μ‖u_T‖ + μr‖u_R‖; advancing with it would lift every sliding
body off its support by h·μ·slip per step (measured: chute spheres sliding at 0.25 m/s with
μ = 1 were 5e-5 m above the floor, i.e. open, after two steps).  So the step is solved with
w̃_N = w_N + s, s = μ‖u_T‖ + μr‖u_R‖, by the usual fixed point on s (as Siconos does for the
non-associated law): s starts from the velocity at the start of the step and is updated from
the solution until it moves by less than 1e-3·margin/h (then the normal drift it causes is
below a thousandth of the margin per step), at most ``desaxce_iterations`` solves.  A quiet
step needs one solve; an impact, where the slip changes, two or three.  The DUMPED problem is
the unshifted FCLIB problem (w_N = max(gap, 0)/h), like the problems Siconos writes.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numpy as np

from ..errors import RfverifyError
from ..model.problem import Problem
from .assembly import contact_matrix, generalized_velocity, mass_matrix
from .geometry import Bodies, Contacts, Statics, detect_contacts, quat_exp, quat_mul


class SceneError(RfverifyError, ValueError):
    """A scene cannot be generated as asked (unknown scene or parameter, impossible size, a
    step whose solve produced no usable iterate, ...).  The message says which and why."""


@dataclass
class StepRecord:
    """What one time step did.

    step : int                 index of the step (0-based) in this stepper's run
    time : float               simulated time at the start of the step
    n_contacts : int
    status : str               solver status ("Solved", ...) or "no contacts"
    success : bool             the step's problem was solved to ``tol`` (True without contacts)
    nit : int                  solver iterations (of the last solve of the step)
    message : str              solver message (empty on success)
    solve_time : float         seconds spent in rfverify.solve
    problem : Problem or None  the one-step problem, when the step was dumped
    contacts : Contacts        contacts of the step (geometry, for analysis)
    v, u, r : ndarray or None  the solution used to advance (None without contacts); u is
                               Hᵀv + w of the unshifted (dumped) problem
    desaxce_solves : int       solves spent on the De Saxcé fixed point
    """

    step: int
    time: float
    n_contacts: int
    status: str
    success: bool
    nit: int
    message: str
    solve_time: float
    problem: Problem | None = None
    contacts: Contacts | None = None
    v: np.ndarray | None = None
    u: np.ndarray | None = None
    r: np.ndarray | None = None
    desaxce_solves: int = 0


STEP_SOLVER_SETTINGS = {"sigma_rule": "paper", "start": "paper", "longdouble_below": None}
"""Solver settings of every step solve, fixed here: a scene's trajectory, hence its problems,
depends on each step's answer to the last digits, so the published collections must not change
when the solver's speed-oriented defaults do (these are the settings they were generated with)."""


@dataclass
class MoreauJean:
    """Moreau–Jean (θ = 1) time stepper for a rigid-body scene (see the module docstring).

    Parameters
    ----------
    bodies : Bodies            initial state (copied; advanced in place in ``self.bodies``)
    statics : Statics
    h : float                  time step
    gravity : (3,) array       acceleration of gravity (length/time²)
    margin : float             contacts with gap ≤ margin enter the problem
    mu_table, mu_r_table : 2-D arrays indexed by (material of A, material of B); μr is a
                               length (r_R is a moment, u_R an angular velocity)
    method, tol, max_iter      passed to :func:`rfverify.solve`
    gyroscopic : bool          include −ω × I_w ω (explicit)
    desaxce_iterations : int   solves per step for the De Saxcé fixed point (module docstring);
                               0 advances with the plain relaxation
    """

    bodies: Bodies
    statics: Statics
    h: float
    gravity: np.ndarray
    margin: float
    mu_table: np.ndarray
    mu_r_table: np.ndarray
    method: str = "jqinv"
    tol: float = 1e-10
    max_iter: int = 100
    gyroscopic: bool = True
    desaxce_iterations: int = 4
    time: float = 0.0
    steps_done: int = 0

    def __post_init__(self):
        self.bodies = self.bodies.copy()
        self.gravity = np.asarray(self.gravity, dtype=float).reshape(3)
        self.mu_table = np.atleast_2d(np.asarray(self.mu_table, dtype=float))
        self.mu_r_table = np.atleast_2d(np.asarray(self.mu_r_table, dtype=float))
        if not self.h > 0:
            raise SceneError(f"time step h = {self.h!r} must be > 0")

    # ------------------------------------------------------------------ one-step problem
    def coefficients(self, contacts: Contacts) -> tuple[np.ndarray, np.ndarray]:
        """(μ, μr) per contact from the material tables."""
        ma = self.bodies.material[contacts.a]
        mb = contacts.material_b
        return self.mu_table[ma, mb], self.mu_r_table[ma, mb]

    def external_forces(self) -> np.ndarray:
        """Generalised external force (6nb,): gravity, and the gyroscopic term if enabled."""
        b = self.bodies
        F = np.zeros((b.count, 6))
        F[:, :3] = b.mass[:, None] * self.gravity[None, :]
        if self.gyroscopic:
            Iw = b.world_inertia()
            F[:, 3:] = -np.cross(b.omega, np.einsum("bij,bj->bi", Iw, b.omega))
        return F.ravel()

    def one_step_arrays(self):
        """(M, H, f, w, mu, mu_r, contacts) of the step from the current state."""
        b = self.bodies
        contacts = detect_contacts(b, self.statics, self.margin)
        M = mass_matrix(b)
        f = M @ generalized_velocity(b) + self.h * self.external_forces()
        H = contact_matrix(b, contacts)
        w = np.zeros(5 * contacts.count)
        w[0::5] = np.maximum(contacts.gap, 0.0) / self.h
        mu, mu_r = self.coefficients(contacts)
        return M, H, f, w, mu, mu_r, contacts

    # ------------------------------------------------------------------ stepping
    def step(self, keep_problem: bool = False) -> StepRecord:
        """Advance one step; the record holds the problem when ``keep_problem``."""
        M, H, f, w, mu, mu_r, contacts = self.one_step_arrays()
        b = self.bodies
        rec_kw = dict(step=self.steps_done, time=self.time, n_contacts=contacts.count,
                      contacts=contacts)
        if contacts.count == 0:
            v = _free_velocity(b, f)
            record = StepRecord(status="no contacts", success=True, nit=0, message="",
                                solve_time=0.0, **rec_kw)
        else:
            problem = Problem.from_arrays(M, H, f, w, mu, mu_r, title="Moreau-Jean step",
                                          description=f"step {self.steps_done}, h = {self.h:g}")
            t0 = _time.perf_counter()
            result, iterations = self._solve_desaxce(problem, H, w, mu, mu_r, generalized_velocity(b))
            elapsed = _time.perf_counter() - t0
            if not np.all(np.isfinite(result.v)):
                raise SceneError(f"Moreau-Jean step {self.steps_done} ({contacts.count} contacts): "
                                 f"the solver returned a non-finite iterate ({result.status}: "
                                 f"{result.message})")
            v = result.v
            record = StepRecord(status=str(result.status), success=bool(result.success),
                                nit=int(result.nit), message="" if result.success else result.message,
                                solve_time=elapsed, problem=problem if keep_problem else None,
                                v=result.v, u=H.T @ result.v + w, r=result.r,
                                desaxce_solves=iterations, **rec_kw)
        self._advance(v)
        return record

    def _solve_desaxce(self, problem, H, w, mu, mu_r, v0):
        """Solve the step with the De Saxcé shift (fixed point, see the module docstring)."""
        from ..solver import solve

        def shift(v):
            U = (H.T @ v).reshape(-1, 5)
            return mu * np.linalg.norm(U[:, 1:3], axis=1) + mu_r * np.linalg.norm(U[:, 3:], axis=1)

        def run(p):
            try:
                return solve(p, method=self.method, tol=self.tol, max_iter=self.max_iter, **STEP_SOLVER_SETTINGS)
            except RfverifyError as exc:
                raise SceneError(f"Moreau-Jean step {self.steps_done}: the solver raised "
                                 f"{type(exc).__name__}: {exc}") from exc

        if self.desaxce_iterations < 1:
            return run(problem), 1
        s = shift(v0)
        tol = 1e-3 * self.margin / self.h
        prev = None
        for it in range(1, self.desaxce_iterations + 1):
            w_shift = w.copy()
            w_shift[0::5] += s
            result = run(Problem.from_arrays(problem.M, H, problem.f, w_shift, mu, mu_r))
            g = shift(result.v)
            if np.max(np.abs(g - s), initial=0.0) <= tol:
                break
            # Contact-wise secant on the fixed point s = g(s): the plain iteration converges
            # only at the rate ~μ·dslip/dr_N (0.3 for a sphere at μ = 0.3), too slowly at impacts.
            s_next = g
            if prev is not None:
                ds = s - prev[0]
                with np.errstate(divide="ignore", invalid="ignore"):
                    rate = np.where(np.abs(ds) > 1e-300, (g - prev[1]) / ds, 0.0)
                rate = np.clip(np.nan_to_num(rate), -0.9, 0.9)
                s_next = np.maximum(s + (g - s) / (1.0 - rate), 0.0)
            prev = (s, g)
            s = s_next
        return result, it

    def _advance(self, v: np.ndarray):
        b = self.bodies
        V = v.reshape(b.count, 6)
        b.vel = V[:, :3].copy()
        b.omega = V[:, 3:].copy()
        b.pos = b.pos + self.h * b.vel
        q = quat_mul(quat_exp(self.h * b.omega), b.quat)
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        b.quat = q
        self.time += self.h
        self.steps_done += 1

    def run(self, n_steps: int, dump_every: int = 1, callback=None) -> list[StepRecord]:
        """Take ``n_steps`` steps and return their records; the problem of every
        ``dump_every``-th step (steps dump_every−1, 2·dump_every−1, ...) that has at least one
        contact is kept in its record (the trace).  ``callback(record)`` after each step."""
        out = []
        for k in range(n_steps):
            rec = self.step(keep_problem=(k + 1) % dump_every == 0)
            out.append(rec)
            if callback is not None:
                callback(rec)
        return out


def _free_velocity(bodies: Bodies, f: np.ndarray) -> np.ndarray:
    """M⁻¹ f body by body (no contacts)."""
    F = f.reshape(bodies.count, 6)
    V = np.empty_like(F)
    V[:, :3] = F[:, :3] / bodies.mass[:, None]
    V[:, 3:] = np.linalg.solve(bodies.world_inertia(), F[:, 3:, None])[..., 0]
    return V.ravel()


__all__ = ["MoreauJean", "StepRecord", "SceneError", "Bodies", "Statics"]
