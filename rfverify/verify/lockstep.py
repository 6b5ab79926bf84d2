"""The lockstep of :func:`rfverify.verify.diagnosis.diagnose`: the diagnosis's context (the
problem, the double run, the exact judge), one exact step from each double iterate, the
digits the double steps keep, where they depart from the exact ones, and those facts in words."""

from __future__ import annotations

import math
import time

import numpy as np

from ..algorithm.rules import rule_at
from ..model.measures import data_scales, measures
from ..model.problem import SPACEDIM, Problem
from ..solver import DOUBLE_REACH
from ..solver.result import Status
from .exact import ExactAlgorithm, ExactStepError, dd_difference

UNIT_ROUNDOFF = 2.0 ** -53

FORM_POWER = {"qp2": 2, "reduced": 2, "schur": 2, "jqinv": 1, "reduced_factored": 1, "noscaling": 1}
"""The power of cond(Q_p) in the condition of the block a form factors: Q_{p²} (qp2),
J Q_{p⁻²} Jᵀ (reduced; inverted inside schur's M + H̃ᵀG⁻¹H̃), Q_{p⁻¹} (jqinv), its factor L
(reduced_factored); noscaling's Arw(z), Arw(s) are counted as one power."""

FORM_BLOCK = {"qp2": "Q_{p²}", "reduced": "J Q_{p⁻²} Jᵀ", "schur": "(J Q_{p⁻²} Jᵀ)⁻¹ inside M + H̃ᵀG⁻¹H̃",
              "jqinv": "Q_{p⁻¹}", "reduced_factored": "L, L Lᵀ = J Q_{p⁻²} Jᵀ", "noscaling": "Arw(z), Arw(s)"}

CAUSES = ("precision", "iterations", "data", "none")

EXACT_EXTRA = 50
"""Iterations the exact continuation may take beyond the double run's limit, to tell "more
iterations" (it meets the tolerance later) from "data" (it never does)."""

WITNESS_MIN_DPS = 34
"""Fewest digits the mpmath witness may carry: it checks double-double steps (2⁻¹⁰⁶ ≈ 1.2e-32, about
32 digits) and may overrule them, so it must carry more (a 9-digit witness overruled a double-double
run that met 1e-25, and a 10-digit one broke down)."""

WITNESS_SECONDS = 90.0
"""Default budget of the mpmath witness (seconds): at 700 contacts one reference step takes
about 3 s (40 digits), so the continuation of a ~750-contact Chute fits, with the rest of the
diagnosis, in two minutes on two cores."""




