"""Algorithm 1's loop (DESIGN §4): Mehrotra predictor–corrector with NT scaling, infeasible
start, one step length for primal and dual, on the lifted Lorentz-cone form

    M v − H̃ᵀ r̃ = f,   H̃ v + w̃ = J z,   z ∘ Jᵀr̃ = 0,   z, Jᵀr̃ ∈ L3^{n3} × L1^{n1}.

Centring: the central path is z ∘ s = τ e cone by cone, which sums to zᵀs = τ·(number of
cones) because eᵀe = 1 per cone; the corrector therefore targets σ·μ_c·e with
μ_c = zᵀs / n_cones, while μ = zᵀs / n_contacts is the paper's measure (DESIGN §4).
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, field
from typing import Any

from .interfaces import PROMOTE, Breakdown, Direction, OutOfTime, Residuals


@dataclass
class Precision:
    """The precision a run works in: its :class:`~.interfaces.Space`, ``cones`` and
    ``newton``.  ``promote(v, r, z)`` (where the policy may ask for a wider precision)
    switches the three in place and returns the iterate converted; ``explain(exc)`` turns a
    precision's own domain error into a breakdown message (None: not one, re-raise)."""

    space: Any
    cones: Any
    newton: Any

    def promote(self, v, r, z):
        raise NotImplementedError(f"{type(self).__name__} has no wider precision")

    def explain(self, exc: Exception) -> str | None:
        return None


@dataclass
class LoopOutcome:
    """What :func:`iterate` ends with: the last iterate (v, r̃, z), the verdict the policy
    (or a breakdown) gave, the last iteration index k, one record per iterate (its columns:
    iter, mu, pinfeas, dinfeas, time, what the policy and the scaling add, and for an
    iterate that computed its step sigma, alpha_aff, alpha, gamma, limit (the scaling's: the
    cone that set the corrector's step, or None), solve_residual, refine_steps), and the
    seconds spent scaling and factoring ("factor") and solving ("solve")."""

    iterate: tuple
    verdict: Any
    k: int
    records: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)


def residuals(space, v, r, z, n_contacts: int) -> Residuals:
    """The iterate's residuals (:class:`~.interfaces.Residuals`) in ``space``."""
    s = space.JT @ r
    Mv, HTr, Hv, Jz = space.M @ v, space.HT @ r, space.velocity(v, r), space.J @ z
    r_d = Mv - HTr - space.f
    r_p = Hv + space.w - Jz
    gap = space.dot(z, s)
    norm = space.norm2
    pinf = norm(r_p) / max(norm(Jz), norm(Hv), norm(space.w), space.tiny)
    dinf = norm(r_d) / max(norm(Mv), norm(space.f), norm(HTr), space.tiny)
    return Residuals(s=s, r_d=r_d, r_p=r_p, dual_terms=(Mv, space.f, HTr), primal_terms=(Hv, space.w, Jz),
                     gap=gap, mu=float(gap / n_contacts), pinfeas=pinf, dinfeas=dinf)


def _predicted_points(space, iterate: tuple, s, pred: Direction, ds_aff, n_contacts: int):
    """``point_at(α)``: the iterate moved α along the predictor's direction, and its μ."""
    v, r, z = iterate

    def point_at(alpha: float):
        z_a = space.axpy(z, alpha, pred.dz)
        # inside the cones z·s ≥ 0: a negative value is the dot product's rounding, shown as 0
        mu = max(0.0, float(space.dot(z_a, space.axpy(s, alpha, ds_aff)) / n_contacts))
        return (space.axpy(v, alpha, pred.dv), space.axpy(r, alpha, pred.dr), z_a), mu
    return point_at


def iterate(precision: Precision, policy, start: tuple, *, n_contacts: int, n_cones: int,
            clock_origin: float) -> LoopOutcome:
    """Run Algorithm 1 from ``start`` = (v, r̃, z) (in ``precision``'s vectors) until the
    policy stops it or a breakdown ends it.  ``clock_origin`` is the perf_counter time the
    records' "time" column counts from."""
    v, r, z = start
    records = []
    timings = {"factor": 0.0, "solve": 0.0}
    gamma = policy.gamma0
    verdict = None
    k = 0
    try:
        for k in itertools.count():
            space = precision.space
            res = residuals(space, v, r, z, n_contacts)
            record = {"iter": k, "mu": res.mu, "pinfeas": res.pinfeas, "dinfeas": res.dinfeas,
                      "time": time.perf_counter() - clock_origin}
            records.append(record)
            decision = policy.observe(k, (v, r, z), res, record)
            if decision is PROMOTE:
                v, r, z = precision.promote(v, r, z)
                space = precision.space
                # μ stays the one the policy judged; the gap and residuals are the new precision's.
                res = residuals(space, v, r, z, n_contacts)
                res.mu = record["mu"]
            elif decision is not None:
                verdict = decision
                break

            t_factor = time.perf_counter()
            scaling = precision.cones.scaling(z, res.s)
            record.update(scaling.describe())
            precision.newton.update(scaling, k, res.mu)
            timings["factor"] += time.perf_counter() - t_factor

            a, b = -res.r_d, -res.r_p
            t_solve = time.perf_counter()
            pred = precision.newton.solve(a, b, scaling.affine_rhs(), "predictor")
            ds_aff = space.JT @ pred.dr
            alpha_aff = min(1.0, scaling.max_step(pred.dz, ds_aff))
            mu_aff = float(space.dot(space.axpy(z, alpha_aff, pred.dz), space.axpy(res.s, alpha_aff, ds_aff))
                           / n_contacts)
            stop = policy.after_predictor(k, alpha_aff, _predicted_points(space, (v, r, z), res.s, pred, ds_aff,
                                                                          n_contacts))
            if stop is not None:
                timings["solve"] += time.perf_counter() - t_solve
                verdict, (v, r, z) = stop
                break
            sigma = policy.sigma(res.mu, mu_aff, alpha_aff)
            mu_c = res.gap / n_cones
            corr = precision.newton.solve(a, b, scaling.corrector_rhs(sigma * mu_c, pred.dz, ds_aff), "corrector")
            ds = space.JT @ corr.dr
            timings["solve"] += time.perf_counter() - t_solve
            alpha = min(1.0, gamma * scaling.max_step(corr.dz, ds))
            record.update(sigma=sigma, alpha_aff=alpha_aff, alpha=alpha, gamma=gamma,
                          limit=getattr(scaling, "limit", None),
                          solve_residual=max(pred.residual, corr.residual), refine_steps=pred.steps + corr.steps)
            verdict = policy.after_direction(k, record, pred, corr)
            if verdict is not None:
                break
            v, r, z = space.move(v, alpha, corr.dv), space.move(r, alpha, corr.dr), space.move(z, alpha, corr.dz)
            gamma = policy.next_gamma(alpha)
            policy.after_step(alpha)
    except Breakdown as exc:
        verdict = policy.breakdown(f"iteration {k}: {exc}")
    except OutOfTime as exc:
        verdict = policy.out_of_time(f"iteration {k}: {exc}")
        if verdict is None:
            raise
    except KeyboardInterrupt:
        # Ctrl-C: a policy that can return its best iterate does (and says so); else it propagates.
        verdict = policy.interrupted(k)
        if verdict is None:
            raise
    except Exception as exc:  # a precision's own domain error (e.g. ConeDomainError), if it names one
        message = precision.explain(exc)
        if message is None:
            raise
        verdict = policy.breakdown(f"iteration {k}: {message}")
    return LoopOutcome(iterate=(v, r, z), verdict=verdict, k=k, records=records, timings=timings)
