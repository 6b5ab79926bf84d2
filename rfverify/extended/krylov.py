"""Krylov solves in double-double with a float64 preconditioner: the residual and product
kernels, iterative refinement (:func:`refine_in_double_double`) and the conjugate gradients
(:func:`conjugate_gradients_in_double_double`, :func:`restarted_conjugate_gradients`) that
:mod:`.mixed`'s float64 factors use where refinement alone stalls, deflated by the directions of
the earlier solves with the same factor (:class:`RecycledDirections`).  A matrix is its upper
triangle in CSC with values (high, low) in double-double."""

from __future__ import annotations

import math
from typing import NamedTuple

import numba
import numpy as np

from . import dd
from ..algorithm.interfaces import OutOfTime
from .stoppable import seconds_left


@numba.njit(cache=True, nogil=True)
def symmetric_residual(n, Ap, Ai, Axh, Axl, bh, bl, xh, xl, rh, rl, ax):
    """r = b − A x in double-double, A symmetric given by its upper triangle in CSC; returns
    the componentwise backward error max_i |r_i| / (|A||x| + |b|)_i (Oettli–Prager), which,
    unlike a normwise one, does not let the large rows of a badly scaled matrix hide the
    error in the small ones.  ax: zero work array (n,)."""
    for i in range(n):
        rh[i] = bh[i]
        rl[i] = bl[i]
    for j in range(n):
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            rh[i], rl[i] = dd.fms_acc(rh[i], rl[i], Axh[p], Axl[p], xh[j], xl[j])
            ax[i] += abs(Axh[p] * xh[j])
            if i != j:
                rh[j], rl[j] = dd.fms_acc(rh[j], rl[j], Axh[p], Axl[p], xh[i], xl[i])
                ax[j] += abs(Axh[p] * xh[i])
    worst = 0.0
    for i in range(n):
        den = ax[i] + abs(bh[i])
        if den > 0.0:
            e = abs(rh[i]) / den
            if not e <= worst:  # NaN propagates
                worst = e
    return worst


@numba.njit(cache=True, nogil=True)
def symmetric_product(n, Ap, Ai, Axh, Axl, ph, pl, qh, ql, xh, ax, ap):
    """q = A p in double-double (A symmetric, its upper triangle in CSC), with, in the same pass
    over A, ax = |A||x| and ap = |A||p| in float64 (x: an iterate's high part): one read of the
    matrix per conjugate-gradient step instead of two."""
    for i in range(n):
        qh[i] = 0.0
        ql[i] = 0.0
        ax[i] = 0.0
        ap[i] = 0.0
    for j in range(n):
        for k in range(Ap[j], Ap[j + 1]):
            i = Ai[k]
            a = abs(Axh[k])
            qh[i], ql[i] = dd.fma_acc(qh[i], ql[i], Axh[k], Axl[k], ph[j], pl[j])
            ax[i] += a * abs(xh[j])
            ap[i] += a * abs(ph[j])
            if i != j:
                qh[j], ql[j] = dd.fma_acc(qh[j], ql[j], Axh[k], Axl[k], ph[i], pl[i])
                ax[j] += a * abs(xh[i])
                ap[j] += a * abs(ph[i])


@numba.njit(cache=True, nogil=True)
def updated_backward(rh, bh, ax, ap, alpha):
    """max_i |r_i| / (ax_i + |α| ap_i + |b_i|): the componentwise backward error of x + αp with
    |A||x + αp| replaced by its bound |A||x| + |α||A||p| (so never above the true one by more than
    that bound's slack, which vanishes as the steps shrink)."""
    worst = 0.0
    a = abs(alpha)
    for i in range(rh.size):
        den = ax[i] + a * ap[i] + abs(bh[i])
        if den > 0.0:
            e = abs(rh[i]) / den
            if not e <= worst:  # NaN propagates
                worst = e
    return worst


