"""The k-digit path's preparation: the double-double phase's set-up, built beside the double
solve on a second thread where CHOLMOD factors without the GIL (:class:`Preparation`), the gate
that says whether the double answer may be proven as it is (:func:`double_answer_may_certify`),
and the interior point the double-double phase starts from (:func:`start_from`)."""

from __future__ import annotations

import math
import threading

import numpy as np
import scipy.sparse as sp

from ..extended import ipm as ext
from ..extended.data import ExtendedData
from ..extended.stoppable import long_kernels
from ..extended.system import choose_backend
from ..extended.workers import threads
from ..model.problem import Problem
from ..proof import ProofContext
from ..solver import SolveResult


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
    always did.  :meth:`cancel` (the path ends early) stops the thread at its next step and
    waits for it."""

    def __init__(self, problem: Problem, backend: str, engine: str, background: bool, refine=None,
                 deadline: float | None = None):
        self.problem, self.backend, self.engine = problem, backend, engine
        self.deadline = deadline  # the path's time limit (perf_counter), for the long kernels of the thread
        self.refine = refine  # refine(data): more exact data for the extended phase (a problem on a face)
        self._ctx = self._ctx_error = None
        self._system = self._system_error = None
        self._ctx_ready = threading.Event()
        self._go = threading.Event()  # start: at the double solve's first GIL-free factorisation, or when asked
        self._cancelled = False
        self._stop_kernels = threading.Event()  # cancel(): a long kernel of the thread stops (.extended.stoppable)
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
        # Ctrl-C reaches only the main thread: the path's cancel() and its time limit stop a
        # long factorisation here (the first update repeats whatever was stopped)
        with long_kernels(self.deadline, cancel=self._stop_kernels):
            self._build_here()

    def _build_here(self) -> None:
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
        if not self._cancelled:
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
        """Stop the thread at its next step and wait for it: a thread left inside a C extension
        (a CHOLMOD factorisation) when the interpreter exits aborts the process ("terminate
        called without an active exception", exit 134: 1 run in 10–20 of a local file refused
        after its double solve)."""
        self._cancelled = True
        self._stop_kernels.set()
        self.start()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join()


def double_answer_may_certify(ctx: ProofContext, problem: Problem, v, r, requested: int,
                              relative: bool = False) -> bool:
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
    return ctx.may_certify(ctx.eps_lower(max(gap - slack, 0.0)), v_inf, u_inf, requested, relative=relative)


def start_from(data: ExtendedData, double: SolveResult) -> dict:
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