class DiagnosisContext:
    """What every stage of one diagnosis reads: the problem, the double run and its lifting,
    the exact algorithm, the data scales and the form's conditioning."""

    def __init__(self, problem, res, lp, method, tol, max_iter, say, deadline):
        from ..solver import component_judge

        self.problem, self.res, self.lp, self.method = problem, res, lp, method
        self.tol, self.max_iter, self.say, self.deadline = tol, max_iter, say, deadline
        self.settings = res.settings
        self.local = problem.local is not None
        self.active = res.extras["active_dofs"]
        self.iterates = res.extras["iterates"]
        self.trace = res.trace
        self.scales = data_scales(problem)
        self.f_inf = float(np.max(np.abs(problem.f), initial=0.0))
        component = component_judge(problem, lp, self.active, np.arange(lp.nk), self.settings)
        self.judge_component = component
        self.exact = ExactAlgorithm(problem, self.settings, self._exact_judge(component))
        m_a = self.active.size
        self.order = {"qp2": m_a + lp.nk + lp.nz, "jqinv": m_a + lp.nk + lp.nz, "noscaling": m_a + lp.nk + lp.nz,
                      "reduced": m_a + lp.nk, "reduced_factored": m_a + lp.nk, "schur": m_a}.get(method, m_a + lp.nk)
        self.reach = -math.log10(self.order * UNIT_ROUNDOFF)  # the most digits a double step can be expected to keep
        self.need = min(-math.log10(tol), self.reach)
        self.r_unique, self.r_unique_note = r_unique(problem, lp)
        self.HT = problem.H.T.tocsr()
        self.H = problem.H.tocsr()
        self.reference = self.reference_order = None

    def lifting_longdouble(self) -> tuple:
        """(W, Hᵀ, H) of a local file in long double, converted once for every step's comparison."""
        if getattr(self, "_lifting_ld", None) is None:
            self._lifting_ld = tuple(sp_matrix.astype(np.longdouble) for sp_matrix in
                                     (self.problem.local.W, self.HT, self.H))
        return self._lifting_ld

    def in_time(self) -> bool:
        return self.deadline is None or time.perf_counter() <= self.deadline

    def v_full(self, v_active):
        v = np.array(self.res.v, dtype=np.longdouble)
        v[self.active] = v_active
        return v

    def _exact_judge(self, component):
        """``judge(v, r̃, z)`` of double-double iterates, as the double run judges its own: the
        component's criterion of the float64 rounding (a local file: on its own u = W r + q);
        below double's reach the criterion of the point itself, in mpmath."""
        problem, lp = self.problem, self.lp
        if self.tol < DOUBLE_REACH and not self.local:  # no float64 answer meets such a tolerance
            def judge(v, r_t, z):
                import mpmath

                with mpmath.workdps(40):
                    return self._criterion_mp([mpmath.mpf(h) + mpmath.mpf(lo) for h, lo in zip(v.h, v.l)],
                                              [mpmath.mpf(h) + mpmath.mpf(lo) for h, lo in zip(r_t.h, r_t.l)])
            return judge
        if self.local:
            def judge(v, r_t, z):
                r = lp.r_from_lifted(np.asarray(r_t.h, dtype=np.float64))
                return measures(problem, problem.H @ r, problem.local.velocity(r), r, "longdouble")
            return judge
        active = self.active

        def judge(v, r_t, z):
            return component(v.longdouble()[active], r_t.longdouble())
        return judge

    def judge_reference(self, it):
        """The criterion of the answer a :class:`reference.Iterate` would give: of its float64
        rounding (as the double run judges), or of the point itself below double's reach."""
        problem, lp = self.problem, self.lp
        if self.tol < DOUBLE_REACH and not self.local:
            return self._criterion_mp(it.v, it.r_t)
        v = np.array([float(x) for x in it.v])
        r_t = np.array([float(x) for x in it.r_t])
        if self.local:
            rf = lp.r_from_lifted(r_t)
            return measures(problem, problem.H @ rf, problem.local.velocity(rf), rf, "longdouble")
        return self.judge_component(np.asarray(v, dtype=np.longdouble)[self.active], np.asarray(r_t, dtype=np.longdouble))

    def _criterion_mp(self, v_values, r_t_values):
        """The measures of (v, r = P r̃, u = Hᵀv + w) computed in mpmath (40 digits) from mpf
        values, with M of the posed equations exactly."""
        import mpmath

        data, lp = self._mp_measures(), self.lp
        with mpmath.workdps(40):
            vm = np.empty(len(v_values), dtype=object)
            vm[:] = [mpmath.mpf(x) for x in v_values]
            r = np.empty(SPACEDIM * self.problem.n_contacts, dtype=object)
            r[:] = mpmath.mpf(0)
            r[lp.keep] = [mpmath.mpf(x) * mpmath.mpf(float(sc)) for x, sc in zip(r_t_values, lp.scale)]
            return data.measures(vm, data.arith.matvec(data.HT, vm) + data.w, r)

    def _mp_measures(self):
        """The measures in mpmath (40 digits) with M of the posed equations exactly."""
        if getattr(self, "_mp_data", None) is None:
            from ..model.measures import MeasureData, MpmathArithmetic

            data = MeasureData.of(self.problem, MpmathArithmetic(40))
            data.M = _exact_posed_M(self.problem, data.arith)  # not (M + Mᵀ)/2 rounded to float64
            self._mp_data = data
        return self._mp_data

    def cone_name(self, c: int) -> str:
        if c is None or c < 0 or c >= self.lp.n_cones:
            return "a cone"
        part = ("friction (N,T) cone", "rolling (N,R) cone", "normal cone")[self.lp.cone_part[c]]
        return f"contact {self.lp.cone_contact[c]} {part}"


