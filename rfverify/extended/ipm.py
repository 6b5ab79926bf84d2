"""The extended-precision phase: Algorithm 1 continued in double-double arithmetic.

Started from an interior iterate of the double solver (or from a candidate solution pushed
into the interior), it drives μ from ~1e-10 to ~1e-30, where the error bound of
:mod:`rfverify.proof` can prove 10 or more digits of the rounded solution.  It differs from
the double solver in three places, each for a reason measured on the reference (DESIGN §5):

* every operation is double-double (≈ 32 digits): data (H̃ = P Hᵀ, w̃, (M + Mᵀ)/2) exactly,
  Jordan algebra, factorisation (:mod:`.ldl`), residuals;
* each Newton solve is refined against the unreduced three-block system (dual, primal,
  complementarity rows).  Without it the primal residual grew like μ^-0.45 and left the
  cones at μ ≈ 1e-28 in 32-digit arithmetic; with one step it stayed at 1e-34;
* the run stops when the *proof* succeeds (``until`` callback), not at a fixed μ.

The Newton system is solved by a back end of :mod:`.system` (by default the scaled
contact-space Schur complement, factored in float64 and refined in double-double).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from . import cones as C
from . import dd
from .system import ExtendedData, choose_backend


class V:
    """A double-double vector (hi, lo) with the few operations the driver needs."""

    __slots__ = ("h", "l")

    def __init__(self, h, l=None):
        self.h = np.ascontiguousarray(h, dtype=np.float64)
        self.l = np.zeros_like(self.h) if l is None else np.ascontiguousarray(l, dtype=np.float64)

    @staticmethod
    def zeros(n):
        return V(np.zeros(n))

    def __add__(self, o):
        out = V.zeros(self.h.size)
        dd.vadd(self.h, self.l, o.h, o.l, out.h, out.l)
        return out

    def __sub__(self, o):
        out = V.zeros(self.h.size)
        dd.vsub(self.h, self.l, o.h, o.l, out.h, out.l)
        return out

    def __neg__(self):
        return V(-self.h, -self.l)

    def scaled(self, a: float):
        out = V.zeros(self.h.size)
        dd.vscale(float(a), 0.0, self.h, self.l, out.h, out.l)
        return out

    def axpy(self, a: float, x: "V"):
        """self + a·x (new vector)."""
        out = V(self.h.copy(), self.l.copy())
        dd.vaxpy(float(a), 0.0, x.h, x.l, out.h, out.l)
        return out

    def dot(self, o) -> float:
        h, l = dd.vdot(self.h, self.l, o.h, o.l)
        return h + l

    def inf(self) -> float:
        return float(np.max(np.abs(self.h), initial=0.0))

    def norm(self) -> float:
        h, l = dd.vnorm2(self.h, self.l)
        return h + l

    def longdouble(self):
        return dd.to_longdouble(self.h, self.l)


@dataclass
class Iterate:
    """The state handed to the ``until`` callback (double-double vectors)."""

    k: int
    v: V
    r_t: V
    z: V
    mu: float
    pinfeas: float
    dinfeas: float


@dataclass
class ExtendedResult:
    """Outcome of :func:`run`: the last iterate (v, r̃, z as double-double), status
    ("Stopped" when ``until`` accepted an iterate, "MaxIterations", "NumericalError"),
    per-iteration trace and timings; ``stats``: the back end's factorisation statistics
    (:meth:`.system._Backend.stats`)."""

    v: V
    r_t: V
    z: V
    status: str
    message: str
    nit: int
    trace: dict = field(default_factory=dict)
    backend: str = ""
    seconds: float = 0.0
    factor_seconds: float = 0.0
    stats: dict = field(default_factory=dict)


def sigma_rule(mu: float, mu_a: float, alpha_a: float) -> float:
    """Mehrotra's centring parameter σ = (μ_a/μ)^e, e = max(1, 3α_a) once μ < 1e-5 (the
    paper's rule), from the predictor's μ_a and step α_a."""
    ratio = max(mu_a, 0.0) / mu if mu > 0 else 0.0
    expo = max(1.0, 3 * alpha_a) if mu < 1e-5 else 1.0
    return min(1.0, ratio ** expo)


def refined_newton(core, residual, a, b, c, *, inf, refine_max: int, floor: float):
    """(dv, dr̃, dz, steps, relative residual): ``core(a, b, c)`` solves the Newton system
    (through a reduced form), then each step refines against the unreduced three-block system
    — ``residual(a, b, c, dv, dr, dz)`` returns its three residual blocks — while the relative
    residual max‖e‖∞ / max(‖a‖∞, ‖b‖∞, ‖c‖∞) at least halves and is above ``floor``.  Any
    vector type with +, and a norm ``inf``, works: double-double here, mpfr in :mod:`.wide`."""
    dv, dr, dz = core(a, b, c)
    scale = max(inf(a), inf(b), inf(c), 1e-300)
    best, steps = math.inf, 0
    for _ in range(refine_max):
        e1, e2, e3 = residual(a, b, c, dv, dr, dz)
        res = max(inf(e1), inf(e2), inf(e3)) / scale
        if not res < 0.5 * best or res < floor:
            best = min(best, res)
            break
        best = res
        ddv, ddr, ddz = core(e1, e2, e3)
        dv, dr, dz = dv + ddv, dr + ddr, dz + ddz
        steps += 1
    return dv, dr, dz, steps, best


def interior_start(data: ExtendedData, v, r, u=None, margin_rel: float = 1e-8) -> dict:
    """A strictly interior lifted point near a candidate solution (v, r) in the original
    variables: r̃ = P⁻¹r and z splitting ũ = P(Hᵀv + w) between the two cones of a contact,
    each pushed inside by ``margin_rel`` times the iterate's scale."""
    lp = data.lp
    problem = data.problem
    if data.local:  # no dofs; u = W r + q of the file's W
        v = np.zeros(0, dtype=np.longdouble)
        if u is None:
            u = problem.local.velocity(r, np.longdouble)
    v = np.asarray(v, dtype=np.longdouble)
    u = (problem.H.T.astype(np.longdouble) @ v + problem.w) if u is None else np.asarray(u, dtype=np.longdouble)
    r_t = np.asarray(r, dtype=np.longdouble)[lp.keep] / lp.scale
    u_t = u[lp.keep] * lp.scale
    scale = max(float(np.max(np.abs(r_t), initial=0.0)), float(np.max(np.abs(u_t), initial=0.0)), 1e-300)
    margin = margin_rel * scale
    z = np.zeros(lp.nz, dtype=np.longdouble)
    # kept-row positions of each cone's components: rows of J
    J = lp.J.tocsc()
    rows_of = J.indices  # z component → kept row
    # friction / rolling bars copy ũ; heads split the slack of u0 evenly
    z[:] = u_t[rows_of]
    heads3 = np.arange(lp.n3) * 3
    bar = np.hypot(z[heads3 + 1].astype(np.float64), z[heads3 + 2].astype(np.float64)).astype(np.longdouble)
    head_row = rows_of[heads3]
    used = np.zeros(lp.nk, dtype=np.longdouble)
    np.add.at(used, head_row, bar)
    count = np.bincount(head_row, minlength=lp.nk).astype(np.longdouble)
    slack = (u_t - used)
    share = np.where(count > 0, slack / np.maximum(count, 1), 0)
    z[heads3] = bar + np.maximum(share[head_row], 0) + margin
    if lp.n1:
        z[3 * lp.n3:] = np.maximum(u_t[rows_of[3 * lp.n3:]], 0) + margin
    # r̃: lift the heads so that Jᵀr̃ is inside both cones by the margin
    s = lp.J.T.astype(np.longdouble) @ r_t
    need = np.zeros(lp.nk, dtype=np.longdouble)
    sbar = np.hypot(s[heads3 + 1].astype(np.float64), s[heads3 + 2].astype(np.float64)).astype(np.longdouble)
    deficit = sbar - s[heads3] + margin
    np.maximum.at(need, head_row, np.maximum(deficit, 0))
    if lp.n1:
        one = rows_of[3 * lp.n3:]
        np.maximum.at(need, one, np.maximum(margin - s[3 * lp.n3:], 0))
    r_t = r_t + need
    return {"v": v, "r_t": r_t, "z": z}


