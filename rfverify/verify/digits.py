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

import time
from dataclasses import dataclass, field

import numpy as np

from ..algorithm.interfaces import OutOfTime
from ..compilation import (
    compile_extended_in_background,
    compile_seconds,
    extended_cache_is_cold,
    float64_kernels_deferred,
)
from ..engines.factor import cholmod_available, on_factoring
from ..errors import InvalidArgumentError, require_time_limit
from ..extended import ipm as ext
from ..extended import wide
from ..extended.contactspace import ENGINES
from ..extended.stoppable import long_kernels
from ..extended.workers import threads
from ..model.scaling import in_contact_units, in_scaled_units
from ..model.problem import Problem
from ..proof import Point, Proof, ProofContext, validate_digits
from ..solver import SolveResult, posed, solve
from .certificate import (Certificate, CertifiedResult, candidate_point, certificate_from_proof, cut_short,
                          unscaled_point)
from .driver import ProofDriver, proof_site, proven_answer
from .second_start import SECOND_START, second_start  # noqa: F401 (SECOND_START: its setting, named here too)
from .extend import Extension, extend
from .prepare import (
    Preparation,
    double_answer_may_certify,
    preparing_beside,
    start_from,
)


@dataclass
class DigitsSolution(CertifiedResult):
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
    def digits(self) -> dict:
        """Proven digits per quantity (the certificate's; None where a quantity has none)."""
        return self.certificate.digits

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
                "extended_status": ext.status, "backend": ext.backend, "factorisation": getattr(ext, "factorisation", ""),
                "wide_iterations": None if wide is None else wide.nit,
                "wide_status": None if wide is None else wide.status,
                "wide_bits": None if wide is None else wide.bits,
                "timings": dict(self.timings), "timed_out": self.timed_out, "interrupted": self.interrupted}

    def __repr__(self) -> str:
        return (f"DigitsSolution(status={self.status}, nit={self.nit}, time={self.time:.3g} s,\n"
                f"    {self.certificate.headline!r})")


DOUBLE_SETTINGS = {"sigma_rule": "paper"}
"""Settings of the double solve the k-digit path continues (a caller's options override
them).  Its iterate is a start, not an answer: the extended phase continues the central path
from it, so the paper's centring rule is kept here — from the default (hybrid) rule's
iterate the hyperstatic Lattice 474's double-double phase stalled at μ = 1e-18 and its
multiple-precision tail took 74 s in all, against μ = 3e-40 and 40 s (measured,
docs/DECISIONS.md).  It costs the path some time: 25 iterations against the default rule's 23 on
the 9675-contact GranularBed, whose double solve is about half of the path (docs/DECISIONS.md, "The
double-double kernels on both cores")."""