def _exact_posed_M(problem: Problem, arith):
    """M of the posed equations in mpmath arithmetic, exactly: M as stored, or (M + Mᵀ)/2 with
    the sums and halvings exact (a float64 (M + Mᵀ)/2 is rounded where M is unsymmetric)."""
    import scipy.sparse as sp

    A = sp.csr_matrix(problem.M, dtype=np.float64)
    if problem.as_stored or problem.matrix_is_symmetric:
        return arith.matrix(A)
    with arith.context():
        mpf = arith.mp.mpf
        entries = {}
        for M in (A.tocoo(), A.T.tocoo()):
            for i, j, x in zip(M.row, M.col, M.data):
                entries[(int(i), int(j))] = entries.get((int(i), int(j)), mpf(0)) + mpf(float(x)) / 2
        keys = sorted(entries)
        rows = np.array([k[0] for k in keys], dtype=np.int64)
        indptr = np.searchsorted(rows, np.arange(A.shape[0] + 1)).astype(np.int64)
        data = np.empty(len(keys), dtype=object)
        data[:] = [entries[k] for k in keys]
        return indptr, np.array([k[1] for k in keys], dtype=np.int64), data, A.shape


def r_unique(problem: Problem, lp) -> tuple[bool, str]:
    """Whether the reactions are unique: H on the kept components (all contacts) has full
    numerical column rank — λmin(HᵀH) above N·u·λmax(HᵀH), N its order — estimated by inverse
    iteration on HᵀH + N·u·λmax·I.  (Sufficient, not necessary: contacts that are open at the
    solution do not count, but are counted here.)  Returns (unique, a sentence)."""
    from scipy.sparse import csc_matrix, identity
    from scipy.sparse.linalg import splu

    nk = lp.nk
    HK = csc_matrix(problem.H)[:, lp.keep]  # (a local file: its lifting, W = HᵀH)
    if nk == 0:
        return True, "no reaction components"
    if nk > HK.shape[0]:
        return False, (f"H has {nk} kept columns and only {HK.shape[0]} rows: r may not be unique (hyperstatic, "
                       "unless enough contacts are open at the solution), Hr is")
    A = (HK.T @ HK).tocsc()
    lam_max = float(np.max(np.asarray(abs(A).sum(axis=1)).ravel(), initial=0.0))
    if lam_max == 0:
        return False, "H is zero on the contacts"
    delta = nk * UNIT_ROUNDOFF * lam_max
    try:
        lu = splu((A + delta * identity(nk, format="csc")).tocsc())
    except RuntimeError:
        return False, "HᵀH is singular to working precision: r is not unique, Hr is"
    x = np.random.default_rng(0).standard_normal(nk)
    lam = math.inf
    for _ in range(30):
        y = lu.solve(x)
        ny = float(np.linalg.norm(y))
        if not ny > 0 or not math.isfinite(ny):
            break
        lam = float(np.linalg.norm(x)) / ny
        x = y / ny
    lam_min = lam - delta
    if lam_min > delta:
        return True, f"unique: H has full column rank on the kept components (λmin/λmax(HᵀH) ≈ {lam_min / lam_max:.1e})"
    return False, (f"r may not be unique (hyperstatic, unless enough contacts are open at the solution): H is "
                   f"rank deficient on the kept components (λmin(HᵀH) ≤ {nk}·u·λmax); Hr is unique")


# ---------------------------------------------------------------------- lockstep
def digits_from_error(err_inf: float, scale: float) -> float:
    if not math.isfinite(err_inf):
        return float("nan")
    if err_inf == 0:
        return math.inf
    return -math.log10(err_inf / scale) if scale > 0 else float("nan")


