"""Algorithm 1 (DESIGN §4): Mehrotra predictor–corrector with NT scaling, infeasible start,
one step length for primal and dual, on the lifted Lorentz-cone form

    M v − H̃ᵀ r̃ = f,   H̃ v + w̃ = J z,   z ∘ Jᵀr̃ = 0,   z, Jᵀr̃ ∈ L3^{n3} × L1^{n1}.

The linear-system form is pluggable (:mod:`rfverify.solver.kkt`).  Centring: the central path
is z ∘ s = τ e cone by cone, which sums to zᵀs = τ·(number of cones) because eᵀe = 1 per
cone; the corrector therefore targets σ·μ_c·e with μ_c = zᵀs / n_cones.  The stopping test
is the criterion of :mod:`rfverify.measures` on the (v, u, r) that would be returned — the
same function every recheck uses; DESIGN's pinfeas, dinfeas and μ = zᵀs / n are computed and
traced beside it.
"""

from __future__ import annotations

import functools
import time

import numpy as np

from ..errors import ConeDomainError
from .cones import ProductCone
from .kkt import FORMS
from .result import TRACE_FIELDS, Settings, Status

_TINY = np.finfo(float).tiny


class _Stop(Exception):
    def __init__(self, status: Status, message: str):
        self.status = status
        self.message = message


def _norm(x) -> float:
    return float(np.sqrt(np.sum(np.square(x, dtype=np.result_type(x, np.float64)))))


