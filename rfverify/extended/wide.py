"""Algorithm 1 continued in multiple precision (gmpy2 ``mpfr``), for the last iterations of the
k-digit path on problems that need a duality gap below what double-double resolves.

Why it exists (measured, DECISIONS "Multiple-precision tail"): the proof converts the M-norm
bound ε ≈ √(2 rᵀu) into per-component digits, so 10 relative digits of a v* that is tiny
against the data (a hyperstatic lattice at rest: ‖v*‖∞ ≈ 1e-10 of ‖M⁻¹f‖∞) need rᵀu ≈ 1e-48.
Double-double fails there twice: λ₂ of a cone whose λ₁ is O(1) falls below its unit roundoff
(the iterates leave the cones in exact arithmetic), and the Newton matrices have condition
≈ 1/μ along redundant sticking contacts, so their float64 and double-double factors lose
definiteness near μ = 1e-41 whatever precision the residuals have.

So everything is wider here: the iterate (v, r̃, z), the residuals, every cone kernel (NT
scaling, Q_{p^k}, products, step lengths; the formulas of :mod:`.cones`, vectorised over cones
in numpy object arrays) and the Newton solve — the dof-space matrix M + BᵀB, B = F⁻¹H̃, formed
(:class:`.wide_factor.WideDofSpace`) and factored sparsely in ``bits``-bit arithmetic in a
minimum-degree order (:class:`.wide_cholesky.SparseWideCholesky`), each solve refined against
the unreduced three-block system.  The cost is Σ c_j² multiply-subtract pairs (O(m³) at
worst), so the k-digit path runs this tail only where double-double stalled and the
factorisation is affordable (:mod:`rfverify.verify.digits`).

gmpy2's precision is set in a local context for the duration of each call; nothing leaks.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..algorithm.interfaces import Breakdown, ReducedBackend
from ..algorithm.loop import Precision, iterate
from ..algorithm.newton import NEWTON_ENOUGH, PREDICTOR_ENOUGH, ReducedNewton
from ..algorithm.policy import UntilPolicy, extended_trace
from ..jordan.mpfr import arrow_solve, centrality, identity, max_step_at, nt_scaling, product, quad_pow
from .data import ExtendedData
from .ipm import ExtendedResult
from .wide_cholesky import DenseWideCholesky, SparseWideCholesky
from .wide_data import WideData, WideMatrix, context, dot, expansion, from_dd, inf_norm, two_norm
from .wide_factor import WideDofSpace

DEFAULT_BITS = 320
"""Working precision: 96 decimal digits, enough for cones whose λ₂/λ₁ is 1e-60 with margin."""


@dataclass
class WideIterate:
    """The state handed to the ``until`` callback: v (m,), r̃ (nk,), z (nz,) as mpfr arrays."""

    k: int
    v: np.ndarray
    r_t: np.ndarray
    z: np.ndarray
    mu: float
    pinfeas: float
    dinfeas: float
    bits: int
    wide_data: WideData = field(repr=False, default=None)
    predicted: bool = False
    """True for the point along iteration k's predictor direction (residuals not evaluated: NaN),
    as :attr:`.ipm.Iterate.predicted`."""

    def describe(self):
        """(rᵀu of the iterate, the point (v, r) as a float64 expansion, ‖v‖∞, ‖u‖∞) for the
        proof driver."""
        data = self.wide_data.data
        lp = data.lp
        terms = -(-self.bits // 53)
        with context(self.bits):
            u_t = self.wide_data.Ht @ self.v + self.wide_data.w_t
            gap = float(abs(dot(self.r_t, u_t)))
            vp = expansion(self.v, terms)
            rp = expansion(self.r_t * from_dd(lp.scale), terms)
        R = np.zeros((terms, 5 * data.n))
        R[:, lp.keep] = rp
        from ..proof import Point

        point = Point(vp[0], vp[1], R[0], R[1], np.array(vp[2:]), R[2:])
        v_inf = float(np.max(np.abs(vp[0]), initial=0.0))
        u_inf = float(np.max(np.abs(data.problem.H.T @ vp[0] + data.problem.w), initial=0.0))
        return gap, point, v_inf, u_inf


def handover(data: ExtendedData, iterates, bits: int = DEFAULT_BITS, min_centrality: float = 1e-2,
             residual_margin: float = 1e4):
    """The latest double-double iterate from which the tail can start: strictly interior in
    ``bits``-bit arithmetic (the last iterates of a stalled double-double run are often not),
    centred (λ₂(λ)/√μ ≥ ``min_centrality`` in every cone), and with residuals within
    ``residual_margin`` of the best ones among ``iterates``.  None if there is none."""
    if not iterates:
        return None
    best_p = min(it.pinfeas for it in iterates)
    best_d = min(it.dinfeas for it in iterates)
    with context(bits):
        JT = WideMatrix(data.JT)
        for it in reversed(iterates):
            if it.pinfeas > residual_margin * best_p or it.dinfeas > residual_margin * best_d:
                continue
            z = from_dd(it.z.h, it.z.l)
            s = JT @ from_dd(it.r_t.h, it.r_t.l)
            sc, _ = nt_scaling(data.n3, z, s)
            if sc is None:
                continue
            if centrality(data.n3, sc, dot(z, s) / (data.n3 + data.n1)) >= min_centrality:
                return it
    return None


@dataclass
class WideResult(ExtendedResult):
    """Outcome of :func:`run`: as :class:`.ipm.ExtendedResult`, with v, r̃, z as mpfr arrays
    and the working precision ``bits``."""

    bits: int = DEFAULT_BITS


class _WideSpace:
    """The lifted problem in ``bits``-bit mpfr (:class:`~rfverify.algorithm.interfaces.Space`):
    :class:`WideData`'s operators, object arrays as vectors."""

    tiny = 1e-300

    def __init__(self, W: WideData):
        self.M, self.H, self.HT, self.J, self.JT = W.M, W.Ht, W.HtT, W.J, W.JT
        self.f, self.w = W.f, W.w_t

    def velocity(self, v, r):
        return self.H @ v

    dot = staticmethod(dot)
    norm2 = staticmethod(two_norm)

    @staticmethod
    def axpy(x, a, y):
        return x + a * y

    move = axpy