def _agreement(ctx: DiagnosisContext, st, v1, r1, z1) -> dict:
    """Digits of agreement of the double iterate (v1 full, r̃1, z1) with the exact one ``st``."""
    lp, problem, sc = ctx.lp, ctx.problem, ctx.scales
    d_r_t = dd_difference(st.r_t, r1)
    r_exact = lp.r_from_lifted(st.r_t.h)
    d_r = lp.r_from_lifted(d_r_t)
    out = {}
    if ctx.local:
        W = problem.local.W
        u_exact = problem.local.velocity(r_exact)
        out["digits_v"] = out["digits_Hr"] = float("nan")
        out["digits_u"] = digits_from_error(inf_norm(W @ d_r), max(inf_norm(u_exact), sc.u_free))
        # The double steps solve the lifting u = HᵀH r + q, the exact ones the file's W: how far
        # the two agree on this r bounds the digits of agreement whatever the rounding.
        r_ld = np.asarray(r_exact, dtype=np.longdouble)
        W_ld, HT_ld, H_ld = ctx.lifting_longdouble()
        gap = W_ld @ r_ld - HT_ld @ (H_ld @ r_ld)
        out["digits_lifting"] = digits_from_error(inf_norm(gap), max(inf_norm(u_exact), sc.u_free))
    else:
        d_v = dd_difference(st.v, v1)
        v_exact = st.v.h
        u_exact = ctx.HT @ v_exact + problem.w
        out["digits_v"] = digits_from_error(inf_norm(d_v), max(inf_norm(v_exact), sc.v_free))
        out["digits_u"] = digits_from_error(inf_norm(ctx.HT @ d_v), max(inf_norm(u_exact), sc.u_free))
        out["digits_Hr"] = digits_from_error(inf_norm(ctx.H @ d_r), max(inf_norm(ctx.H @ r_exact), ctx.f_inf))
    if ctx.r_unique:
        out["digits_r_t"] = digits_from_error(inf_norm(d_r), max(inf_norm(r_exact), sc.r))
        out["digits_z"] = digits_from_error(inf_norm(dd_difference(st.z, z1)), max(inf_norm(st.z.h), sc.u_free))
    else:
        out["digits_r_t"] = out["digits_z"] = float("nan")
    counted = [out[k] for k in ("digits_v", "digits_u", "digits_Hr", "digits_r_t", "digits_z")
               if not math.isnan(out[k])]
    out["digits"] = min(counted) if counted else float("nan")
    return out


def inf_norm(x) -> float:
    return float(np.max(np.abs(x), initial=0.0))


def _expected(ctx: DiagnosisContext, cond: float) -> float:
    """−log10(N·u·κ), κ = cond(Q_p)^power of the form: the digits a backward-stable double
    solve of the form keeps at an iterate with that cond(Q_p)."""
    if not (cond > 0 and math.isfinite(cond)):
        return float("nan")
    return ctx.reach - FORM_POWER.get(ctx.method, 1) * math.log10(max(cond, 1.0))


def lockstep(ctx: DiagnosisContext):
    """One record per step of the double run (see :class:`Diagnosis`); the time limit cuts it."""
    res, tr, iterates = ctx.res, ctx.trace, ctx.iterates
    n = len(iterates) - 1
    nan = float("nan")
    records = []
    for k in range(n):
        if not ctx.in_time():
            return records, (f"time limit of {ctx.settings.time_limit:g} s reached after {k} of {n} exact steps "
                             "(the steps done are kept)")
        ctx.say(f"exact step {k + 1} of {n}")
        v_k, r_k, z_k = iterates[k]
        v1, r1, z1 = iterates[k + 1]
        lam2_z_dbl = float(tr["min_lam2_z"][k + 1]) if k + 1 < len(tr["iter"]) else nan
        lam2_s_dbl = float(tr["min_lam2_s"][k + 1]) if k + 1 < len(tr["iter"]) else nan
        cond = float(tr["max_cond_Qp"][k])
        record = {"iter": k, "mu": float(tr["mu"][k]), "criterion": float(tr["criterion"][k]),
                  "max_cond_Qp": cond, "solve_residual": float(tr["solve_residual"][k]),
                  "alpha": float(tr["alpha"][k])}
        try:
            st = ctx.exact.step(ctx.exact.point(ctx.v_full(v_k), r_k, z_k), float(tr["gamma"][k]),
                                rule_at(ctx.settings.sigma_rule, float(tr["criterion"][k])))
        except ExactStepError as exc:
            records.append({**record, "digits_v": nan, "digits_u": nan, "digits_Hr": nan, "digits_r_t": nan,
                            "digits_z": nan, **({"digits_lifting": nan} if ctx.local else {}),
                            "digits": nan, "max_cond_Qp_exact": nan, "expected": nan,
                            "threshold": nan, "alpha_exact": nan,
                            "min_lam2_z": {"double": lam2_z_dbl, "reference": nan},
                            "min_lam2_s": {"double": lam2_s_dbl, "reference": nan},
                            "flags": [f"no exact step from the double iterate: {exc}"],
                            "reference_step": f"no exact step: {exc}"})
            continue
        rec = {**record, **_agreement(ctx, st, ctx.v_full(v1), r1, z1)}
        rec["max_cond_Qp_exact"] = st.max_cond_Qp
        rec["expected"] = _expected(ctx, st.max_cond_Qp)
        rec["threshold"] = min(ctx.need, rec["expected"]) if not math.isnan(rec["expected"]) else ctx.need
        rec["alpha_exact"] = st.alpha
        rec["min_lam2_z"] = {"double": lam2_z_dbl, "reference": st.min_lam2_z}
        rec["min_lam2_s"] = {"double": lam2_s_dbl, "reference": st.min_lam2_s}
        rec["lam2_cones"] = {"z": ctx.cone_name(st.min_lam2_z_cone), "s": ctx.cone_name(st.min_lam2_s_cone)}
        flags = []
        for name, d, e in (("z", lam2_z_dbl, st.min_lam2_z), ("Jᵀr̃", lam2_s_dbl, st.min_lam2_s)):
            if e > 0 and not d > 0:
                flags.append(f"λ2({name}) ≤ 0 in double while exact is {e:.2e}")
            elif e > 0 and d < 1e-300:
                flags.append(f"λ2({name}) underflowed in double (exact {e:.2e})")
        rec["flags"] = flags
        rec["reference_step"] = "exact step (double-double) from the double iterate"
        records.append(rec)
    return records, None


