"""The k-digit path: a double solve, the extended-precision phase, and a proof (DESIGN §6).

1. Algorithm 1 in double (mixed precision) to ``tol`` (default 1e-10).
2. Algorithm 1 continued in double-double from the last double iterate
   (:mod:`rfverify.extended`), until
3. the rigorous error bound (:mod:`rfverify.proof`), evaluated at the current iterate and
   carried to its float64 rounding, proves ``digits`` correct digits of v, u and Hr (and r
   where r is unique) — or a stated limit is reached (``extended_max_iter`` iterations, or μ
   no longer decreasing).

The proof is tried only at iterates where a cheap necessary condition holds
(:meth:`ProofContext.may_certify`), so it costs O(nnz) a few times per run; the double answer
too (:func:`double_answer_may_certify`), whose proof otherwise waits until no later point is
proven.  With two CPUs the set-up of stage 2 is built on the second one during stage 1
(:class:`Preparation`): CHOLMOD's factorisations there release the GIL
(:mod:`rfverify.engines.cholmod_nogil`).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .certificate import Certificate, candidate_point, certificate_from_proof
from ..errors import InvalidArgumentError
from ..extended import ipm as ext
from ..extended.dd import vmul_d
from ..extended import wide, wide_factor
from ..extended.contactspace import ENGINES
from ..extended.data import ExtendedData
from ..extended.system import choose_backend
from ..extended.workers import threads
from ..model.problem import SPACEDIM, Problem
from ..compilation import (compile_extended_in_background, compile_seconds, extended_cache_is_cold,
                          float64_kernels_deferred)
from ..proof import Point, Proof, ProofContext, merit, validate_digits
from ..solver import SolveResult, Status, posed, solve
from ..engines.factor import cholmod_available, on_factoring
from ..solver.result import ResultAliases


@dataclass
class DigitsSolution(ResultAliases):
    """Result of :func:`solve_to_digits`.

    ``v`` (m,), ``u`` (5n,), ``r`` (5n,) are float64 (the extended point rounded to nearest);
    ``point`` the extended-precision point the proof is about; ``certificate`` the proof's
    verdict; ``double`` the double solve; ``extended`` the double-double run; ``wide`` the
    multiple-precision tail (None when it did not run); ``timings`` seconds per stage
    (``double``, ``setup``, ``extended``, ``wide``, ``proof``, ``total``; proofs excluded from
    the others; ``setup`` is what the double-double phase's set-up still took after the double
    solve — on two CPUs it is built beside it, :class:`Preparation`; ``compile``: numba
    compiling kernels on a cold start, excluded from the stage it happened in, see
    :mod:`rfverify.compilation`).  ``timed_out``: the run stopped at its
    ``time_limit`` (status MaxTime unless what it had proven by then is enough).
    """

    v: np.ndarray
    u: np.ndarray
    r: np.ndarray
    point: Point | None
    certificate: Certificate
    double: SolveResult
    extended: object
    wide: object = None
    timings: dict = field(default_factory=dict)
    timed_out: bool = False
    interrupted: bool = False  # Ctrl-C ended the path: the best proof reached is the certificate

    @property
    def success(self) -> bool:
        return self.certificate.certified

    @property
    def status(self) -> Status:
        """``Status.CERTIFIED``, ``NOT_CERTIFIED``, or ``MAX_TIME`` when the time limit ended the
        run short of the requested digits (the best proof reached is the certificate)."""
        return self.certificate.status

    @property
    def digits(self) -> dict:
        """Proven digits per quantity (the certificate's; None where a quantity has none)."""
        return self.certificate.digits

    @property
    def message(self) -> str:
        """The certificate's verdict: what was proven, or why not."""
        return self.certificate.verdict

    @property
    def nit(self) -> int:
        """Iterations in all: the double solve, the double-double phase and the tail."""
        ext_nit = getattr(self.extended, "nit", 0) or 0
        return int(self.double.nit) + int(ext_nit) + (0 if self.wide is None else int(self.wide.nit))

    @property
    def proof(self) -> Proof | None:
        return self.certificate.proof

    def as_dict(self) -> dict:
        """The JSON-able summary ``rfverify solve --digits K --json`` prints (its stages, the
        certificate, timings)."""
        ext, wide = self.extended, self.wide
        return {"status": str(self.status), "success": self.success, "message": self.message, "nit": self.nit,
                "time": self.time, "digits_requested": self.certificate.requested, "digits": self.digits,
                "certificate": self.certificate.as_dict(), "double_status": str(self.double.status),
                "double_iterations": self.double.nit, "extended_iterations": ext.nit,
                "extended_status": ext.status, "backend": ext.backend,
                "wide_iterations": None if wide is None else wide.nit,
                "wide_status": None if wide is None else wide.status,
                "wide_bits": None if wide is None else wide.bits,
                "timings": dict(self.timings), "timed_out": self.timed_out, "interrupted": self.interrupted}

    def __repr__(self) -> str:
        return (f"DigitsSolution(status={self.status}, nit={self.nit}, time={self.time:.3g} s,\n"
                f"    {self.certificate.headline!r})")


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


DOUBLE_SETTINGS = {"sigma_rule": "paper"}
"""Settings of the double solve the k-digit path continues (a caller's options override
them).  Its iterate is a start, not an answer: the extended phase continues the central path
from it, so the paper's centring rule is kept here — from the default (hybrid) rule's
iterate the hyperstatic Lattice 474's double-double phase stalled at μ = 1e-18 and its
multiple-precision tail took 74 s in all, against μ = 3e-40 and 40 s (measured,
docs/DECISIONS.md).  It costs the path some time: 25 iterations against the default rule's 23 on
the 9675-contact GranularBed, whose double solve is about half of the path (docs/DECISIONS.md, "The
double-double kernels on both cores")."""

RECENT = 8
"""Iterates the driver keeps: candidates for the wide tail's start, and the last three are
proven when no proof succeeded."""

WIDE_MAX_FACTOR_OPS = 2e7
"""Largest factorisation given the tail, in multiply-subtract pairs (Σ c_j² over the column
counts of L in its minimum-degree order): measured ~0.26 µs each at 320 bits (the whole
iteration ~2× its factorisation), so about 5 s per factorisation at the limit (a 274-contact
Lattice: 1.0e6, a 769-contact SpheresPile: 1.5e7).  This is the tail's only limit: its factor
is sparse (:class:`.extended.wide_cholesky.SparseWideCholesky`, memory O(nnz(L))), so the number
of dofs does not matter, only the fill (the 9675-contact GranularBed: 1.3e10, about 56 min per
factorisation; docs/DECISIONS.md, "The 10-digit path at scale")."""


WIDE_SECONDS_PER_OP = 0.26e-6
"""Measured cost of one multiply-subtract pair of the tail's factorisation (320 bits, this
machine), for the estimate the certificate states when the tail is skipped."""

WIDE_GIVE_UP = 5
"""The tail stops after this many invalid proofs in a row (measured: a Chute whose wedge
contacts leave no strictly feasible point stays outside K* at every one of 40 iterations)."""


def preparing_beside() -> bool:
    """True when the k-digit path builds its double-double phase's set-up on a second thread
    during the double solve (:class:`Preparation`): two threads are allowed
    (``RFVERIFY_THREADS``) and CHOLMOD factors without the GIL here
    (:mod:`rfverify.engines.cholmod_nogil`), so that the double solve's factorisations leave the
    interpreter to the set-up."""
    from ..engines import cholmod_nogil

    return threads() >= 2 and cholmod_nogil.available()


class Preparation:
    """The double-double phase's set-up: the proof's per-problem pieces (:class:`ProofContext`),
    the extended data, the Newton back end and what its first update needs no iterate for
    (``prepare()``, e.g. :meth:`.extended.contactspace.ContactSpace.prepare`).

    With ``background`` they are built on a second thread — begun (:meth:`start`, the engines'
    :func:`~rfverify.engines.factor.on_factoring` hook) at the double solve's first CHOLMOD
    factorisation, which releases the GIL (before it the solve sets itself up in Python
    and GIL-holding calls, and a thread beside it measurably slowed it), or when the results are
    asked for — and without it here, when asked for, as before.  The results are the same
    either way.  An error is raised where the serial path raises it: ProofContext's by
    :meth:`context`, the extended data's and back end's by :meth:`system`; a failure of
    ``prepare()`` is left to the first update, which repeats the step and reports it where it
    always did.  :meth:`cancel` (the path ends early) stops the thread at its next step."""

    def __init__(self, problem: Problem, backend: str, engine: str, background: bool, refine=None):
        self.problem, self.backend, self.engine = problem, backend, engine
        self.refine = refine  # refine(data): more exact data for the extended phase (a problem on a face)
        self._ctx = self._ctx_error = None
        self._system = self._system_error = None
        self._ctx_ready = threading.Event()
        self._go = threading.Event()  # start: at the double solve's first GIL-free factorisation, or when asked
        self._cancelled = False
        self._thread = None
        if background:
            self._thread = threading.Thread(target=self._build, name="rfverify-prepare", daemon=True)
            self._thread.start()

    @property
    def in_background(self) -> bool:
        return self._thread is not None

    def start(self) -> None:
        """Let the thread begin now: the double solve's first GIL-free factorisation (the hook
        :func:`rfverify.engines.factor.on_factoring` calls), or the caller needs its results, or
        it is cancelled."""
        self._go.set()

    def _build(self) -> None:
        # Waiting for the double solve's first factorisation keeps this thread off the GIL while
        # the solve sets itself up (patterns, orderings: Python and GIL-holding calls).
        self._go.wait()
        if self._cancelled:
            self._ctx_ready.set()
            return
        try:
            self._ctx = ProofContext(self.problem)
        except BaseException as exc:  # noqa: BLE001 — raised again in the caller's thread, by context()
            self._ctx_error = exc
        finally:
            self._ctx_ready.set()
        if self._cancelled or self._ctx_error is not None:
            return
        try:
            self._system = self._new_system()
        except BaseException as exc:  # noqa: BLE001 — raised again in the caller's thread, by system()
            self._system_error = exc
            return
        system = self._system[1]
        if not self._cancelled and hasattr(system, "prepare"):
            try:
                system.prepare()
            except Exception:  # noqa: BLE001, S110 — the first update repeats the step and reports it
                pass

    def context(self) -> ProofContext:
        if self._thread is None:
            if self._ctx is None:
                self._ctx = ProofContext(self.problem)
            return self._ctx
        self.start()
        self._ctx_ready.wait()
        if self._ctx_error is not None:
            raise self._ctx_error
        if self._ctx is None:  # cancelled before it began
            self._ctx = ProofContext(self.problem)
        return self._ctx

    def system(self):
        """(ExtendedData, back end)."""
        if self._thread is not None:
            self.start()
            self._thread.join()
            if self._system_error is not None:
                raise self._system_error
        if self._system is None:  # serial, or the thread was cancelled before it got here
            self._system = self._new_system()
        return self._system

    def _new_system(self):
        data = ExtendedData(self.problem)
        if self.refine is not None:
            self.refine(data)
        return data, choose_backend(data, self.backend, engine=self.engine)

    def cancel(self) -> None:
        self._cancelled = True
        self.start()


def double_answer_may_certify(ctx: ProofContext, problem: Problem, v, r, requested: int) -> bool:
    """:meth:`ProofContext.may_certify` for the double solve's answer (v, r), from its duality
    gap rᵀu (u = Hᵀv + w, or W r + q for a local problem) computed in long double and lowered by
    twice a bound of that computation's rounding error, (k + N + 3)·ε·Σ|r_i|(|Hᵀ||v| + |w|)_i
    (k entries per column of H, N entries of r, ε long double's unit roundoff: float64's where
    the platform has no wider type), so that an exact answer (gap 0) is always proven.  False:
    no proof of this answer can certify ``requested`` digits (the proof's ε is at least √(rᵀu))."""
    ld = np.longdouble
    r = np.asarray(r, dtype=ld)
    with np.errstate(all="ignore"):
        if problem.local is not None:
            A, x, c = sp.csr_matrix(problem.local.W, dtype=ld), r, np.asarray(problem.local.q, dtype=ld)
            v_inf = 0.0
        else:
            A, x, c = sp.csr_matrix(problem.H.T, dtype=ld), np.asarray(v, dtype=ld), np.asarray(problem.w, dtype=ld)
            v_inf = float(np.max(np.abs(x), initial=0.0))
        u = A @ x + c
        size = abs(A) @ np.abs(x) + np.abs(c)  # ≥ |u_i|, and what u_i's rounding error is relative to
        k = int(np.max(np.diff(A.indptr), initial=0))
        gap = float(np.sum(r * u))
        slack = float(2 * (k + r.size + 3) * np.finfo(ld).eps * np.sum(np.abs(r) * size))
        u_inf = float(np.max(np.abs(u), initial=0.0))
    if not (math.isfinite(gap) and math.isfinite(slack) and math.isfinite(u_inf) and math.isfinite(v_inf)):
        return True  # let the proof say what it can
    return ctx.may_certify(ctx.eps_lower(max(gap - slack, 0.0)), v_inf, u_inf, requested)


def _proven_answer(ctx: ProofContext, point: Point, digits: int, relative: bool):
    """(proof, (v, u, r)) of a float64 answer's point, its (v, u, r) rounded as the proof
    judges them."""
    v, u, r = ctx.rounded(point)
    return ctx.prove(point, v, u, r, requested=digits, relative=relative), (v, u, r)


def proof_site(phase: str, iteration: int | None = None, *, on_face: bool = False) -> dict:
    """Where a proof's point came from: ``phase`` "double" (the double solve's answer),
    "extended" (a double-double iterate) or "multiple-precision" (an iterate of the tail),
    its ``iteration``, and ``on_face`` when it is an iterate of the problem reduced to a face,
    lifted back (DESIGN §6.5)."""
    return {"phase": phase, "iteration": iteration, "on_face": bool(on_face)}


def site_words(at: dict | None) -> str:
    """A :func:`proof_site` in words: "extended iteration 4", "the double solve's answer",
    "extended iteration 3 on the face"."""
    if at is None:
        return "no point"
    words = "the double solve's answer" if at["phase"] == "double" else f"{at['phase']} iteration {at['iteration']}"
    return words + (" on the face" if at.get("on_face") else "")


class ProofDriver:
    """The ``until`` callback of the extended phase: tries the proof where it may succeed,
    keeps the best one, and stops the run once ``requested`` digits are proven, or when μ
    has stalled for ``stall`` iterations."""

    def __init__(self, ctx: ProofContext, data: ExtendedData, requested: int, target=None, stall: int = 4,
                 progress=None, relative: bool = False, deadline: float | None = None):
        self.ctx, self.data, self.requested = ctx, data, requested
        self.relative = relative
        self.target = target  # (v, u, r) to certify; None: the rounding of each point
        self.face = None  # (FaceReduction, stresses): iterates of the reduced problem, proven lifted back
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
    def score(proof: Proof) -> float:
        """Fewest proven digits (:func:`rfverify.proof.merit`): which of two proofs says more."""
        return merit(proof)

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
        if not force and self.deadline is not None and time.perf_counter() > self.deadline:
            self.timed_out = True  # the time limit: stop here; the best proof so far stands
            self.recent = (self.recent + [it])[-RECENT:]
            return True
        if it.mu < 0.5 * self._mu_best:
            self._mu_best, self._since = it.mu, 0
        else:
            self._since += 1
        stalled = self._since >= self.stall
        data = self.data
        if not force:
            self.recent = (self.recent + [it])[-RECENT:]
        if isinstance(it, wide.WideIterate):
            gap, point, v_inf, u_inf = it.describe()
            key = ("wide", it.k)
        else:
            u_t = ext.V(*data.velocity(it.v.h, it.v.l, it.r_t.h, it.r_t.l))
            gap = abs(it.r_t.dot(u_t))
            point = point_from_iterate(data, it.v, it.r_t)
            v_inf = float(np.max(np.abs(it.v.h), initial=0.0))
            if data.local:
                u_inf = float(np.max(np.abs(data.problem.local.W @ point.r_hi + data.problem.local.q), initial=0.0))
            else:
                u_inf = float(np.max(np.abs(data.problem.H.T @ it.v.h + data.problem.w), initial=0.0))
            key = ("dd", it.k)
        eps_lower = self.ctx.eps_lower(gap)
        if not (stalled or force) and not self.ctx.may_certify(eps_lower, v_inf, u_inf, self.requested):
            return False
        if key in self.proven_keys:
            return False
        self.proven_keys.add(key)
        t0 = time.perf_counter()
        if self.face is not None:  # an iterate of the problem on a face: proven on the problem itself
            point = self.face[0].lift(point)
        sol = self.target if self.target is not None else self.answer(point)
        proof = self.ctx.prove(point, *sol, requested=self.requested, relative=self.relative)
        self.proof_seconds += time.perf_counter() - t0
        self.attempts += 1
        phase = "multiple-precision" if key[0] == "wide" else "extended"
        self.offer(proof, point, sol, proof_site(phase, it.k, on_face=self.face is not None))
        if self.progress and not quiet:
            self.progress(f"proof at {phase} iteration {it.k} (μ = {it.mu:.1e}): {proof.summary()}")
        if proof.certified:
            return True
        self._invalid_run = 0 if proof.valid else self._invalid_run + 1
        if self.invalid_limit is not None and self._invalid_run >= self.invalid_limit:
            self.gave_up = f"{self._invalid_run} proofs in a row were invalid ({proof.summary()})"
            return True
        if self.target is not None and proof.valid and self._distance_dominates(proof):
            # Certifying a given solution: once an uncertified quantity's bound is the distance
            # from the point to the solution, more iterations cannot certify it.
            self.hopeless = True
            return True
        return stalled


def solve_to_digits(problem: Problem, digits: int = 10, method: str = "auto", tol: float = 1e-10,
                    max_iter: int = 100, *, extended_max_iter: int = 80, backend: str = "auto",
                    wide_tail: bool = True, wide_bits: int = wide.DEFAULT_BITS, wide_max_iter: int = 40,
                    relative: bool = False, progress=None, factor_engine: str = "auto",
                    as_stored: bool | None = None, time_limit: float | None = None, callback=None,
                    _face_depth: int = 0, _on_face=None, **options) -> DigitsSolution:
    """Solve ``problem`` so that v, u, Hr (and r where unique) are proven right to ``digits``
    significant digits (1 … 15; DESIGN §6.3 says what "digits" means when a quantity is zero).
    ``progress(message)`` receives one line per stage; ``callback`` is the double solve's
    (:func:`rfverify.solve`: once per iteration, True stops it).

    Example
    -------
    >>> import rfverify
    >>> ten = rfverify.solve_to_digits(rfverify.load("bundled:chute"), digits=10)
    >>> ten.status, ten.digits                      # doctest: +SKIP
    (<Status.CERTIFIED: 'Certified'>, {'v': 12.2, 'u': 10.4, 'Hr': 11.9, 'r': 11.6})
    >>> ten.message                                 # doctest: +SKIP
    'proven to 10 digits (v 12.2 digits, ...) for the convex relaxation with (M + Mᵀ)/2. ...'

    ``ten.v``, ``ten.u``, ``ten.r`` are the proven answer (float64); ``ten.certificate`` holds the
    proof (recheck it with :func:`rfverify.certify`, or write it with ``rfverify solve --digits
    10 --out``).

    Stages: the double solve (``method``, ``tol``, ``max_iter``, :data:`DOUBLE_SETTINGS` unless
    ``options`` say otherwise), Algorithm 1 in double-double
    (``extended_max_iter`` iterations at most, Newton back end ``backend``, whose float64
    factorisation is ``factor_engine``: "auto" (CHOLMOD, from cvxopt, on contact-space matrices of
    at least ``CHOLMOD_MIN_ROWS`` rows, see :func:`.extended.contactspace.resolve_engine`),
    "cholmod" or "ldl"), and — only when
    that ends without a proof, on a problem whose sparse dof-space factor costs at most
    ``WIDE_MAX_FACTOR_OPS`` — Algorithm 1
    in ``wide_bits``-bit arithmetic (``wide_max_iter`` iterations at most; ``wide_tail=False``
    switches it off).  Each stage stops as soon as the proof succeeds.  ``relative=True``
    demands relative digits of every quantity (a quantity that may be zero is then not
    certified; DESIGN §6.3).

    ``time_limit`` (seconds): the whole path stops there — the double solve, the setup, each
    iteration of the extended phases — and returns the best proof reached so far (status
    MaxTime when it falls short of ``digits``).

    ``as_stored``: True proves the equations with M exactly as stored, False those with
    (M + Mᵀ)/2, None (default) what ``problem.equations`` says (symmetrised unless the problem
    came from :meth:`Problem.stored_equations`); they differ only for an unsymmetric M, and a
    proof of (M + Mᵀ)/2 then also states how many digits of the stored equations' solution the
    answer has (DESIGN §6.1).

    For a problem read from a local file (``problem.local``) the quantities are u and r of the
    file's own local problem (DESIGN §6.1b): the double solve runs on the lifting, the
    double-double phase on the file's W, and the proof on W exactly.  When a hypothesis of the
    theorem fails on the data themselves (M not proven positive definite, W not positive
    semidefinite as stored) no point can be proven: the path stops after the double solve
    and says why."""
    digits = validate_digits(digits)
    if time_limit is not None and not (isinstance(time_limit, (int, float)) and time_limit > 0):
        raise InvalidArgumentError("time_limit", f"must be a number of seconds > 0, got {time_limit!r}",
                                   fix="pass e.g. time_limit=60, or None for no limit")
    problem = posed(problem, as_stored, method)
    from ..model.scaling import binary_scaling, scaled_problem

    scaling = binary_scaling(problem)
    if scaling is not None and _on_face is None:  # data beyond float64's safe range: the whole path in scaled units
        scaled = scaled_problem(problem, scaling)
        out = solve_to_digits(scaled, digits, method, tol, max_iter,
                              extended_max_iter=extended_max_iter, backend=backend, wide_tail=wide_tail,
                              wide_bits=wide_bits, wide_max_iter=wide_max_iter, relative=relative, progress=progress,
                              factor_engine=factor_engine, time_limit=time_limit, callback=callback, **options)
        return _unscaled_solution(out, scaled, scaling)
    threads()  # a bad RFVERIFY_THREADS is refused now, not after the double solve
    if factor_engine not in ENGINES:
        raise InvalidArgumentError("factor_engine", f"{factor_engine!r} is not one of {', '.join(ENGINES)}",
                                   fix="use 'auto', 'cholmod' or 'ldl'")
    if factor_engine == "cholmod" and not cholmod_available():
        raise InvalidArgumentError("factor_engine", "'cholmod' needs cvxopt (a dependency of rfverify), which "
                                                    "does not import here",
                                   fix="pip install cvxopt, or use factor_engine='auto'")
    if method == "clarabel":
        raise InvalidArgumentError("method", "the k-digit path continues an Algorithm 1 iterate, not Clarabel's",
                                   fix="use method='auto' (default) or an Algorithm 1 form")
    say = progress or (lambda msg: None)
    # On a cold numba cache the other core compiles the kernels, and the double solve runs its
    # cone operations in numpy (bit for bit the compiled ones) instead of compiling them first.
    compiling = compile_extended_in_background()
    cold = {"compiled_kernels": False} if float64_kernels_deferred() else {}
    t0, c0 = time.perf_counter(), compile_seconds()
    prepared = Preparation(problem, backend, factor_engine,
                           background=not compiling and not extended_cache_is_cold() and preparing_beside(),
                           refine=None if _on_face is None else _on_face[1].refine)
    deadline = None if time_limit is None else t0 + time_limit
    limit = {} if time_limit is None else {"time_limit": time_limit}
    try:
        with on_factoring(prepared.start if prepared.in_background else None):
            double = solve(problem, method=method, tol=tol, max_iter=max_iter, callback=callback,
                           **{**DOUBLE_SETTINGS, **cold, **limit, **options})
    except BaseException:
        prepared.cancel()
        raise
    t_double = time.perf_counter() - t0
    c1 = compile_seconds()
    say(f"double solve ({double.method}{' by auto' if method == 'auto' else ''}): {double.status} in "
        f"{double.nit} iterations, {t_double:.2f} s")
    t1 = time.perf_counter()
    try:
        ctx = prepared.context()
    except BaseException:
        prepared.cancel()
        raise
    if _on_face is not None:  # this problem is another's on a face: prove that one (solve_on_face)
        ctx = _on_face[0]

    # The double answer itself first: an exact one (a wedge, an all-open scene) is proven here
    # at O(nnz) cost, and where the feasible set has no interior no iterate could do better.
    # Where a hypothesis fails on the data themselves (M, W) no point can be proven: stop here.
    # Where its duality gap alone rules out the digits asked for (the usual case) the proof
    # waits: it is made after the extended phase, only if no iterate was proven.
    point = candidate_point(double.v, double.r)
    out_of_time = deadline is not None and time.perf_counter() > deadline
    interrupted = bool(double.extras.get("interrupted"))
    first = None
    if _on_face is None and (out_of_time or interrupted or not ctx.hypotheses_proven
                             or double_answer_may_certify(ctx, problem, double.v, double.r, digits)):
        first = _proven_answer(ctx, point, digits, relative)
    if first is not None and (first[0].certified or not ctx.hypotheses_proven or out_of_time or interrupted):
        prepared.cancel()
        proof, (v, u, r) = first
        if proof.certified:
            say(f"the double solve's answer is proven as it is: {proof.summary()}")
            source, why = "the double solve's answer itself", "not needed"
        elif interrupted:
            source, why = "the double solve (interrupted)", "interrupted (Ctrl-C)"
        elif out_of_time:
            say(f"time limit of {time_limit:g} s reached after the double solve: {proof.summary()}")
            source, why = "the double solve (time limit reached)", f"time limit of {time_limit:g} s reached"
        else:
            say(f"no proof is possible: {proof.failure}")
            source, why = "the double solve (no proof possible)", proof.failure
        extra = {"point_source": source}
        if out_of_time and not proof.certified:
            extra["time_limit"] = time_limit
        cert = certificate_from_proof(ctx.with_companion(proof, point, v, u, r), point, extra=extra)
        return DigitsSolution(v=v, u=u, r=r, point=point, certificate=cert, double=double,
                              extended=ext.ExtendedResult(None, None, None, "NotRun", why, 0),
                              timings={"double": t_double - (c1 - c0),
                                       "setup": time.perf_counter() - t1 - (compile_seconds() - c1), "extended": 0.0,
                                       "wide": 0.0, "proof": proof.seconds, "compile": compile_seconds() - c0,
                                       "total": time.perf_counter() - t0},
                              timed_out=out_of_time and not proof.certified, interrupted=interrupted)
    data, system = prepared.system()
    t_setup = time.perf_counter() - t1
    c2 = compile_seconds()
    say(f"extended phase: double-double, {system.name}, setup {t_setup:.2f} s")
    start = _start_from(data, double)
    driver = ProofDriver(ctx, data, digits, progress=say, relative=relative, deadline=deadline)
    if _on_face is not None:
        driver.face, driver.target = _on_face[1:3], _on_face[3]
    c_ext = compile_seconds()  # (what _start_from compiled counts in "compile" only)
    if first is not None:  # the double answer's proof, to beat
        driver.offer(first[0], point, first[1], proof_site("double"))
    try:
        ext_out = extend(data, start, driver, system, max_iter=extended_max_iter, wide_tail=wide_tail,
                         wide_bits=wide_bits, wide_max_iter=wide_max_iter, say=say, verbose=progress is not None)
    except KeyboardInterrupt:  # Ctrl-C: the best proof reached so far is the answer
        interrupted = True
        ext_out = Extension(ext.ExtendedResult(None, None, None, "Stopped", "interrupted (Ctrl-C)", 0), None,
                            "not run (interrupted)", None, time.perf_counter() - t1, 0.0)
    if first is None and not driver.certified and _on_face is None:  # the double answer's proof, left until now
        t_first = time.perf_counter()
        first = _proven_answer(ctx, point, digits, relative)
        driver.proof_seconds += time.perf_counter() - t_first
        # ties: the double answer, as when it was proven first
        became_best = driver.offer(first[0], point, first[1], proof_site("double"), ties=True)
        if driver.proofs > 1:  # after the iterates' proofs: a line, as they have
            say(f"the double solve's answer proven too: {first[0].summary()}"
                + ("; it is the best proof" if became_best else ""))
    face_note = None
    if (not driver.certified and not interrupted and not driver.timed_out and _face_depth < MAX_FACE_DEPTH
            and _on_face is None):
        face_note = solve_on_face(problem, ctx, driver, digits, relative, say, deadline,
                                   dict(method=method, tol=tol, max_iter=max_iter, extended_max_iter=extended_max_iter,
                                        backend=backend, wide_tail=wide_tail, wide_bits=wide_bits,
                                        wide_max_iter=wide_max_iter, factor_engine=factor_engine, **options),
                                   _face_depth)
    _, proof, point, (v, u, r) = driver.best
    extra = {"point_source": ext_out.point_source, **ext_out.summary(), "proof_attempts": driver.attempts,
             "proven_at": driver.proven_at()}
    if face_note is not None:
        extra["face"] = face_note
        if driver.best[2] is face_note.get("_point"):
            extra["point_source"] = "the problem reduced to the face of its self-stresses (DESIGN §6.8), lifted back"
        face_note.pop("_point", None)
    timed_out = driver.timed_out and not proof.certified
    if timed_out:
        extra["time_limit"] = time_limit
    cert = certificate_from_proof(ctx.with_companion(proof, point, v, u, r), point, extra=extra)
    c3 = compile_seconds()  # in extend(): the double-double kernels (the tail and the proofs compile none)
    timings = {"double": t_double - (c1 - c0), "setup": t_setup - (c2 - c1), "extended": ext_out.seconds_dd - (c3 - c_ext),
               "wide": ext_out.seconds_wide, "proof": driver.proof_seconds, "compile": c3 - c0,
               "total": time.perf_counter() - t0}
    if face_note is not None and face_note.get("seconds"):
        timings["face"] = face_note["seconds"]  # the solve on the face (its final proof is in "proof")
    return DigitsSolution(v=v, u=u, r=r, point=point, certificate=cert, double=double, extended=ext_out.run,
                          wide=ext_out.wide, timings=timings, timed_out=timed_out, interrupted=interrupted)


MAX_FACE_DEPTH = 2
"""Facial reductions nested at most this deep (a reduced problem with a self-stress of its own)."""


def solve_on_face(problem: Problem, ctx: ProofContext, driver: ProofDriver, digits: int, relative: bool, say,
                   deadline, settings: dict, depth: int) -> dict | None:
    """Where verified self-stresses leave the feasible set no interior (DESIGN §6.8): the problem
    reduced to their face (:mod:`.proof.reduction`) is solved by this same path, each of its
    iterates lifted back and proven on ``problem`` itself (a reduced iterate's own proof would be
    about rounded data: contacts sticking beside the face sit ~1e-29 inside their cones there,
    less than that rounding) — for the driver's target (a solution being certified) or, without
    one, for the point's own rounding with r moved along the self-stresses into K
    (:func:`.proof.face.returned_reactions`); the result replaces the driver's best when it says
    more.  Returns what was done (for the certificate), or None when no
    self-stress is known."""
    from ..proof.reduction import reduce_to_face

    stresses = ctx.self_stresses()
    if not stresses:
        return None
    t0 = time.perf_counter()
    reduction = reduce_to_face(problem, stresses)
    note = {"self_stresses": [s.as_dict() for s in stresses],
            "description": "; ".join(s.describe() for s in stresses)}
    if reduction is None:
        note["reduction"] = "not possible (the face leaves those bodies no motion, or stresses share bodies)"
        say(f"self-stress found ({stresses[0].describe()}); the problem could not be reduced to its face")
        return note
    say(f"self-stress: {'; '.join(s.describe() for s in stresses)}. Solving the problem on that face "
        f"({reduction.problem.n_dofs} dofs, {reduction.problem.n_contacts} contacts), each of its points "
        "proven on the problem itself")
    limit = None if deadline is None else deadline - time.perf_counter()
    if limit is not None and limit <= 0:
        note["reduction"] = "not solved (the time limit was reached)"
        return note
    sub = solve_to_digits(reduction.problem, digits, progress=(lambda msg: say("  (on the face) " + msg)),
                          relative=relative, time_limit=limit, _face_depth=depth + 1,
                          _on_face=(ctx, reduction, stresses, driver.target), **settings)
    note.update(reduction=f"solved there, each point proven on the problem itself: {sub.status}",
                seconds=time.perf_counter() - t0, reduced_dofs=reduction.problem.n_dofs,
                reduced_contacts=reduction.problem.n_contacts, reduced_iterations=sub.nit)
    proof, point = sub.certificate.proof, sub.point
    if proof is None or point is None:
        return note
    say(f"the face's points, lifted back: {proof.summary()}")
    sub_at = sub.certificate.extra.get("proven_at") or {}
    at = proof_site(sub_at.get("phase", "double"), sub_at.get("iteration"), on_face=True)
    sol = driver.target if driver.target is not None else (sub.v, sub.u, sub.r)
    if driver.offer(proof, point, sol, at, proofs=int(sub_at.get("proofs", 1))):
        note["_point"] = point
    return note


def _unscaled_solution(out: DigitsSolution, scaled: Problem, scaling) -> DigitsSolution:
    """A k-digit solution found in the scaled units of ``scaled`` (:mod:`rfverify.model.scaling`), in
    the problem's own units.  Where the answer scales back exactly its certificate does too;
    where it rounds (subnormal entries) the rounded answer is proven again at the same point,
    in the scaled units (scaling the rounded answer up is exact); where it overflows nothing is
    certified."""
    import dataclasses

    from .certificate import unscaled_certificate

    back = {name: scaling.scale(name, getattr(out, name), inverse=True) for name in ("v", "u", "r")}
    if all(x is not None for x in back.values()):
        cert = unscaled_certificate(out.certificate, scaling)
        return dataclasses.replace(out, **back, point=cert.point, certificate=cert)
    with np.errstate(all="ignore"):
        back = {name: np.ldexp(np.asarray(getattr(out, name), dtype=np.float64), -scaling.exponent(name))
                for name in ("v", "u", "r")}
    if not all(np.all(np.isfinite(x)) for x in back.values()):
        cert = Certificate(out.certificate.requested, False, "not certified: the proven answer overflows float64 in "
                                                             f"the problem's own units ({scaling.describe()})",
                           None, None, None, dict(out.certificate.extra), out.certificate.seconds)
        return dataclasses.replace(out, **back, point=None, certificate=cert)
    ups = [scaling.scale(name, back[name]) for name in ("v", "u", "r")]
    ctx = ProofContext(scaled)
    proof = ctx.with_companion(ctx.prove(out.point, *ups, requested=out.certificate.requested), out.point, *ups)
    again = certificate_from_proof(proof, out.point, dict(out.certificate.extra))
    cert = unscaled_certificate(again, scaling)
    return dataclasses.replace(out, **back, point=cert.point, certificate=cert)


@dataclass
class Extension:
    """What :func:`extend` ran: the double-double run, the multiple-precision tail (None if it
    did not run; ``wide_note`` says why), and their wall times without the proofs."""

    run: ext.ExtendedResult
    wide: wide.WideResult | None
    wide_note: str
    handover_iteration: int | None
    seconds_dd: float
    seconds_wide: float

    @property
    def point_source(self) -> str:
        if self.wide is not None:
            return f"extended phase, then the {self.wide.bits}-bit multiple-precision tail"
        return "extended phase"

    def summary(self) -> dict:
        out = {"extended_status": self.run.status, "extended_iterations": self.run.nit, "backend": self.run.backend,
               "wide_tail": self.wide_note}
        if self.wide is not None:
            out.update(wide_status=self.wide.status, wide_iterations=self.wide.nit, wide_bits=self.wide.bits,
                       wide_handover_iteration=self.handover_iteration)
        return out


def extend(data: ExtendedData, start: dict, driver: ProofDriver, system, *, max_iter: int = 80,
           wide_tail: bool = True, wide_bits: int = wide.DEFAULT_BITS, wide_max_iter: int = 40, say=None,
           verbose: bool = False) -> Extension:
    """Algorithm 1 in double-double from ``start`` until ``driver`` accepts a proof or the run
    stalls; then, if no proof succeeded and the tail's factor is within
    ``WIDE_MAX_FACTOR_OPS``, the multiple-precision tail (:mod:`.extended.wide`) from the latest healthy double-double
    iterate.  At the end, if nothing was certified, the last iterates are proven so that the
    driver's best proof reports the best digits reached."""
    say = say or (lambda msg: None)

    def tick(phase):
        return (lambda k, mu, pinf, dinf: say(f"  {phase} iteration {k}: μ = {mu:.2e}, pinfeas = {pinf:.1e}, "
                                              f"dinfeas = {dinf:.1e}")) if verbose else None

    t0 = time.perf_counter()
    p0 = driver.proof_seconds
    run = ext.run(data, start, until=driver, max_iter=max_iter, backend=system, progress=tick("extended"))
    seconds_dd = time.perf_counter() - t0 - (driver.proof_seconds - p0)
    tail, note, hand_k, seconds_wide = None, "not needed", None, 0.0
    if not driver.certified:
        if driver.timed_out:
            note = "not run (the time limit was reached)"
        elif not wide_tail:
            note = "not run (switched off)"
        elif driver.hopeless:
            note = "not run (the candidate is farther from the point than any tail could fix)"
        elif data.local:
            note = "not run (the tail works in the dofs of a global problem; a local problem has none)"
        elif driver.face is None and (driver.ctx.self_stresses() or (driver.recent and not isinstance(driver.recent[-1], wide.WideIterate)
                                            and driver.ctx.look_for_self_stress(point_from_iterate(
                                                data, driver.recent[-1].v, driver.recent[-1].r_t).r_hi))):
            note = ("not run (a self-stress leaves the feasible set no interior: more precision cannot help, "
                    "the problem is solved on its face instead)")
        elif (ordering := wide_factor.dof_space_ordering(data))[1] > WIDE_MAX_FACTOR_OPS:
            ops = ordering[1]
            note = (f"not run (its factorisation would take {ops:.1e} multiply-subtract pairs > "
                    f"{WIDE_MAX_FACTOR_OPS:.0e}, about {ops * WIDE_SECONDS_PER_OP:.0f} s per factorisation)")
        else:
            it = wide.handover(data, driver.recent, bits=wide_bits)
            if it is None:
                note = "not run (no interior, centred double-double iterate to start from)"
            else:
                hand_k = it.k
                say(f"multiple-precision tail: {wide_bits}-bit mpfr, sparse dof-space factor, from extended "
                    f"iteration {it.k} (μ = {it.mu:.2e})")
                driver.restart(invalid_limit=WIDE_GIVE_UP)
                t1 = time.perf_counter()
                p1 = driver.proof_seconds
                tail = wide.run(data, {"v": (it.v.h, it.v.l), "r_t": (it.r_t.h, it.r_t.l), "z": (it.z.h, it.z.l)},
                                until=driver, max_iter=wide_max_iter, bits=wide_bits, perm=ordering[0],
                                progress=tick("multiple-precision"))
                seconds_wide = time.perf_counter() - t1 - (driver.proof_seconds - p1)
                note = f"{tail.status}: {tail.message}" + (f"; {driver.gave_up}" if driver.gave_up else "")
    if not driver.certified:
        # No proof succeeded: prove the last iterates (the final one may have left a cone
        # after a failed step) so that the verdict reports the best proven digits.
        again = [it for it in driver.recent[-3:] if ("dd", it.k) not in driver.proven_keys
                 and ("wide", it.k) not in driver.proven_keys]
        for it in again:
            driver(it, force=True, quiet=True)
        if again and driver.best is not None:
            # one line, not one per iterate: the progress goes forward
            say(f"the last iterates ({', '.join(str(it.k) for it in again)}) proven too, in case the final one "
                f"left a cone: the best proof is {site_words(driver.best_at)}'s: {driver.best[1].summary()}")
    return Extension(run, tail, note, hand_k, seconds_dd, seconds_wide)


def _start_from(data: ExtendedData, double: SolveResult) -> dict:
    """The double solver's last lifted iterate if it is interior, else a point pushed into the
    interior from its (v, r)."""
    z = double.extras.get("z")
    r_t = double.extras.get("r_t")
    if data.local:  # the double solve's v belongs to the lifting; the local form has no dofs
        if z is not None and r_t is not None and len(z) == data.nz and len(r_t) == data.nk:
            from ..extended import cones as C
            from ..extended.dd import from_longdouble

            zh, zl = from_longdouble(z)
            sh, sl = data.JT.matvec(*from_longdouble(r_t))
            if C.min_lambda2(data.n3, zh, zl)[0] > 0 and C.min_lambda2(data.n3, sh, sl)[0] > 0:
                return {"v": np.zeros(0, dtype=np.longdouble), "r_t": r_t, "z": z}
        return ext.interior_start(data, np.zeros(0), double.r)
    if z is not None and r_t is not None and len(z) == data.nz and len(r_t) == data.nk:
        from ..extended import cones as C
        from ..extended.dd import from_longdouble

        zh, zl = from_longdouble(z)
        sh, sl = data.JT.matvec(*from_longdouble(r_t))
        if C.min_lambda2(data.n3, zh, zl)[0] > 0 and C.min_lambda2(data.n3, sh, sl)[0] > 0:
            return {"v": np.asarray(double.v, dtype=np.longdouble), "r_t": r_t, "z": z}
    return ext.interior_start(data, double.v, double.r)
