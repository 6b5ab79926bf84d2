"""Why a double run stalled, shown by the same algorithm in exact arithmetic (DESIGN §5).

:func:`diagnose` runs ``method`` in double as ``rfverify solve`` runs it (the run diagnosed), and
again as one system keeping every iterate, every linear solve refined to the floor of the
extended arithmetic (the lockstep's run: its digits measure rounding alone); where that run meets
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

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .exact import ExactAlgorithm, ExactRun, ExactStepError, dd_difference
from ..extended import ipm as ext
from ..model.lifting import lift
from ..model.measures import data_scales, measures
from ..model.problem import SPACEDIM, Problem
from ..solver import DOUBLE_REACH, posed, solve
from ..algorithm.rules import rule_at
from ..solver.result import ALGORITHM1_METHODS, ResultAliases, Status, method_unavailable

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

WITNESS_SECONDS = 90.0
"""Default budget of the mpmath witness (seconds): at 700 contacts one reference step takes
about 3 s (40 digits), so the continuation of a ~750-contact Chute fits, with the rest of the
diagnosis, in two minutes on two cores."""


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
                              step), ``digits`` (the fewest of those measured), ``expected``
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
    rounding alone, and unless ``extended_below`` is, it runs in the extended arithmetic from
    the first iteration (``extended_below=None``), so that every iteration's digits measure the
    same arithmetic.  The remedies run with the solver's defaults, as ``rfverify solve`` does.

    ``noscaling``'s Newton direction (Arw(s), Arw(z)) is not the NT direction the exact steps
    take: its digits measure that difference as well as rounding, no departure is located, and
    the counterfactual continues the NT algorithm from its best iterate.
    """
    say = progress or (lambda message: None)
    t0 = time.perf_counter()
    time_limit = options.get("time_limit")
    deadline = None if time_limit is None else t0 + time_limit
    user_options = {k: v for k, v in options.items() if k != "time_limit"}
    options.setdefault("refine_tol", None)
    options.setdefault("extended_below", None)
    problem = posed(problem, options.pop("as_stored", None), method)
    from ..model.scaling import binary_scaling, scaled_problem

    scaling = binary_scaling(problem)
    note_units = None
    if scaling is not None:  # digits and causes do not depend on units: diagnose in the scaled ones
        problem = scaled_problem(problem, scaling)
        note_units = f"diagnosed in exactly scaled units ({scaling.describe()})"

    # The run as `rfverify solve` makes it (default settings, independent components split): the
    # run whose outcome the diagnosis is about.  Then the lockstep's run: the same form as one
    # system, keeping every iterate, its solves refined to the floor (see above).
    plain = solve(problem, method=method, tol=tol, max_iter=max_iter, **user_options)
    res = solve(problem, method=method, tol=tol, max_iter=max_iter, keep_iterates=True, **options)
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
    ctx = _Context(problem, res, lp, method, tol, max_iter, say, deadline)
    if lp.nk != ctx.exact.data.nk or lp.nz != ctx.exact.data.nz:
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("reduce_cones", "the exact steps work on the reduced lifting (DESIGN §2.1)",
                                   fix="drop reduce_cones=False")
    t2 = time.perf_counter()
    steps, cut = _lockstep(ctx)
    diag.steps = steps
    t3 = time.perf_counter()
    evidence = {"r_unique": ctx.r_unique, "r_unique_note": ctx.r_unique_note,
                "mu_zero_contacts": int(np.sum(problem.mu == 0)), "form_block": FORM_BLOCK.get(method),
                "form_power": FORM_POWER.get(method), "form_order": ctx.order, "text": []}
    evidence["run"] = _run_record(plain, "as `rfverify solve` runs it")
    evidence["lockstep_run"] = _run_record(res, "one system, every linear solve refined to the floor, extended "
                                                "arithmetic from the first iteration (refine_tol=None, "
                                                "extended_below=None unless given)")
    if note_units:
        evidence["units"] = note_units
    timings = {"double": t1 - t0, "setup": t2 - t1, "steps": t3 - t2, "exact": 0.0, "witness": 0.0,
               "remedies": 0.0}
    dep = sf = None
    if method != "noscaling":  # (its direction is not the exact steps', see above)
        dep, sf = _departure(ctx, steps), _shortfall(ctx, steps)
    evidence["departure"], evidence["shortfall"] = dep, sf
    marks = [m["iter"] for m in (dep, sf) if m is not None]
    focus = min(marks) if marks else None  # the first step that is not good enough
    if cut is not None:
        diag.status, diag.message = Status.MAX_TIME, f"{plain.message}; {cut}"
        evidence["text"].append(cut)
    elif plain.success or res.success:
        if plain.success:
            diag.cause = "none"
            evidence["text"].append(_healthy_text(ctx, steps))
        else:  # the same form with every solve refined meets the tolerance: the default solves' precision
            diag.cause = "precision"
            evidence["text"].append(_refined_text(ctx, plain, res))
        _witness(ctx, steps, focus, None, evidence, dps, witness_time, timings)
        evidence["text"] += (evidence.get("witness") or {}).get("text", [])
        if not plain.success and remedies and ctx.in_time():
            t5 = time.perf_counter()
            diag.remedy, evidence["remedies_tried"] = _remedies(ctx, "precision", None, user_options)
            timings["remedies"] = time.perf_counter() - t5
    else:
        t4 = time.perf_counter()
        main, early = _counterfactual(ctx, focus, keep=witness_time > 0)
        evidence["exact"] = main.as_dict()
        evidence["exact_from_start"] = None if early is None else early.as_dict()
        timings["exact"] = time.perf_counter() - t4
        decided = early if early is not None and _better(early, main, max_iter) else main
        diag.cause = _cause(ctx, decided)
        _witness(ctx, steps, focus, decided, evidence, dps, witness_time, timings)
        diag.cause = _witnessed_cause(diag.cause, evidence.get("witness"), max_iter)
        evidence["text"] += _cause_text(ctx, diag.cause, dep, sf, main, early, decided, steps, evidence)
        if remedies and ctx.in_time():
            t5 = time.perf_counter()
            diag.remedy, evidence["remedies_tried"] = _remedies(ctx, diag.cause, decided, user_options)
            timings["remedies"] = time.perf_counter() - t5
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


