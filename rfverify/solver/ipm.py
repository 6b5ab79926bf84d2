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

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConeDomainError
from .cones import ProductCone
from .kkt import FORMS, ScalingPoint, _amax
from .result import TRACE_FIELDS, IterationInfo, Outcome, Settings, Status
from .termination import Termination, Verdict

_TINY = np.finfo(float).tiny


def _norm(x) -> float:
    return float(np.sqrt(np.sum(np.square(x, dtype=np.result_type(x, np.float64)))))


@dataclass
class RunResult(Outcome):
    """What one run of Algorithm 1 returns (one independent component or the whole problem):
    the lifted iterate (v, r̃, z) in the working precision, its status and measures, the
    trace, timings and factorisation counts, and (on request) every iterate."""

    v: np.ndarray
    r_t: np.ndarray
    z: np.ndarray
    measures: object
    trace: dict
    timings: dict
    factorisations: int
    unregularised_factorisations: int
    tol: float
    iterates: list = field(default_factory=list)
    # Iteration from which the run used the extended arithmetic (None: float64 throughout).
    extended_from: int | None = None


def run(M, f, H_t, w_t, J, cones: ProductCone, n_contacts: int, form: str, settings: Settings,
        judge, describe_cone=lambda k: f"cone {k}", keep_iterates: bool = False, callback=None,
        component: int = 0, t0: float | None = None, printer=None) -> RunResult:
    """Run Algorithm 1 on one lifted problem.

    ``judge(v, r̃)`` returns the :class:`rfverify.measures.Measures` of the iterate in the
    original variables (the one definition of "solved"); :class:`Termination` decides from it.
    ``callback(IterationInfo)`` is called once per iteration; returning True stops the run
    (status Stopped).  ``printer(IterationInfo)`` (verbose output) is called likewise.
    ``describe_cone(k)`` turns a global cone index into words for messages;
    ``keep_iterates`` stores every iterate (v, r̃, z) (for lockstep diagnosis).
    """
    t0 = time.perf_counter() if t0 is None else t0
    t_run = time.perf_counter()
    arithmetic = _Arithmetic(settings, M, H_t, J, f, w_t)
    extended = settings.extended_below is None or not _float64_safe(M.data, H_t.data, f, w_t)
    extended_from = 0 if extended else None
    work, jd, ref = arithmetic.dtypes(extended)
    system = FORMS[form](M, H_t, J, cones, dtype_ref=ref,
                         static_reg=settings.static_reg, adaptive_reg=settings.adaptive_reg,
                         refine_max=settings.refine_max,
                         refine_tol=None if settings.refine_tol == "adaptive" else settings.refine_tol,
                         forcing=REFINE_FORCING if settings.refine_tol == "adaptive" else None)
    term = Termination(settings, callback, t0)
    Mx, Hx, HTx, Jx, JTx, f_x, w_x = arithmetic.operators(work)
    m, nk = M.shape[0], H_t.shape[0]

    # Infeasible start: v = 0, r̃ with r̃_N = 1 on every contact (so Jᵀr̃ = e), z = e
    # (or θ·e, see velocity_scale).
    v = np.zeros(m, dtype=work)
    e = cones.identity(work)
    r_t = np.zeros(nk, dtype=work)
    r_t[J.tocsc().indices[np.flatnonzero(e)]] = 1.0  # rows of the cone heads = N components
    z = e.copy()
    if settings.start == "velocity_scaled":
        z *= velocity_scale(w_x)
    if settings.start == "least_squares":
        v, r_t, z = _least_squares_start(system, cones, f_x, w_x, JTx, v, r_t, z, jd, work)

    trace = {k: [] for k in TRACE_FIELDS}
    timings = {"factor": 0.0, "solve": 0.0}
    gamma = settings.gamma0
    record = None
    iterates = []
    verdict = None
    current = None
    k = 0
    double_short = False  # a float64 solve fell short of what the iteration needs
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
            # The sizes of the terms of the dual and primal residuals (see _adequate; only the
            # float64 phase asks).
            term_scales = None if extended else (max(_amax(Mv), _amax(f_x), _amax(HTr)),
                                                 max(_amax(Hv), _amax(w_x), _amax(Jz)), 0.0)
            judged = judge(v, r_t)
            lam2_z, cz = cones.min_lambda2(z)
            lam2_s, cs = cones.min_lambda2(s)
            record = dict(iter=k, criterion=judged.max, pinfeas=pinf, dinfeas=dinf, mu=mu, sigma=np.nan,
                          alpha_aff=np.nan, alpha=np.nan, gamma=np.nan, min_lam2_z=lam2_z, min_lam2_z_cone=cz,
                          min_lam2_s=lam2_s, min_lam2_s_cone=cs, max_cond_Qp=np.nan,
                          solve_residual=np.nan, refine_steps=0, time=time.perf_counter() - t0)
            current = ((v, r_t, z), judged, (pinf, dinf, mu))
            verdict = term.observe(k, judged, (pinf, dinf, mu), (v.copy(), r_t.copy(), z.copy()))
            if verdict is not None:
                break
            if not extended and (judged.max <= settings.extended_below or double_short):
                extended, extended_from = True, k
                work, jd, ref = arithmetic.dtypes(extended)
                Mx, Hx, HTx, Jx, JTx, f_x, w_x = arithmetic.operators(work)
                v, r_t, z = v.astype(work), r_t.astype(work), z.astype(work)
                system.set_refinement_dtype(ref)
                s = JTx @ r_t
                r_d = Mx @ v - HTx @ r_t - f_x
                r_p = Hx @ v + w_x - Jx @ z
                gap = float(z @ s)
            if lam2_z <= 0 or lam2_s <= 0:
                which, c, val = ("z", cz, lam2_z) if lam2_z <= 0 else ("Jᵀr̃", cs, lam2_s)
                verdict = Verdict(Status.NUMERICAL_ERROR,
                                  f"iteration {k}: λ2({which}) = {val:.3e} ≤ 0 at {describe_cone(c)}: the "
                                  "iterate left the cone interior by rounding")
                break

            # ---- scaling and factorisation
            zj, sj = z.astype(jd, copy=False), s.astype(jd, copy=False)
            tf = time.perf_counter()
            if system.symmetric:
                p, p_inv, lam, cond = cones.nt_scaling(zj, sj)
                point = ScalingPoint(p=p, p_inv=p_inv)
                record["max_cond_Qp"] = float(cond.max(initial=1.0))
            else:
                point = ScalingPoint(z=zj, s=sj)
            if not system.update(point):
                verdict = Verdict(Status.NUMERICAL_ERROR, f"iteration {k}: {system.failure}")
                break
            timings["factor"] += time.perf_counter() - tf

            a = -r_d
            b = r_p
            ts = time.perf_counter()
            # ---- predictor (σ = 0)
            c_aff = -lam if system.symmetric else -cones.product(zj, sj)
            pred = system.solve(a, b, c_aff, adapt=True)
            _check_finite(k, "predictor", form, pred)
            ds_a = JTx @ pred.dr
            max_step = cones.stepper(zj, sj)  # predictor and corrector step from the same point
            alpha_aff = min(1.0, max_step(pred.dz.astype(jd), ds_a.astype(jd)))
            mu_aff = float((z + alpha_aff * pred.dz) @ (s + alpha_aff * ds_a)) / n_contacts
            sigma = _sigma(rule_at(settings.sigma_rule, judged.max), mu_aff, mu, alpha_aff)

            # ---- corrector
            mu_c = gap / cones.n_cones
            if system.symmetric:
                dzs = cones.quad_operator(p)(pred.dz.astype(jd))
                dss = cones.quad_operator(p_inv)(ds_a.astype(jd))
                xi = sigma * mu_c * cones.identity(jd) - cones.product(lam, lam) - cones.product(dzs, dss)
                c = cones.arrow_solve(lam, xi)
            else:
                c = (sigma * mu_c * cones.identity(jd) - cones.product(zj, sj)
                     - cones.product(pred.dz.astype(jd), ds_a.astype(jd)))
            corr = system.solve(a, b, c)
            _check_finite(k, "corrector", form, corr)
            ds = JTx @ corr.dr
            timings["solve"] += time.perf_counter() - ts
            # In float64 a solve must give the iteration what it needs (_adequate); one that
            # falls short needs the extended arithmetic from the next iteration.
            double_short = not extended and not (_adequate(pred, settings.tol, term_scales)
                                                 and _adequate(corr, settings.tol, term_scales))
            alpha_max = max_step(corr.dz.astype(jd), ds.astype(jd))
            alpha = min(1.0, gamma * alpha_max)
            record.update(sigma=sigma, alpha_aff=alpha_aff, alpha=alpha, gamma=gamma,
                          solve_residual=max(pred.backward_error, corr.backward_error),
                          refine_steps=pred.steps + corr.steps)
            _append(trace, record)
            info = _info(record, component)
            record = None
            if printer is not None:
                printer(info)
            verdict = term.ask_callback(info)
            if verdict is not None:
                current = None  # the step is computed but not taken: return the best iterate
                break
            v = v + alpha * corr.dv.astype(work)
            r_t = r_t + alpha * corr.dr.astype(work)
            z = z + alpha * corr.dz.astype(work)
            gamma = 0.9 + 0.09 * alpha
            term.after_step(alpha)
    except _NonFinite as exc:
        verdict = Verdict(Status.NUMERICAL_ERROR, str(exc))
    except ConeDomainError as exc:
        where = describe_cone(exc.cone) if exc.cone is not None else "a cone"
        verdict = Verdict(Status.NUMERICAL_ERROR, f"iteration {k}: {exc.operation} failed at {where}: {exc}")
    if record is not None:
        _append(trace, record)
        if printer is not None:
            printer(_info(record, component))
    if verdict is None:  # unreachable: the loop ends by a verdict; kept for a clear failure
        verdict = Verdict(Status.NUMERICAL_ERROR, f"iteration {k}: the iteration ended without a verdict")
    status, message, ((out_v, out_r, out_z), judged_o, (pinf_o, dinf_o, mu_o)) = term.final(verdict, current)
    timings["total"] = time.perf_counter() - t_run
    return RunResult(v=out_v, r_t=out_r, z=out_z, status=status, message=message,
                     nit=len(trace["iter"]) - 1 if trace["iter"] else 0,
                     pinfeas=float(pinf_o), dinfeas=float(dinf_o), mu=float(mu_o), measures=judged_o,
                     trace={key: np.asarray(val) for key, val in trace.items()}, timings=timings,
                     factorisations=system.factor_count, unregularised_factorisations=system.unregularised_count,
                     tol=settings.tol, iterates=iterates, extended_from=extended_from)