def run(M, f, H_t, w_t, J, cones: ProductCone, n_contacts: int, form: str, settings: Settings,
        judge, describe_cone=lambda k: f"cone {k}", keep_iterates: bool = False):
    """Run Algorithm 1.  Returns a dict with v, r_t, z, status, message, nit, trace, measures.

    ``judge(v, r̃)`` returns the :class:`rfverify.measures.Measures` of the iterate in the
    original variables (the one definition of "solved"); the run stops when its ``max`` is at
    most ``settings.tol``.  ``describe_cone(k)`` turns a global cone index into words (contact
    and part) for messages.  ``keep_iterates`` stores every iterate (v, r̃, z) in
    ``iterates`` (for lockstep diagnosis).
    """
    t0 = time.perf_counter()
    ext = np.longdouble if settings.extended_residuals else np.float64
    jd = np.longdouble if settings.extended_jordan else np.float64
    work = np.result_type(ext, jd)
    system = FORMS[form](M, H_t, J, cones, dtype_ref=np.longdouble if settings.refine_extended else np.float64,
                         static_reg=settings.static_reg, adaptive_reg=settings.adaptive_reg)
    solve_kkt = functools.partial(system.solve, refine_max=settings.refine_max,
                                  refine_extended=settings.refine_extended, refine_tol=settings.refine_tol)
    # A refined backward error this far above the refinement target means δ is in the way.
    eps_ref = float(np.finfo(np.longdouble if settings.refine_extended else np.float64).eps)
    reg_fallback_above = max(1e3 * eps_ref, 10 * (settings.refine_tol or 0.0))
    Mx, Hx, HTx = M.astype(work), H_t.astype(work), H_t.T.tocsr().astype(work)
    Jx, JTx = J.astype(work), J.T.tocsr().astype(work)
    f_x = np.asarray(f, dtype=work)
    w_x = np.asarray(w_t, dtype=work)
    m, nk = M.shape[0], H_t.shape[0]

    # Infeasible start: v = 0, r̃ with r̃_N = 1 on every contact (so Jᵀr̃ = e), z = e.
    v = np.zeros(m, dtype=work)
    e = cones.identity(work)
    r_t = np.zeros(nk, dtype=work)
    r_t[J.tocsc().indices[np.flatnonzero(e)]] = 1.0  # rows of the cone heads = N components
    z = e.copy()

    trace = {k: [] for k in TRACE_FIELDS}
    timings = {"factor": 0.0, "solve": 0.0}
    gamma = settings.gamma0
    best = None  # (merit, k, v, r_t, z, pinf, dinf, mu)
    since_best = 0
    best_each = [np.inf, np.inf, np.inf]  # best pinfeas, dinfeas, μ so far
    engaged = False  # a step with α ≥ 0.5 was taken
    status, message = Status.MAX_ITERATIONS, f"reached max_iter = {settings.max_iter}"
    k = 0
    record = None
    iterates = []
    try:
        for k in range(settings.max_iter + 1):
            if keep_iterates:
                iterates.append((v.copy(), r_t.copy(), z.copy()))
            s = JTx @ r_t
            Mv, HTr, Hv, Jz = Mx @ v, HTx @ r_t, Hx @ v, Jx @ z
            r_d = Mv - HTr - f_x
            r_p = Hv + w_x - Jz
            pinf = _norm(r_p) / max(_norm(Jz), _norm(Hv), _norm(w_x), _TINY)
            dinf = _norm(r_d) / max(_norm(Mv), _norm(f_x), _norm(HTr), _TINY)
            gap = float(z @ s)
            mu = gap / n_contacts
            judged = judge(v, r_t)
            merit = judged.max
            # merit is +inf while a scale is still 0 (v = 0 at the start of a problem with f = 0)
            if np.isnan(merit) or not np.isfinite(pinf + dinf + mu):
                raise _Stop(Status.NUMERICAL_ERROR, f"iteration {k}: residuals are not finite")
            # Progress = some measure not yet at tol fell 10% below its own best.  Judging
            # the merit alone stopped badly scaled problems at iteration 0: there μ rises
            # 1e6-fold while the infeasibilities fall (measured on the Millimetre scene).
            improved = False
            progress_measures = (max(judged.velocity, judged.dual_cone), judged.dynamics,
                                 max(judged.complementarity, judged.primal_cone))
            for i, val in enumerate(progress_measures):
                if val > settings.tol and val < 0.9 * best_each[i]:
                    improved = True
                best_each[i] = min(best_each[i], val)
            # The unit start can be far from a badly scaled problem's scale; the first steps
            # are then tiny (α ~ 1e-5 … 1e-3, growing) and nothing improves by 10% for several
            # iterations before the first long step.  Stall counting starts after that step.
            since_best = 0 if improved or not engaged else since_best + 1
            if best is None or merit < best[0]:
                best = (merit, k, v.copy(), r_t.copy(), z.copy(), pinf, dinf, mu, judged)
            lam2_z, cz = cones.min_lambda2(z)
            lam2_s, cs = cones.min_lambda2(s)
            record = dict(iter=k, criterion=merit, pinfeas=pinf, dinfeas=dinf, mu=mu, sigma=np.nan, alpha_aff=np.nan,
                          alpha=np.nan, gamma=np.nan, min_lam2_z=lam2_z, min_lam2_z_cone=cz,
                          min_lam2_s=lam2_s, min_lam2_s_cone=cs, max_cond_Qp=np.nan,
                          solve_residual=np.nan, refine_steps=0, time=time.perf_counter() - t0)
            if merit <= settings.tol:
                status, message = Status.SOLVED, (f"criterion {merit:.2e} ≤ tol (worst: {judged.worst()}); "
                                                  f"paper's max(pinfeas, dinfeas, mu) = {max(pinf, dinf, mu):.2e}")
                break
            if k == settings.max_iter:
                break
            if since_best >= settings.stall_iterations:
                raise _Stop(Status.INSUFFICIENT_PROGRESS,
                            f"iteration {k}: none of the primal, dual and gap measures above tol improved by 10% in "
                            f"{since_best} iterations (best max {best[0]:.2e} at iteration {best[1]})")
            if lam2_z <= 0 or lam2_s <= 0:
                which, c, val = ("z", cz, lam2_z) if lam2_z <= 0 else ("Jᵀr̃", cs, lam2_s)
                raise _Stop(Status.NUMERICAL_ERROR,
                            f"iteration {k}: λ2({which}) = {val:.3e} ≤ 0 at {describe_cone(c)}: the "
                            "iterate left the cone interior by rounding")

            # ---- scaling and factorisation
            zj, sj = z.astype(jd, copy=False), s.astype(jd, copy=False)
            tf = time.perf_counter()
            if system.symmetric:
                p, p_inv, lam, cond = cones.nt_scaling(zj, sj)
                system.set_point(p, p_inv)
                record["max_cond_Qp"] = float(cond.max(initial=1.0))
            else:
                system.set_point(z=zj, s=sj)
            try:
                system.factor()
            except Exception as exc:  # qdldl/SuperLU report singular pivots this way
                raise _Stop(Status.NUMERICAL_ERROR,
                            f"iteration {k}: factorisation of the {form} matrix failed ({exc})") from None
            timings["factor"] += time.perf_counter() - tf

            a = -r_d
            b = r_p
            ts = time.perf_counter()
            # ---- predictor (σ = 0)
            if system.symmetric:
                c_aff = -lam
            else:
                c_aff = -cones.product(zj, sj)
            dv_a, dr_a, dz_a, res_a, st_a = solve_kkt(a, b, c_aff)
            adaptive = settings.adaptive_reg and system.regularisable
            if adaptive and res_a > reg_fallback_above and system.regularised:
                # Refinement against the true matrix did not converge: δ is in the way.
                if system.refactor_unregularised():
                    retry = solve_kkt(a, b, c_aff)
                    if retry[3] < res_a:
                        dv_a, dr_a, dz_a, res_a, st_a = retry
                    else:  # no better: back to the regularised factorisation
                        system.refactor_regularised()
            elif adaptive and res_a > reg_fallback_above:
                # The factorisation without δ carried over from the last iteration solves
                # badly now: try δ again and keep whichever solves better.
                system.refactor_regularised()
                retry = solve_kkt(a, b, c_aff)
                if retry[3] < res_a:
                    dv_a, dr_a, dz_a, res_a, st_a = retry
                else:  # back to the factorisation that solved better, if it still factors
                    system.refactor_unregularised()
            # Redundant contacts need the factorisation without δ for several iterations in a
            # row (measured: 7 of the 34 iterations on a 1380-contact Chute); trying it first
            # there saves a regularised factorisation and a refined solve each time.
            system.prefer_unregularised = adaptive and not system.regularised
            _check_finite(k, "predictor", form, dv_a, dr_a, dz_a)
            ds_a = JTx @ dr_a
            max_step = cones.stepper(zj, sj)  # predictor and corrector step from the same point
            alpha_aff = min(1.0, max_step(dz_a.astype(jd), ds_a.astype(jd)))
            mu_aff = float((z + alpha_aff * dz_a) @ (s + alpha_aff * ds_a)) / n_contacts
            sigma = _sigma(settings.sigma_rule, mu_aff, mu, alpha_aff)

            # ---- corrector
            mu_c = gap / cones.n_cones
            if system.symmetric:
                dzs = system.Qp(dz_a.astype(jd))
                dss = system.Qp_inv(ds_a.astype(jd))
                xi = sigma * mu_c * cones.identity(jd) - cones.product(lam, lam) - cones.product(dzs, dss)
                c = cones.arrow_solve(lam, xi)
            else:
                c = (sigma * mu_c * cones.identity(jd) - cones.product(zj, sj)
                     - cones.product(dz_a.astype(jd), ds_a.astype(jd)))
            dv, dr, dz, res, st = solve_kkt(a, b, c)
            _check_finite(k, "corrector", form, dv, dr, dz)
            ds = JTx @ dr
            timings["solve"] += time.perf_counter() - ts
            alpha_max = max_step(dz.astype(jd), ds.astype(jd))
            alpha = min(1.0, gamma * alpha_max)
            record.update(sigma=sigma, alpha_aff=alpha_aff, alpha=alpha, gamma=gamma,
                          solve_residual=max(res_a, res), refine_steps=st_a + st)
            _append(trace, record)
            record = None
            v = v + alpha * dv.astype(work)
            r_t = r_t + alpha * dr.astype(work)
            z = z + alpha * dz.astype(work)
            gamma = 0.9 + 0.09 * alpha
            if not engaged and alpha >= 0.5:
                engaged = True
                best_each = [np.inf, np.inf, np.inf]  # μ may have grown on the way: judge from here
    except _Stop as stop:
        status, message = stop.status, stop.message
    except ConeDomainError as exc:
        where = describe_cone(exc.cone) if exc.cone is not None else "a cone"
        status = Status.NUMERICAL_ERROR
        message = f"iteration {k}: {exc.operation} failed at {where}: {exc}"
    if record is not None:
        _append(trace, record)

    if status is Status.SOLVED:
        out_v, out_r, out_z, pinf_o, dinf_o, mu_o, judged_o = v, r_t, z, pinf, dinf, mu, judged
    else:
        _, kb, out_v, out_r, out_z, pinf_o, dinf_o, mu_o, judged_o = best
        if best[0] <= settings.almost_factor * settings.tol:
            message = (f"{status}: {message}; best iterate (iteration {kb}) reached "
                       f"{best[0]:.2e} ≤ {settings.almost_factor:g}·tol")
            status = Status.ALMOST_SOLVED
        elif kb != k:
            message += f"; returning the best iterate (iteration {kb}, merit {best[0]:.2e})"
    timings["total"] = time.perf_counter() - t0
    return dict(v=out_v, r_t=out_r, z=out_z, status=status, message=message,
                nit=len(trace["iter"]) - 1 if trace["iter"] else 0,
                pinfeas=float(pinf_o), dinfeas=float(dinf_o), mu=float(mu_o), measures=judged_o,
                trace={key: np.asarray(val) for key, val in trace.items()}, timings=timings,
                factorisations=system.factor_count,
                unregularised_factorisations=system.unregularised_count, tol=settings.tol, iterates=iterates)


def _sigma(rule: str, mu_aff: float, mu: float, alpha_aff: float) -> float:
    ratio = max(mu_aff, 0.0) / mu if mu > 0 else 0.0
    if rule == "paper":
        expo = max(1.0, 3 * alpha_aff) if mu < 1e-5 else 1.0
        return min(1.0, ratio ** expo)
    expo = max(1.0, 3 * alpha_aff ** 2) if mu > 1e-5 else max(1.0, 3 * alpha_aff)
    return min(1.0, ratio ** expo) / 5


def _check_finite(k, phase, form, *vecs):
    for name, vec in zip(("dv", "dr̃", "dz"), vecs):
        if not np.all(np.isfinite(vec)):
            bad = int(np.flatnonzero(~np.isfinite(vec))[0])
            raise _Stop(Status.NUMERICAL_ERROR,
                        f"iteration {k}: the {phase} solve of the {form} system produced a "
                        f"non-finite {name}[{bad}]")


def _append(trace, record):
    for key in TRACE_FIELDS:
        trace[key].append(record[key])
