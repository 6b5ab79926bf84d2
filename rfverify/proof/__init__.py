"""Rigorous a-posteriori error bounds (DESIGN §6): the proof behind a certificate.

:func:`prove` evaluates the bound of :mod:`.bound` for an extended-precision point and
carries it to a returned float64 solution.  :class:`ProofContext` holds what depends only on
the problem (exact data, verified bounds on M and on the columns of H, data scales), so that
several points of one problem are proven at O(nnz) cost each.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..model.problem import Problem
from .bound import ExactData, Proof, data_scales, prove as _prove
from .quantity import FLOAT64_DIGITS, MAX_CERTIFIABLE_DIGITS, QuantityBound, validate_digits
from .dyadic import Dyadic
from .massbounds import MassBounds, verify_mass_matrix

__all__ = ["Proof", "ProofContext", "QuantityBound", "Point", "validate_digits", "merit", "FLOAT64_DIGITS",
           "MAX_CERTIFIABLE_DIGITS"]


@dataclass(frozen=True)
class Point:
    """An extended-precision point (v, r) in the original variables, as float64 expansions:
    v = v_hi + v_lo + Σ v_more[i] exactly, v (m,), r (5n,).  A double-double point has no
    ``*_more`` terms; a point of the multiple-precision tail (:mod:`rfverify.extended.wide`)
    has ``v_more`` and ``r_more`` of shape (k, m) and (k, 5n)."""

    v_hi: np.ndarray
    v_lo: np.ndarray
    r_hi: np.ndarray
    r_lo: np.ndarray
    v_more: np.ndarray | None = None
    r_more: np.ndarray | None = None

    @property
    def terms(self) -> int:
        """Float64 terms per number (2: double-double)."""
        return 2 + (0 if self.v_more is None else len(self.v_more))

    def exact(self):
        v = Dyadic.from_dd(self.v_hi, self.v_lo)
        r = Dyadic.from_dd(self.r_hi, self.r_lo)
        for part in () if self.v_more is None else self.v_more:
            v = v + Dyadic.from_float(part)
        for part in () if self.r_more is None else self.r_more:
            r = r + Dyadic.from_float(part)
        return v, r


@dataclass(frozen=True)
class _ExactPoint:
    """A proof point given exactly (dyadic v and r), where a :class:`Point` is asked for."""

    v: Dyadic
    r: Dyadic

    def exact(self):
        return self.v, self.r


def merit(proof: Proof) -> float:
    """Fewest digits over the quantities with a bound (an absolute-mode certified one counts as
    many as it may), −∞ for an invalid proof: which of two proofs of one answer says more."""
    if not proof.valid:
        return -math.inf
    vals = [math.inf if (q.certified and q.mode == "absolute") else (-math.inf if q.digits is None else q.digits)
            for q in proof.quantities.values() if q.mode != "information"]
    return min(vals) if vals else -math.inf


class ProofContext:
    """Per-problem pieces of the proof, computed once (``setup_seconds``).  For a problem read
    from a local file (``problem.local``) the pieces are those of the local theorem
    (:mod:`.local`): the proof is about the file's W and q, never about the lifting."""

    def __init__(self, problem: Problem):
        t0 = time.perf_counter()
        self.problem = problem
        self.is_local = problem.local is not None
        if self.is_local:
            from .local import LocalExact, local_data_scales

            self.local = LocalExact(problem)
            self.scales = local_data_scales(problem)
            self.w_diag = self.local.facts.w_diag
        else:
            self.exact = ExactData(problem)
            self.mass: MassBounds = verify_mass_matrix(problem.M, problem.M_sym, problem.blocks)
            self.w_diag = self.mass.quad_upper_columns(problem.H) if self.mass.proven else None
            self.scales = data_scales(problem, self.exact, self.mass, self.w_diag)
        self._stored_scales = None
        self.setup_seconds = time.perf_counter() - t0

    @property
    def hypotheses_proven(self) -> bool:
        """M ≻ 0 (global) or W ⪰ 0 (local) is proven: proofs can succeed at all."""
        return self.local.facts.psd if self.is_local else self.mass.proven

    def rounded(self, point: Point):
        """The float64 solution (v, u, r) a point rounds to: v and r to nearest, u of the *point*
        rounded to nearest (Hᵀv + w, or W r + q for a local problem; closer to u* than the
        same formula applied to rounded vectors)."""
        pv, pr = point.exact()
        if self.is_local:
            u = self.local.u_of(pr).nearest()
        else:
            u = (self.exact.HT.matvec(pv) + self.exact.w).nearest()
        return point.v_hi.copy(), u, point.r_hi.copy()

    def prove(self, point: Point, v, u, r, requested: int, relative: bool = False) -> Proof:
        parts = (point.v_hi, point.v_lo, point.r_hi, point.r_lo, *(point.v_more if point.v_more is not None else ()),
                 *(point.r_more if point.r_more is not None else ()))
        if not all(np.all(np.isfinite(x)) for x in parts):  # an iteration that broke down: nothing to prove
            from .bound import invalid_proof

            return invalid_proof(requested, "the point has NaN or Inf entries (its iteration broke down)",
                                 time.perf_counter())
        pv, pr = point.exact()
        if self.is_local:
            from .local import prove_local

            return prove_local(self.problem, pr, u, r, requested=requested, exact=self.local, scales=self.scales,
                               relative=relative)
        return _prove(self.problem, pv, pr, v, u, r, requested=requested, mass=self.mass, exact=self.exact,
                      scales=self.scales, w_diag=self.w_diag, relative=relative)

    @property
    def has_companion(self) -> bool:
        """True when a proof of the symmetrised equations of a global problem whose stored M is
        unsymmetric gets a companion: the same point judged by the stored equations."""
        p = self.problem
        return p.equations == "symmetrised" and not p.matrix_is_symmetric

    def with_companion(self, proof: Proof, point: Point, v, u, r) -> Proof:
        """``proof`` with :attr:`Proof.stored_equations` set where :attr:`has_companion`: the
        same answer proven against the stored, unsymmetric M (W) — how many digits of the stored
        equations' solution it has (DESIGN §6.1) — at the proof's point or at the answer itself,
        whichever proves more (an answer of the stored equations is its own best point).  Costs
        two proofs."""
        if not self.has_companion or not proof.valid:
            return proof
        stored = self.problem.stored_equations()
        candidates = [point, Point(np.asarray(v, dtype=np.float64), np.zeros(np.size(v)),
                                   np.asarray(r, dtype=np.float64), np.zeros(np.size(r)))]
        if not self.is_local:
            refit = self._refitted(point)
            if refit is not None:
                candidates.append(refit)
        best = None
        for at in candidates:
            pv, pr = at.exact()
            if self.is_local:
                from .local import prove_local

                st = prove_local(stored, pr, u, r, requested=proof.requested, exact=self.local, scales=self.scales)
            else:
                if self._stored_scales is None:
                    self._stored_scales = data_scales(stored, self.exact, self.mass, self.w_diag)
                st = _prove(stored, pv, pr, v, u, r, requested=proof.requested, mass=self.mass, exact=self.exact,
                            scales=self._stored_scales, w_diag=self.w_diag)
            if best is None or merit(st) > merit(best):
                best = st
        proof.stored_equations = best
        return proof

    def _refitted(self, point: Point):
        """``point`` with r moved to fit the *stored* equations (an object whose ``exact()``
        gives the exact (v, r), like a :class:`Point`'s), or None.  The theorem holds for any
        r ∈ K: where the stored and symmetrised solutions differ on contacts that carry load,
        the symmetrised point's residual g in the stored equations is mostly H times that
        reaction difference, which the bound would otherwise count as a velocity error.

        r moves within the face of K it lies on, so that it stays in K and the gap rᵀu does
        not grow: along its own ray, r_c ← (1 + α_c) r_c exactly (a sliding contact stays on
        its cone's boundary), and freely in the (N, T) or R components that are strictly
        inside their cone.  α and those shifts minimise ‖S(g_C − H Δr)‖₂ (S the equilibration
        of M; C the dofs outside the free blocks, which are bounded exactly anyway).  The
        proof checks the new r ∈ K exactly."""
        from scipy.sparse.linalg import lsqr

        from .dyadic import Dyadic

        p = self.problem
        n = p.n_contacts
        if n == 0:
            return None
        pv, pr = point.exact()
        g = (self.exact.M.matvec(pv) - self.exact.H.matvec(pr) - self.exact.f).nearest()
        r = point.r_hi.reshape(n, 5)
        mu, mur = np.asarray(p.mu), np.asarray(p.mu_r)
        loaded = r[:, 0] > 0
        t_in = loaded & (mu * r[:, 0] - np.hypot(r[:, 1], r[:, 2]) > 1e-6 * mu * r[:, 0])
        r_in = loaded & (mur * r[:, 0] - np.hypot(r[:, 3], r[:, 4]) > 1e-6 * mur * r[:, 0])
        if not loaded.any():
            return None
        H = sp.csc_matrix(p.H)
        rows = np.flatnonzero(self.exact.free_blocks(self.mass, True).coupled)
        J = np.flatnonzero(loaded)
        ray = sp.csc_matrix((point.r_hi.reshape(n, 5)[J].ravel(), (np.repeat(np.arange(J.size), 5),
                                                                      (5 * J[:, None] + np.arange(5)).ravel())),
                            shape=(J.size, 5 * n))
        shift_cols = np.concatenate([(5 * np.flatnonzero(t_in)[:, None] + np.arange(3)).ravel(),
                                     (5 * np.flatnonzero(r_in)[:, None] + np.arange(3, 5)).ravel()]).astype(np.int64)
        A = sp.hstack([H @ ray.T, H[:, shift_cols]]).tocsr()[rows]
        scale = np.ldexp(1.0, self.mass.exponents[rows])
        A = sp.diags(scale) @ A
        with np.errstate(all="ignore"):
            x = lsqr(A, scale * g[rows], atol=1e-15, btol=1e-15, iter_lim=20 * A.shape[1] + 100)[0]
        if not np.all(np.isfinite(x)) or not np.any(x):
            return None
        alpha = np.zeros(n)
        alpha[J] = np.maximum(x[:J.size], -0.5)  # 1 + α > 0: the ray stays in K
        shift = np.zeros(5 * n)
        shift[shift_cols] = x[J.size:]
        new = r * (1 + alpha)[:, None] + shift.reshape(n, 5)
        keep_t = mu * new[:, 0] - np.hypot(new[:, 1], new[:, 2]) > 1e-9 * mu * new[:, 0]
        keep_r = mur * new[:, 0] - np.hypot(new[:, 3], new[:, 4]) > 1e-9 * mur * new[:, 0]
        sh = shift.reshape(n, 5)
        sh[~(keep_t & t_in), 0:3] = 0.0
        sh[~(keep_r & r_in), 3:5] = 0.0
        r_new = pr + Dyadic.from_float(np.repeat(alpha, 5)) * pr + Dyadic.from_float(shift)
        return _ExactPoint(pv, r_new)

    def self_stresses(self) -> list:
        """The verified, feasible self-stresses its proofs have found so far (DESIGN §6.8)."""
        if self.is_local:
            return []
        return [s for s in self.exact.face_search.found if not s.infeasible]

    def look_for_self_stress(self, r, seeds: int = 8) -> list:
        """Search for self-stresses near the ``seeds`` contacts with the largest r_N in ``r``
        (5n,): an interior-point run's reactions grow without bound along a self-stress, so
        its contacts are among the most loaded ones.  Returns :meth:`self_stresses`."""
        if self.is_local:
            return []
        from .face import find_self_stress

        rN = np.asarray(r, dtype=np.float64)[::5]
        top = np.argsort(-rN, kind="stable")[:seeds]
        top = top[rN[top] > 0]
        if top.size:
            find_self_stress(self.problem, top, self.exact.face_search)
        return self.self_stresses()

    def eps_lower(self, gap: float) -> float:
        """The smallest ε a point with duality gap rᵀu = ``gap`` can give (√gap: the theorem's
        ε with g = 0, globally and for the local theorem)."""
        return math.sqrt(max(gap, 0.0))

    def may_certify(self, eps_lower: float, v_inf: float, u_inf: float, requested: int,
                    relative: bool = False) -> bool:
        """Necessary condition, cheap: with ε ≥ ``eps_lower`` the bounds on v and u are at least
        √((M⁻¹)_jj)·ε (j outside the free blocks, which are bounded without ε) and √(W_kk)·ε
        (√(W_kk)·ε on u for a local problem).  A quantity is certified relatively only where its
        bound fits 10⁻ᵏ of its own norm, and absolutely only where the norm itself is below 10⁻ᵏ
        of its data scale (:func:`.quantity.quantity_bound`; never with ``relative``), so a
        bound between the two tests is refused here as in the proof.  False means no proof of
        this point can certify ``requested`` digits."""
        if not self.hypotheses_proven:
            return True  # let the proof say why
        tol = 10.0 ** (-requested)

        def fits(bound: float, norm: float, scale: float) -> bool:
            # 1.01: the norms here are of the iterate, the proof's of its rounded answer
            if bound <= tol * norm * 1.01:
                return True
            return not relative and norm <= tol * scale * 1.01 and bound <= tol * scale * 1.01

        eu = float(np.sqrt(np.max(self.w_diag, initial=0.0))) * eps_lower
        if self.is_local:
            return fits(eu, u_inf, self.scales["u"])
        coupled = self.exact.free_blocks(self.mass, self.problem.as_stored).coupled
        ev = float(np.sqrt(np.max(self.mass.minv_diag_upper[coupled], initial=0.0))) * eps_lower
        return fits(ev, v_inf, self.scales["v"]) and fits(eu, u_inf, self.scales["u"])