# Data entries above this start the run in the extended arithmetic: their products and squares
# in residuals and norms would approach float64's range (tiny entries are harmless: they
# underflow gracefully, and the cone kernels rescale rows on their own).
FLOAT64_SAFE_MAGNITUDE = 2.0 ** 128


def _float64_safe(*arrays) -> bool:
    return all(np.all(np.abs(np.asarray(x, dtype=np.float64)) <= FLOAT64_SAFE_MAGNITUDE) for x in arrays)


class _Arithmetic:
    """The run's two arithmetics: float64 while the criterion is above
    ``settings.extended_below``, then the extended settings (longdouble where asked).  The
    data as operators in each dtype are built on first use."""

    def __init__(self, settings, M, H_t, J, f, w_t):
        self.settings = settings
        self.data = (M, H_t, J, f, w_t)
        self._ops = {}

    def dtypes(self, extended: bool):
        """(work, jordan, refinement) dtypes of the phase."""
        st = self.settings
        if not extended:
            return np.float64, np.float64, np.float64
        ext = np.longdouble if st.extended_residuals else np.float64
        jd = np.longdouble if st.extended_jordan else np.float64
        return np.result_type(ext, jd), jd, np.longdouble if st.refine_extended else np.float64

    def operators(self, work):
        """(M, H̃, H̃ᵀ, J, Jᵀ, f, w̃) in ``work``."""
        key = np.dtype(work)
        if key not in self._ops:
            M, H_t, J, f, w_t = self.data
            self._ops[key] = (M.astype(work), H_t.astype(work), H_t.T.tocsr().astype(work), J.astype(work),
                              J.T.tocsr().astype(work), np.asarray(f, dtype=work), np.asarray(w_t, dtype=work))
        return self._ops[key]


