"""The proof driver of the extended phases (:class:`ProofDriver`): which iterates are proven,
which proof is the best so far, where it was made (:func:`proof_site`), and when a run stops."""

from __future__ import annotations

import math
import time

import numpy as np

from ..extended import ipm as ext
from ..extended import wide
from ..extended.data import ExtendedData
from ..extended.dd import vmul_d
from ..model.problem import SPACEDIM
from ..proof import Point, Proof, ProofContext, merit


def point_from_iterate(data: ExtendedData, v, r_t) -> Point:
    """(v, r = P r̃) of an extended iterate as double-double (r̃ scaled by μ or μr exactly
    enough: one double-double rounding)."""
    lp = data.lp
    n5 = SPACEDIM * data.n
    th, tl = np.zeros(lp.nk), np.zeros(lp.nk)
    vmul_d(lp.scale, r_t.h, r_t.l, th, tl)
    rh, rl = np.zeros(n5), np.zeros(n5)
    rh[lp.keep], rl[lp.keep] = th, tl
    if data.local:  # no dofs in the local form: v of the lifting (M = I, f = 0) is H r, information only
        vh = np.asarray(data.problem.H @ rh, dtype=np.float64)
        return Point(vh, np.zeros_like(vh), rh, rl)
    return Point(v.h.copy(), v.l.copy(), rh, rl)


RECENT = 8
"""Iterates the driver keeps: candidates for the wide tail's start, and the last three are
proven when no proof succeeded."""

def proven_answer(ctx: ProofContext, point: Point, digits: int, relative: bool):
    """(proof, (v, u, r)) of a float64 answer's point, its (v, u, r) rounded as the proof
    judges them."""
    v, u, r = ctx.rounded(point)
    return ctx.prove(point, v, u, r, requested=digits, relative=relative), (v, u, r)


def proof_site(phase: str, iteration: int | None = None, *, on_face: bool = False, predicted: bool = False) -> dict:
    """Where a proof's point came from: ``phase`` "double" (the double solve's answer),
    "extended" (a double-double iterate) or "multiple-precision" (an iterate of the tail),
    its ``iteration``, ``on_face`` when it is an iterate of the problem reduced to a face,
    lifted back (DESIGN §6.5), and ``predicted`` when it is not the iterate but the point along
    its predictor's direction (:meth:`rfverify.algorithm.policy.UntilPolicy.after_predictor`)."""
    return {"phase": phase, "iteration": iteration, "on_face": bool(on_face), "predicted": bool(predicted)}


def site_words(at: dict | None) -> str:
    """A :func:`proof_site` in words: "extended iteration 4", "the double solve's answer",
    "extended iteration 3 on the face", "extended iteration 12's predictor point"."""
    if at is None:
        return "no point"
    words = "the double solve's answer" if at["phase"] == "double" else f"{at['phase']} iteration {at['iteration']}"
    words += "'s predictor point" if at.get("predicted") else ""
    return words + (" on the face" if at.get("on_face") else "")


