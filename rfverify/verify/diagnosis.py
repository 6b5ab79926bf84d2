"""Why a double run stalled, shown by the same algorithm in exact arithmetic (DESIGN §5).

:func:`diagnose` runs ``method`` in double as ``rfverify solve`` runs it (the run diagnosed), and
again as one system keeping every iterate, every linear solve refined to the floor of the
longdouble arithmetic (the lockstep's run: its digits measure rounding alone); where that run meets
the tolerance and the first does not, the precision of the default linear solves is the cause.
Otherwise:

1. **Lockstep.**  From every double iterate k, the exact step (:mod:`rfverify.verify.exact`: Algorithm
   1 in double-double, every Newton solve refined to that arithmetic's floor) with the double
   run's own γ and σ rule; the difference from the double iterate k+1 is the error of
   iteration k.  Measured where the exact step is defined — v, u = Hᵀv + w and Hr (unique
   always), r and z only when r is unique — each relative to the larger of its exact size and
   its data scale (‖M⁻¹f‖, ‖HᵀM⁻¹f + w‖, ‖f‖: a quantity that vanishes at the solution does not
   make its digits meaningless).  Also per iteration: max cond(Q_p) (double and exact), min λ2
   of z and of s = Jᵀr̃ in double and exactly, and flags where a double λ2 underflowed or went
   non-positive while the exact one is positive.
2. **Departure.**  The first iteration whose agreement falls below its threshold
   ``max(need, expected)``: ``expected`` = −log10(N·u·κ), the digits a backward-stable double
   solve of the form keeps at that iterate (u = 2⁻⁵³, N the order of the form's matrix, κ the
   condition of the form's scaling block: cond(Q_p)² for qp2, reduced and schur, which factor
   Q_{p²} or Q_{p⁻²}; cond(Q_p) for jqinv and reduced_factored), and ``need`` = −log10(tol),
   the digits the tolerance asks of an iterate (at most what a double step can hold).  A step
   below ``expected`` lost more than its conditioning explains (a linear solve that missed its
   target, a λ2 lost to cancellation, a NaN); one between the two lost what the conditioning
   predicts, and more than the tolerance allows.
3. **Counterfactual.**  When the run missed its tolerance, the same Algorithm 1 continued in
   exact arithmetic from the double run's own iterate at the departure (or, with none, at its
   best iterate): its policy, its criterion, its iteration limit.  It meets the tolerance
   within the limit → **cause "precision"**; later → **"iterations"**; it stalls or breaks down
   too → **"data"** (with the evidence: r not unique, μ = 0 contacts, which measure stalls).
   Where the continuation from the departure does not meet the limit, the exact algorithm is
   also run from the double run's start (iteration 0).  The mpmath reference
   (:mod:`reference`, independent code) repeats the deciding exact step and, within a time
   budget, the continuation (:func:`rfverify.verify.exact.witness`).
4. **Remedy.**  Candidates run as ``rfverify solve`` would run them (another ``--method``, more
   ``--max-iter``, ``--digits K``), in an order set by the cause; the first whose answer meets
   the tolerance is the remedy, with its figures.

The result is a :class:`Diagnosis`; :meth:`Diagnosis.to_dict` is what ``rfverify diagnose
--json`` prints.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from ..model.lifting import cone_words, lift
from ..model.measures import measures
from ..model.problem import Problem
from ..solver import posed, solve
from ..solver.result import ResultAliases, Status, renamed_settings
from .cause import (
    better_run,
    cause_of,
    cause_text,
    command_args,
    counterfactual,
    try_remedies,
    witnessed_cause,
)
from .lockstep import (
    FORM_BLOCK,
    FORM_POWER,
    WITNESS_MIN_DPS,
    WITNESS_SECONDS,
    DiagnosisContext,
    departure,
    healthy_text,
    lockstep,
    refined_text,
    run_record,
    shortfall,
)
from .witness import run_witness


@dataclass
class Diagnosis(ResultAliases):
    """Result of :func:`diagnose` (docs/RESULTS.md has the fields of every result in one table).

    Attributes
    ----------
    method : str              linear-system form of the double run
    status : Status           the double run's status, as ``rfverify solve`` runs it (a str
                              enum: ``status == "Solved"``)
    success : bool            status is Solved
    message : str             the double run's message
    nit : int                 iterations of the double run (alias ``iterations``); the lockstep's
                              run (one system, solves refined) is ``evidence["lockstep_run"]``
    steps : list of dict      one record per iteration k (the lockstep): ``iter``, ``mu``,
                              ``criterion``, ``digits_v``, ``digits_u``, ``digits_Hr``,
                              ``digits_r_t`` and ``digits_z`` (digits of agreement of the
                              double iterate k+1 with the exact step from iterate k; r̃ and z
                              NaN unless r is unique, everything NaN where there is no exact
                              step; a local file's also ``digits_lifting``: how well the lifting
                              HᵀH the double steps solve agrees with W on the step's r, as digits
                              of u), ``digits`` (the fewest of those measured), ``expected``
                              and ``threshold`` (digits; module docstring), ``max_cond_Qp``
                              (the double run's) and ``max_cond_Qp_exact``,
                              ``solve_residual`` (the double solve's backward error),
                              ``min_lam2_z`` and ``min_lam2_s`` (each ``{"double",
                              "reference"}``: smallest λ2 of z and of Jᵀr̃, the exact one
                              under "reference"), ``flags`` (list of str), ``reference_step``
    failure : str or None     the message of a run that was not Solved
    timings : dict            seconds: ``double``, ``setup`` (exact data and back end),
                              ``steps`` (the lockstep), ``exact`` (the continuation),
                              ``witness`` (mpmath), ``remedies``, ``total`` (alias
                              ``solve_time`` = ``timings["total"]``)
    cause : str or None       "precision", "iterations", "data", or "none" (the run was
                              Solved); None when the time limit stopped the diagnosis first
    evidence : dict           ``text`` (sentences with the figures), ``departure`` (the first
                              departing step: ``iter``, ``digits``, ``threshold``,
                              ``expected``, ``through``), ``exact`` (the counterfactual run,
                              :meth:`rfverify.verify.exact.ExactRun.as_dict`), ``exact_from_start``,
                              ``witness``, ``r_unique``, ``mu_zero_contacts``,
                              ``steps_held`` (the run's steps a cone's boundary cut short,
                              ``SolveResult.steps_held``), ``held_most`` (the cone that held
                              the most of them, :func:`held_most`; named in ``text`` when the
                              run was not Solved),
                              ``remedies_tried`` (every candidate run: ``args``, ``status``,
                              ``criterion``, ``time``)
    remedy : dict or None     the first candidate that met the tolerance: ``args`` (for
                              ``rfverify solve PROBLEM ARGS --tol T``), ``status``,
                              ``criterion``, ``time`` (seconds); None when none did
    tol : float               the tolerance diagnosed
    """

    method: str
    status: Status
    message: str
    nit: int
    steps: list = field(default_factory=list)
    failure: str | None = None
    timings: dict = field(default_factory=dict)
    cause: str | None = None
    evidence: dict = field(default_factory=dict)
    remedy: dict | None = None
    tol: float = float("nan")

    @property
    def success(self) -> bool:
        return self.status == Status.SOLVED

    @property
    def flagged(self) -> list:
        """The steps with at least one flag (a λ2 underflow, a sign lost, no exact step)."""
        return [s for s in self.steps if s["flags"]]

    @property
    def departure(self) -> dict | None:
        """The first step that departed from the exact one (``evidence["departure"]``)."""
        return self.evidence.get("departure")

    def as_dict(self) -> dict:
        """The JSON-able dict ``rfverify diagnose --json`` prints (:meth:`to_dict`)."""
        return self.to_dict()

    @property
    def conclusion(self) -> str:
        """The cause and the remedy in one sentence (the first line of ``rfverify diagnose``)."""
        return _conclusion(self)

    def to_dict(self) -> dict:
        """The JSON-able dict ``rfverify diagnose --json`` prints: ``method``, ``status`` (its
        name), ``message``, ``nit``, ``tol``, ``iterations`` (the list of :attr:`steps`),
        ``failure``, ``timings``, ``cause``, ``evidence``, ``remedy``, ``conclusion``."""
        return {"method": self.method, "status": str(self.status), "message": self.message, "nit": self.nit,
                "tol": self.tol, "iterations": list(self.steps), "failure": self.failure,
                "timings": dict(self.timings), "cause": self.cause, "evidence": dict(self.evidence),
                "remedy": None if self.remedy is None else dict(self.remedy), "conclusion": self.conclusion}

    def __repr__(self) -> str:
        dep = self.departure
        first = (f"departed at iteration {dep['iter']} ({dep['digits']:.1f} digits)" if dep else "no departure")
        total = self.timings.get("total", float("nan"))
        remedy = " ".join(self.remedy["args"]) if self.remedy else None
        return (f"Diagnosis(method={self.method!r}, status={self.status}, nit={self.nit}, cause={self.cause!r}, "
                f"time={total:.3g} s,\n    {first}, remedy={remedy!r},\n    {self.message!r})")


# ---------------------------------------------------------------------- the diagnosis
def _in_diagnosis_units(problem: Problem) -> tuple:
    """(the problem the diagnosis works on, a note or None): contacts' units brought together
    first, as `rfverify solve` does (the lockstep compares iterates of one problem), then data
    beyond float64's safe range scaled exactly (digits and causes do not depend on units)."""
    from ..model.scaling import binary_scaling, contact_units, problem_in_contact_units, scaled_problem

    notes = []
    units = contact_units(problem)
    if units is not None:
        problem = problem_in_contact_units(problem, units)
        notes.append(f"with the reactions of {int(np.count_nonzero(units.exponents))} of {units.exponents.size} "
                     f"contacts in units brought together by exact powers of two (2^{int(units.exponents.min())} … "
                     f"2^{int(units.exponents.max())}), as rfverify solve runs it")
    scaling = binary_scaling(problem)
    if scaling is not None:
        problem = scaled_problem(problem, scaling)
        notes.append(f"in exactly scaled units ({scaling.describe()})")
    return problem, (f"diagnosed {'; and '.join(notes)}" if notes else None)


def diagnose(problem: Problem, method: str = "jqinv", tol: float = 1e-10, max_iter: int = 100,
             dps: int = 40, progress=None, *, remedies: bool = True, witness_time: float = WITNESS_SECONDS,
             **options) -> Diagnosis:
    """Diagnose a run of ``method`` at ``tol`` and ``max_iter`` (see the module docstring).

    Returns a :class:`Diagnosis`: the double run's ``status``/``message``/``nit``, the
    lockstep ``steps``, the ``cause`` ("precision", "iterations", "data", "none"), its
    ``evidence`` and a ``remedy`` the diagnosis ran; ``to_dict()`` is its JSON.  ``status``,
    ``message``, ``nit`` are those of the run as ``rfverify solve`` makes it (default settings,
    independent components split); the lockstep's run is the same form as one system.
    ``progress(message)`` receives one line per stage and per exact step.

    ``dps``: digits of the mpmath witness; ``witness_time``: its budget in seconds (0: no
    witness).  ``remedies=False`` runs no remedy.  ``options`` are solver settings of the
    double run; ``time_limit`` (seconds) bounds the whole diagnosis: the double run gets it,
    and each later stage stops at the first step past it (status MaxTime; the steps done are
    kept, and stages not reached leave ``cause`` None).  Unless ``refine_tol`` is among the
    options, the double run refines every linear solve to 4·eps (``refine_tol=None``) instead
    of the solver's default inexact-Newton stop, so that the digits of agreement measure
    rounding alone, and unless ``longdouble_below`` is, it runs in longdouble arithmetic from
    the first iteration (``longdouble_below=None``), so that every iteration's digits measure the
    same arithmetic.  The remedies run with the solver's defaults, as ``rfverify solve`` does.

    ``noscaling``'s Newton direction (Arw(s), Arw(z)) is not the NT direction the exact steps
    take: its digits measure that difference as well as rounding, no departure is located, and
    the counterfactual continues the NT algorithm from its best iterate.
    """
    say = progress or (lambda message: None)
    _check_arguments(method, dps, witness_time)
    t0 = time.perf_counter()
    options = renamed_settings(options)
    time_limit = options.get("time_limit")
    deadline = None if time_limit is None else t0 + time_limit
    user_options = {k: v for k, v in options.items() if k != "time_limit"}
    options = {"refine_tol": None, "longdouble_below": None, **options}  # the lockstep run's (docstring)
    problem = posed(problem, options.pop("as_stored", None), method)
    problem, note_units = _in_diagnosis_units(problem)

    # The run as `rfverify solve` makes it (default settings, independent components split): the
    # run whose outcome the diagnosis is about.  Then the lockstep's run: the same form as one
    # system, keeping every iterate, its solves refined to the floor (see above).
    limited = lambda: {} if deadline is None else {"time_limit": max(deadline - time.perf_counter(), 1e-12)}  # noqa: E731
    plain = solve(problem, method=method, tol=tol, max_iter=max_iter, **user_options,  # the user's limit, as named
                  **({} if time_limit is None else {"time_limit": time_limit}))
    res = solve(problem, method=method, tol=tol, max_iter=max_iter, keep_iterates=True,
                **{k: v for k, v in options.items() if k != "time_limit"}, **limited())
    if res.extras.get("zero_data"):  # f = w = 0: answered exactly, without iterating
        return Diagnosis(method=method, status=Status(res.status), message=res.message, nit=0, tol=float(tol),
                         cause="none", evidence={"text": [res.message]},
                         timings={"double": time.perf_counter() - t0, "total": time.perf_counter() - t0})
    settings = res.settings
    lp = lift(problem, reduce_cones=settings.reduce_cones)
    iterates = res.extras["iterates"]
    nsteps = len(iterates) - 1
    say(f"double run ({method}): {plain.status} after {plain.nit} iterations; the lockstep's run (one system, "
        f"solves refined to the floor): {res.status} after {res.nit}; lockstep of its {nsteps} steps in double-double")
    t1 = time.perf_counter()
    diag = Diagnosis(method=method, status=Status(plain.status), message=plain.message, nit=int(plain.nit),
                     failure=None if plain.success else plain.message, tol=float(tol))
    ctx = DiagnosisContext(problem, res, lp, method, tol, max_iter, say, deadline)
    if lp.nk != ctx.exact.data.nk or lp.nz != ctx.exact.data.nz:
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("reduce_cones", "the exact steps work on the reduced lifting (DESIGN §2.1)",
                                   fix="drop reduce_cones=False")
    t2 = time.perf_counter()
    steps, cut = lockstep(ctx)
    diag.steps = steps
    t3 = time.perf_counter()
    evidence = {"r_unique": ctx.r_unique, "r_unique_note": ctx.r_unique_note,
                "mu_zero_contacts": int(np.sum(problem.mu == 0)), "form_block": FORM_BLOCK.get(method),
                "form_power": FORM_POWER.get(method), "form_order": ctx.order, "text": []}
    evidence["run"] = run_record(plain, f"as `rfverify solve --method {method}` runs it")
    evidence["steps_held"], evidence["held_most"] = plain.steps_held, held_most(plain)
    evidence["lockstep_run"] = run_record(res, "one system, every linear solve refined to the floor, longdouble "
                                                "arithmetic from the first iteration (refine_tol=None, "
                                                "longdouble_below=None unless given)")
    evidence.update({"units": note_units} if note_units else {})
    timings = {"double": t1 - t0, "setup": t2 - t1, "steps": t3 - t2, "exact": 0.0, "witness": 0.0,
               "remedies": 0.0}
    dep = sf = None
    if method != "noscaling":  # (its direction is not the exact steps', see above)
        dep, sf = departure(ctx, steps), shortfall(ctx, steps)
    evidence["departure"], evidence["shortfall"] = dep, sf
    marks = [m["iter"] for m in (dep, sf) if m is not None]
    focus = min(marks) if marks else None  # the first step that is not good enough
    if cut is not None:
        diag.status, diag.message = Status.MAX_TIME, f"{plain.message}; {cut}"
        evidence["text"].append(cut)
    elif (file_only := solved_on_the_lifting_only(problem, plain)) is not None:
        diag.cause, evidence["file_only"] = "data", file_only
        evidence["text"].append(file_only["text"])
        if remedies and ctx.in_time():
            _run_remedies(ctx, diag, evidence, timings, "data", None, user_options)
    elif plain.success or res.success:
        if plain.success:
            diag.cause = "none"
            evidence["text"].append(healthy_text(ctx, steps))
        else:  # the same form with every solve refined meets the tolerance: the default solves' precision
            diag.cause = "precision"
            evidence["text"].append(refined_text(ctx, plain, res))
        run_witness(ctx, steps, focus, None, evidence, dps, witness_time, timings)
        evidence["text"] += (evidence.get("witness") or {}).get("text", [])
        if not plain.success and remedies and ctx.in_time():
            _run_remedies(ctx, diag, evidence, timings, "precision", None, user_options)
    else:
        t4 = time.perf_counter()
        main, early = counterfactual(ctx, focus, keep=witness_time > 0)
        evidence["exact"] = main.as_dict()
        evidence["exact_from_start"] = None if early is None else early.as_dict()
        timings["exact"] = time.perf_counter() - t4
        decided = early if early is not None and better_run(early, main, max_iter) else main
        diag.cause = cause_of(ctx, decided)
        run_witness(ctx, steps, focus, decided, evidence, dps, witness_time, timings)
        diag.cause = witnessed_cause(diag.cause, evidence.get("witness"), max_iter)
        evidence["text"] += cause_text(ctx, diag.cause, dep, sf, main, early, decided, steps, evidence)
        evidence["text"] += held_text(evidence["held_most"], plain.nit)
        if remedies and ctx.in_time():
            _run_remedies(ctx, diag, evidence, timings, diag.cause, decided, user_options)
        elif remedies:
            evidence["remedies_tried"] = []
            evidence["text"].append("the time limit was reached before any remedy was tried")
        if not ctx.in_time() and diag.cause is None:
            cut = f"time limit of {time_limit:g} s reached before the diagnosis decided the cause"
            diag.status, diag.message = Status.MAX_TIME, f"{plain.message}; {cut}"
            evidence["text"].append(cut)
    timings["total"] = time.perf_counter() - t0
    diag.timings = timings
    diag.evidence = evidence
    return diag


def _check_arguments(method: str, dps: int, witness_time: float) -> None:
    from ..errors import InvalidArgumentError

    if method not in FORM_POWER:  # the lockstep compares a form of Algorithm 1 with its exact steps
        raise InvalidArgumentError("method", f"{method!r} is not a form of Algorithm 1 the diagnosis can follow",
                                   fix=f"use one of {', '.join(FORM_POWER)}")
    if witness_time and dps < WITNESS_MIN_DPS:
        raise InvalidArgumentError("dps", f"is {dps}, below {WITNESS_MIN_DPS}: the mpmath witness checks, and may "
                                          "overrule, double-double steps (about 32 digits), so it must carry more",
                                   fix=f"pass dps ≥ {WITNESS_MIN_DPS} (default 40), or witness_time=0 for no witness")


def _run_remedies(ctx, diag: Diagnosis, evidence: dict, timings: dict, cause, run, user_options) -> None:
    """The remedy candidates for ``cause`` (:func:`.cause.try_remedies`), into the diagnosis."""
    t0 = time.perf_counter()
    diag.remedy, evidence["remedies_tried"] = try_remedies(ctx, cause, run, user_options)
    timings["remedies"] = time.perf_counter() - t0


def solved_on_the_lifting_only(problem: Problem, result) -> dict | None:
    """For a local file's problem whose run's answer misses the tolerance on the file's own
    u = W r + q because the lifting the double run solves is not the file's W
    (:func:`rfverify.solver.judged_on_the_file`): {"lifting_status", "lifting_criterion" (the
    same answer's on the lifting), "criterion" (the file's), "text"}; None otherwise.

    Two cases: the run met the tolerance on its lifting (whatever W is); or it did not, W as
    stored has a negative eigenvalue (the lifting, HᵀH, drops it: the file's problem is not
    convex), and the file's criterion is more than 10× the lifting's, so that the part of W the
    lifting dropped, not the run's steps, sets it.  Either way the cause is the data: the double
    run solves the convex lifting, while the exact steps of the counterfactual would run on the
    file's own W, a different problem, so their comparison says nothing about rounding."""
    run_status = (result.extras.get("run_verdict") or (None, None))[0]
    if problem.local is None or result.success:
        return None
    lift = problem.provenance.get("lift") or problem.provenance.get("lifted") or {}
    lowest = float(lift.get("min_eigenvalue", 0.0))
    # the answer as the run judged it: u = Hᵀv + w rounded to float64
    on_lifting = measures(problem, result.v, problem.H.T @ result.v + problem.w, result.r, "longdouble").max
    solved_lifting = run_status == Status.SOLVED
    if not (solved_lifting or (lowest < 0 and result.criterion > 10 * on_lifting)):
        return None
    why = ("W as stored is not positive semidefinite (the lifting dropped "
           f"{lift.get('dropped')} eigenvalue(s), the smallest {lowest:.2e})"
           if lowest < 0 else "the lifting is not the file's W")
    if solved_lifting:
        text = (f"the run solved the lifting of the file's local problem, but the file's own u = W r + q is "
                f"not met (criterion {result.criterion:.2e}): {why}; the run's own arithmetic already met the "
                "tolerance on the lifting, so precision is not the cause")
    else:
        text = (f"the run's answer meets the lifting it solves to {on_lifting:.2e} but the file's own u = W r + q "
                f"only to {result.criterion:.2e}: {why}, so the file's local problem is not convex and the "
                "double run solves its convex lifting instead; the part of W the lifting dropped, not the "
                "rounding of the run's steps, sets the file's criterion (`--psd-shift` proves W + D, D ≥ 0 a "
                "small diagonal, a backward error on q)")
    return {"lifting_status": str(run_status), "lifting_criterion": float(on_lifting),
            "criterion": float(result.criterion), "text": text}


def held_most(result) -> dict | None:
    """The cone that cut the most of a run's steps short (``SolveResult.steps_held``; the first
    to do so on a tie): {"contact", "part", "side", ("component"), "count", "iterations" (the
    steps it held, by the iterate they start from), "short_steps" (all steps shorter than 1)};
    None when every step was full."""
    held = result.steps_held
    if not held:
        return None
    names = [tuple((key, h[key]) for key in ("component", "contact", "part", "side") if key in h) for h in held]
    counts = Counter(names)
    top = max(counts, key=counts.get)  # counters keep first-seen order, and max keeps the first maximum
    return {**dict(top), "count": counts[top], "short_steps": len(held),
            "iterations": [h["from_iteration"] for h, name in zip(held, names) if name == top]}


def held_text(most: dict | None, nit: int) -> list[str]:
    """The sentence of :func:`held_most` for the evidence (none for None): where a stalled run's
    steps hit a cone's boundary."""
    if most is None:
        return []
    its = most["iterations"]
    # nit is the longest component's: a component's iterations are its own
    # numbered from 0, as contacts are, and as solve --verbose and the JSON number components
    where, of = (f" (component {most['component']})", "") if "component" in most else ("", f" (of {nit})")
    return [f"{most['short_steps']} of the run's steps were cut short by a cone's boundary; "
            f"{cone_words(most)}{where} held {most['count']} of them, the first at iteration {its[0]} and the "
            f"last at iteration {its[-1]}{of}"]


CAUSE_WORDS = {"precision": "double precision", "iterations": "too few iterations", "data": "the data, not precision",
               "none": "none"}


def _conclusion(d: Diagnosis) -> str:
    """Cause and remedy in one sentence."""
    ev = d.evidence or {}
    if d.cause is None:
        why = (ev.get("text") or ["the diagnosis stopped before its counterfactual"])[-1]
        return f"Cause: not determined ({why}). Remedy: none tried."
    if d.cause == "none":
        return f"Cause: none — the {d.method} run was Solved at tol = {d.tol:g}; nothing to fix."
    run = ev.get("exact") or {}
    early = ev.get("exact_from_start") or {}
    dep = ev.get("departure")
    if d.cause == "precision" and not run:
        lock = ev.get("lockstep_run") or {}
        what = (f"Cause: double precision — the {d.method} run ended {d.status} as `rfverify solve --method {d.method}` runs it, while the "
                f"same form with every linear solve refined to the floor of longdouble arithmetic meets tol = "
                f"{d.tol:g} ({lock.get('status')} after {lock.get('nit')} iterations).")
    elif d.cause == "precision":
        reached = run.get("reached_at") if run.get("reached_at") is not None else early.get("reached_at")
        start = run.get("start") if run.get("reached_at") is not None else 0
        sf = ev.get("shortfall")
        where = (f", departing from the exact steps at iteration {dep['iter']} ({dep['digits']:.1f} digits)" if dep
                 else f", its steps keeping fewer digits than the tolerance needs from iteration {sf['iter']} "
                      f"({sf['digits']:.1f}; cond(Q_p) = {sf['max_cond_Qp']:.1e})" if sf else "")
        what = (f"Cause: double precision — the {d.method} run ended {d.status}{where}, while the same algorithm in "
                f"exact arithmetic, continued from its iteration {start}, meets tol = {d.tol:g} at iteration {reached}.")
    elif d.cause == "iterations":
        reached = run.get("reached_at") if run.get("reached_at") is not None else early.get("reached_at")
        what = (f"Cause: too few iterations — the run's steps are the exact ones, and the exact algorithm needs "
                f"{reached if reached is not None else 'more than'} {'iterations' if reached is not None else ''}"
                .rstrip() + f" (max_iter = {d.nit if d.status == Status.MAX_ITERATIONS else 'its limit'}).")
    elif ev.get("file_only"):
        what = f"Cause: the data, not double precision — {ev['file_only']['text']}."
    elif d.remedy and "--sigma-rule" in d.remedy["args"]:
        what = (f"Cause: the centring rule on these data, not double precision — the same algorithm in exact "
                f"arithmetic stalls too ({run.get('status', '?')}, best criterion "
                f"{run.get('best_criterion', float('nan')):.1e}), while with the paper's σ rule the double solve meets "
                f"tol = {d.tol:g}.")
    else:
        what = (f"Cause: the data, not double precision — the same algorithm in exact arithmetic stalls too "
                f"({run.get('status', '?')}, best criterion {run.get('best_criterion', float('nan')):.1e}).")
    if d.remedy:
        r = d.remedy
        what += (f" Remedy: `rfverify solve PROBLEM {command_args(r['args'], d.tol)}` "
                 f"({r['status']}, criterion {r['criterion']:.1e}, {r['time']:.2f} s, run by this diagnosis).")
    else:
        tried = ev.get("remedies_tried") or []
        what += (" Remedy: none of " + "; ".join(f"`{' '.join(t['args'])}` ({t['status']}, {t['criterion']:.1e})"
                                                 for t in tried) + " met the tolerance." if tried
                 else " Remedy: none tried.")
    return what