@second_start
def solve_to_digits(problem: Problem, digits: int = 10, method: str = "auto", tol: float = 1e-10,
                    max_iter: int = 100, *, extended_max_iter: int = 80, backend: str = "auto",
                    wide_tail: bool = True, wide_bits: int = wide.DEFAULT_BITS, wide_max_iter: int = 40,
                    relative: bool = False, progress=None, factor_engine: str = "auto",
                    as_stored: bool | None = None, time_limit: float | None = None, callback=None,
                    _face_depth: int = 0, _on_face=None, _named_limit: float | None = None, _own=None,
                    **options) -> DigitsSolution:
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
    MaxTime when it falls short of ``digits``).  (``_named_limit``: a caller's whole limit, of
    which ``time_limit`` is what is left; the verdict and the progress lines name it.)

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
    require_time_limit(time_limit)
    named_limit = time_limit if _named_limit is None else _named_limit
    problem = posed(problem, as_stored, method)
    if _on_face is None:  # data beyond float64's safe range: the whole path in scaled units
        again = lambda scaled, _, _own=None: solve_to_digits(  # noqa: E731
            scaled, digits, method, tol, max_iter, extended_max_iter=extended_max_iter, backend=backend,
            wide_tail=wide_tail, wide_bits=wide_bits, wide_max_iter=wide_max_iter, relative=relative,
            progress=progress, factor_engine=factor_engine, time_limit=time_limit, callback=callback,
            _named_limit=_named_limit, _own=_own, **options)
        out = _in_other_units(problem, again, relative)
        if out is not None:
            return out
    _check_path_arguments(method, factor_engine)
    say = progress or (lambda msg: None)
    # On a cold numba cache the other core compiles the kernels, and the double solve runs its
    # cone operations in numpy (bit for bit the compiled ones) instead of compiling them first.
    compiling = compile_extended_in_background()
    cold = {"compiled_kernels": False} if float64_kernels_deferred() else {}
    t0, c0 = time.perf_counter(), compile_seconds()
    prepared = Preparation(problem, backend, factor_engine,
                           background=not compiling and not extended_cache_is_cold() and preparing_beside(),
                           refine=None if _on_face is None else _on_face[1].refine,
                           deadline=None if time_limit is None else t0 + time_limit)
    deadline = prepared.deadline
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
    zero_data = bool(double.extras.get("zero_data"))  # f = w = 0: the exact answer, nothing to iterate
    say("double solve: none needed (f = 0 and w = 0: v = u = r = 0 exactly)" if zero_data else
        f"double solve ({double.method}{' by auto' if method == 'auto' else ''}): {double.status} in "
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
    out_of_time = deadline is not None and time.perf_counter() > deadline
    interrupted = bool(double.extras.get("interrupted"))
    first, point, at_rest = _double_answer_first(problem, ctx, double, digits, relative, _on_face is None and (
        out_of_time or interrupted or not ctx.hypotheses_proven or zero_data), on_face=_on_face)
    # An exact zero answer is the answer: no iterate can prove relative digits of it either.
    if first is not None and (first[0].certified or not ctx.hypotheses_proven or out_of_time or interrupted
                              or zero_data):
        prepared.cancel()
        return _ended_after_double(first, ctx, point, double, say, at_rest=at_rest, interrupted=interrupted,
                                   out_of_time=out_of_time,
                                   time_limit=named_limit, clock=(t0, c0, t1, c1, t_double))
    data, system = prepared.system()
    t_setup = time.perf_counter() - t1
    c2 = compile_seconds()
    say(f"extended phase: double-double, {system.name}, setup {t_setup:.2f} s")
    start = start_from(data, double)
    driver = ProofDriver(ctx, data, digits, progress=say, relative=relative, deadline=deadline, own=_own)
    if _on_face is not None:
        driver.face, driver.target = _on_face[1:3], _on_face[3]
    c_ext = compile_seconds()  # (what start_from compiled counts in "compile" only)
    if first is not None:  # the double answer's proof, to beat
        driver.offer(first[0], point, first[1], proof_site("double"))
    ext_out, interrupted = _extend_stoppably(data, start, driver, system, deadline, progress, t1, dict(
        max_iter=extended_max_iter, wide_tail=wide_tail, wide_bits=wide_bits, wide_max_iter=wide_max_iter))
    if first is None and not driver.certified and _on_face is None:  # the double answer's proof, left until now
        _prove_double_answer_last(driver, ctx, point, digits, relative, say)
    face_note = None
    if (not driver.certified and not interrupted and not driver.timed_out and _face_depth < MAX_FACE_DEPTH
            and _on_face is None):
        face_note = solve_on_face(problem, ctx, driver, digits, relative, say, deadline,
                                   dict(method=method, tol=tol, max_iter=max_iter, extended_max_iter=extended_max_iter,
                                        backend=backend, wide_tail=wide_tail, wide_bits=wide_bits,
                                        wide_max_iter=wide_max_iter, factor_engine=factor_engine,
                                        _named_limit=named_limit, **options),
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
        extra["time_limit"] = named_limit
    extra.update(_stall_words(driver, ext_out) if not proof.certified else {})
    cert = certificate_from_proof(ctx.with_companion(proof, point, v, u, r), point, extra=extra)
    c3 = compile_seconds()  # in extend(): the double-double kernels (the tail and the proofs compile none)
    timings = {"double": t_double - (c1 - c0), "setup": t_setup - (c2 - c1), "extended": ext_out.seconds_dd - (c3 - c_ext),
               "wide": ext_out.seconds_wide, "proof": driver.proof_seconds, "compile": c3 - c0,
               "total": time.perf_counter() - t0}
    if face_note is not None and face_note.get("seconds"):
        timings["face"] = face_note["seconds"]  # the solve on the face (its final proof is in "proof")
    return DigitsSolution(v=v, u=u, r=r, point=point, certificate=cert, double=double, extended=ext_out.run,
                          wide=ext_out.wide, timings=timings, timed_out=timed_out, interrupted=interrupted)


def _extend_stoppably(data, start, driver: ProofDriver, system, deadline, progress, t1: float,
                      limits: dict) -> tuple[Extension, bool]:
    """(:func:`.extend.extend`'s outcome, interrupted): a Ctrl-C, or the time limit reached
    outside Algorithm 1's loop (which returns its best iterate itself), ends it with the best
    proof so far; long factorisations inside are stopped by either (:mod:`.extended.stoppable`)."""
    try:
        with long_kernels(deadline, progress):
            return extend(data, start, driver, system, say=progress, verbose=progress is not None, **limits), False
    except KeyboardInterrupt:
        return Extension(ext.ExtendedResult(None, None, None, "Stopped", "interrupted (Ctrl-C)", 0), None,
                         "not run (interrupted)", None, time.perf_counter() - t1, 0.0), True
    except OutOfTime as exc:
        driver.timed_out = True
        return Extension(ext.ExtendedResult(None, None, None, "MaxTime", str(exc), 0), None,
                         "not run (the time limit was reached)", None, time.perf_counter() - t1, 0.0), False


def _check_path_arguments(method: str, factor_engine: str) -> None:
    """Refuse, before the double solve, what the path could only refuse after it."""
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


def _double_answer_first(problem, ctx, double, digits: int, relative: bool, must: bool, on_face):
    """(first, point, at_rest): the proof of the double answer's point where it is made now (``must``,
    or it may certify), or of v = 0, r = 0 where that is the answer (:func:`at_rest_answer`).
    ``on_face``: the solve-on-face tuple of a problem on a face (:func:`solve_on_face`), or None."""
    point = candidate_point(double.v, double.r)
    if on_face is not None:  # a problem on a face: only its exact answer of no data is proven here, lifted back
        if double.extras.get("zero_data"):
            return (*_face_zero_answer(ctx, on_face, point, digits, relative), False)
        return None, point, False
    if not double.extras.get("zero_data"):
        rest = at_rest_answer(problem, ctx, double, digits, relative)
        if rest is not None:
            return rest[:2], rest[2], True
    if must or double_answer_may_certify(ctx, problem, double.v, double.r, digits, relative):
        return proven_answer(ctx, point, digits, relative), point, False
    return None, point, False


def _face_zero_answer(ctx, on_face, point, digits: int, relative: bool):
    """((proof, (v, u, r)), lifted point) where the problem on a face has f = w = 0: its answer,
    no motion along the face and no reaction, is exact (an iterate from it would divide by μ = 0),
    and is proven lifted back on the problem itself, as the face's iterates are."""
    from ..proof.face import returned_reactions

    _, reduction, stresses, target = on_face
    lifted = reduction.lift(point)
    v, u, r = ctx.rounded(lifted)
    sol = target if target is not None else (v, u, returned_reactions(ctx.problem, stresses, r))
    return (ctx.prove(lifted, *sol, requested=digits, relative=relative), sol), lifted


def at_rest_answer(problem: Problem, ctx, double, digits: int, relative: bool):
    """(proof, (v, u, r), point) of v = 0, r = 0 where f = 0 and that proves ``digits``, else None.

    With no force every body may stay at rest: where w ∈ K* at every contact the answer is
    v = u − w = 0, r = 0 exactly, and its proof (bound 0) costs O(nnz), where an interior-point
    iterate only approaches it (1.2e-7 of error after 80 double-double iterations on an audit's
    one open contact)."""
    if np.any(problem.f) or not np.any(double.v):
        return None
    at_rest = candidate_point(np.zeros_like(double.v), np.zeros_like(double.r))
    proof, answer = proven_answer(ctx, at_rest, digits, relative)
    return (proof, answer, at_rest) if proof.certified else None


def _ended_after_double(first, ctx, point, double, say, *, interrupted: bool, out_of_time: bool, time_limit,
                        clock: tuple, at_rest: bool = False) -> DigitsSolution:
    """The path's answer when it ends with the double solve's: proven as it is, interrupted, out
    of time, or no proof possible on these data.  ``clock``: (t0, c0, t1, c1, t_double), the
    path's start, the double solve's end and its seconds (perf_counter, compile_seconds)."""
    t0, c0, t1, c1, t_double = clock
    proof, (v, u, r) = first
    if proof.certified and at_rest:
        say(f"f = 0 and w ∈ K*: v = 0, r = 0 (every body at rest) is proven: {proof.summary()}")
        source, why = "v = 0, r = 0 (f = 0: every body at rest)", "not needed"
    elif proof.certified:
        say(f"the double solve's answer is proven as it is: {proof.summary()}")
        source, why = "the double solve's answer itself", "not needed"
    elif interrupted:
        source, why = "the double solve (interrupted)", "interrupted (Ctrl-C)"
    elif out_of_time:
        say(f"time limit of {time_limit:g} s reached after the double solve: {proof.summary()}")
        source, why = "the double solve (time limit reached)", f"time limit of {time_limit:g} s reached"
    else:  # the data rule a proof out, or (f = w = 0) the exact zero answer has no relative digits
        why = proof.failure or proof.summary()
        say(f"no proof is possible: {why}")
        source = "the double solve (no proof possible)"
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


def _prove_double_answer_last(driver: ProofDriver, ctx, point, digits: int, relative: bool, say) -> None:
    """The double answer's proof, made after the extended phases where no point was proven to
    the digits asked (certified); on a tie it is the best (as when it is proven first)."""
    t_first = time.perf_counter()
    first = proven_answer(ctx, point, digits, relative)
    driver.proof_seconds += time.perf_counter() - t_first
    became_best = driver.offer(first[0], point, first[1], proof_site("double"), ties=True)
    if driver.proofs > 1:  # after the iterates' proofs: a line, as they have
        say(f"the double solve's answer proven too: {first[0].summary()}"
            + ("; it is the best proof" if became_best and first[0].valid else ""))


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
        note["reduction"] = ("not possible (the face leaves those bodies no motion, stresses share bodies, or every "
                             "contact is stuck on it: no contact problem is left to pose)")
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
                reduced_contacts=reduction.problem.n_contacts, reduced_iterations=sub.nit,
                extended_steps_held=sub.certificate.extra.get("extended_steps_held", []))
    proof, point = sub.certificate.proof, sub.point
    if proof is None or point is None:
        return note
    say(f"the face's points, lifted back: {proof.summary()}")
    sub_at = sub.certificate.extra.get("proven_at") or {}
    at = proof_site(sub_at.get("phase", "double"), sub_at.get("iteration"), on_face=True,
                    predicted=bool(sub_at.get("predicted")))
    sol = driver.target if driver.target is not None else (sub.v, sub.u, sub.r)
    if driver.offer(proof, point, sol, at, proofs=int(sub_at.get("proofs", 1))):
        note["_point"] = point
    return note


def _stall_words(driver: ProofDriver, ext_out: Extension) -> dict:
    """``{"search_stopped": why}`` where the search for a proof point ended because μ stopped
    falling (the iteration, and the cone that held the last step), else {}."""
    if driver.stalled_at is None or driver.timed_out:
        return {}
    k, mu = driver.stalled_at
    held = (ext_out.wide_steps_held or ext_out.steps_held)
    last = f"; its last step was {held[-1]['alpha']:.1e} long, held by contact {held[-1]['contact']}'s " \
           f"{held[-1]['part']} cone ({held[-1]['side']})" if held else ""
    tail = f"; the multiple-precision tail: {ext_out.wide_note}" if ext_out.wide is None else ""
    return {"search_stopped": f"the search stopped at iteration {k}: μ = {mu:.1e} had not halved in "
                              f"{driver.stall} iterations{last}{tail}"}


def _in_other_units(problem: Problem, again, relative: bool) -> DigitsSolution | None:
    """The whole path ``again(scaled, scaling, _own=…)`` on the problem with its contacts' units
    brought together (each point proven in the problem's own units), or with its data brought
    into float64's safe range (proven in the scaled units, the bounds scaled back); None where
    neither applies (:mod:`rfverify.model.scaling`)."""
    out = in_contact_units(problem, lambda scaled, units: again(scaled, None, _own=(ProofContext(problem), units)),
                           lambda res, own, _, units: _in_own_contact_units(res, own, units, relative))
    return out if out is not None else in_scaled_units(problem, again, _unscaled_solution)


def _in_own_contact_units(out: DigitsSolution, problem: Problem, units, relative: bool) -> DigitsSolution:
    """A k-digit solution found with per-contact units brought together
    (:func:`rfverify.model.scaling.contact_units`), in the problem's own units, its point proven
    again there: the theorem's gap and residual are the same numbers in either units (the change
    is exact), but relative digits of u and r are taken against the problem's own ‖u*‖∞, ‖r*‖∞
    (the run's driver judged its iterates so too: :attr:`.driver.ProofDriver.own`)."""
    import dataclasses

    back = {"v": out.v, "u": units.back("u", out.u), "r": units.back("r", out.r)}
    old = out.certificate
    extra = {**old.extra, "contact_units": units.describe(proof=True)}
    point = unscaled_point(out.point, units)
    if point is None or old.proof is None or not old.proof.valid:  # nothing to prove again
        verdict = (f"not certified: the proof point, found in contact units, does not carry back to the "
                   f"problem's units exactly ({old.verdict})") if old.certified else old.verdict
        cert = Certificate(old.requested, False, verdict, None, None, old.cross_check, extra, old.seconds)
        return dataclasses.replace(out, **back, point=point, certificate=cert)
    ctx = ProofContext(problem)
    proof = ctx.prove(point, *back.values(), requested=old.requested, relative=relative)
    cert = certificate_from_proof(ctx.with_companion(proof, point, *back.values()), point, extra, old.seconds)
    if out.timed_out and not cert.certified and "time_limit" in old.extra:
        cert = cut_short(cert, old.extra["time_limit"])
    return dataclasses.replace(out, **back, point=point, certificate=cert)


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
    back = {name: scaling.back(name, getattr(out, name)) for name in ("v", "u", "r")}
    if not all(np.all(np.isfinite(x)) for x in back.values()):
        # an unproven answer (a run that failed in the scaled units) is not called a proven one
        verdict = (f"not certified: the proven answer overflows float64 in the problem's own units "
                   f"({scaling.describe()})" if out.certificate.certified else
                   f"{out.certificate.verdict} — in units scaled by exact powers of two ({scaling.describe()}); "
                   "that run's answer, not proven, also overflows float64 when scaled back")
        cert = Certificate(out.certificate.requested, False, verdict,
                           None, None, None, dict(out.certificate.extra), out.certificate.seconds)
        return dataclasses.replace(out, **back, point=None, certificate=cert)
    ups = [scaling.scale(name, back[name]) for name in ("v", "u", "r")]
    ctx = ProofContext(scaled)
    proof = ctx.with_companion(ctx.prove(out.point, *ups, requested=out.certificate.requested), out.point, *ups)
    again = certificate_from_proof(proof, out.point, dict(out.certificate.extra))
    cert = unscaled_certificate(again, scaling)
    return dataclasses.replace(out, **back, point=cert.point, certificate=cert)