def refine_in_double_double(Ap, Ai, A, bh, bl, oracle, max_steps: int, stop_at: float = 1e-31):
    """Iterative refinement of A x = b to double-double accuracy with a float64 ``oracle``
    (``oracle(r)`` ≈ A⁻¹r in float64: a factor of A rounded to double), as in SoPlex's
    iterative refinement.  ``A`` = (high, low) values of the upper triangle in CSC (``Ap``,
    ``Ai``); b = (bh, bl).  Stops at a componentwise backward error below ``stop_at``, after
    ``max_steps``, or when a step does not halve it (stalled or NaN: the best iterate is kept).
    Returns (best backward error, (xh, xl), steps taken)."""
    n = Ap.size - 1
    pbh = np.ascontiguousarray(bh, dtype=np.float64)
    pbl = np.ascontiguousarray(bl, dtype=np.float64)
    rh, rl = pbh.copy(), pbl.copy()
    best, best_x = math.inf, (np.zeros(n), np.zeros(n))
    steps = 0
    for steps in range(1, max_steps + 1):
        d = oracle(rh)
        nh, nl = np.empty(n), np.empty(n)
        dd.vadd(best_x[0], best_x[1], d, np.zeros(n), nh, nl)
        backward = symmetric_residual(n, Ap, Ai, A[0], A[1], pbh, pbl, nh, nl, rh, rl, np.zeros(n))
        if not backward < 0.5 * best:  # stalled (or NaN): keep the best solution
            best = min(best, backward) if backward == backward else best
            break
        best, best_x = backward, (nh, nl)
        if backward < stop_at:
            break
    return best, best_x, steps


RECYCLE_BYTES = 128 * 2**20
"""Memory for the search directions one factor keeps for its later solves (:class:`RecycledDirections`:
each direction and its product, n float64 each).  On the 9675-contact turned touching bed (n = 48375)
a factor's solves made up to 224 directions, 173 MB; keeping all of them took 956 conjugate-gradient
steps where none took 2193; keeping the first 100 took 1008, the last 100 1526 (docs/DECISIONS.md,
"touching piles")."""
RECYCLE_DROP = 1e-8
"""Eigenvalues of the recycled directions' Gram matrix WᵀAW (columns scaled to unit A-norm) below
this fraction of the largest are dropped from its pseudo-inverse: directions that are nearly
dependent, since each solve's Krylov space overlaps the last ones'."""