class _WideScaling:
    """The NT scaling of one mpfr iterate and its cone operations."""

    def __init__(self, n3: int, n_cones: int, e, z, s):
        sc, bad = nt_scaling(n3, z, s)
        if sc is None:
            raise Breakdown(f"cone {bad} is not strictly interior")
        self.n3, self.n_cones, self.e, self.z, self.s, self.sc = n3, n_cones, e, z, s, sc
        self.limit = None  # set by max_step

    def describe(self) -> dict:
        return {"centrality": centrality(self.n3, self.sc, dot(self.z, self.s) / self.n_cones)}

    def quad(self, k: int, y):
        return quad_pow(self.n3, k, self.sc, y)

    def affine_rhs(self):
        return -self.sc.lam

    def corrector_rhs(self, target, dz_aff, ds_aff):
        n3, lam = self.n3, self.sc.lam
        xi = target * self.e - product(n3, lam, lam) - product(n3, self.quad(1, dz_aff), self.quad(-1, ds_aff))
        return arrow_solve(n3, lam, xi)

    def max_step(self, dz, ds) -> float:
        """The largest α keeping z + α dz and s + α ds in their cones; :attr:`limit` is then
        (cone, "z" or "s") of the cone that sets it, the z side on a tie (None when unbounded)."""
        step_z, cone_z = max_step_at(self.n3, self.z, dz)
        step_s, cone_s = max_step_at(self.n3, self.s, ds)
        step = min(step_z, step_s)
        self.limit = None if step == math.inf else ((cone_z, "z") if step_z <= step_s else (cone_s, "s"))
        return step


class _WideCones:
    def __init__(self, n3: int, nz: int, n_cones: int):
        self.n3, self.n_cones, self.e = n3, n_cones, identity(n3, nz)

    def scaling(self, z, s):
        return _WideScaling(self.n3, self.n_cones, self.e, z, s)


class _WideBackend(ReducedBackend):
    """A dof-space factor seen through the Newton interface (it takes the scaling's
    :class:`Scaling` and mpfr vectors as they are)."""

    def __init__(self, factor):
        self.factor = factor
        self.name = factor.name

    def update(self, scaling: _WideScaling) -> bool:
        return self.factor.update(scaling.sc)

    def solve(self, a, t):
        return self.factor.solve(a, t)


def run(data: ExtendedData, start: dict, *, until=None, max_iter: int = 30, bits: int = DEFAULT_BITS,
        refine_max: int = 8, gamma_max: float = 0.99, perm=None, progress=None, sparse: bool = True,
        enough: float | None = NEWTON_ENOUGH, predictor_enough: float | None = PREDICTOR_ENOUGH,
        offer_predicted: bool = False) -> WideResult:
    """Algorithm 1 (:func:`rfverify.algorithm.loop.iterate`) in ``bits``-bit arithmetic from
    ``start`` = {"v", "r_t", "z"}, each a (hi, lo) pair of float64 arrays (a double-double
    iterate) or an mpfr array.  ``until(WideIterate)`` is called at every iterate; True stops
    the run ("Stopped"); with ``offer_predicted`` also with each iteration's predictor point, as
    in :func:`.ipm.run`.  Same policy as :func:`.ipm.run` (the paper's σ rule, the capped step
    rule) and the same inexact Newton solves (``enough``, ``predictor_enough``; None refines
    every solve to the floor, 2^(24 − bits)).  ``perm``: the factor's ordering from :func:`.wide_factor.dof_space_ordering`, if
    the caller computed it.  ``sparse``: the factor's engine is :class:`SparseWideCholesky`
    (default; memory O(nnz(L))), else :class:`DenseWideCholesky` (m × m; kept as the reference
    the sparse one is tested against)."""
    t0 = time.perf_counter()
    n_cones = data.n3 + data.n1
    with context(bits):
        W = WideData(data)
        factor = WideDofSpace(data, W, SparseWideCholesky if sparse else DenseWideCholesky, perm=perm)
        space = _WideSpace(W)
        newton = ReducedNewton(space, _WideBackend(factor), refine_max=refine_max, floor=2.0 ** (-bits + 24),
                               inf=inf_norm, enough=enough,
                               predictor_enough=predictor_enough)
        policy = UntilPolicy(until, progress, max_iter,
                             lambda k, it, res: WideIterate(k, *it, res.mu, res.pinfeas, res.dinfeas, bits, W),
                             gamma_max, "stopped by the proof driver",
                             make_predicted=(lambda k, it, mu: WideIterate(k, *it, mu, math.nan, math.nan, bits, W,
                                                                           predicted=True))
                             if offer_predicted else None)

        def lift(x):
            return from_dd(*x) if isinstance(x, tuple) else np.asarray(x, dtype=object) + 0

        begin = tuple(lift(start[key]) for key in ("v", "r_t", "z"))
        out = iterate(Precision(space, _WideCones(data.n3, data.nz, n_cones), newton), policy, begin,
                      n_contacts=data.n, n_cones=n_cones, clock_origin=t0)
    status, message = out.verdict
    return WideResult(*out.iterate, status, message, out.k, extended_trace(out.records), factor.name,
                      time.perf_counter() - t0, bits=bits)
