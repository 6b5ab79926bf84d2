"""Float64 factorisations refined to double-double accuracy, the extended phase's default.

A float64 factor of a symmetric positive definite matrix given in double-double is the
"oracle" of an iterative refinement with double-double residuals (as in SoPlex's iterative
refinement, :func:`.krylov.refine_in_double_double`): :class:`MixedCholesky` with QDLDL's LDLᵀ,
:class:`CholmodMixed` with CHOLMOD (cvxopt's wheel, a dependency) — the
float64 engines of :mod:`rfverify.engines.factor`, the ones the double solver's forms use.
Both fall back, for good, to the double-double :class:`.ldl.DDCholesky` where the float64
factorisation fails or refinement stalls.
"""

from __future__ import annotations

import math
import time

import numpy as np
import scipy.sparse as sp

from ..algorithm.interfaces import Breakdown, OutOfTime
from ..engines.factor import CholmodEngine, QDLDLEngine
from .krylov import RecycledDirections, refine_in_double_double, restarted_conjugate_gradients
from .ldl import DDCholesky, symbolic_ldl, symmetric_pattern, upper_csc, upper_positions

SHIFTS = (1.0, 4.0, 16.0, 64.0)
"""Ulps of each diagonal entry by which a float64 factor that failed is shifted, tried in turn:
the smallest whose float64 factorisation succeeds preconditions the conjugate gradients, and
where they stall on it the next one is factored and tried, before the double-double factor.  A
shift covers the rounding of a Cholesky factorisation (a few ulps of the entries per row) and
moves only rows of the size eps⁻¹ and above by more than a relative 1e-14; the conjugate
gradients meet it on the near-null space of the huge block.  With a patience of 5 steps, which
shift served varied by matrix and not monotonically (the factorisation where the 9675-contact
turned touching bed fell back with 64 ulps: 1, 2 and 4 ulps reached 1e-30, 8 reached 7e-21,
16–4096 stalled at 1e-9 to 1e-8); with :data:`.krylov.CG_PATIENCE` = 20 every shift from 2 to 64 reached
1e-20 there, and 1 ulp is the smallest that still factors (docs/DECISIONS.md, "touching piles")."""
CG_TARGET = 1e-27
"""Componentwise backward error at which the conjugate gradients stop when the caller refines
each solve itself (an unchecked float64 solve otherwise): double-double's matrix-vector product
limits them near 1e-27 on the touching beds measured.  Where the caller sets
:attr:`_RefinedFloat64Factor.residual_target` they stop at that residual instead, or earlier
here."""
CG_GIVE_UP = 1e-8
"""A conjugate-gradient solve whose best backward error stays above this (or above 1e-20 when the
caller asked for 1e-29 and does not judge it: :attr:`_RefinedFloat64Factor.judged_by_caller`)
moves to the next shift of :data:`SHIFTS`, and after the last to the double-double factor, for
good."""
SHIFT_MIN_ROWS = 1000
"""Smallest matrix on which a failed float64 factor is replaced by the shifted one with conjugate
gradients; below it the double-double factor is cheap, and it is what held on the small
ill-conditioned local files measured (a 3-row W = diag(1, 1, 2⁻⁴⁴) file went to NaN through the
shifted path, whose later double-double fallback met a singular matrix)."""
class _RefinedFloat64Factor:
    """The part :class:`MixedCholesky` and :class:`CholmodMixed` share: a float64 factor whose
    solves are refined against the double-double matrix (:func:`refine_in_double_double`) to
    a componentwise backward error ≤ ``backward_target`` (refinement goes on to a hundredth of it,
    for headroom), and the fallback, for good, to a
    double-double factor where the float64 factorisation fails or refinement stalls
    (:attr:`precision` says which is in use, :attr:`fallback_reason` why).

    A subclass provides ``_float64_factor()`` (factors ``self._A[0]``; returns why it failed,
    or "" on success), ``_float64_solve(r)`` (≈ A⁻¹r in float64, r in the stored order),
    ``_dd_factor()`` and ``_dd_solve(bh, bl)`` (the double-double factor), and
    ``_to_stored(bh, bl)`` / ``_from_stored(xh, xl)`` (between the caller's order and that of
    the stored upper triangle ``Ap``, ``Ai``)."""

    def _init_refinement(self, backward_target: float, max_steps: int) -> None:
        self.set_backward_target(backward_target)
        self.max_steps = max_steps
        self.precision = "mixed"
        self.fallback_reason = ""
        self.last_backward_error = math.nan
        self.last_steps = 0
        self.solves = 0  # statistics: solves and refinement steps so far
        self.refinement_steps = 0
        self.factorisations = 0  # numeric factorisations asked for, and the one that fell back
        self.fallback_at = None
        self.unfinished = ""  # a factorisation refused before it started or stopped at the time limit, and why
        self.factor_seconds = {"float64": 0.0, "double-double": 0.0}
        self.factor_counts = {"float64": 0, "shifted": 0, "double-double": 0}
        self.factor_seconds["shifted"] = 0.0
        self.failed_float64 = 0
        self.shifted_from = None  # the factorisation from which the float64 factor is shifted, and why
        self.shift_reason = ""
        self.shift_at = None  # the index in SHIFTS of the shifted factor in use, and every shift used
        self.shifts_used = set()
        self.cg_from = None  # the factorisation from which solves run conjugate gradients, and why
        self.cg_reason = ""
        self.cg_iterations = 0
        self.judged_by_caller = False  # a checked CG solve short of 1e-20 is returned, the caller judges it
        self.cg_short = 0  # such solves, and the worst backward error among them
        self.cg_short_worst = 0.0
        self.residual_target = None  # a residual norm at which a CG solve is good enough (the caller's)
        # A p in double-double, cheaper than the stored upper triangle (the owner's: the contact space
        # through its factors), for solves to residual_target; ``product(ph, pl)`` in the pattern's order
        self.operator = None
        self.operator_solves = 0  # CG solves that used it
        self.cg_stopped_early = 0  # CG solves returned on it
        self.recycled_most = 0  # the most directions one factor's solves recycled
        self._recycled = None  # RecycledDirections of the current matrix and float64 factor
        self._recycling_off = False  # True where they failed this factor (until the next one)
        self.recycling_dropped = 0  # factors whose recycled directions failed a solve
        self._A = None

    def _solve_by_cg(self, bh: np.ndarray, bl: np.ndarray):
        """A solve with the float64 factor (shifted, or one whose refinement stalled) as the
        preconditioner of conjugate gradients against the double-double matrix, to
        ``backward_target`` (:data:`CG_TARGET` when unchecked).  Where it misses what the solve
        accepts (:data:`CG_GIVE_UP`; 1e-20 for a checked solve that no caller judges), the next
        shift of :data:`SHIFTS` is factored and the solve tried again, and after the last the
        double-double factor, for good.  Each solve is deflated by the directions the earlier
        solves with this factor found (:class:`.krylov.RecycledDirections`); where a deflated solve
        misses, it runs again without them, and this factor recycles nothing more.  With
        :attr:`residual_target` set, a solve whose residual ‖b − Ax‖∞ meets it is returned as it
        is (the caller refines against a larger system and needs only that)."""
        target = min(self.backward_target, CG_TARGET)
        good_enough = max(target, CG_GIVE_UP if self.backward_target == math.inf else 1e-20)
        if self._recycled is None:
            self._recycled = RecycledDirections(self.n)
        stop_norm = self.residual_target
        args = (self.Ap, self.Ai, self._A, *self._to_stored(bh, bl), self._float64_solve, target, good_enough)
        product = None if stop_norm is None or self.operator is None else self._stored_product
        self.operator_solves += product is not None
        passes = self._recycled.deflated
        best, best_x, steps, norm = restarted_conjugate_gradients(
            *args, recycled=None if self._recycling_off else self._recycled, stop_norm=stop_norm, product=product)
        self.recycled_most = max(self.recycled_most, self._recycled.count)
        met = stop_norm is not None and norm <= stop_norm
        if not best <= good_enough and not met and self._recycled.deflated > passes:
            # the recycled directions' Gram matrix is float64 and can be poor where A's entries
            # reach eps⁻²: the solve again without them, and no more of them for this factor
            self._recycling_off, self.recycling_dropped = True, self.recycling_dropped + 1
            self._recycled.clear()
            again, again_x, more, norm_again = restarted_conjugate_gradients(*args, stop_norm=stop_norm,
                                                                             product=product)
            steps += more
            if again < best or not best == best:
                best, best_x = again, again_x
            if stop_norm is not None and norm_again <= stop_norm:
                best, best_x, met = again, again_x, True
        self.last_backward_error, self.last_steps = best, steps
        self.solves += 1
        self.refinement_steps += steps
        self.cg_iterations += steps
        if met:
            self.cg_stopped_early += 1
            return self._from_stored(*best_x)
        if self.backward_target == math.inf and not best <= CG_GIVE_UP and best == best:
            # unchecked: the Newton driver refines against the unreduced system and asks for a
            # retry (checked solves) where that fails; the best iterate is its starting point
            return self._from_stored(*best_x)
        if not best <= good_enough and self.judged_by_caller and best <= CG_GIVE_UP:
            # the Newton driver refines against the unreduced system and calls escalate() where
            # that still stalls: the double-double factor only where the direction needs it
            self.cg_short += 1
            self.cg_short_worst = max(self.cg_short_worst, best)
            return self._from_stored(*best_x)
        if not best <= good_enough:
            which = "shifted " if self.shifted_from is not None else ""
            reason = f"conjugate gradients on the {which}float64 factor stalled at backward error {best:.1e}"
            following = 0 if self.shift_at is None else self.shift_at + 1
            if following < len(SHIFTS):  # another shift is cheap beside the double-double factor
                self._factor_shifted(reason, following)
            else:
                self._fall_back(reason)
            if self.precision == "mixed":
                return self._solve_by_cg(bh, bl)
            if not self.factored:  # the double-double factorisation failed too: no answer (NaN)
                return np.full(self.n, np.nan), np.full(self.n, np.nan)
            return self._dd_solve(bh, bl)
        return self._from_stored(*best_x)

    def _stored_product(self, ph: np.ndarray, pl: np.ndarray):
        """:attr:`operator` between the stored order and the pattern's own."""
        return self._to_stored(*self.operator(*self._from_stored(ph, pl)))

    def escalate(self, reason: str) -> bool:
        """The caller's refinement stalled with this factor's checked conjugate-gradient solves:
        the next shift of :data:`SHIFTS` if one is left, else the double-double factor from now on,
        for good (``reason`` says why).  True when that changed anything (False where no conjugate
        gradients ran, or already in double-double)."""
        if self.precision != "mixed" or (self.cg_from is None and self.shifted_from is None):
            return False
        if self.cg_short:
            reason += (f" ({self.cg_short} conjugate-gradient solve{'s' if self.cg_short != 1 else ''} short of "
                       f"1e-20, worst {self.cg_short_worst:.1e})")
        following = 0 if self.shift_at is None else self.shift_at + 1
        if following < len(SHIFTS):
            self._factor_shifted(reason, following)
        else:
            self._fall_back(reason)
        return True

    def set_backward_target(self, backward_target: float) -> None:
        """Solves are refined to a componentwise backward error ≤ ``backward_target`` (1e-29:
        double-double accuracy); ``math.inf``: one float64 solve each, unchecked, for a caller
        that refines against a larger system itself and checks what it gets."""
        self.backward_target = float(backward_target)
        self.stop_at = self.backward_target / 100

    def _shifted_values(self, shift: float) -> np.ndarray:
        """The high part with each diagonal entry raised by ``shift`` ulps of itself: a
        float64 rounding of A moves A's eigenvalues by about eps·max A_ii, which on the near-null
        space of a huge block swamps the O(1) ones (docs/DECISIONS.md, "touching piles"); a
        relative shift keeps rows of moderate size almost as they were."""
        if getattr(self, "_diagonal", None) is None:
            cols = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.Ap))
            self._diagonal = np.flatnonzero(self.Ai == cols)
        values = self._A[0].copy()
        d = values[self._diagonal]
        values[self._diagonal] = d + shift * np.finfo(np.float64).eps * np.maximum(d, 0.0)
        return values

    def _factor_shifted(self, reason: str, first: int = 0) -> int:
        """The matrix shifted by each of :data:`SHIFTS` from index ``first`` in turn, factored in
        float64 until one succeeds; its solves by conjugate gradients
        (:func:`.krylov.restarted_conjugate_gradients`).  The double-double factor where none does."""
        failure = ""
        for at in range(first, len(SHIFTS)):
            failure = self._timed("shifted", lambda: self._float64_factor(self._shifted_values(SHIFTS[at])))
            if not failure:
                break
        if failure:
            return self._fall_back(f"{reason}; shifted by {SHIFTS[first]:g} to {SHIFTS[-1]:g} ulps: {failure}")
        if self.shifted_from is None:
            self.shifted_from, self.shift_reason = self.factorisations, reason
        self.shift_at = at
        self.shifts_used.add(SHIFTS[at])
        self.factored = True
        return -1

    def _fall_back(self, reason: str) -> int:
        self.precision = "double-double"
        self.fallback_reason = reason
        self.fallback_at = self.factorisations
        bad = self._timed("double-double", self._dd_factor)
        self.factored = bad < 0
        return bad

    def _timed(self, precision: str, factor):
        if self._recycled is not None:  # a new factor: directions found with the old one no longer fit
            self._recycled.clear()
        self._recycling_off = False
        t0 = time.perf_counter()
        finished = False
        try:
            bad = factor()
            finished = True
            return bad
        except (Breakdown, OutOfTime) as exc:  # refused before it started, or stopped at the time limit
            self.unfinished = f"factorisation {self.factorisations}: {exc}"
            raise
        finally:
            self.factor_seconds[precision] += time.perf_counter() - t0
            self.factor_counts[precision] += finished

    def describe_cost(self) -> str:
        """Which factorisations ran and what they cost, for the time line: e.g. "4 float64
        factorisations and 1 that failed 2.1 s, 8 in double-double 120.4 s (double-double from factorisation 5:
        the float64 factorisation failed (…))" (a float64 factor whose solves stall is refactored
        in double-double, so one matrix can count in both)."""
        counts, secs = self.factor_counts, self.factor_seconds
        failed = f" and {self.failed_float64} that failed" if self.failed_float64 else ""
        out = (f"{counts['float64']} float64 factorisation{'s' if counts['float64'] != 1 else ''}{failed} "
               f"{secs['float64']:.1f} s")
        if self.cg_from is not None:
            out += (f", solved by conjugate gradients in double-double from factorisation {self.cg_from} "
                    f"({self.cg_reason})")
        if self.shifted_from is not None:
            by = ", ".join(f"{x:g}" for x in sorted(self.shifts_used))
            out += (f", {counts['shifted']} shifted in float64 {secs['shifted']:.1f} s (by {by} "
                    f"ulp{'' if self.shifts_used == {1.0} else 's'}; shifted from "
                    f"factorisation {self.shifted_from}: {self.shift_reason})")
        if self.cg_iterations:
            out += f", {self.cg_iterations} conjugate-gradient steps in double-double"
            notes = []
            if self.recycled_most:
                notes.append(f"deflated by up to {self.recycled_most} directions recycled from earlier solves with "
                             "the same factor" + (f", dropped where they failed a solve, {_times(self.recycling_dropped)}"
                                                  if self.recycling_dropped else ""))
            if self.operator_solves:
                notes.append(f"{_solves(self.operator_solves)} multiplying by the scaled matrix through its factors")
            if self.cg_stopped_early:
                notes.append(f"{_solves(self.cg_stopped_early)} stopped at the residual the Newton refinement asked for")
            out += f" ({'; '.join(notes)})" if notes else ""
        if self.cg_short and self.fallback_at is None:
            out += (f" ({self.cg_short} checked solve{'s' if self.cg_short != 1 else ''} short of 1e-20, "
                    f"worst {self.cg_short_worst:.1e}, accepted by the Newton refinement)")
        if self.fallback_at is not None:  # (none finished: refused or stopped, said below)
            done = f"{counts['double-double']} in double-double" if counts["double-double"] else "double-double"
            out += (f", {done} {secs['double-double']:.1f} s (double-double from factorisation {self.fallback_at}: "
                    f"{self.fallback_reason})")
        return out + (f"; not finished: {self.unfinished}" if self.unfinished else "")

    def factor(self, Axh: np.ndarray, Axl: np.ndarray) -> int:
        """Numeric factorisation; -1 on success, else a non-positive pivot (in double-double,
        after a fallback)."""
        self._A = (np.ascontiguousarray(Axh, dtype=np.float64).copy(),
                   np.ascontiguousarray(Axl, dtype=np.float64).copy())
        self.factorisations += 1
        if self.precision == "double-double":
            bad = self._timed("double-double", self._dd_factor)
            self.factored = bad < 0
            return bad
        if self.shifted_from is not None:  # the unshifted factor failed before: it fails again as μ falls
            return self._factor_shifted(self.shift_reason)
        failure = self._timed("float64", self._float64_factor)
        if failure:
            self.factor_counts["float64"] -= 1  # an attempt, not a factor: counted apart
            self.failed_float64 += 1
            if self.n < SHIFT_MIN_ROWS:
                return self._fall_back(failure)
            return self._factor_shifted(failure)
        self.factored = True
        return -1

    def solve(self, bh: np.ndarray, bl: np.ndarray):
        """x = A⁻¹ b to double-double accuracy (b and x in the pattern's own order); with an
        infinite ``backward_target``, one float64 solve of the high part, unchecked."""
        if self.precision == "double-double":
            if not self.factored:  # its double-double factorisation failed: no answer (the caller sees NaN)
                return np.full(self.n, np.nan), np.full(self.n, np.nan)
            return self._dd_solve(bh, bl)
        if self.shifted_from is not None or self.cg_from is not None:
            return self._solve_by_cg(bh, bl)
        if self.backward_target == math.inf:
            x = self._float64_solve(np.ascontiguousarray(self._to_stored(bh, bl)[0], dtype=np.float64))
            self.solves += 1
            self.refinement_steps += 1  # one float64 solve, as the counts of refined solves mean
            self.last_steps, self.last_backward_error = 1, math.nan
            return self._from_stored(x, np.zeros_like(x))
        best, best_x, steps = refine_in_double_double(self.Ap, self.Ai, self._A, *self._to_stored(bh, bl),
                                                      self._float64_solve, self.max_steps, self.stop_at)
        self.last_backward_error, self.last_steps = best, steps
        self.solves += 1
        self.refinement_steps += steps
        if not best <= self.backward_target:
            reason = f"refinement stalled at backward error {best:.1e}"
            if self.n >= SHIFT_MIN_ROWS:
                # the factor holds but is inexact on a few directions (a touching pile's near
                # self-stresses): conjugate gradients remove what refinement cannot, for this
                # and every later factorisation (μ falls: it only gets worse)
                self.cg_from, self.cg_reason = self.factorisations, reason
                return self._solve_by_cg(bh, bl)
            if self._fall_back(reason) >= 0:
                return np.full(self.n, np.nan), np.full(self.n, np.nan)
            return self._dd_solve(bh, bl)
        return self._from_stored(*best_x)