class RecycledDirections:
    """Search directions p and their products Ap (float64: the high parts) from earlier conjugate-
    gradient solves with one matrix A and one preconditioner M, kept to deflate the later ones
    (Krylov subspace recycling, as in deflated CG, Saad, Yeung, Erhel and Guyomarc'h 2000): the
    directions CG spent its steps finding — a touching pile's near self-stresses, where the
    shifted float64 factor is poor — are projected out once instead of found again.

    Speed only: the preconditioner it makes is float64 and approximate, the solve's residual and
    backward error are still double-double and recomputed from A, x and b.  Keeps the first
    ``max_bytes`` worth (the earliest directions are the ones the preconditioner misses most);
    :meth:`clear` when A or M changes."""

    def __init__(self, n: int, max_bytes: int | None = None):
        self.n = n
        budget = RECYCLE_BYTES if max_bytes is None else max_bytes
        self.capacity = int(budget // (16 * max(n, 1)))
        self.deflated = 0  # passes that ran deflated (statistics)
        self.clear()

    def clear(self) -> None:
        self._W = np.empty((self.n, 0), order="F")
        self._AW = np.empty((self.n, 0), order="F")
        self.count = 0  # directions in use
        self.staged = 0  # directions of the solve under way, kept after it (:meth:`commit`)
        self._space = None

    @property
    def room(self) -> int:
        return self.capacity - self.count - self.staged

    def stage(self, p: np.ndarray, q: np.ndarray) -> None:
        """Keep the direction p and its product q = Ap (float64, length n) if there is room; it
        deflates the solves after the current one (:meth:`commit`), whose deflation stays fixed."""
        if self.room <= 0:
            return
        if self._W.shape[1] < self.capacity:  # untouched pages of np.empty cost no memory
            self._W = np.empty((self.n, self.capacity), order="F")
            self._AW = np.empty((self.n, self.capacity), order="F")
        self._W[:, self.count + self.staged] = p
        self._AW[:, self.count + self.staged] = q
        self.staged += 1

    def commit(self) -> None:
        """The staged directions join those in use."""
        if self.staged:
            self.count += self.staged
            self.staged = 0
            self._space = None

    def add(self, directions: list) -> None:
        """Keep (p, Ap) pairs (float64 arrays of length n) while there is room."""
        for p, q in directions:
            self.stage(p, q)
        self.commit()

    def _build(self):
        if self._space is None:
            W, AW = self._W[:, :self.count], self._AW[:, :self.count]
            E = W.T @ AW
            # columns scaled to unit A-norm, so that the cut-off compares directions, not their lengths
            scale = np.sqrt(np.abs(np.diag(E)))
            scale[~(scale > 0)] = 1.0
            lam, V = np.linalg.eigh((E + E.T) / 2 / np.outer(scale, scale))
            keep = lam > RECYCLE_DROP * lam.max(initial=0.0)
            V = V[:, keep] / scale[:, None]
            self._space = (W, AW, (V / lam[keep]) @ V.T)
        return self._space

    def preconditioner(self, inner):
        """The balancing preconditioner Q r + (I − QA) M⁻¹ (I − AQ) r, Q = W (WᵀAW)⁺ Wᵀ, of the
        recycled directions W around ``inner`` (r ↦ M⁻¹r); ``inner`` itself while none are kept.
        Symmetric where M is, so the conjugate gradients keep their recurrences."""
        if not self.count:
            return inner
        W, AW, Ei = self._build()
        self.deflated += 1

        def apply(r):
            c = Ei @ (W.T @ r)
            z = inner(r - AW @ c)
            return z - W @ (Ei @ (AW.T @ z)) + W @ c

        return apply


CG_REPLACE_ABOVE = 1e9
"""A conjugate-gradient step whose update r − αAp is this many times larger than the residual it
leaves (that many digits cancelled, from a direction in the near-null space of a huge block)
replaces the updated residual by the true one (residual replacement, van der Vorst and Ye 2000).
At 1e6 the replacements cost conjugacy: the 2800-contact turned touching bed took 516 steps, not
330 (1e9, 1e12 and none: 330); with none, two seeds of the touching matrix in miniature took
44–46 steps of one pass where 1e9 takes 9."""
CG_MAX_STEPS = 100
CG_ENERGY_STALL = 1e-30
"""A step that lowers the error's A-norm² by less than this share of all the steps before it has
stalled (double-double rounding of the products is ~1e-32 of them)."""
CG_PATIENCE = 20
"""Steps without a better backward error before a pass of the conjugate gradients returns its
best.  Their componentwise backward error can stall for many steps and then fall (a spread of
outliers in the preconditioned matrix): with 5, every shift stalled near 1e-9 at the 9675-contact
bed's 10th factorisation; with 20 each reached 1e-20 in 66–175 steps, and the whole path took
381 s instead of 697 s (docs/DECISIONS.md, "touching piles")."""


class CGResult(NamedTuple):
    """What a conjugate-gradient solve returns: the componentwise backward error of ``x``
    (recomputed in double-double from A, x and b), ``x`` as (high, low), the steps taken, and
    ‖b − Ax‖∞ of ``x`` (from the same recomputed residual)."""

    backward: float
    x: tuple
    steps: int
    residual_norm: float


def conjugate_gradients_in_double_double(Ap, Ai, A, bh, bl, preconditioner, target: float,
                                         max_steps: int | None = None, patience: int | None = None,
                                         recycled: RecycledDirections | None = None,
                                         stop_norm: float | None = None, product=None) -> CGResult:
    """A x = b (A symmetric positive definite: values (high, low) of its upper triangle in CSC)
    by conjugate gradients with residuals, products and iterates in double-double and a float64
    ``preconditioner`` (``preconditioner(r)`` ≈ P⁻¹r, P a float64 factor of a shifted A).  The
    Polak–Ribière β keeps it convergent when the preconditioner is applied inexactly (a float64
    solve of a rounded residual: "flexible" CG, Notay 2000).  Each step takes the true residual
    b − Ax in double-double, updated as r − αAp from the product the step computes anyway (the
    updated and the recomputed residual differ by the rounding of x + αp, ~1e-32 of |A||x| per
    step), and its componentwise backward error against the bound |A||x| + |α||A||p| of |A||x + αp|
    from the same pass; stops at ``target``, after ``patience`` steps without a better one, or
    after ``max_steps``.  With ``stop_norm`` (a caller that refines against a larger system and
    needs only that much), the best iterate is the one of least ‖r‖∞ instead, ``patience``
    counts steps without a smaller one — but only once an iterate has beaten x = 0, until when it
    stops only where the error's A-norm no longer falls (:data:`CG_ENERGY_STALL`) — and the solve
    also stops once ‖r‖∞ ≤ ``stop_norm``.
    The best iterate's residual and backward error are then recomputed from A, x and b: what it
    returns is that (:class:`CGResult`).  With ``recycled``, the directions of earlier solves with the same A
    and preconditioner deflate this one (:class:`RecycledDirections`), and this solve's are added
    to them at its end.  ``product(ph, pl)`` (only with ``stop_norm``, which needs no |A||x|)
    returns A p in double-double some cheaper way than the stored upper triangle (the contact
    space's through its factors, :class:`.scaled_operator.ScaledProduct`); the
    residual of the returned iterate is still recomputed from the stored A."""
    if product is not None and stop_norm is None:
        raise ValueError("a product of its own needs stop_norm: the steps track ‖r‖∞, not |A||x|")
    if recycled is not None:
        preconditioner = recycled.preconditioner(preconditioner)
    max_steps = CG_MAX_STEPS if max_steps is None else max_steps
    patience = CG_PATIENCE if patience is None else patience
    n = Ap.size - 1
    bh = np.ascontiguousarray(bh, dtype=np.float64)
    bl = np.ascontiguousarray(bl, dtype=np.float64)
    zero = np.zeros(n)
    xh, xl = np.zeros(n), np.zeros(n)
    rh, rl = bh.copy(), bl.copy()
    # x = 0: r = b, whose componentwise backward error is 1 (0 where b = 0; NaN propagates), without
    # the pass over A that symmetric_residual would make (~20 ms a solve on a 9675-contact bed)
    backward = math.nan if not np.isfinite(bh).all() else (1.0 if bh.any() else 0.0)
    best, best_x, since, steps = backward, (xh.copy(), xl.copy()), 0, 0
    best_measure = backward if stop_norm is None else float(np.max(np.abs(rh)))
    z = preconditioner(rh.copy())
    ph, pl = z.copy(), np.zeros(n)
    rz = dd.vdot(rh, rl, z, zero)[0]
    qh, ql, ax, ap = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    fresh = True  # p is the preconditioned true residual: a breakdown now is final
    energy, beaten = 0.0, False  # the A-norm² decrease so far; whether an iterate beat x = 0 yet
    for steps in range(1, max_steps + 1):
        left = seconds_left()  # a solve at 10⁵ contacts can take minutes: the time limit is checked each step
        if left is not None and left < 0:
            raise OutOfTime(f"the time limit was reached during a conjugate-gradient solve (step {steps})")
        if product is None:
            symmetric_product(n, Ap, Ai, A[0], A[1], ph, pl, qh, ql, xh, ax, ap)  # q = A p
        else:
            qh, ql = product(ph, pl)
        pq = dd.vdot(ph, pl, qh, ql)[0]
        if not (pq > 0.0 and math.isfinite(rz)):
            if fresh:
                break
            # pᵀAp ≤ 0 on a positive definite A: the recurrences lost it; restart from the best
            # iterate's true residual
            xh, xl = best_x[0].copy(), best_x[1].copy()
            symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, xh, xl, rh, rl, np.zeros(n))
            z = preconditioner(rh.copy())
            ph, pl = z.copy(), np.zeros(n)
            rz, fresh = dd.vdot(rh, rl, z, zero)[0], True
            continue
        fresh = False
        if recycled is not None:
            recycled.stage(ph, qh)
        alpha = rz / pq
        step_energy = alpha * rz  # this step's decrease of the error's A-norm² (exact CG: ‖e‖²_A = Σ of those to come)
        energy += step_energy
        dd.vaxpy(alpha, 0.0, ph, pl, xh, xl)
        r_old = rh.copy()
        dd.vaxpy(-alpha, 0.0, qh, ql, rh, rl)
        if abs(alpha) * np.max(np.abs(qh)) > CG_REPLACE_ABOVE * np.max(np.abs(rh)):
            # the update cancelled too many digits to be trusted: the true residual instead
            backward = symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, xh, xl, rh, rl, np.zeros(n))
        elif product is None:
            backward = updated_backward(rh, bh, ax, ap, alpha)
        else:  # no |A||x| from this product: the backward error is known only where recomputed
            backward = math.inf if np.isfinite(rh).all() else math.nan
        # progress: the backward error, or with stop_norm the residual's size, which is what the caller needs
        measure = backward if stop_norm is None else float(np.max(np.abs(rh)))
        if measure < best_measure:
            best, best_measure, best_x, since, beaten = backward, measure, (xh.copy(), xl.copy()), 0, True
        else:
            since += 1
        # patience with ‖r‖∞ only once x = 0 is beaten: a CG residual can grow for many steps while the
        # error's A-norm falls (the 96 256-contact touching bed returned x = 0 after 20 steps of it); until
        # then it stops where the A-norm no longer falls (docs/DECISIONS.md, "Stoppable kernels")
        stalled = since >= patience and (beaten or not step_energy > CG_ENERGY_STALL * energy)
        if best <= target or stalled or not backward == backward:
            break
        if stop_norm is not None and best_measure <= stop_norm:
            break
        if rz == 0.0:  # rᵀM⁻¹r vanished (M⁻¹r ⟂ r): no direction to build from; the best iterate stands
            break
        z = preconditioner(rh.copy())
        rz_new = dd.vdot(rh, rl, z, zero)[0]
        beta = (rz_new - float(np.dot(r_old, z))) / rz
        rz = rz_new
        sh, sl = np.empty(n), np.empty(n)
        dd.vscale(beta, 0.0, ph, pl, sh, sl)
        dd.vadd(z, zero, sh, sl, ph, pl)
    rh = np.empty(n)
    best = symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, best_x[0], best_x[1], rh, np.empty(n), np.zeros(n))
    if recycled is not None:
        recycled.commit()
    return CGResult(best, best_x, steps, float(np.max(np.abs(rh), initial=0.0)))


