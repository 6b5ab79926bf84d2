"""The mpmath witness of a diagnosis (:func:`rfverify.verify.diagnosis.diagnose`): the
independent reference (:mod:`reference`) run on the deciding steps, within a time budget, and
the digits on which it and the exact steps agree."""

from __future__ import annotations

import math
import time

import numpy as np

from ..algorithm.rules import rule_at
from ..extended import ipm as ext
from .cause import gamma_after
from .exact import ExactStepError
from .lockstep import digits_from_error, inf_norm


def _reference_layout(lp, order, v, r_t, z) -> tuple:
    """A production iterate (v, r̃, z in the lifted layout of :func:`rfverify.model.lifting.lift`)
    as (v, r̃, z cones) in the reference's layout: the same kept components, cones contact by
    contact (friction, rolling, normal ray) instead of all L3 cones first."""
    z = np.asarray(z)
    cones = [z[3 * c:3 * c + 3] for c in range(lp.n3)] + [z[3 * lp.n3 + k:3 * lp.n3 + k + 1] for k in range(lp.n1)]
    return np.asarray(v), np.asarray(r_t), [cones[i] for i in order]


def _reference(ctx, dps):
    """The mpmath reference on the problem, built once per diagnosis (W̃, block inverses, ordering)."""
    import reference

    if ctx.reference is None:
        ctx.reference = reference.Solver(ctx.problem, dps=dps)
        ctx.reference_order = np.lexsort((ctx.lp.cone_part, ctx.lp.cone_contact))
    return ctx.reference


def _minus_mp(a: ext.V, xs) -> np.ndarray:
    """a − x for a double-double vector and mpf numbers, as float64 (x split as hi + lo; the
    differences of the parts are exact where they are close)."""
    hi = np.array([float(x) for x in xs])
    lo = np.array([float(x - h) for x, h in zip(xs, hi)])
    return (a.h - hi) + (a.l - lo)


def _mp_digits(ctx, it_mp, v_dd: ext.V, r_dd: ext.V) -> float:
    """Digits of agreement of an mpmath iterate with a double-double one (v, r̃), on v, u and Hr
    (u for a local problem), each as in the lockstep."""
    d_r = ctx.lp.r_from_lifted(_minus_mp(r_dd, it_mp.r_t))
    r_exact = ctx.lp.r_from_lifted(r_dd.h)
    if ctx.local:
        return digits_from_error(inf_norm(ctx.problem.local.W @ d_r),
                       max(inf_norm(ctx.problem.local.velocity(r_exact)), ctx.scales.u_free))
    d_v = _minus_mp(v_dd, it_mp.v)
    return min(digits_from_error(inf_norm(d_v), max(inf_norm(v_dd.h), ctx.scales.v_free)),
               digits_from_error(inf_norm(ctx.HT @ d_v), max(inf_norm(ctx.HT @ v_dd.h + ctx.problem.w), ctx.scales.u_free)),
               digits_from_error(inf_norm(ctx.H @ d_r), max(inf_norm(ctx.H @ r_exact), ctx.f_inf)))


def _reference_iterate(ctx, ref, v: ext.V, r_t: ext.V, z: ext.V):
    """A double-double iterate as a :class:`reference.Iterate`, exactly (hi + lo in the
    reference's own precision, 2·dps digits ≥ 106 bits)."""
    import reference

    mpf = ref.ctx.mpf

    def exact(x):
        return [mpf(float(h)) + mpf(float(lo)) for h, lo in zip(x.h, x.l)]

    zz = exact(z)
    _, _, cones = _reference_layout(ctx.lp, ctx.reference_order, [], [], np.array(zz, dtype=object))
    return reference.Iterate(v=exact(v) if not ctx.local else [mpf(0)] * ref.m, r_t=exact(r_t),
                             z=[list(c) for c in cones])


def _no_step(exc, dps: int) -> str:
    """What a reference step that raised ``exc`` says: no exact step (its point is not interior),
    or a breakdown of the reference's own linear algebra at ``dps`` digits (it proves nothing)."""
    from reference import jordan as RJ

    return "no exact step" if isinstance(exc, RJ.ReferenceDomainError) else \
        f"no step: its linear algebra broke down at {dps} digits"