class MixedCholesky(_RefinedFloat64Factor, DDCholesky):
    """:class:`DDCholesky` whose factorisation is done in float64 and whose solves are refined
    to double-double accuracy (a double "oracle" with double-double residuals, as in SoPlex's
    iterative refinement).  The float64 factor is QDLDL's (:class:`.QDLDLEngine`: its own AMD
    order on top of the stored one, symbolic analysis kept), of the upper triangle in the
    stored order.  Its pivots are not inspected: reading them copies L (``factors()``, +580 MB
    of peak memory on a 9675-contact bed), and refinement judges the factor anyway — an
    indefinite LDLᵀ of S is still an exact factorisation, and a failed one (qdldl's update
    does not report a zero pivot) makes refinement stall, which falls back as below.

    Refinement converges when the double factor is accurate in the matrix's own scaling, which
    holds for the scaled contact-space matrix I + F⁻¹W̃F⁻ᵀ while W̃ is well conditioned on the
    contacts that carry load, however small μ is.  Where it does not (the backward error of a
    solve stays above ``backward_target``, or the double factorisation meets a non-positive
    pivot) the matrix is refactored in double-double and every later factorisation stays in
    double-double: :attr:`precision` says which is in use, :attr:`fallback_reason` why.
    """

    def __init__(self, pattern: sp.spmatrix, perm: np.ndarray | None = None,
                 backward_target: float = 1e-29, max_steps: int = 12):
        super().__init__(pattern, perm)
        self._engine = QDLDLEngine()
        self._init_refinement(backward_target, max_steps)

    def _float64_factor(self, values: np.ndarray | None = None) -> str:
        values = self._A[0] if values is None else values
        try:
            self._engine.factor(sp.csc_matrix((values, self.Ai, self.Ap), shape=(self.n, self.n)))
        except (RuntimeError, ValueError) as exc:
            return f"a zero pivot in the float64 factorisation (QDLDL: {' '.join(str(exc).split())})"
        return ""

    def _float64_solve(self, rh: np.ndarray) -> np.ndarray:
        return self._engine.solve(rh)  # rh in float64: its rounding error is refined away

    def _dd_factor(self) -> int:
        return DDCholesky.factor(self, *self._A)

    def _dd_solve(self, bh: np.ndarray, bl: np.ndarray):
        return DDCholesky.solve(self, bh, bl)

    def _to_stored(self, bh: np.ndarray, bl: np.ndarray):
        return bh[self.perm], bl[self.perm]

    def _from_stored(self, xh: np.ndarray, xl: np.ndarray):
        oh, ol = np.empty(self.n), np.empty(self.n)
        oh[self.perm], ol[self.perm] = xh, xl
        return oh, ol