def run(data: ExtendedData, start: dict, *, until=None, max_iter: int = 60, backend=None,
        refine_max: int = 3, gamma_max: float = 0.99, progress=None) -> ExtendedResult:
    """Algorithm 1 in double-double from ``start`` = {"v", "r_t", "z"} (any float dtype;
    converted exactly).  ``until(iterate)`` is called at every iterate (before the step);
    returning True stops the run with status "Stopped".  ``gamma_max`` caps the
    step-to-boundary fraction γ = 0.9 + 0.09α (the paper's rule) from above."""
    t0 = time.perf_counter()
    n3, nz, n = data.n3, data.nz, data.n
    backend = backend or choose_backend(data)
    v = V(*dd.from_longdouble(start["v"]))
    r_t = V(*dd.from_longdouble(start["r_t"]))
    z = V(*dd.from_longdouble(start["z"]))
    f = V(*data.f)
    w_t = V(*data.w_t)
    e = V(C.identity(n3, nz))
    n_cones = n3 + data.n1
    trace = {k: [] for k in ("mu", "pinfeas", "dinfeas", "sigma", "alpha", "refine", "solve_residual", "time")}
    gamma = 0.9
    status, message = "MaxIterations", f"reached max_iter = {max_iter}"
    factor_time = 0.0
    k = 0

    def mv(A, x):
        return V(*A.matvec(x.h, x.l))

    def cone(fn, x, y):
        out = V.zeros(nz)
        fn(n3, x.h, x.l, y.h, y.l, out.h, out.l)
        return out

    for k in range(max_iter + 1):
        s = mv(data.JT, r_t)
        Mv, HtTr, Hv, Jz = mv(data.M, v), mv(data.HtT, r_t), mv(data.Ht, v), mv(data.J, z)
        r_d = Mv - HtTr - f
        if data.local:  # ũ = W̃r̃ + q̃ of the file's W (no dofs)
            Hv = mv(data.Wt, r_t)
        r_p = Hv + w_t - Jz
        mu = z.dot(s) / n
        pinf = r_p.norm() / max(Jz.norm(), Hv.norm(), w_t.norm(), 1e-300)
        dinf = r_d.norm() / max(Mv.norm(), f.norm(), HtTr.norm(), 1e-300)
        trace["mu"].append(mu)
        trace["pinfeas"].append(pinf)
        trace["dinfeas"].append(dinf)
        trace["time"].append(time.perf_counter() - t0)
        if progress:
            progress(k, mu, pinf, dinf)
        if until is not None and until(Iterate(k, v, r_t, z, mu, pinf, dinf)):
            status, message = "Stopped", f"accepted at iteration {k} (μ = {mu:.2e})"
            break
        if k == max_iter:
            break
        ph, pl, pih, pil, lh, ll = (np.zeros(nz) for _ in range(6))
        spec = np.zeros((n_cones, 8))
        try:
            bad = C.nt_scaling(n3, z.h, z.l, s.h, s.l, ph, pl, pih, pil, lh, ll, spec)
        except ZeroDivisionError:  # a cone's determinant is exactly 0: the iterate reached the boundary
            bad = max(0, min(C.min_lambda2(n3, z.h, z.l), C.min_lambda2(n3, s.h, s.l))[1])
        if bad >= 0:
            status, message = "NumericalError", f"iteration {k}: cone {bad} is not strictly interior"
            break
        lam = V(lh, ll)

        def Qp(k, y):
            out = V.zeros(nz)
            C.quad_pow(n3, k, spec, y.h, y.l, out.h, out.l)
            return out

        if hasattr(backend, "observe"):
            backend.observe(k, mu, trace["solve_residual"][-1] if trace["solve_residual"] else None)
        tf = time.perf_counter()
        ok = backend.update(ph, pl, pih, pil, spec)
        factor_time += time.perf_counter() - tf
        if not ok:
            status, message = "NumericalError", f"iteration {k}: the {backend.name} matrix lost definiteness"
            break

        def core(a, b, c):
            qc = Qp(-1, c)
            t = b + mv(data.J, qc)
            dv, dr = backend.solve((a.h, a.l), (t.h, t.l))
            dv, dr = V(*dv), V(*dr)
            w = Qp(-1, mv(data.JT, dr))
            dz = Qp(-1, c - w)
            return dv, dr, dz

        def residual(a, b, c, dv, dr, dz):
            second = b - (mv(data.Wt, dr) if data.local else mv(data.Ht, dv)) + mv(data.J, dz)
            return (a - mv(data.M, dv) + mv(data.HtT, dr), second, c - Qp(1, dz) - Qp(-1, mv(data.JT, dr)))

        def newton(a, b, c):
            return refined_newton(core, residual, a, b, c, inf=V.inf, refine_max=refine_max, floor=1e-31)

        a, b = -r_d, -r_p
        dv_a, dr_a, dz_a, st_a, res_a = newton(a, b, -lam)
        if not math.isfinite(res_a):
            status, message = "NumericalError", f"iteration {k}: the {backend.name} solve failed"
            break
        ds_a = mv(data.JT, dr_a)
        alpha_a = min(1.0, C.max_step(n3, z.h, z.l, dz_a.h, dz_a.l), C.max_step(n3, s.h, s.l, ds_a.h, ds_a.l))
        mu_a = z.axpy(alpha_a, dz_a).dot(s.axpy(alpha_a, ds_a)) / n
        sigma = sigma_rule(mu, mu_a, alpha_a)
        mu_c = z.dot(s) / n_cones
        dzs = Qp(1, dz_a)
        dss = Qp(-1, ds_a)
        xi = e.scaled(sigma * mu_c) - cone(C.product, lam, lam) - cone(C.product, dzs, dss)
        c = cone(C.arrow_solve, lam, xi)
        dv, dr, dz, st, res = newton(a, b, c)
        if not math.isfinite(res):
            status, message = "NumericalError", f"iteration {k}: the {backend.name} solve failed"
            break
        ds = mv(data.JT, dr)
        alpha_max = min(C.max_step(n3, z.h, z.l, dz.h, dz.l), C.max_step(n3, s.h, s.l, ds.h, ds.l))
        alpha = min(1.0, gamma * alpha_max)
        trace["sigma"].append(sigma)
        trace["alpha"].append(alpha)
        trace["refine"].append(st_a + st)
        trace["solve_residual"].append(max(res_a, res))
        v, r_t, z = v.axpy(alpha, dv), r_t.axpy(alpha, dr), z.axpy(alpha, dz)
        gamma = min(gamma_max, 0.9 + (gamma_max - 0.9) * alpha)
    return ExtendedResult(v, r_t, z, status, message, k, trace, backend.name,
                          time.perf_counter() - t0, factor_time, _stats(backend))


def _stats(backend) -> dict:
    """The back end's factorisation statistics (benchmarks); {} where it has none."""
    try:
        return backend.stats() if hasattr(backend, "stats") else {}
    except AttributeError:  # a back end without a single factor (the hybrid)
        return {}