def velocity_scale(w_t) -> float:
    """θ = max(1, rms(w̃)) of ``start="velocity_scaled"`` (z = θ·e).  At v = 0 the primal
    equation reads J z = w̃, so a z far below the free velocities w̃ starts the run far from
    its own equations: on the Chutes (rms(w̃) ≈ 2.5, entries up to 30) the unit start took
    ~8 iterations of short steps while μ grew tenfold, and z = 0.1·e never converged."""
    w = np.asarray(w_t, dtype=np.float64)
    return max(1.0, float(np.sqrt(np.mean(np.square(w))))) if w.size else 1.0


def _least_squares_start(system, cones, f, w_t, JT, v, r_t, z, jd, work):
    """The Newton step from the origin at identity scaling (z = Jᵀr̃ = e, so the
    complementarity row reads dz + Jᵀdr̃ = 0), then each of z and s = Jᵀr̃ shifted by
    (1 + its most negative λ2)·e unless it is already interior; s is shifted through the
    normal rows of r̃ (Jᵀ of them is e).  Returns the paper's start unchanged if that solve
    fails."""
    e = cones.identity(jd)
    s = JT @ r_t
    if system.symmetric:
        p, p_inv, _, _ = cones.nt_scaling(z.astype(jd), s.astype(jd))
        point = ScalingPoint(p=p, p_inv=p_inv)
    else:
        point = ScalingPoint(z=z.astype(jd), s=s.astype(jd))
    if not system.update(point):
        return v, r_t, z
    sol = system.solve(np.asarray(f, dtype=work), np.asarray(w_t, dtype=work), np.zeros(cones.nz, dtype=jd))
    if not all(np.all(np.isfinite(x)) for x in (sol.dv, sol.dr, sol.dz)):
        return v, r_t, z
    v0, r0, z0 = sol.dv.astype(work), sol.dr.astype(work), sol.dz.astype(work)
    normal = r_t.copy()  # 1 on the normal rows: Jᵀ normal = e
    for x, shift_along in ((z0, None), (r0, normal)):
        lam2 = cones.lambda2((JT @ x) if shift_along is not None else x)
        worst = -float(lam2.min(initial=0.0))
        if worst >= -1e-8 * max(float(np.max(np.abs(x), initial=0.0)), 1.0):
            x += (1.0 + worst) * (e.astype(work) if shift_along is None else shift_along)
    return v0, r0, z0