class _Context:
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
        return False, f"H has {nk} kept columns and only {HK.shape[0]} rows: r is not unique (hyperstatic), Hr is"
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
    return False, (f"r is not unique (hyperstatic): H is rank deficient on the kept components "
                   f"(λmin(HᵀH) ≤ {nk}·u·λmax); Hr is unique")


# ---------------------------------------------------------------------- lockstep
def _digits(err_inf: float, scale: float) -> float:
    if not math.isfinite(err_inf):
        return float("nan")
    if err_inf == 0:
        return math.inf
    return -math.log10(err_inf / scale) if scale > 0 else float("nan")


def _agreement(ctx: _Context, st, v1, r1, z1) -> dict:
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
        out["digits_u"] = _digits(_inf(W @ d_r), max(_inf(u_exact), sc.u_free))
    else:
        d_v = dd_difference(st.v, v1)
        v_exact = st.v.h
        u_exact = ctx.HT @ v_exact + problem.w
        out["digits_v"] = _digits(_inf(d_v), max(_inf(v_exact), sc.v_free))
        out["digits_u"] = _digits(_inf(ctx.HT @ d_v), max(_inf(u_exact), sc.u_free))
        out["digits_Hr"] = _digits(_inf(ctx.H @ d_r), max(_inf(ctx.H @ r_exact), ctx.f_inf))
    if ctx.r_unique:
        out["digits_r_t"] = _digits(_inf(d_r), max(_inf(r_exact), sc.r))
        out["digits_z"] = _digits(_inf(dd_difference(st.z, z1)), max(_inf(st.z.h), sc.u_free))
    else:
        out["digits_r_t"] = out["digits_z"] = float("nan")
    counted = [out[k] for k in ("digits_v", "digits_u", "digits_Hr", "digits_r_t", "digits_z")
               if not math.isnan(out[k])]
    out["digits"] = min(counted) if counted else float("nan")
    return out


def _inf(x) -> float:
    return float(np.max(np.abs(x), initial=0.0))


def _expected(ctx: _Context, cond: float) -> float:
    """−log10(N·u·κ), κ = cond(Q_p)^power of the form: the digits a backward-stable double
    solve of the form keeps at an iterate with that cond(Q_p)."""
    if not (cond > 0 and math.isfinite(cond)):
        return float("nan")
    return ctx.reach - FORM_POWER.get(ctx.method, 1) * math.log10(max(cond, 1.0))


def _lockstep(ctx: _Context):
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
                            "digits_z": nan, "digits": nan, "max_cond_Qp_exact": nan, "expected": nan,
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


def _departure(ctx: _Context, steps: list) -> dict | None:
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


def _shortfall(ctx: _Context, steps: list) -> dict | None:
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
        return 4 * np.finfo(np.longdouble if settings.refine_extended else np.float64).eps
    if rt == "adaptive":
        from ..solver.ipm import REFINE_FORCING

        return REFINE_FORCING
    return float(rt)


def _through(ctx: _Context, s: dict) -> str:
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
    return (f"rounding beyond the form's conditioning: cond(Q_p) = {s['max_cond_Qp_exact']:.1e} leaves "
            f"{s['expected']:.1f} digits, the step kept {s['digits']:.1f}")


