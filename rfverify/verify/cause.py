"""The cause a diagnosis names (:func:`rfverify.verify.diagnosis.diagnose`): Algorithm 1
continued in exact arithmetic from where the double steps departed (the counterfactual run),
what it says in words, and the remedies it tries (other forms, more iterations, the k-digit path)."""

from __future__ import annotations

import math
import time

import numpy as np

from ..model.measures import measures
from ..solver import DOUBLE_REACH, solve
from ..solver.result import ALGORITHM1_METHODS, Status, method_unavailable
from .exact import ExactRun
from .lockstep import EXACT_EXTRA, DiagnosisContext, quantities_words, shortfall_text


def counterfactual(ctx: DiagnosisContext, focus, keep: bool = False):
    """The exact continuation from iteration ``focus`` (the first step not good enough; None:
    the best iterate); and, if that does not meet the tolerance within the double run's limit,
    from the double run's start."""
    tr = ctx.trace
    crit = np.asarray(tr["criterion"], dtype=float)
    if focus is not None:
        j = int(focus)
    else:
        j = int(np.nanargmin(np.where(np.isfinite(crit), crit, np.inf))) if crit.size else 0
    j = min(j, len(ctx.iterates) - 1)
    limit = ctx.max_iter + max(EXACT_EXTRA, ctx.max_iter)

    def run_from(k):
        v, r, z = ctx.iterates[k]
        gamma = float(tr["gamma"][k]) if k < len(tr["gamma"]) and np.isfinite(tr["gamma"][k]) else ctx.settings.gamma0
        ctx.say(f"the same algorithm in double-double from iteration {k} of the double run")

        def tick(kk, mu, criterion):
            ctx.say(f"  double-double iteration {kk}: μ = {mu:.2e}, criterion {criterion:.2e}")

        return ctx.exact.run(ctx.exact.point(ctx.v_full(v), r, z), k, gamma, limit, deadline=ctx.deadline,
                             progress=tick, keep=keep)

    main = run_from(j)
    early = None
    if not (main.reached_at is not None and main.reached_at <= ctx.max_iter) and j > 0 and ctx.in_time():
        early = run_from(0)
    return main, early


def better_run(a: ExactRun, b: ExactRun, max_iter: int) -> bool:
    """Whether run ``a`` says more than ``b``: it met the tolerance within the limit, or sooner."""
    ka = a.reached_at if a.reached_at is not None else math.inf
    kb = b.reached_at if b.reached_at is not None else math.inf
    return ka < kb


def cause_of(ctx: DiagnosisContext, run: ExactRun) -> str | None:
    if run.status is Status.MAX_TIME:
        return None
    if run.reached_at is not None:
        return "precision" if run.reached_at <= ctx.max_iter else "iterations"
    if run.status is Status.MAX_ITERATIONS and _still_progressing(run):
        return "iterations"
    return "data"


def _still_progressing(run: ExactRun, window: int = 8) -> bool:
    """The criterion fell by at least 10 % over the last ``window`` iterates."""
    c = [r["criterion"] for r in run.rows]
    return len(c) > window and c[-1] < 0.9 * min(c[-window - 1:-1])


def witnessed_cause(cause, wit, max_iter):
    """The mpmath witness's own continuation, where it ran to its end, decides a disagreement."""
    if not wit or wit.get("run") is None or cause is None:
        return cause
    run = wit["run"]
    if run["reached_at"] is not None:
        return "precision" if run["reached_at"] <= max_iter else "iterations"
    if run["stopped"].startswith("no step"):
        return "data"
    return cause  # the witness stopped early (budget): the double-double run stands