# Settings.refine_tol = "adaptive": the forcing term of the inexact-Newton test that may end
# refinement early (KKTSystem.refined).
REFINE_FORCING = 1e-4


# A dual or primal block residual of a float64 solve within TOL_MARGIN·tol of the size of
# that residual's terms is resolved as far as the answer can see (see _adequate).
TOL_MARGIN = 1e-2


def _adequate(info, tol, term_scales) -> bool:
    """Whether a float64 solve gave the iteration what it needs (else the run switches to
    the extended arithmetic): it converged (the inexact-Newton test or the refinement target),
    or every block residual e_i is at most max(REFINE_FORCING·‖rhs_i‖, TOL_MARGIN·tol·s_i),
    with s_i the size of the terms of the dual and primal residuals (‖Mv‖, ‖f‖, ‖H̃ᵀr̃‖ and
    ‖H̃v‖, ‖w̃‖, ‖Jz‖, ∞-norms) and s_i = 0 for complementarity.  Near the solution the dual
    and primal right-hand sides are ~1e-10 of their terms; asking for 1e-4 of that asks for
    rounding, and longdouble does not deliver it either (a fresh 1000-contact Chute: same
    iterations, same answer, its last two iterations five times dearer)."""
    if info.converged:
        return True
    if len(info.block_residuals) != 3:
        return False
    return all(e <= max(REFINE_FORCING * rn, TOL_MARGIN * tol * sc)
               for e, rn, sc in zip(info.block_residuals, info.rhs_norms, term_scales))