def _shortfall_text(ctx: _Context, sf: dict) -> str:
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


def _run_record(res, how: str) -> dict:
    return {"how": how, "status": str(res.status), "message": res.message, "nit": int(res.nit),
            "criterion": float(res.criterion), "components": len(res.extras.get("component_runs") or []) or 1}


def _refined_text(ctx, plain, res) -> str:
    split = plain.extras.get("component_runs") or []
    how = f", split into {len(split)} independent components" if split else ""
    return (f"as `rfverify solve` runs it (default inexact linear solves, float64 until the criterion is 1e-9{how}) "
            f"the {ctx.method} run ends {plain.status} at criterion {plain.criterion:.1e}; the same form as one system "
            f"with every linear solve refined to the floor of the extended arithmetic meets the tolerance "
            f"({res.status} after {res.nit} iterations, criterion {res.criterion:.1e}; its steps against the exact "
            f"ones below): more precision in the linear algebra is what the run lacks")


def _healthy_text(ctx, steps) -> str:
    finite = [s for s in steps if math.isfinite(s["digits"])]
    if not finite:
        return "the run reached its tolerance"
    worst = min(finite, key=lambda s: s["digits"])
    return (f"the run reached its tolerance; its steps agreed with the exact steps from the same points to at least "
            f"{worst['digits']:.1f} digits of {_quantities(ctx)} (at iteration {worst['iter']}, cond(Q_p) = "
            f"{worst['max_cond_Qp']:.1e})")


def _quantities(ctx) -> str:
    q = ["u"] if ctx.local else ["v", "u", "Hr"]
    if ctx.r_unique:
        q += ["r", "z"]
    return ", ".join(q)


# ---------------------------------------------------------------------- counterfactual
def _counterfactual(ctx: _Context, focus, keep: bool = False):
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


def _better(a: ExactRun, b: ExactRun, max_iter: int) -> bool:
    """Whether run ``a`` says more than ``b``: it met the tolerance within the limit, or sooner."""
    ka = a.reached_at if a.reached_at is not None else math.inf
    kb = b.reached_at if b.reached_at is not None else math.inf
    return ka < kb


def _cause(ctx: _Context, run: ExactRun) -> str | None:
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


def _witnessed_cause(cause, wit, max_iter):
    """The mpmath witness's own continuation, where it ran to its end, decides a disagreement."""
    if not wit or wit.get("run") is None or cause is None:
        return cause
    run = wit["run"]
    if run["reached_at"] is not None:
        return "precision" if run["reached_at"] <= max_iter else "iterations"
    if run["stopped"].startswith("no step"):
        return "data"
    return cause  # the witness stopped early (budget): the double-double run stands


def _cause_text(ctx, cause, dep, sf, main, early, decided, steps, evidence) -> list:
    """The evidence in sentences, with the figures."""
    res, tol = ctx.res, ctx.tol
    out = []
    if dep is not None and dep["kind"] == "beyond conditioning":
        out.append(f"the double step first departed from the exact one at iteration {dep['iter']}: "
                   f"{dep['digits']:.1f} digits of {_quantities(ctx)}, below its threshold {dep['threshold']:.1f} "
                   f"(the fewer of the digits the tolerance needs and those the form's conditioning leaves), "
                   f"through {dep['through']}")
    elif dep is not None:
        out.append(f"the double step first departed from the exact one at iteration {dep['iter']} "
                   f"({dep['digits']:.1f} digits of {_quantities(ctx)}), through {dep['through']}")
    if sf is not None and (dep is None or sf["iter"] != dep["iter"] or sf["within_conditioning"]):
        out.append(_shortfall_text(ctx, sf))
    if dep is None and sf is None and ctx.method != "noscaling":
        finite = [s for s in steps if math.isfinite(s["digits"])]
        if finite:
            worst = min(finite, key=lambda s: s["digits"])
            out.append(f"every double step kept the digits the tolerance needs (fewest {worst['digits']:.1f} of "
                       f"{_quantities(ctx)}, at iteration {worst['iter']})")
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
        return _digits(_inf(ctx.problem.local.W @ d_r),
                       max(_inf(ctx.problem.local.velocity(r_exact)), ctx.scales.u_free))
    d_v = _minus_mp(v_dd, it_mp.v)
    return min(_digits(_inf(d_v), max(_inf(v_dd.h), ctx.scales.v_free)),
               _digits(_inf(ctx.HT @ d_v), max(_inf(ctx.HT @ v_dd.h + ctx.problem.w), ctx.scales.u_free)),
               _digits(_inf(ctx.H @ d_r), max(_inf(ctx.H @ r_exact), ctx.f_inf)))


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