def run_witness(ctx, steps, focus, run, evidence, dps, budget, timings):
    """The mpmath reference on the iterations that decide the verdict, within ``budget``
    seconds: (1) the exact step from the deciding double iterate (``focus``, else the fewest
    digits), against the double-double step and the double one; for a run that missed
    its tolerance, (2) the last step of the exact continuation ``run`` (the one that met the
    tolerance, or its last), from its double-double iterate, and (3) as far as the budget
    allows, the whole continuation in mpmath, iterate by iterate."""
    finite = [s for s in steps if math.isfinite(s["digits"])]
    if budget <= 0 or not finite or not ctx.in_time():
        return
    from reference import jordan as RJ

    from .exact import witness

    t0 = time.perf_counter()
    stop = t0 + budget if ctx.deadline is None else min(t0 + budget, ctx.deadline)
    tr = ctx.trace
    k = int(focus) if focus is not None else int(min(finite, key=lambda s: s["digits"])["iter"])
    ctx.say(f"mpmath witness ({dps} digits): the step from iteration {k} of the double run")
    ref = _reference(ctx, dps)
    v_k, r_k, z_k = ctx.iterates[k]
    v1, r1, _ = ctx.iterates[k + 1]
    gamma, rule = float(tr["gamma"][k]), rule_at(ctx.settings.sigma_rule, float(tr["criterion"][k]))
    out = {"dps": dps, "step": {"iter": k}, "last_step": None, "run": None, "text": []}
    after = None
    try:
        step = ref.step(ref.iterate(*_reference_layout(ctx.lp, ctx.reference_order, ctx.v_full(v_k), r_k, z_k)),
                        gamma, sigma_rule=rule)
    except (RJ.ReferenceDomainError, ArithmeticError) as exc:
        out["step"].update(agrees_with_double_double=None, double_digits=None)
        out["text"].append(f"mpmath witness: {_no_step(exc, dps)} from iteration {k} ({exc})")
    else:
        after = step
        try:
            st = ctx.exact.step(ctx.exact.point(ctx.v_full(v_k), r_k, z_k), gamma, rule)
            dd_agree = _mp_digits(ctx, step.iterate, st.v, st.r_t)
        except ExactStepError:
            dd_agree = float("nan")
        dv, dr, _ = ctx.exact.point(ctx.v_full(v1), r1, np.zeros(0))
        dbl = _mp_digits(ctx, step.iterate, dv, dr)
        lock = next(s["digits"] for s in steps if s["iter"] == k)
        out["step"].update(agrees_with_double_double=dd_agree, double_digits=dbl)
        out["text"].append(f"mpmath witness ({dps} digits), the exact step from iteration {k}: the double-double "
                           f"step agrees with it to {dd_agree:.1f} digits, the double step to {dbl:.1f} (the "
                           f"lockstep said {lock:.1f})")
    if ctx.local:  # the exact run of a local problem has no dofs; the reference works on the lifting
        run = None
    step_seconds = time.perf_counter() - t0  # the reference's build and one step: what the next step may cost
    if run is not None and run.kept and time.perf_counter() + step_seconds < stop:
        last = run.reached_at if run.reached_at is not None else run.rows[-1]["iter"]
        kl = last - 1
        if kl >= run.start and kl in run.kept and last in run.kept:
            row = next(r for r in run.rows if r["iter"] == kl)
            ctx.say(f"mpmath witness: the exact continuation's step from iteration {kl}")
            it = _reference_iterate(ctx, ref, *run.kept[kl])
            entry = {"iter": kl}
            try:
                nxt = ref.step(it, row["gamma"], sigma_rule=rule_at(ctx.settings.sigma_rule, row["criterion"]))
            except (RJ.ReferenceDomainError, ArithmeticError) as exc:
                entry.update(agrees_with_double_double=None, criterion=None)
                out["text"].append(f"mpmath witness: {_no_step(exc, dps)} from the exact continuation's iteration "
                                   f"{kl} ({exc})")
            else:
                crit = ctx.judge_reference(nxt.iterate).max
                agree = _mp_digits(ctx, nxt.iterate, *run.kept[last][:2])
                entry.update(agrees_with_double_double=agree, criterion=crit)
                out["text"].append(f"mpmath witness, the exact continuation's last step (from iteration {kl}): "
                                   f"agrees with double-double to {agree:.1f} digits; its iterate {last} has "
                                   f"criterion {crit:.1e}" + (" ≤ tol" if crit <= ctx.tol else f" > tol = {ctx.tol:g}"))
            out["last_step"] = entry
    if run is not None and time.perf_counter() < stop and len(run.rows) > 1:
        n = len(run.rows) - 1
        if after is not None and run.start == k:
            start, k0, g0, n = after.iterate, k + 1, gamma_after(after.alpha), n - 1
        else:
            v, r, z = ctx.iterates[run.start]
            start = _reference_layout(ctx.lp, ctx.reference_order, ctx.v_full(v), r, z)
            k0, g0 = run.start, run.rows[0]["gamma"]
        ctx.say(f"mpmath witness: the same algorithm from iteration {k0}, up to {n} steps, "
                f"{max(0.0, stop - time.perf_counter()):.0f} s left")

        def compare(kk, it):
            kept = run.kept.get(kk)
            return _mp_digits(ctx, it, kept[0], kept[1]) if kept is not None else float("nan")

        def tick(kk, crit):
            ctx.say(f"  mpmath iteration {kk}: criterion {crit:.2e}")

        w = witness(ref, start, k0, g0, ctx.settings, ctx.judge_reference, compare, n, stop, dps, tick,
                    step_seconds=step_seconds)
        out["run"] = w.as_dict()
        agree = f"{w.agreement:.1f}" if math.isfinite(w.agreement) else "all"
        if w.reached_at is not None:
            out["text"].append(f"mpmath witness: the same algorithm from iteration {k0} meets tol at iteration "
                               f"{w.reached_at} (double-double: {run.reached_at}), its iterates agreeing with the "
                               f"double-double ones to {agree} digits")
        else:
            out["text"].append(f"mpmath witness: the same algorithm from iteration {k0} ran {w.steps} steps "
                               f"({w.stopped}), best criterion {min(w.criteria):.1e}, its iterates agreeing with "
                               f"the double-double ones to {agree} digits")
    if not ctx.problem.as_stored and not ctx.problem.matrix_is_symmetric:
        X = "W" if ctx.local else "M"
        out["text"].append(f"(the mpmath reference solves with ({X} + {X}ᵀ)/2 rounded to float64, the exact steps "
                           f"with it exact: {X} is unsymmetric here, so the two agree only to that rounding)")
    out["seconds"] = time.perf_counter() - t0
    timings["witness"] += out["seconds"]
    evidence["witness"] = out