CG_RESTARTS = 4
"""Passes of :func:`restarted_conjugate_gradients` after the first: on touching piles one pass of
the conjugate gradients stalls near a backward error of 1e-20 (its directions lose conjugacy
against the few outliers of the preconditioned matrix), and a pass restarted on the true
double-double residual goes on to 1e-30 (2800-contact turned touching bed: every solve, where
the one-pass version fell back to the double-double factor; docs/DECISIONS.md, "touching piles")."""


def restarted_conjugate_gradients(Ap, Ai, A, bh, bl, preconditioner, target: float, good_enough: float,
                                  restarts: int | None = None, recycled: RecycledDirections | None = None,
                                  stop_norm: float | None = None, product=None) -> CGResult:
    """:func:`conjugate_gradients_in_double_double` to ``target`` (or ``stop_norm``); where its
    best backward error is still above ``good_enough`` and its residual norm above
    ``stop_norm``, restarted up to ``restarts`` times (:data:`CG_RESTARTS` by default) on the
    residual b − Ax of the best iterate so far (in double-double), each pass adding its
    correction while that lowers the componentwise backward error; every pass is deflated by, and
    adds to, ``recycled``.  Returns a :class:`CGResult` (steps of all passes)."""
    restarts = CG_RESTARTS if restarts is None else restarts
    n = Ap.size - 1
    bh = np.ascontiguousarray(bh, dtype=np.float64)
    bl = np.ascontiguousarray(bl, dtype=np.float64)
    best, (xh, xl), steps, norm = conjugate_gradients_in_double_double(Ap, Ai, A, bh, bl, preconditioner, target,
                                                                       recycled=recycled, stop_norm=stop_norm,
                                                                       product=product)
    for _ in range(restarts):
        if not best > good_enough or (stop_norm is not None and norm <= stop_norm):  # reached (or NaN)
            break
        rh, rl = np.empty(n), np.empty(n)
        symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, xh, xl, rh, rl, np.zeros(n))
        # the correction's own pass runs until it stalls: its scale is the residual's, not b's
        _, (dh, dl), more, _ = conjugate_gradients_in_double_double(Ap, Ai, A, rh, rl, preconditioner, 0.0,
                                                                    recycled=recycled, stop_norm=stop_norm,
                                                                    product=product)
        steps += more
        yh, yl = np.empty(n), np.empty(n)
        dd.vadd(xh, xl, dh, dl, yh, yl)
        ry = np.empty(n)
        backward = symmetric_residual(n, Ap, Ai, A[0], A[1], bh, bl, yh, yl, ry, np.empty(n), np.zeros(n))
        norm_y = float(np.max(np.abs(ry), initial=0.0))
        if not backward < best and not (stop_norm is not None and norm_y < norm):
            break
        best, xh, xl, norm = backward, yh, yl, norm_y
    return CGResult(best, (xh, xl), steps, norm)
