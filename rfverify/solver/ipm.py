"""The double solver's precision and policy for Algorithm 1 (DESIGN §4), whose loop is
:func:`rfverify.algorithm.loop.iterate`, on the lifted Lorentz-cone form

    M v − H̃ᵀ r̃ = f,   H̃ v + w̃ = J z,   z ∘ Jᵀr̃ = 0,   z, Jᵀr̃ ∈ L3^{n3} × L1^{n1}.

Here the loop's interfaces are: numpy vectors in float64, then in the extended dtypes
(longdouble where the settings ask) once the criterion is below ``longdouble_below`` or a
float64 solve falls short; the product cone of :mod:`.cones` (numba kernels for float64);
a pluggable linear-system form of :mod:`.forms` as the Newton solver; and :class:`Termination`
with the settings' σ rule as the policy.  The stopping test is the criterion of
:mod:`rfverify.model.measures` on the (v, u, r) that would be returned — the same function every
recheck uses; DESIGN's pinfeas, dinfeas and μ = zᵀs / n are computed and traced beside it.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..algorithm import rules
from ..algorithm.interfaces import PROMOTE, Breakdown, Direction
from ..algorithm.loop import Precision, iterate
from ..errors import ConeDomainError
from ..model.lifting import CONE_SIDES
from .cones import ProductCone
from .forms import FORMS
from .kkt import ScalingPoint, abs_max
from .result import TRACE_FIELDS, IterationInfo, Outcome, Settings, Status
from .termination import PaperPolicy, Termination, Verdict

_TINY = np.finfo(float).tiny


def _norm(x) -> float:
    with np.errstate(over="ignore", invalid="ignore"):  # (as dot: inf is the loop's to judge)
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
    # Iteration from which the run used longdouble arithmetic (None: float64 throughout).
    longdouble_from: int | None = None
    # True when Ctrl-C ended the run (status Stopped, the last judged iterate returned).
    interrupted: bool = False
    # The iteration whose iterate is returned (the best one when the run did not end Solved).
    returned_iteration: int | None = None


def run(M, f, H_t, w_t, J, cones: ProductCone, n_contacts: int, form: str, settings: Settings,
        judge, describe_cone=lambda k: f"cone {k}", keep_iterates: bool = False, callback=None,
        component: int = 0, t0: float | None = None, printer=None, M_eq=None, held_by=None) -> RunResult:
    """Run Algorithm 1 (:func:`rfverify.algorithm.loop.iterate`) on one lifted problem in
    float64, continued in the extended settings (longdouble where asked) once the criterion
    is below ``settings.longdouble_below`` or a float64 solve falls short (:func:`_adequate`).

    ``judge(v, r̃)`` returns the :class:`rfverify.model.measures.Measures` of the iterate in the
    original variables (the one definition of "solved"); :class:`Termination` decides from it.
    ``callback(IterationInfo)`` is called once per iteration; returning True stops the run
    (status Stopped).  ``printer(IterationInfo)`` (verbose output) is called likewise.
    ``describe_cone(k)`` turns a global cone index into words for messages; ``held_by(k,
    side)`` names cone k on side "z" or "s" for the step reports, as
    :meth:`rfverify.model.lifting.LiftedProblem.held_by` with "cone", its index in the lifted
    problem (default: {"cone": k, "side": ...} alone);
    ``keep_iterates`` stores every iterate (v, r̃, z) (for lockstep diagnosis).
    ``M_eq`` (default ``M``) is the matrix of the equations the residuals are measured with:
    the stored, unsymmetric M of ``as_stored`` problems, while the forms factor the symmetric
    ``M`` and refine each solve against ``M_eq`` (accepted asymmetry is small, so refinement
    with the symmetric factor converges to the stored system's direction).
    """
    t0 = time.perf_counter() if t0 is None else t0
    t_run = time.perf_counter()
    M_eq = M if M_eq is None else M_eq
    arithmetic = _Arithmetic(settings, M_eq, H_t, J, f, w_t)
    extended = settings.longdouble_below is None or not _float64_safe(M.data, H_t.data, f, w_t)
    work, jd, ref = arithmetic.dtypes(extended)
    system = FORMS[form](M, H_t, J, cones, dtype_ref=ref,
                         static_reg=settings.static_reg, adaptive_reg=settings.adaptive_reg,
                         refine_max=settings.refine_max,
                         refine_tol=None if settings.refine_tol == "adaptive" else settings.refine_tol,
                         forcing=REFINE_FORCING if settings.refine_tol == "adaptive" else None,
                         M_eq=None if M_eq is M else M_eq)
    precision = _NumpyPrecision(arithmetic, extended, cones, _KKTNewton(system, form), describe_cone)
    space = precision.space

    # Infeasible start: v = 0, r̃ with r̃_N = 1 on every contact (so Jᵀr̃ = e), z = e
    # (or θ·e, see velocity_scale).
    v = np.zeros(M.shape[0], dtype=work)
    e = cones.identity(work)
    r_t = np.zeros(H_t.shape[0], dtype=work)
    r_t[J.tocsc().indices[np.flatnonzero(e)]] = 1.0  # rows of the cone heads = N components
    z = e.copy()
    if settings.start == "velocity_scaled":
        z *= velocity_scale(space.w)
    if settings.start == "least_squares":
        v, r_t, z = _least_squares_start(system, cones, space.f, space.w, space.JT, v, r_t, z, jd, work)

    policy = _DoublePolicy(settings, Termination(settings, callback, t0), judge, cones, extended,
                           keep_iterates, component, printer, describe_cone, form, held_by)
    out = iterate(precision, policy, (v, r_t, z), n_contacts=n_contacts, n_cones=cones.n_cones, clock_origin=t0)
    # An iterate whose judging raised never became a trace row (the loop stopped there).
    records = [rec for rec in out.records if "criterion" in rec]
    if records and "sigma" not in records[-1] and printer is not None:
        printer(_info(_with_defaults(records[-1]), component, form))  # the last iterate, stepped or not
    trace = {key: np.asarray([_with_defaults(rec)[key] for rec in records]) for key in TRACE_FIELDS}
    status, message, bundle, returned_k = policy.term.final(out.verdict, policy.current)
    if bundle is None:
        # The first iterate was never judged (its residuals or measures overflowed): return it
        # as it stands, with NaN measures, never nothing.
        from ..model.measures import Measures

        nan = float("nan")
        bundle = (out.iterate, Measures(nan, nan, nan, nan, nan, nan, nan), (nan, nan, nan))
        if status is Status.SOLVED:
            status = Status.NUMERICAL_ERROR
    ((out_v, out_r, out_z), judged_o, (pinf_o, dinf_o, mu_o)) = bundle
    timings = dict(out.timings, total=time.perf_counter() - t_run)
    return RunResult(v=out_v, r_t=out_r, z=out_z, status=status, message=message,
                     nit=len(records) - 1 if records else 0,
                     pinfeas=float(pinf_o), dinfeas=float(dinf_o), mu=float(mu_o), measures=judged_o,
                     trace=trace, timings=timings,
                     factorisations=system.factor_count, unregularised_factorisations=system.unregularised_count,
                     tol=settings.tol, iterates=policy.iterates, longdouble_from=policy.longdouble_from,
                     interrupted=getattr(policy, "was_interrupted", False), returned_iteration=returned_k)


class _NumpySpace:
    """The lifted problem as scipy/numpy operators in one dtype (float64 or longdouble)."""

    tiny = _TINY

    def __init__(self, operators):
        self.M, self.H, self.HT, self.J, self.JT, self.f, self.w = operators

    def velocity(self, v, r):
        return self.H @ v

    @staticmethod
    def dot(x, y) -> float:
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging run's inf is judged by the loop
            return float(x @ y)

    norm2 = staticmethod(_norm)

    @staticmethod
    def axpy(x, a, y):
        return x + a * y

    @staticmethod
    def move(x, a, y):
        return x + a * y.astype(x.dtype)


class _NumpyScaling:
    """The NT scaling of one iterate (symmetric forms) or the iterate itself (noscaling),
    with the cone operations of :class:`ProductCone` in the Jordan dtype ``jd``."""

    def __init__(self, cones: ProductCone, jd, z, s, symmetric: bool):
        self.cones, self.jd, self.symmetric = cones, jd, symmetric
        self.z, self.s = z.astype(jd, copy=False), s.astype(jd, copy=False)
        if symmetric:
            self.p, self.p_inv, self.lam, self.cond = cones.nt_scaling(self.z, self.s)
            self.point = ScalingPoint(p=self.p, p_inv=self.p_inv)
        else:
            self.point = ScalingPoint(z=self.z, s=self.s)
        self._stepper = None
        self.limit = None

    def describe(self) -> dict:
        return {"max_cond_Qp": float(self.cond.max(initial=1.0))} if self.symmetric else {}

    def affine_rhs(self):
        return -self.lam if self.symmetric else -self.cones.product(self.z, self.s)

    def corrector_rhs(self, target, dz_aff, ds_aff):
        C, jd = self.cones, self.jd
        if self.symmetric:
            dzs = C.quad_operator(self.p)(dz_aff.astype(jd))
            dss = C.quad_operator(self.p_inv)(ds_aff.astype(jd))
            xi = target * C.identity(jd) - C.product(self.lam, self.lam) - C.product(dzs, dss)
            return C.arrow_solve(self.lam, xi)
        return target * C.identity(jd) - C.product(self.z, self.s) - C.product(dz_aff.astype(jd), ds_aff.astype(jd))

    def max_step(self, dz, ds) -> float:
        """The largest α keeping z + α dz and s + α ds in their cones; :attr:`limit` is then
        (cone, "z" or "s") of the cone that sets it (None when unbounded)."""
        if self._stepper is None:  # the predictor and the corrector step from the same point
            self._stepper = self.cones.stepper(self.z, self.s)
        step, self.limit = self._stepper(dz.astype(self.jd), ds.astype(self.jd))
        return step


class _KKTNewton:
    """A float64 form of :mod:`.forms` through the Newton interface: its own regularisation and
    refinement; its second block row is −H̃ dv + J dz = −b."""

    def __init__(self, system, form: str):
        self.system, self.form, self.name = system, form, form

    def update(self, scaling: _NumpyScaling, k: int, mu: float) -> None:
        if not self.system.update(scaling.point):
            raise Breakdown(self.system.failure)

    def solve(self, a, b, c, phase: str) -> Direction:
        info = self.system.solve(a, -b, c, adapt=phase == "predictor")
        for name, vec in (("dv", info.dv), ("dr̃", info.dr), ("dz", info.dz)):
            if not np.all(np.isfinite(vec)):
                bad = int(np.flatnonzero(~np.isfinite(vec))[0])
                raise Breakdown(f"the {phase} solve of the {self.form} system produced a non-finite {name}[{bad}]")
        return Direction(dv=info.dv, dr=info.dr, dz=info.dz, steps=info.steps, residual=info.backward_error, info=info)


class _NumpyPrecision(Precision):
    """float64 while the policy says so, then the extended dtypes (:class:`_Arithmetic`)."""

    def __init__(self, arithmetic, extended: bool, cones: ProductCone, newton: _KKTNewton, describe_cone):
        self.arithmetic, self.describe_cone = arithmetic, describe_cone
        work, self.jd, _ = arithmetic.dtypes(extended)
        super().__init__(_NumpySpace(arithmetic.operators(work)), _NumpyCones(cones, self), newton)

    def promote(self, v, r, z):
        work, self.jd, ref = self.arithmetic.dtypes(True)
        self.space = _NumpySpace(self.arithmetic.operators(work))
        self.newton.system.set_refinement_dtype(ref)
        return v.astype(work), r.astype(work), z.astype(work)

    def explain(self, exc):
        if not isinstance(exc, ConeDomainError):
            return None
        where = self.describe_cone(exc.cone) if exc.cone is not None else "a cone"
        return f"{exc.operation} failed at {where}: {exc}"


class _NumpyCones:
    def __init__(self, cones: ProductCone, precision: _NumpyPrecision):
        self.cones, self.precision = cones, precision

    def scaling(self, z, s):
        return _NumpyScaling(self.cones, self.precision.jd, z, s, self.precision.newton.system.symmetric)


class _DoublePolicy(PaperPolicy):
    """The double solver's policy: :class:`Termination` (criterion, stall, limits, callback,
    best iterate), the switch to longdouble arithmetic, the σ rule of the settings, the
    paper's γ = 0.9 + 0.09α, the λ₂ check of every iterate, and the trace columns."""

    def __init__(self, settings: Settings, term: Termination, judge, cones: ProductCone, extended: bool,
                 keep_iterates: bool, component: int, printer, describe_cone, form: str = "",
                 held_by=None):
        self.settings, self.term, self.judge, self.cones = settings, term, judge, cones
        self.form = form
        self.held_by = held_by or _unnamed_cone
        self.describe_cone = describe_cone
        self.extended = extended
        self.longdouble_from = 0 if extended else None
        self.keep_iterates, self.component, self.printer = keep_iterates, component, printer
        self.gamma0 = settings.gamma0
        self.iterates = []
        self.current = None  # (iterate, measures, paper's measures) of the iterate last observed
        self.double_short = False  # a float64 solve fell short of what the iteration needs
        self.term_scales = None
        self.criterion = np.nan

    def observe(self, k, iterate, res, record):
        v, r_t, z = iterate
        if self.keep_iterates:
            self.iterates.append((v.copy(), r_t.copy(), z.copy()))
        # The sizes of the terms of the dual and primal residuals (see _adequate; only the
        # float64 phase asks).
        self.term_scales = None if self.extended else (max(abs_max(t) for t in res.dual_terms),
                                                       max(abs_max(t) for t in res.primal_terms), 0.0)
        judged = self.judge(v, r_t)
        self.criterion = judged.max
        lam2_z, cz = self.cones.min_lambda2(z)
        lam2_s, cs = self.cones.min_lambda2(res.s)
        record.update(criterion=judged.max, min_lam2_z=lam2_z, min_lam2_z_cone=cz, min_lam2_s=lam2_s,
                      min_lam2_s_cone=cs)
        paper = (res.pinfeas, res.dinfeas, res.mu)
        self.current = ((v, r_t, z), judged, paper)
        verdict = self.term.observe(k, judged, paper, (v.copy(), r_t.copy(), z.copy()))
        if verdict is not None:
            return verdict
        promote = not self.extended and (judged.max <= self.settings.longdouble_below or self.double_short)
        if promote:
            self.extended, self.longdouble_from = True, k
        if lam2_z <= 0 or lam2_s <= 0:
            which, c, val = ("z", cz, lam2_z) if lam2_z <= 0 else ("Jᵀr̃", cs, lam2_s)
            return Verdict(Status.NUMERICAL_ERROR, f"iteration {k}: λ2({which}) = {val:.3e} ≤ 0 at "
                                                   f"{self.describe_cone(c)}: the iterate left the cone interior "
                                                   "by rounding")
        return PROMOTE if promote else None

    def sigma(self, mu, mu_aff, alpha_aff):
        return rules.centring(rules.rule_at(self.settings.sigma_rule, self.criterion), mu_aff, mu, alpha_aff)

    def after_direction(self, k, record, predictor, corrector):
        # In float64 a solve must give the iteration what it needs (_adequate); one that
        # falls short needs longdouble arithmetic from the next iteration.
        self.double_short = not self.extended and not (_adequate(predictor.info, self.settings.tol, self.term_scales)
                                                       and _adequate(corrector.info, self.settings.tol,
                                                                     self.term_scales))
        # The cone whose boundary cut the step short, in the problem's terms (none for a full step).
        limit = record.get("limit")
        held = self.held_by(*limit) if limit is not None and record["alpha"] < 1.0 else None
        record.update(step_cone=-1 if held is None else held["cone"],
                      step_side=-1 if held is None else int(limit[1] == "s"))
        info = _info(_with_defaults(record), self.component, self.form, held)
        if self.printer is not None:
            self.printer(info)
        verdict = self.term.ask_callback(info)
        if verdict is not None:
            self.current = None  # the step is computed but not taken: return the best iterate
        return verdict

    def after_step(self, alpha):
        self.term.after_step(alpha)

    def interrupted(self, k):
        """Ctrl-C at iteration k: stop, returning the last iterate judged (Stopped)."""
        self.was_interrupted = True
        return Verdict(Status.STOPPED, f"interrupted (Ctrl-C) at iteration {k}")