class ProofDriver:
    """The ``until`` callback of the extended phase: tries the proof where it may succeed,
    keeps the best one, and stops the run once ``requested`` digits are proven, or when μ
    has stalled for ``stall`` iterations."""

    def __init__(self, ctx: ProofContext, data: ExtendedData, requested: int, target=None, stall: int = 4,
                 progress=None, relative: bool = False, deadline: float | None = None, own=None):
        self.ctx, self.data, self.requested = ctx, data, requested
        self.relative = relative
        self.target = target  # (v, u, r) to certify; None: the rounding of each point
        self.face = None  # (FaceReduction, stresses): iterates of the reduced problem, proven lifted back
        # (ProofContext of the problem in its own units, ContactUnits): the run's problem has its
        # contacts' units brought together, and each point is proven in the problem's own units
        self.own = own
        self.best: tuple | None = None  # (score, proof, point, (v, u, r))
        self.best_at: dict | None = None  # where the best proof was made (proof_site), and
        self.last_at: dict | None = None  # where the last one was
        self.proofs = 0  # points proven in all (the double answer's and a face's included)
        self.proof_seconds = 0.0
        self.attempts = 0
        self.stall = stall
        self._mu_best = math.inf
        self._since = 0
        self.progress = progress
        self.recent = []  # the last few iterates: handover to the wide tail, and proven at the end
        self.proven_keys = set()  # ("dd" or "wide", iteration) of the iterates proven
        self.hopeless = False  # certifying a target: the point is already far closer than the target
        self.invalid_limit = None  # stop after this many invalid proofs in a row (None: never)
        self._invalid_run = 0
        self.gave_up = ""
        self.stalled_at = None  # (iteration, μ) where a stall ended a run, for the verdict
        self.deadline = deadline  # time.perf_counter() value past which the run stops (None: never)
        self.timed_out = False

    @property
    def certified(self) -> bool:
        return self.best is not None and self.best[1].certified

    def offer(self, proof: Proof, point: Point, sol, at: dict, *, ties: bool = False, proofs: int = 1) -> bool:
        """Record a proof made at ``at`` (:func:`proof_site`) — ``proofs`` points proven to
        reach it (a face's sub-run proves several) — and keep it as the best when it says more
        (with ``ties``, also when it says as much).  True when it became the best."""
        self.last_at = at
        self.proofs += proofs
        sc = self.score(proof)
        if self.best is None or sc > self.best[0] or (ties and sc >= self.best[0]):
            self.best, self.best_at = (sc, proof, point, sol), at
            return True
        return False

    def proven_at(self) -> dict | None:
        """Where the best proof was made, for the certificate (``extra["proven_at"]``): the
        :func:`proof_site` with ``where`` (its words), ``proofs`` (points proven in all) and
        ``last`` (where the last one was); None before any proof."""
        if self.best_at is None:
            return None
        return {**self.best_at, "where": site_words(self.best_at), "proofs": self.proofs,
                "last": site_words(self.last_at)}

    def answer(self, point: Point):
        """The float64 (v, u, r) a point stands for: its rounding, with r moved along the
        self-stresses into K where the point came from a face (DESIGN §6.8)."""
        v, u, r = self.ctx.rounded(point)
        if self.face is not None:
            from ..proof.face import returned_reactions

            r = returned_reactions(self.ctx.problem, self.face[1], r)
        return v, u, r

    def restart(self, invalid_limit: int | None = None):
        """Forget the stall counter and the recent iterates (a new phase begins); with
        ``invalid_limit``, stop once that many proofs in a row are invalid (a point outside the
        cones at every iterate: the feasible set has no interior, and iterating does not help)."""
        self._mu_best, self._since = math.inf, 0
        self.recent = []
        self.invalid_limit, self._invalid_run = invalid_limit, 0

    @staticmethod
    def score(proof: Proof) -> tuple:
        """Which of two proofs says more: the fewest proven digits (:func:`rfverify.proof.merit`)
        first, then the next fewest, and so on (a tuple compared in that order).  With every
        point tied at "Hr: no relative digits" (``relative`` where Hr* = 0) the digits of v and u
        then decide, not the order in which the points were proven."""
        if not proof.valid:
            return (-math.inf,)
        vals = sorted(math.inf if (q.certified and q.mode == "absolute") else
                      (-math.inf if q.digits is None else q.digits)
                      for q in proof.quantities.values() if q.mode != "information")
        return (merit(proof), *vals)

    @staticmethod
    def _distance_dominates(proof: Proof) -> bool:
        """True when v's or u's bound is uncertified and its point part (√(M⁻¹)_jj·ε or
        √W_kk·ε, and the free blocks' verified solve: the part more iterations shrink) is below
        1e-3 of it: the rest is the fixed distance from the point to the candidate."""
        t = proof.terms
        own = {"u": t.get("u_point_part", t["max_sqrt_W_kk"] * proof.eps_M)}
        if not proof.local:
            own["v"] = t.get("v_point_part", t["max_sqrt_Minv_jj"] * proof.eps_M)
        return any(not q.certified and own[name] < 1e-3 * q.abs_bound
                   for name, q in proof.quantities.items() if name in own and q.mode != "information")

    def __call__(self, it: ext.Iterate, force: bool = False, quiet: bool = False) -> bool:
        if getattr(it, "predicted", False):
            return self._predicted(it)
        if not force and self.deadline is not None and time.perf_counter() > self.deadline:
            self.timed_out = True  # the time limit: stop here; the best proof so far stands
            self.recent = (self.recent + [it])[-RECENT:]
            return True
        if it.mu < 0.5 * self._mu_best:
            self._mu_best, self._since = it.mu, 0
        else:
            self._since += 1
        stalled = self._since >= self.stall
        if not force:
            self.recent = (self.recent + [it])[-RECENT:]
        if isinstance(it, wide.WideIterate):
            gap, point, v_inf, u_inf = it.describe()
            key = ("wide", it.k)
        else:
            gap, point, v_inf, u_inf = self._describe(it)
            key = ("dd", it.k)
        if not math.isfinite(gap):  # not a point (a run that broke down): nothing to prove
            return stalled
        if not (stalled or force) and not self._may_certify(gap, v_inf, u_inf, point):
            return False
        if key in self.proven_keys:
            return False
        self.proven_keys.add(key)
        proof = self._prove(it, point, "multiple-precision" if key[0] == "wide" else "extended", quiet)
        if proof.certified:
            return True
        self._invalid_run = 0 if proof.valid else self._invalid_run + 1
        if stalled and not force:
            self.stalled_at = (it.k, it.mu)
        if self.invalid_limit is not None and self._invalid_run >= self.invalid_limit:
            self.gave_up = f"{self._invalid_run} proofs in a row were invalid ({proof.summary()})"
            return True
        if self.target is not None and proof.valid and self._distance_dominates(proof):
            # Certifying a given solution: once an uncertified quantity's bound is the distance
            # from the point to the solution, more iterations cannot certify it.
            self.hopeless = True
            return True
        return stalled

    def _describe(self, it: ext.Iterate) -> tuple:
        """(|r̃ᵀũ|, the point, ‖v‖∞, ‖u‖∞) of a double-double iterate, for :meth:`_may_certify`."""
        data = self.data
        u_t = ext.V(*data.velocity(it.v.h, it.v.l, it.r_t.h, it.r_t.l))
        point = point_from_iterate(data, it.v, it.r_t)
        v_inf = float(np.max(np.abs(it.v.h), initial=0.0))
        if data.local:
            u_inf = float(np.max(np.abs(data.problem.local.W @ point.r_hi + data.problem.local.q), initial=0.0))
        else:
            u_inf = float(np.max(np.abs(data.problem.H.T @ it.v.h + data.problem.w), initial=0.0))
        return abs(it.r_t.dot(u_t)), point, v_inf, u_inf

    def _may_certify(self, gap: float, v_inf: float, u_inf: float, point: Point | None = None) -> bool:
        ctx = self.ctx
        if self.own is not None and point is not None:  # the gate of the proof made: in the own units
            ctx, units = self.own
            u = units.back("u", self.data.problem.H.T @ point.v_hi + self.data.problem.w)
            u_inf = float(np.max(np.abs(u), initial=0.0))
        return ctx.may_certify(ctx.eps_lower(gap), v_inf, u_inf, self.requested, relative=self.relative)

    def _prove(self, it, point: Point, phase: str, quiet: bool, predicted: bool = False) -> Proof:
        """Prove ``point`` (an iterate's, or iteration k's predictor point) and offer it."""
        t0 = time.perf_counter()
        if self.face is not None:  # an iterate of the problem on a face: proven on the problem itself
            point = self.face[0].lift(point)
        sol = self.target if self.target is not None else self.answer(point)
        proof = self._own_proof(point, sol) if self.own is not None else \
            self.ctx.prove(point, *sol, requested=self.requested, relative=self.relative)
        self.proof_seconds += time.perf_counter() - t0
        self.attempts += 1
        at = proof_site(phase, it.k, on_face=self.face is not None, predicted=predicted)
        self.offer(proof, point, sol, at)
        if self.progress and not quiet:
            self.progress(f"proof at {site_words(at)} (μ = {it.mu:.1e}): {proof.summary()}")
        return proof

    def _own_proof(self, point: Point, sol) -> Proof:
        """The proof of ``point`` and its answer ``sol`` (in the run's units) made in the problem's
        own units (:attr:`own`): the same gap and residual, digits against its own norms."""
        from ..proof.bound import invalid_proof
        from .certificate import unscaled_point

        ctx, units = self.own
        own_point = unscaled_point(point, units)
        if own_point is None:
            return invalid_proof(self.requested, "the point does not carry back to the problem's own units exactly "
                                                 "(an entry leaves float64's range)", time.perf_counter())
        v, u, r = sol
        return ctx.prove(own_point, v, units.back("u", u), units.back("r", r), requested=self.requested,
                         relative=self.relative)

    def _predicted(self, it: ext.Iterate) -> bool:
        """Iteration k's predictor point (:data:`rfverify.algorithm.policy.PREDICTED_FRACTION`
        of its largest step): proven where it may certify, and the run stops only when it does —
        it counts neither towards a stall nor among the recent iterates."""
        if self.deadline is not None and time.perf_counter() > self.deadline:
            return False  # the iterate's own call stops the run
        wide_point = isinstance(it, wide.WideIterate)
        key = ("wide-predicted" if wide_point else "predicted", it.k)
        gap, point, v_inf, u_inf = it.describe() if wide_point else self._describe(it)
        if key in self.proven_keys or not math.isfinite(gap) or not self._may_certify(gap, v_inf, u_inf, point):
            return False
        self.proven_keys.add(key)
        phase = "multiple-precision" if wide_point else "extended"
        return self._prove(it, point, phase, quiet=False, predicted=True).certified