def cause_text(ctx, cause, dep, sf, main, early, decided, steps, evidence) -> list:
    """The evidence in sentences, with the figures."""
    res, tol = ctx.res, ctx.tol
    out = []
    if dep is not None and dep["kind"] == "beyond conditioning":
        out.append(f"the double step first departed from the exact one at iteration {dep['iter']}: "
                   f"{dep['digits']:.1f} digits of {quantities_words(ctx)}, below its threshold {dep['threshold']:.1f} "
                   f"(the fewer of the digits the tolerance needs and those the form's conditioning leaves), "
                   f"through {dep['through']}")
    elif dep is not None:
        out.append(f"the double step first departed from the exact one at iteration {dep['iter']} "
                   f"({dep['digits']:.1f} digits of {quantities_words(ctx)}), through {dep['through']}")
    if sf is not None and (dep is None or sf["iter"] != dep["iter"] or sf["within_conditioning"]):
        out.append(shortfall_text(ctx, sf))
    if dep is None and sf is None and ctx.method != "noscaling":
        finite = [s for s in steps if math.isfinite(s["digits"])]
        if finite:
            worst = min(finite, key=lambda s: s["digits"])
            out.append(f"every double step kept the digits the tolerance needs (fewest {worst['digits']:.1f} of "
                       f"{quantities_words(ctx)}, at iteration {worst['iter']})")
    if ctx.method == "noscaling":
        out.append("noscaling's direction (Arw(s), Arw(z)) is not the NT direction of the exact steps: its digits "
                   "measure that difference as well as rounding, so no departure is located")

    def said(run, where):
        if run.reached_at is not None:
            return (f"the same algorithm in exact arithmetic (double-double), continued from {where}, met tol = "
                    f"{tol:g} at iteration {run.reached_at} (criterion {run.rows[-1]['criterion']:.1e})")
        last = run.rows[-1] if run.rows else None
        tail = (f" (best criterion {run.best:.1e}; at its end μ = {last['mu']:.1e}, the {last['worst']} measure "
                f"{last['criterion']:.1e})" if last else "")
        return (f"the same algorithm in exact arithmetic (double-double), continued from {where}, ended "
                f"{run.status}: {run.message}{tail}")

    out.append(said(main, f"iteration {main.start} of the double run"))
    if early is not None:
        out.append(said(early, "the double run's start"))
    double_end = (f"the lockstep's double run ended {res.status} after {res.nit} iterations (criterion "
                  f"{res.criterion:.1e})")
    if cause == "precision":
        out.append(f"{double_end}: double precision is the cause")
    elif cause == "iterations":
        out.append(f"{double_end} at max_iter = {ctx.max_iter}: the exact algorithm needs "
                   f"{decided.reached_at if decided.reached_at is not None else 'more'} iterations; "
                   "double precision is not the cause")
    elif cause == "data":
        out.append(f"{double_end}; exact arithmetic does not reach the tolerance either, so double precision is not "
                   f"the cause: the data are. {_data_facts(ctx, decided)}")
    wit = evidence.get("witness")
    if wit:
        out.extend(wit.get("text", []))
    return out


def _data_facts(ctx, run: ExactRun) -> str:
    facts = []
    if not ctx.r_unique:
        facts.append(ctx.r_unique_note)
    n0 = int(np.sum(ctx.problem.mu == 0))
    if n0:
        facts.append(f"{n0} contacts have μ = 0")
    last = run.rows[-1] if run.rows else None
    if last:
        why = ""
        if last["worst"] in ("velocity", "cone") and last["mu"] < 1e-3 * ctx.tol:
            why = " — the constraints leave (almost) no strictly feasible point"
        elif last["worst"] == "dynamics" and not ctx.r_unique and ctx.scales.r > 0:
            grown = last["r_t_inf"] / ctx.scales.r
            first = run.rows[0]["r_t_inf"] / ctx.scales.r
            if grown > 10 * max(first, 1.0):
                why = (f" — the reactions grow along the self-stress of the redundant contacts (‖r̃‖∞ from {first:.1e} "
                       f"to {grown:.1e} times the reaction scale ‖f‖/max‖h_k‖), and the float64 rounding of so large "
                       "an r alone leaves that dynamics residual")
        facts.append(f"the exact run stalls on its {last['worst']} measure ({last['criterion']:.1e}) while μ = "
                     f"{last['mu']:.1e}{why}")
    return "Evidence: " + "; ".join(facts) + "." if facts else ""