# Data entries above this start the run in longdouble arithmetic: their products and squares
# in residuals and norms would approach float64's range (tiny entries are harmless: they
# underflow gracefully, and the cone kernels rescale rows on their own).
FLOAT64_SAFE_MAGNITUDE = 2.0 ** 128


def _float64_safe(*arrays) -> bool:
    return all(np.all(np.abs(np.asarray(x, dtype=np.float64)) <= FLOAT64_SAFE_MAGNITUDE) for x in arrays)


class _Arithmetic:
    """The run's two arithmetics: float64 while the criterion is above
    ``settings.longdouble_below``, then the extended settings (longdouble where asked).  The
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
        ext = np.longdouble if st.longdouble_residuals else np.float64
        jd = np.longdouble if st.longdouble_jordan else np.float64
        return np.result_type(ext, jd), jd, np.longdouble if st.refine_longdouble else np.float64

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
    longdouble arithmetic): it converged (the inexact-Newton test or the refinement target),
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


def _unnamed_cone(cone: int, side: str) -> dict:
    return {"cone": int(cone), "side": CONE_SIDES[side]}


def _info(record, component, form: str = "", held_by: dict | None = None) -> IterationInfo:
    return IterationInfo(component=component, method=form, iteration=int(record["iter"]),
                         criterion=float(record["criterion"]),
                         pinfeas=float(record["pinfeas"]), dinfeas=float(record["dinfeas"]), mu=float(record["mu"]),
                         sigma=float(record["sigma"]), alpha_aff=float(record["alpha_aff"]),
                         alpha=float(record["alpha"]), min_lam2_z=float(record["min_lam2_z"]),
                         min_lam2_s=float(record["min_lam2_s"]), max_cond_Qp=float(record["max_cond_Qp"]),
                         solve_residual=float(record["solve_residual"]), elapsed=float(record["time"]),
                         held_by=held_by)


# The columns of a trace row that only an iterate that computed its step fills.
_STEP_DEFAULTS = dict(sigma=np.nan, alpha_aff=np.nan, alpha=np.nan, gamma=np.nan, max_cond_Qp=np.nan,
                      solve_residual=np.nan, refine_steps=0, step_cone=-1, step_side=-1)


def _with_defaults(record: dict) -> dict:
    return {**_STEP_DEFAULTS, **record}