def departure(ctx: DiagnosisContext, steps: list) -> dict | None:
    """The first step that lost more than its conditioning explains — digits below its
    threshold min(need, expected) —, or with a λ2 lost, or whose result has no exact step;
    with the mechanism it went through (:func:`_through`)."""
    for i, s in enumerate(steps):
        if s["flags"] and s["flags"][0].startswith("no exact step"):
            # iterate k is not interior in exact arithmetic: the step that made it departed
            prev = steps[max(i - 1, 0)]
            return {"iter": prev["iter"], "digits": prev["digits"], "threshold": prev.get("threshold", float("nan")),
                    "expected": prev.get("expected", float("nan")), "kind": "left the cone",
                    "through": f"its result is not interior in exact arithmetic ({s['flags'][0]})"}
        if not (s["digits"] >= s["threshold"]) or s["flags"]:
            return {"iter": s["iter"], "digits": s["digits"], "threshold": s["threshold"],
                    "expected": s["expected"], "kind": "lambda2" if s["flags"] else "beyond conditioning",
                    "through": _through(ctx, s)}
    return None


def shortfall(ctx: DiagnosisContext, steps: list) -> dict | None:
    """The first step that kept fewer digits than the tolerance needs (whether or not its
    conditioning explains it), with what its conditioning leaves."""
    for s in steps:
        if s["digits"] < ctx.need:
            return {"iter": s["iter"], "digits": s["digits"], "need": ctx.need, "expected": s["expected"],
                    "max_cond_Qp": s.get("max_cond_Qp_exact", s["max_cond_Qp"]),
                    "within_conditioning": bool(s["digits"] >= s["expected"])}
    return None


def _refine_target(settings) -> float:
    rt = settings.refine_tol
    if rt is None:
        return 4 * np.finfo(np.longdouble if settings.refine_longdouble else np.float64).eps
    if rt == "adaptive":
        from ..solver.ipm import REFINE_FORCING

        return REFINE_FORCING
    return float(rt)


