"""Lockstep diagnosis of the double-precision solver against the mpmath reference (DESIGN §5).

For every iteration k of a double run, the reference takes the *exact* step from the double
iterate k (one iteration of its Algorithm 1 from there, :meth:`reference.Solver.step`); the
difference between that exact next iterate and the double iterate k+1 is the rounding error of
iteration k.  Reported per iteration: digits of agreement of (v, r̃, z), max cond(Q_p), and min
λ2 of z and Jᵀr̃ in double and in the reference — flagging where the double λ2 has underflowed
or gone non-positive while the exact one is positive — and, for a failed run, the iteration,
operation and cone where it stopped (the solver's own diagnosed message).  A double iterate that
is not interior in exact arithmetic has no exact step: its digits and reference λ2 are NaN and
a flag says why.

The result is a :class:`Diagnosis` (status, message, nit, timings, and the per-iteration
``steps``); :meth:`Diagnosis.to_dict` is the JSON that ``rfverify diagnose --json`` prints.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from .lifting import lift
from .problem import Problem
from .solver import solve
from .algorithm.rules import rule_at
from .solver.result import ResultAliases, Status


@dataclass
class Diagnosis(ResultAliases):
    """Result of :func:`diagnose` (docs/RESULTS.md has the fields of every result in one table).

    Attributes
    ----------
    method : str              linear-system form of the double run
    status : Status           the double run's status (a str enum: ``status == "Solved"``)
    success : bool            status is Solved
    message : str             the double run's message
    nit : int                 iterations of the double run (alias ``iterations``)
    steps : list of dict      one record per iteration k: ``iter``, ``mu``, ``digits_v``,
                              ``digits_r_t``, ``digits_z`` (digits of agreement of iterate k+1
                              with the exact step from iterate k; NaN where there is none),
                              ``max_cond_Qp``, ``min_lam2_z`` and ``min_lam2_s`` (each a dict
                              ``{"double", "reference"}``: smallest λ2 of z and of Jᵀr̃),
                              ``flags`` (list of str), ``reference_step``
    failure : str or None     the message of a run that was not Solved
    timings : dict            seconds: ``double`` (the double run), ``reference`` (building the
                              reference), ``steps`` (the exact steps), ``total``
                              (alias ``solve_time`` = ``timings["total"]``)
    """

    method: str
    status: Status
    message: str
    nit: int
    steps: list = field(default_factory=list)
    failure: str | None = None
    timings: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.status == Status.SOLVED

    @property
    def flagged(self) -> list:
        """The steps with at least one flag (a λ2 underflow, a sign lost, no exact step)."""
        return [s for s in self.steps if s["flags"]]

    def as_dict(self) -> dict:
        """The JSON-able dict ``rfverify diagnose --json`` prints (:meth:`to_dict`)."""
        return self.to_dict()

    @property
    def conclusion(self) -> str:
        """The diagnosis in words: what broke, where, why, and what to do (or that nothing did)."""
        steps = [s for s in self.steps if np.isfinite(s.get("digits_v", np.nan))]
        worst = min(steps, key=lambda s: min(s["digits_v"], s["digits_r_t"], s["digits_z"]), default=None)
        flagged = self.flagged
        if flagged:
            f = flagged[0]
            return (f"Double precision broke at iteration {f['iter']}: {f['flags'][0]}. Why: at μ = {f['mu']:.1e} "
                    f"the NT scaling's condition cond(Q_p) = {f['max_cond_Qp']:.1e} "
                    f"{'exceeds' if f['max_cond_Qp'] > 1 / np.finfo(float).eps else 'nears'} 1/eps ≈ 4.5e15, so rounding "
                    "moves the iterate across the cone boundary that the exact step keeps. What to do: ask for "
                    "a tolerance the run reached before that (its criterion is in `rfverify solve --verbose`), or "
                    "`rfverify solve --digits K`, which continues in double-double and proves K digits.")
        if worst is None:
            return f"No exact step could be compared: {self.message}"
        low = min(worst["digits_v"], worst["digits_r_t"], worst["digits_z"])
        where = f"(fewest {low:.1f} digits, at iteration {worst['iter']}, cond(Q_p) = {worst['max_cond_Qp']:.1e})"
        if self.success:
            return (f"Healthy: every double iterate agreed with the exact step from the same point {where}, and "
                    "the run reached its tolerance; nothing to fix.")
        return (f"The double run ended {self.status} without a rounding failure: its iterates agreed with the "
                f"exact steps {where}, so double precision is not the cause. What to do: more --max-iter, "
                "another --method, or `rfverify solve --verbose` to see which measure stalls.")

    def to_dict(self) -> dict:
        """The JSON-able dict ``rfverify diagnose --json`` prints: ``method``, ``status`` (its
        name), ``message``, ``nit``, ``iterations`` (the list of :attr:`steps`), ``failure``,
        ``timings``."""
        return {"method": self.method, "status": str(self.status), "message": self.message, "nit": self.nit,
                "iterations": list(self.steps), "failure": self.failure, "timings": dict(self.timings),
                "conclusion": self.conclusion}

    def __repr__(self) -> str:
        flagged = self.flagged
        first = (f"first flag at iteration {flagged[0]['iter']}: {flagged[0]['flags'][0]}" if flagged
                 else "no flag")
        total = self.timings.get("total", float("nan"))
        return (f"Diagnosis(method={self.method!r}, status={self.status}, nit={self.nit}, "
                f"steps={len(self.steps)}, flagged={len(flagged)}, time={total:.3g} s,\n"
                f"    {first},\n    {self.message!r})")


def _digits(a, b) -> float:
    scale = np.max(np.abs(b), initial=0.0)
    err = np.max(np.abs(a - b), initial=0.0)
    if err == 0:
        return math.inf
    return float(-math.log10(err / scale)) if scale > 0 else 0.0


def diagnose(problem: Problem, method: str = "jqinv", tol: float = 1e-10, max_iter: int = 100,
             dps: int = 40, progress=None, **options) -> Diagnosis:
    """Run ``method`` in double and the reference in lockstep; see the module docstring.

    Returns a :class:`Diagnosis`: ``status``/``message``/``nit`` of the double run, ``steps``
    (one record per iteration) and ``timings``; ``to_dict()`` is its JSON.  ``progress(message)`` receives one line per stage and per
    exact step (the steps are the slow part: seconds each at a few hundred contacts).

    ``options`` are solver settings; ``time_limit`` (seconds) bounds the whole diagnosis: the
    double run gets it, and the lockstep stops at the first exact step past it (status MaxTime,
    the steps done so far kept).  Unless ``refine_tol`` is among them, the double run
    refines every linear solve to 4·eps (``refine_tol=None``) instead of the solver's default
    inexact-Newton stop, so that the digits of agreement measure rounding alone (the default
    stops a solve at residuals of 1e-4 of its right-hand side, which this comparison would
    count as error: 11–12 digits on the bundled problems instead of 14–16), and unless
    ``extended_below`` is, it runs in the extended arithmetic from the first iteration
    (``extended_below=None``) instead of the solver's default float64 start, so that every
    iteration's digits measure the same arithmetic.
    """
    options.setdefault("refine_tol", None)
    options.setdefault("extended_below", None)
    say = progress or (lambda message: None)
    import reference
    from reference import jordan as RJ

    t0 = time.perf_counter()
    time_limit = options.get("time_limit")
    deadline = None if time_limit is None else t0 + time_limit
    res = solve(problem, method=method, tol=tol, max_iter=max_iter, keep_iterates=True, **options)
    lp = lift(problem, reduce_cones=res.settings.reduce_cones)
    order = np.lexsort((lp.cone_part, lp.cone_contact))
    active = res.extras["active_dofs"]
    iterates = res.extras["iterates"]
    tr = res.trace
    say(f"double run ({method}): {res.status} after {res.nit} iterations; building the reference at {dps} digits")
    t1 = time.perf_counter()
    exact = reference.Solver(problem, dps=dps)  # one build for every step of the run
    t2 = time.perf_counter()
    records = []
    cut = None
    for k in range(len(iterates) - 1):
        if deadline is not None and time.perf_counter() > deadline:
            cut = (f"time limit of {time_limit:g} s reached after {k} of {len(iterates) - 1} exact steps "
                   "(the steps done are kept)")
            say(cut)
            break
        say(f"exact step {k + 1} of {len(iterates) - 1}")
        v_k, r_k, z_k = iterates[k]
        v_full = np.array(res.v, dtype=np.longdouble)
        v_full[active] = v_k
        v1, r1, z1 = iterates[k + 1]
        lam2_z_dbl = float(tr["min_lam2_z"][k + 1]) if k + 1 < len(tr["iter"]) else float("nan")
        lam2_s_dbl = float(tr["min_lam2_s"][k + 1]) if k + 1 < len(tr["iter"]) else float("nan")
        record = {"iter": k, "max_cond_Qp": float(tr["max_cond_Qp"][k]), "mu": float(tr["mu"][k])}
        try:
            # Same step-length fraction γ and σ rule as the double run at this iteration.
            step = exact.step(exact.iterate(*_reference_layout(lp, order, v_full, r_k, z_k)),
                              gamma=float(tr["gamma"][k]),
                              sigma_rule=rule_at(res.settings.sigma_rule, float(tr["criterion"][k])))
        except RJ.ReferenceDomainError as exc:
            nan = float("nan")
            records.append({**record, "digits_v": nan, "digits_r_t": nan, "digits_z": nan,
                            "min_lam2_z": {"double": lam2_z_dbl, "reference": nan},
                            "min_lam2_s": {"double": lam2_s_dbl, "reference": nan},
                            "flags": [f"no exact step from the double iterate: {exc}"],
                            "reference_step": f"no exact step: {exc}"})
            continue
        nxt = step.iterate
        ref_v = np.array([float(x) for x in nxt.v])[active]
        ref_r = np.array([float(x) for x in nxt.r_t])
        # z of the double iterate in the reference's cone order, flattened the same way.
        z1_cones = _reference_layout(lp, order, v_full, r1, z1)[2]
        ref_z = np.concatenate([[float(x) for x in c] for c in nxt.z])
        dbl_z = np.concatenate([np.asarray(c, dtype=np.float64) for c in z1_cones])
        lam2_z_ref = min(float(RJ.spectral_values(c)[1]) for c in nxt.z)
        lam2_s_ref = min((float(RJ.spectral_values(c)[1]) for c in exact.s_cones(nxt)), default=math.inf)
        flags = []
        for name, d, e in (("z", lam2_z_dbl, lam2_z_ref), ("Jᵀr̃", lam2_s_dbl, lam2_s_ref)):
            if e > 0 and not d > 0:
                flags.append(f"λ2({name}) ≤ 0 in double while exact is {e:.2e}")
            elif e > 0 and d < 1e-300:
                flags.append(f"λ2({name}) underflowed in double (exact {e:.2e})")
        records.append({
            "iter": k,
            "digits_v": _digits(np.asarray(v1, dtype=np.float64), ref_v),
            "digits_r_t": _digits(np.asarray(r1, dtype=np.float64), ref_r),
            "digits_z": _digits(dbl_z, ref_z),
            "max_cond_Qp": record["max_cond_Qp"],
            "min_lam2_z": {"double": lam2_z_dbl, "reference": lam2_z_ref},
            "min_lam2_s": {"double": lam2_s_dbl, "reference": lam2_s_ref},
            "mu": record["mu"],
            "flags": flags,
            "reference_step": "exact step from the double iterate",
        })
    t3 = time.perf_counter()
    status, message = Status(res.status), res.message
    if cut is not None:
        status, message = Status.MAX_TIME, f"{message}; {cut}"
    return Diagnosis(method=method, status=status, message=message, nit=int(res.nit),
                     steps=records, failure=None if res.success else res.message,
                     timings={"double": t1 - t0, "reference": t2 - t1, "steps": t3 - t2, "total": t3 - t0})


def _reference_layout(lp, order, v, r_t, z) -> tuple:
    """A production iterate (v, r̃, z in the lifted layout of :func:`rfverify.lifting.lift`)
    as (v, r̃, z cones) in the reference's layout: the same kept components, cones contact by
    contact (friction, rolling, normal ray) instead of all L3 cones first."""
    z = np.asarray(z)
    cones = [z[3 * c:3 * c + 3] for c in range(lp.n3)] + [z[3 * lp.n3 + k:3 * lp.n3 + k + 1] for k in range(lp.n1)]
    return np.asarray(v), np.asarray(r_t), [cones[i] for i in order]