class CholmodMixed(_RefinedFloat64Factor):
    """The interface of :class:`MixedCholesky` (values aligned with :meth:`positions`,
    ``factor``, ``solve`` to double-double accuracy) with the float64 factorisation done by
    CHOLMOD's supernodal Cholesky (cvxopt; AMD or nested dissection, symbolic analysis once) and
    every solve refined against the double-double matrix to a componentwise backward error
    ≤ ``backward_target`` — the same refinement as :class:`MixedCholesky`, only the float64
    oracle differs.  CHOLMOD works on dense supernodes with BLAS-3 where the up-looking LDLᵀ
    works entry by entry (measured 10–30× faster at 10³–10⁴ contacts, docs/DECISIONS.md,
    "The 10-digit path at scale").

    The values are stored as the upper triangle of the pattern in its own (natural) order, in
    CSC (:attr:`Ap`, :attr:`Ai`); no fill-reducing order or symbolic LDLᵀ of our own is
    computed unless refinement stalls or CHOLMOD meets a non-positive pivot: then the matrix is
    refactored by :class:`DDCholesky` (double-double) and stays so, as in
    :class:`MixedCholesky` (:attr:`precision`, :attr:`fallback_reason`).
    """

    def __init__(self, pattern: sp.spmatrix, backward_target: float = 1e-29, max_steps: int = 12):
        self._engine = CholmodEngine("the cholmod engine")  # first: fails early when CHOLMOD is absent
        n = pattern.shape[0]
        self.n = n
        self.pattern = symmetric_pattern(pattern)
        self.Ap, self.Ai, self._keys = upper_csc(self.pattern)
        # CHOLMOD reads the lower triangle in CSC: the transpose of U, as a gather map into the values
        T = sp.csc_matrix((np.arange(1, self.Ai.size + 1, dtype=np.float64), self.Ai, self.Ap), shape=(n, n)).T.tocsc()
        T.sort_indices()
        self._lower_map = T.data.astype(np.int64) - 1
        self._lower_indices, self._lower_indptr = T.indices, T.indptr
        self._init_refinement(backward_target, max_steps)
        self.factored = False
        self._dd = None

    @property
    def nnz_upper(self) -> int:
        return int(self.Ai.size)

    def prepare(self) -> None:
        """CHOLMOD's symbolic analysis of the pattern (it needs no values), done before the
        first :meth:`factor` — on another thread while the double solve runs
        (:mod:`rfverify.verify.digits`)."""
        ones = np.ones(self._lower_indices.size)
        self._engine.analyse(sp.csc_matrix((ones, self._lower_indices, self._lower_indptr), shape=(self.n, self.n)))

    @property
    def Lp(self) -> np.ndarray:
        """Column pointers of L in CHOLMOD's order (computed on demand: statistics only), or
        of the double-double factor after a fallback."""
        if self._dd is not None:
            return self._dd.Lp
        counts = self._engine.column_counts() if self._engine.permutation() is not None else None
        if counts is not None:  # CHOLMOD's own symbolic counts: no analysis of ours
            return np.concatenate(([0], np.cumsum(counts)))
        perm = self._engine.permutation()
        perm = np.arange(self.n) if perm is None else perm
        Ap, Ai, _ = upper_csc(self.pattern[perm][:, perm])
        return symbolic_ldl(self.n, Ap, Ai)[1]

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    def positions(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Index into the upper-CSC value array of the entries (rows[k], cols[k]) (either
        triangle: the symmetric partner is found)."""
        return upper_positions(self._keys, self.n, np.asarray(rows, dtype=np.int64),
                                np.asarray(cols, dtype=np.int64))

    def _dd_factor(self) -> int:
        if self._dd is None:
            # CHOLMOD's fill-reducing order, where it has one: no ordering of our own to compute
            # (SuperLU's minimum degree factors the pattern to find it, minutes at 10⁵ contacts)
            # and the fill CHOLMOD's factor had
            self._dd = DDCholesky(self.pattern, perm=self._engine.permutation())
            cols = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.Ap))
            self._dd_pos = self._dd.positions(self.Ai, cols)
        self._engine.release()  # in double-double for good: the float64 factor's memory is not needed
        h, lo = np.zeros(self._dd.nnz_upper), np.zeros(self._dd.nnz_upper)
        h[self._dd_pos], lo[self._dd_pos] = self._A
        bad = self._dd.factor(h, lo)
        self.factored = bad < 0
        return bad

    def _dd_solve(self, bh: np.ndarray, bl: np.ndarray):
        return self._dd.solve(bh, bl)

    def _float64_factor(self, values: np.ndarray | None = None) -> str:
        values = self._A[0] if values is None else values
        try:
            self._engine.factor(sp.csc_matrix((values[self._lower_map], self._lower_indices,
                                               self._lower_indptr), shape=(self.n, self.n)))
        except ArithmeticError as exc:  # about the float64 rounding of this matrix, not about the problem's M
            why = str(exc).replace("not positive definite", "a non-positive pivot in its float64 rounding")
            return f"the float64 factorisation failed ({why})"
        return ""

    def _float64_solve(self, rh: np.ndarray) -> np.ndarray:  # CHOLMOD's float64 solve on the residual
        return self._engine.solve(rh)

    def _to_stored(self, bh: np.ndarray, bl: np.ndarray):
        return bh, bl

    def _from_stored(self, xh: np.ndarray, xl: np.ndarray):
        return xh.copy(), xl.copy()


def _solves(k: int) -> str:
    return f"{k} solve{'s' if k != 1 else ''}"


def _times(k: int) -> str:
    return f"{k} time{'s' if k != 1 else ''}"