# ---------------------------------------------------------------------- the mpmath witness
def gamma_after(alpha) -> float:
    """The paper's γ after a step α (the double run's rule)."""
    from ..algorithm.rules import step_fraction

    return step_fraction(float(alpha), 0.09)


# ---------------------------------------------------------------------- remedies
def try_remedies(ctx: DiagnosisContext, cause, run: ExactRun, user_options: dict):
    """Run the candidates in the order the cause suggests; the first whose answer meets the
    tolerance is the remedy.  Returns (remedy or None, every candidate tried)."""
    from .digits import solve_to_digits

    problem, tol, max_iter, method = ctx.problem, ctx.tol, ctx.max_iter, ctx.method
    base = ["--max-iter", str(max_iter)] if max_iter != 100 else []
    if problem.as_stored:
        base += ["--as-stored"]
    options = {k: v for k, v in user_options.items() if k not in ("refine_tol", "longdouble_below", "as_stored")}
    forms = [m for m in ALGORITHM1_METHODS if m != method and method_unavailable(m) is None]
    reached = None if run is None else run.reached_at
    more = max(2 * max_iter, int(1.25 * reached) + 5) if reached is not None else 2 * max_iter
    # Below double's reach no float64 answer meets the criterion: a proof of K digits is the answer.
    ks = (15, 12, 10) if tol < DOUBLE_REACH else (max(1, min(15, math.ceil(-math.log10(tol)))),)
    iters = [("solve", {"method": method, "max_iter": more}, ["--method", method, "--max-iter", str(more)])]
    by_form = [("solve", {"method": m, "max_iter": max_iter}, ["--method", m] + base) for m in forms]
    # the paper's centring rule, as the k-digit path's double solve runs it: where the default rule's
    # steps stall on the data, exact arithmetic stalls with them, and the other rule may not
    sigma = [("solve", {"method": method, "max_iter": max_iter, "sigma_rule": "paper"},
              ["--method", method, "--sigma-rule", "paper"] + base)] if options.get("sigma_rule") != "paper" else []
    if tol < DOUBLE_REACH:  # the double stage of the k-digit path at a tolerance double can reach
        digits = [("digits", {"digits": k, "max_iter": max_iter, "tol": 1e-10},
                   ["--digits", str(k), "--tol", "1e-10"] + base) for k in ks]
    else:
        digits = [("digits", {"digits": k, "max_iter": max_iter}, ["--digits", str(k)] + base) for k in ks]
    plan = {"precision": by_form + sigma + digits, "iterations": iters + by_form + sigma + digits,
            "data": sigma + by_form + iters + digits}.get(cause, by_form + sigma + digits)
    tried = []
    for kind, kw, args in plan:
        if not ctx.in_time():
            break
        ctx.say(f"remedy: rfverify solve PROBLEM {command_args(args, tol)}")
        limit = {} if ctx.deadline is None else {"time_limit": max(ctx.deadline - time.perf_counter(), 1e-3)}
        t0 = time.perf_counter()
        if kind == "solve":
            out = solve(problem, tol=tol, **{**options, **kw}, **limit)
            crit, status = float(out.criterion), str(out.status)
            ok = out.success
        else:
            out = solve_to_digits(problem, **{"tol": tol, **kw}, **limit)
            crit = measures(problem, out.v, out.u, out.r, "longdouble").max
            status = str(out.status)
            # `solve --digits` exits 0 only when certified: a remedy is one the command says has worked
            ok = out.success and (crit <= tol or tol < DOUBLE_REACH)
        entry = {"args": args, "status": status, "criterion": crit, "time": time.perf_counter() - t0,
                 "reached": bool(ok)}
        tried.append(entry)
        if ok:
            return {k: entry[k] for k in ("args", "status", "criterion", "time")}, tried
    return None, tried


# ---------------------------------------------------------------------- words


def command_args(args: list, tol: float) -> str:
    """``rfverify solve`` arguments: the remedy's, then the tolerance unless they set one."""
    return " ".join(list(args) + ([] if "--tol" in args else ["--tol", f"{tol:g}"]))
