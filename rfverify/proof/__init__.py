"""Rigorous a-posteriori error bounds (DESIGN §6): the proof behind a certificate.

:func:`prove` evaluates the bound of :mod:`.bound` for an extended-precision point and
carries it to a returned float64 solution.  :class:`ProofContext` holds what depends only on
the problem (exact data, verified bounds on M and on the columns of H, data scales), so that
several points of one problem are proven at O(nnz) cost each.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..problem import SPACEDIM, Problem
from .bound import (FLOAT64_DIGITS, MAX_CERTIFIABLE_DIGITS, ExactData, Proof, QuantityBound, data_scales,
                    prove as _prove, validate_digits)
from .dyadic import Dyadic
from .massbounds import MassBounds, verify_mass_matrix

__all__ = ["Proof", "ProofContext", "QuantityBound", "Point", "validate_digits", "FLOAT64_DIGITS",
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


class ProofContext:
    """Per-problem pieces of the proof, computed once (``setup_seconds``)."""

    def __init__(self, problem: Problem):
        t0 = time.perf_counter()
        self.problem = problem
        self.exact = ExactData(problem)
        self.mass: MassBounds = verify_mass_matrix(problem.M, problem.M_sym)
        self.w_diag = self.mass.quad_upper_columns(problem.H) if self.mass.proven else None
        self.scales = data_scales(problem)
        self.setup_seconds = time.perf_counter() - t0

    def rounded(self, point: Point):
        """The float64 solution (v, u, r) a point rounds to: v and r to nearest, u = Hᵀv + w of
        the *point* rounded to nearest (closer to u* than Hᵀ(rounded v) + w)."""
        pv, _ = point.exact()
        u = (self.exact.HT.matvec(pv) + self.exact.w).nearest()
        return point.v_hi.copy(), u, point.r_hi.copy()

    def prove(self, point: Point, v, u, r, requested: int) -> Proof:
        pv, pr = point.exact()
        return _prove(self.problem, pv, pr, v, u, r, requested=requested, mass=self.mass, exact=self.exact,
                      scales=self.scales, w_diag=self.w_diag)

    def may_certify(self, eps_lower: float, v_inf: float, u_inf: float, requested: int) -> bool:
        """Necessary condition, cheap: with ε ≥ ``eps_lower`` the bounds on v and u are at least
        √((M⁻¹)_jj)·ε and √(W_kk)·ε, which must fit 10⁻ᵏ of the larger of the vector's norm and
        its data scale.  False means no proof of this point can certify ``requested`` digits."""
        if not self.mass.proven:
            return True  # let the proof say why
        tol = 10.0 ** (-requested)
        ev = float(np.sqrt(np.max(self.mass.minv_diag_upper, initial=0.0))) * eps_lower
        eu = float(np.sqrt(np.max(self.w_diag, initial=0.0))) * eps_lower
        return ev <= tol * max(v_inf, self.scales["v"]) * 1.01 and eu <= tol * max(u_inf, self.scales["u"]) * 1.01