def _witness(ctx, steps, focus, run, evidence, dps, budget, timings):
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
    except RJ.ReferenceDomainError as exc:
        out["step"].update(agrees_with_double_double=None, double_digits=None)
        out["text"].append(f"mpmath witness: no exact step from iteration {k} either ({exc})")
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
            except RJ.ReferenceDomainError as exc:
                entry.update(agrees_with_double_double=None, criterion=None)
                out["text"].append(f"mpmath witness: no step from the exact continuation's iteration {kl} ({exc})")
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
            start, k0, g0, n = after.iterate, k + 1, _gamma_after(after.alpha), n - 1
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
        out["text"].append("(the mpmath reference solves with (M + Mᵀ)/2 rounded to float64, the exact steps with it "
                           "exact: M is unsymmetric here, so the two agree only to that rounding)")
    out["seconds"] = time.perf_counter() - t0
    timings["witness"] += out["seconds"]
    evidence["witness"] = out


def _gamma_after(alpha) -> float:
    """The paper's γ after a step α (the double run's rule)."""
    from ..algorithm.rules import step_fraction

    return step_fraction(float(alpha), 0.09)


# ---------------------------------------------------------------------- remedies
def _remedies(ctx: _Context, cause, run: ExactRun, user_options: dict):
    """Run the candidates in the order the cause suggests; the first whose answer meets the
    tolerance is the remedy.  Returns (remedy or None, every candidate tried)."""
    from .digits import solve_to_digits

    problem, tol, max_iter, method = ctx.problem, ctx.tol, ctx.max_iter, ctx.method
    base = ["--max-iter", str(max_iter)] if max_iter != 100 else []
    if problem.as_stored:
        base += ["--as-stored"]
    options = {k: v for k, v in user_options.items() if k not in ("refine_tol", "extended_below", "as_stored")}
    forms = [m for m in ALGORITHM1_METHODS if m != method and method_unavailable(m) is None]
    reached = None if run is None else run.reached_at
    more = max(2 * max_iter, int(1.25 * reached) + 5) if reached is not None else 2 * max_iter
    # Below double's reach no float64 answer meets the criterion: a proof of K digits is the answer.
    ks = (15, 12, 10) if tol < DOUBLE_REACH else (max(1, min(15, math.ceil(-math.log10(tol)))),)
    iters = [("solve", {"method": method, "max_iter": more}, ["--method", method, "--max-iter", str(more)])]
    by_form = [("solve", {"method": m, "max_iter": max_iter}, ["--method", m] + base) for m in forms]
    if tol < DOUBLE_REACH:  # the double stage of the k-digit path at a tolerance double can reach
        digits = [("digits", {"digits": k, "max_iter": max_iter, "tol": 1e-10},
                   ["--digits", str(k), "--tol", "1e-10"] + base) for k in ks]
    else:
        digits = [("digits", {"digits": k, "max_iter": max_iter}, ["--digits", str(k)] + base) for k in ks]
    plan = {"precision": by_form + digits, "iterations": iters + by_form + digits,
            "data": by_form + iters + digits}.get(cause, by_form + digits)
    tried = []
    for kind, kw, args in plan:
        if not ctx.in_time():
            break
        ctx.say(f"remedy: rfverify solve PROBLEM {_command_args(args, tol)}")
        limit = {} if ctx.deadline is None else {"time_limit": max(ctx.deadline - time.perf_counter(), 1e-3)}
        t0 = time.perf_counter()
        if kind == "solve":
            out = solve(problem, tol=tol, **kw, **options, **limit)
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
CAUSE_WORDS = {"precision": "double precision", "iterations": "too few iterations", "data": "the data, not precision",
               "none": "none"}


def _command_args(args: list, tol: float) -> str:
    """``rfverify solve`` arguments: the remedy's, then the tolerance unless they set one."""
    return " ".join(list(args) + ([] if "--tol" in args else ["--tol", f"{tol:g}"]))


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
        what = (f"Cause: double precision — the {d.method} run ended {d.status} as `rfverify solve` runs it, while the "
                f"same form with every linear solve refined to the floor of the extended arithmetic meets tol = "
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
    else:
        what = (f"Cause: the data, not double precision — the same algorithm in exact arithmetic stalls too "
                f"({run.get('status', '?')}, best criterion {run.get('best_criterion', float('nan')):.1e}).")
    if d.remedy:
        r = d.remedy
        what += (f" Remedy: `rfverify solve PROBLEM {_command_args(r['args'], d.tol)}` "
                 f"({r['status']}, criterion {r['criterion']:.1e}, {r['time']:.2f} s, run by this diagnosis).")
    else:
        tried = ev.get("remedies_tried") or []
        what += (" Remedy: none of " + "; ".join(f"`{' '.join(t['args'])}` ({t['status']}, {t['criterion']:.1e})"
                                                 for t in tried) + " met the tolerance." if tried
                 else " Remedy: none tried.")
    return what