def _info(record, component) -> IterationInfo:
    return IterationInfo(component=component, iteration=int(record["iter"]), criterion=float(record["criterion"]),
                         pinfeas=float(record["pinfeas"]), dinfeas=float(record["dinfeas"]), mu=float(record["mu"]),
                         sigma=float(record["sigma"]), alpha_aff=float(record["alpha_aff"]),
                         alpha=float(record["alpha"]), min_lam2_z=float(record["min_lam2_z"]),
                         min_lam2_s=float(record["min_lam2_s"]), max_cond_Qp=float(record["max_cond_Qp"]),
                         solve_residual=float(record["solve_residual"]), elapsed=float(record["time"]))


# sigma_rule="hybrid": Mehrotra's cubic σ, bounded below by HYBRID_SIGMA_FLOOR, while the
# iterate's criterion is above HYBRID_SWITCH; the paper's rule below it (Settings.sigma_rule).
HYBRID_SWITCH = 1e-4
HYBRID_SIGMA_FLOOR = 0.2


def rule_at(rule: str, criterion: float) -> str:
    """The σ rule one iteration uses: ``rule`` itself, or for ``hybrid`` "mehrotra" (the
    floored cube of :func:`_sigma`) while ``criterion`` (the iterate's, before the step) is
    above :data:`HYBRID_SWITCH` and "paper" from there on.  The diagnosis's lockstep asks the
    same question of the double run's trace."""
    if rule == "hybrid":
        return "mehrotra" if criterion > HYBRID_SWITCH else "paper"
    return rule


def _sigma(rule: str, mu_aff: float, mu: float, alpha_aff: float) -> float:
    ratio = max(mu_aff, 0.0) / mu if mu > 0 else 0.0
    if rule == "paper":
        expo = max(1.0, 3 * alpha_aff) if mu < 1e-5 else 1.0
        return min(1.0, ratio ** expo)
    if rule == "mehrotra":
        # The floor: with σ far below it the FE sticking blocks ended 1.3–2.8× less accurate
        # at the same criterion than under the paper's rule (docs/DECISIONS.md, "σ rule").
        return max(HYBRID_SIGMA_FLOOR, min(1.0, ratio ** 3))
    expo = max(1.0, 3 * alpha_aff ** 2) if mu > 1e-5 else max(1.0, 3 * alpha_aff)
    return min(1.0, ratio ** expo) / 5


class _NonFinite(Exception):
    """A linear solve produced NaN or Inf (the message names iteration, phase and entry)."""


def _check_finite(k, phase, form, info):
    for name, vec in (("dv", info.dv), ("dr̃", info.dr), ("dz", info.dz)):
        if not np.all(np.isfinite(vec)):
            bad = int(np.flatnonzero(~np.isfinite(vec))[0])
            raise _NonFinite(f"iteration {k}: the {phase} solve of the {form} system produced a "
                             f"non-finite {name}[{bad}]")


def _append(trace, record):
    for key in TRACE_FIELDS:
        trace[key].append(record[key])