def _through(ctx: DiagnosisContext, s: dict) -> str:
    """In words, what a departing step went through: a breakdown of the double run, a λ2 lost,
    the form's linear solve, or rounding the conditioning does not explain."""
    k = s["iter"]
    res = ctx.res
    if res.status == Status.NUMERICAL_ERROR and (f"iteration {k + 1}:" in res.message or f"iteration {k}:" in res.message):
        return f"a breakdown of the double run: {res.message.split('; ')[0]}"
    if s["flags"]:
        which = "z" if "λ2(z)" in s["flags"][0] else "s"
        return (f"λ2 cancellation: {s['flags'][0]}, at {s['lam2_cones'][which]} (the double λ2 is the difference of "
                "two numbers that agree to more digits than double holds)")
    beta, target = s["solve_residual"], _refine_target(ctx.settings)
    if beta > target:
        return (f"the {ctx.method} linear solve: its refinement stopped at a backward error of {beta:.1e} "
                f"(its target {target:.1e}): its matrix is singular to double precision at this iterate, "
                f"although cond(Q_p) is only {s['max_cond_Qp']:.1e}")
    lam = _lam2_loss(s)
    if lam is not None:
        return lam
    if ctx.local and s.get("digits_lifting", math.inf) <= s["digits"] + 0.3:
        lift = ctx.problem.provenance.get("lift") or ctx.problem.provenance.get("lifted") or {}
        dropped = (f" (which dropped {lift['dropped']} eigenvalue(s) of W, the smallest {lift['min_eigenvalue']:.2e})"
                   if lift.get("dropped") else "")
        return (f"the lifting, not rounding: the double steps solve the lifting u = HᵀH r + q{dropped}, the "
                f"exact steps the file's u = W r + q, and on this iterate's r the two agree to "
                f"{s['digits_lifting']:.1f} digits of u")
    return (f"rounding beyond the form's conditioning: cond(Q_p) = {s['max_cond_Qp_exact']:.1e} leaves "
            f"{s['expected']:.1f} digits, the step kept {s['digits']:.1f}")


def shortfall_text(ctx: DiagnosisContext, sf: dict) -> str:
    power = FORM_POWER.get(ctx.method, 1)
    left = (f"leaves about {sf['expected']:.1f} digits" if sf["expected"] > 0
            else f"leaves no digit guaranteed (−log10(N·u·κ) = {sf['expected']:.1f})")
    why = ("within what the form's conditioning allows" if sf["within_conditioning"]
           else "below even what the form's conditioning allows")
    return (f"from iteration {sf['iter']} the double steps keep fewer digits than the {sf['need']:.1f} the tolerance "
            f"needs ({sf['digits']:.1f}, {why}): there cond(Q_p) = {sf['max_cond_Qp']:.1e}, and {ctx.method} factors "
            f"{FORM_BLOCK.get(ctx.method, 'Q_p')}, whose condition cond(Q_p)^{power} {left} in double")


def _lam2_loss(s: dict) -> str | None:
    """A λ2 of the double iterate that lost its leading digit against the exact one."""
    for name, key in (("z", "min_lam2_z"), ("Jᵀr̃", "min_lam2_s")):
        d, e = s[key]["double"], s[key]["reference"]
        if e > 0 and math.isfinite(d) and abs(d - e) > 0.1 * e:
            cone = s.get("lam2_cones", {}).get("z" if name == "z" else "s", "a cone")
            return (f"λ2 cancellation: min λ2({name}) = {d:.2e} in double against {e:.2e} exactly, at {cone}")
    return None


def run_record(res, how: str) -> dict:
    return {"how": how, "status": str(res.status), "message": res.message, "nit": int(res.nit),
            "criterion": float(res.criterion), "components": len(res.extras.get("component_runs") or []) or 1}


def refined_text(ctx, plain, res) -> str:
    split = plain.extras.get("component_runs") or []
    how = f", split into {len(split)} independent components" if split else ""
    return (f"as `rfverify solve --method {ctx.method}` runs it (default inexact linear solves, float64 until the criterion is 1e-9{how}) "
            f"the {ctx.method} run ends {plain.status} at criterion {plain.criterion:.1e}; the same form as one system "
            f"with every linear solve refined to the floor of longdouble arithmetic meets the tolerance "
            f"({res.status} after {res.nit} iterations, criterion {res.criterion:.1e}; its steps against the exact "
            f"ones below): more precision in the linear algebra is what the run lacks")


def healthy_text(ctx, steps) -> str:
    finite = [s for s in steps if math.isfinite(s["digits"])]
    if not finite:
        return "the run reached its tolerance"
    worst = min(finite, key=lambda s: s["digits"])
    return (f"the run reached its tolerance; its steps agreed with the exact steps from the same points to at least "
            f"{worst['digits']:.1f} digits of {quantities_words(ctx)} (at iteration {worst['iter']}, cond(Q_p) = "
            f"{worst['max_cond_Qp']:.1e})")


def quantities_words(ctx) -> str:
    q = ["u"] if ctx.local else ["v", "u", "Hr"]
    if ctx.r_unique:
        q += ["r", "z"]
    return ", ".join(q)


# ---------------------------------------------------------------------- counterfactual
