"""The one definition of "solved": residual measures of a candidate (v, u, r), and the criterion.

Every part of rfverify that judges a solution — the solver's stopping test, ``info``'s check of
a file's ``/solution``, the bench's independent recheck, the judgement of Clarabel's answers,
the report — calls :func:`measures` (or :func:`measures_from_arrays`); only the arithmetic
differs (float64, numpy.longdouble, or mpmath at a chosen precision).

Measures (dimensionless, ∞-norms, 0 is exact).  Each residual is divided by the size of the
terms it is computed from *and* by a scale taken from the data alone, so that no denominator
vanishes at a correct solution — all contacts sticking with w = 0 (u* = 0), v* = 0, all
contacts open (r* = 0):

``dynamics``        ‖M v − H r − f‖ / D,    D = max(‖M v‖, ‖H r‖, ‖f‖, ‖M‖‖v‖)
``velocity``        ‖u − Hᵀv − w‖ / U,      U = max(‖u‖, ‖Hᵀv‖, ‖w‖, ‖Hᵀ‖‖v‖, U₀)
``primal_cone``     max_i max(‖r_T‖ − μ r_N, ‖r_R‖ − μr r_N, −r_N, 0) / R,   R = max(‖r‖, R₀)
``dual_cone``       max_i max(μ‖u_T‖ + μr‖u_R‖ − u_N, −u_N, 0) / U
``complementarity`` |rᵀu| / E,     E = max(fᵀM⁻¹f, ‖w‖² / max_k W̃_kk)

with the data scales U₀ = ‖Hᵀ M⁻¹ f + w‖ (the contact velocity without reactions) and
R₀ = ‖f‖ / max_k ‖h_k‖₂ (a reaction that balances f; h_k = column k of H), and operator norms
‖·‖∞ of the data applied to v (unique and bounded).  There is deliberately no ‖H‖‖r‖ term:
hyperstatic contacts admit self-equilibrated reactions of any size (r ~ 1e6·‖f‖ measured on
a lattice), and a scale growing with them would accept a dynamics residual far above the
applied forces.  For the same reason the gap rᵀu (an energy: impulse × velocity) is
measured against an energy of the data — fᵀM⁻¹f (twice the kinetic energy the bodies would
reach without contacts), or for problems driven by w alone (lifted local problems, f = 0)
‖w‖²/max_k W̃_kk with W̃_kk = Σ_j H_jk²/M_jj (a cheap scale of the Delassus diagonal) — not
against ‖r‖·‖u‖, nor against vᵀMv, which near a solution at rest tracks the error itself
(‖v − v*‖²_M ≈ 2rᵀu by the bound of DESIGN §6: the ratio stayed at 1.1 while μ fell 2000-fold
on a 1422-contact PrimitiveSoup).  Criterion:
``max`` = the largest of dynamics, velocity, cone = max(primal_cone, dual_cone) and
complementarity; a candidate meets ``tol`` when ``max ≤ tol``.

The paper's measures (DESIGN §4) are computed beside, for the record, in the original
variables and on the point judged: ``paper_dinfeas`` = ‖Mv − f − Hr‖₂ / max(‖Mv‖₂, ‖f‖₂, ‖Hr‖₂)
and ``paper_mu`` = |uᵀr| / n.  They are not the solver's ``SolveResult.dinfeas`` and ``mu``, which
are the iterate's own (μ = zᵀJᵀr̃ / n with the lifted slack z, not u = Hᵀv + w; they differ by the
primal residual, e.g. in the 7th digit; DESIGN §4.5).  ``paper_mu`` is absolute (it changes with the units), and the paper's pinfeas scale
max(‖Jz‖, ‖H̃v‖, ‖w̃‖) vanishes when every contact sticks with w = 0: the reasons for the
definition above.
"""

from __future__ import annotations

import math
import weakref
from contextlib import nullcontext
from dataclasses import asdict, dataclass

import numpy as np
import scipy.sparse as sp

from .problem import SPACEDIM, Problem

CRITERION = ("dynamics", "velocity", "cone", "complementarity")


# ---------------------------------------------------------------------- arithmetic
class Arithmetic:
    """numpy floating arithmetic of one dtype (float64 or longdouble)."""

    def __init__(self, dtype):
        self.dtype = np.dtype(dtype)
        self.name = self.dtype.name

    def context(self):
        return nullcontext()

    def vector(self, x):
        return np.asarray(x, dtype=self.dtype)

    def matrix(self, A):
        return sp.csr_matrix(A).astype(self.dtype)

    def matvec(self, A, x):
        return A @ x

    def hypot(self, a, b):
        return np.hypot(a, b)

    def amax(self, x) -> float:
        return float(np.max(np.abs(x), initial=0))

    def norm2(self, x) -> float:
        s = np.max(np.abs(x), initial=0)
        return float(s * np.sqrt(np.sum((x / s) ** 2))) if s > 0 else 0.0

    def dot(self, x, y) -> float:
        return float(np.dot(x, y))


class MpmathArithmetic(Arithmetic):
    """mpmath at ``dps`` digits (local precision), vectorised as numpy object arrays."""

    def __init__(self, dps: int):
        import mpmath

        self.mp = mpmath
        self.dtype = np.dtype(object)
        self.dps = int(dps)
        self.name = f"mpmath({self.dps})"
        self._hypot = np.frompyfunc(mpmath.hypot, 2, 1)
        self._mpf = np.frompyfunc(lambda x: mpmath.mpf(float(x)), 1, 1)

    def context(self):
        return self.mp.workdps(self.dps)

    def vector(self, x):
        x = np.asarray(x)
        if x.dtype == object:  # already mpf (e.g. computed in this arithmetic)
            return x
        return self._mpf(x.astype(np.float64)).astype(object)

    def matrix(self, A):
        A = sp.csr_matrix(A)
        A.sum_duplicates()
        return (A.indptr.astype(np.int64), A.indices.astype(np.int64), self.vector(A.data), A.shape)

    def matvec(self, A, x):
        indptr, indices, data, shape = A
        out = np.empty(shape[0], dtype=object)
        out[:] = self.mp.mpf(0)
        if data.size:
            prod = data * x[indices]
            nonempty = np.flatnonzero(np.diff(indptr) > 0)
            out[nonempty] = np.add.reduceat(prod, indptr[nonempty])
        return out

    def hypot(self, a, b):
        return self._hypot(a, b)

    def amax(self, x) -> float:
        return float(max((abs(t) for t in x), default=0))

    def norm2(self, x) -> float:
        return float(self.mp.sqrt(self.mp.fsum(t * t for t in x)))

    def dot(self, x, y) -> float:
        return float(self.mp.fsum(a * b for a, b in zip(x, y)))


FLOAT64 = Arithmetic(np.float64)
LONGDOUBLE = Arithmetic(np.longdouble)


def arithmetic(spec) -> Arithmetic:
    """``"float64"``, ``"longdouble"``, an int (mpmath digits) or an Arithmetic."""
    if isinstance(spec, Arithmetic):
        return spec
    if spec in ("float64", np.float64, float):
        return FLOAT64
    if spec in ("longdouble", np.longdouble):
        return LONGDOUBLE
    if isinstance(spec, int) and not isinstance(spec, bool):
        return MpmathArithmetic(spec)
    raise ValueError(f"unknown arithmetic {spec!r}: use 'float64', 'longdouble' or mpmath digits (int)")


# ---------------------------------------------------------------------- data scales
@dataclass(frozen=True)
class DataScales:
    """Scales from the data alone (float64; they only set the size of a denominator).

    ``v_free`` = ‖M⁻¹f‖∞, ``u_free`` = ‖Hᵀ M⁻¹ f + w‖∞ (U₀), ``f`` = ‖f‖∞,
    ``r`` = ‖f‖∞ / max_k ‖h_k‖₂ (R₀), ``energy`` = max(fᵀM⁻¹f, ‖w‖²∞ / max_k Σ_j H_jk²/M_jj),
    and the operator norms ‖M‖∞, ‖H‖∞, ‖Hᵀ‖∞."""

    v_free: float
    u_free: float
    f: float
    r: float
    norm_M: float = 0.0
    norm_H: float = 0.0
    norm_HT: float = 0.0
    energy: float = 0.0


_SCALES: "weakref.WeakKeyDictionary[Problem, DataScales]" = weakref.WeakKeyDictionary()


def data_scales_from_arrays(M, H, f, w) -> DataScales:
    from scipy.sparse.linalg import splu

    f = np.asarray(f, dtype=np.float64)
    try:
        v_free = splu(sp.csc_matrix(M, dtype=np.float64)).solve(f) if f.size else f
    except RuntimeError:  # singular: validation refuses such problems; keep the scale finite
        v_free = np.zeros_like(f)
    H = sp.csc_matrix(H)
    u_free = H.T @ v_free + np.asarray(w, dtype=np.float64)
    col = np.sqrt(np.asarray(H.power(2).sum(axis=0)).ravel()) if H.shape[1] else np.zeros(0)
    f_inf = float(np.max(np.abs(f), initial=0.0))
    cmax = float(np.max(col, initial=0.0))
    absH = abs(H)
    diag = sp.csr_matrix(M).diagonal()
    w_inf = float(np.max(np.abs(w), initial=0.0))
    W_diag = np.asarray(H.power(2).multiply(1.0 / np.where(diag > 0, diag, np.inf)[:, None]).sum(axis=0)).ravel() \
        if H.shape[1] else np.zeros(0)
    wmax = float(np.max(W_diag, initial=0.0))
    energy_w = w_inf * w_inf / wmax if wmax > 0 else 0.0
    return DataScales(v_free=float(np.max(np.abs(v_free), initial=0.0)),
                      u_free=float(np.max(np.abs(u_free), initial=0.0)), f=f_inf,
                      r=f_inf / cmax if cmax > 0 else 0.0,
                      norm_M=float(np.max(np.asarray(abs(sp.csr_matrix(M)).sum(axis=1)).ravel(), initial=0.0)),
                      norm_H=float(np.max(np.asarray(absH.sum(axis=1)).ravel(), initial=0.0)),
                      norm_HT=float(np.max(np.asarray(absH.sum(axis=0)).ravel(), initial=0.0)),
                      energy=max(float(abs(f @ v_free)), energy_w))


def data_scales(problem: Problem) -> DataScales:
    """:class:`DataScales` of a problem (computed once per problem object)."""
    s = _SCALES.get(problem)
    if s is None:
        s = data_scales_from_arrays(problem.M_sym, problem.H, problem.f, problem.w)
        _SCALES[problem] = s
    return s


# ---------------------------------------------------------------------- measures
@dataclass(frozen=True)
class Measures:
    """Result of :func:`measures` (see the module docstring); floats."""

    dynamics: float
    velocity: float
    primal_cone: float
    dual_cone: float
    complementarity: float
    paper_dinfeas: float
    paper_mu: float
    arithmetic: str = "float64"

    @property
    def cone(self) -> float:
        return max(self.primal_cone, self.dual_cone)

    @property
    def max(self) -> float:
        vals = (self.dynamics, self.velocity, self.cone, self.complementarity)
        return math.inf if any(math.isnan(x) for x in vals) else max(vals)

    def meets(self, tol: float) -> bool:
        return self.max <= tol

    def worst(self) -> str:
        vals = {"dynamics": self.dynamics, "velocity": self.velocity, "cone": self.cone,
                "complementarity": self.complementarity}
        return max(vals, key=lambda k: -1 if math.isnan(vals[k]) else vals[k])

    def as_dict(self) -> dict:
        d = asdict(self)
        d["cone"] = self.cone
        d["max"] = self.max
        return d


class MeasureData:
    """The data of one problem (or one independent component) in a given arithmetic, built
    once so that many candidates (iterates, trajectories) are measured cheaply."""

    def __init__(self, M, H, f, w, mu, mu_r, scales: DataScales, arith: Arithmetic = FLOAT64):
        self.arith = arith
        self.n = int(np.asarray(mu).size)
        self.scales = scales
        with arith.context():
            self.M = arith.matrix(M)
            self.H = arith.matrix(H)
            self.HT = arith.matrix(sp.csr_matrix(H).T)
            self.f = arith.vector(f)
            self.w = arith.vector(w)
            self.mu = arith.vector(mu)
            self.mu_r = arith.vector(mu_r)

    @staticmethod
    def of(problem: Problem, arith=FLOAT64) -> "MeasureData":
        return MeasureData(problem.M_eq, problem.H, problem.f, problem.w, problem.mu, problem.mu_r,
                           data_scales(problem), arithmetic(arith))

    def measures(self, v, u, r) -> Measures:
        a = self.arith
        nan = float("nan")
        if not all(np.all(np.isfinite(np.asarray(x, dtype=np.float64))) for x in (v, u, r)):
            return Measures(nan, nan, nan, nan, nan, nan, nan, a.name)
        with a.context():
            V, Uv, Rv = a.vector(v), a.vector(u), a.vector(r)
            Mv, Hr, HTv = a.matvec(self.M, V), a.matvec(self.H, Rv), a.matvec(self.HT, V)
            d_res = Mv - Hr - self.f
            sc = self.scales
            v_inf = a.amax(V)
            dyn_scale = max(a.amax(Mv), a.amax(Hr), a.amax(self.f), sc.norm_M * v_inf)
            dyn = _ratio(a.amax(d_res), dyn_scale)
            U = max(a.amax(Uv), a.amax(HTv), a.amax(self.w), sc.norm_HT * v_inf, sc.u_free)
            R = max(a.amax(Rv), self.scales.r)
            vel = _ratio(a.amax(Uv - HTv - self.w), U)
            n = self.n
            rc = Rv.reshape(n, SPACEDIM)
            uc = Uv.reshape(n, SPACEDIM)
            zero = rc[:, 0] * 0
            rT = a.hypot(rc[:, 1], rc[:, 2])
            rR = a.hypot(rc[:, 3], rc[:, 4])
            prim = np.maximum(np.maximum(rT - self.mu * rc[:, 0], rR - self.mu_r * rc[:, 0]),
                              np.maximum(-rc[:, 0], zero))
            uT = a.hypot(uc[:, 1], uc[:, 2])
            uR = a.hypot(uc[:, 3], uc[:, 4])
            dual = np.maximum(self.mu * uT + self.mu_r * uR - uc[:, 0], np.maximum(-uc[:, 0], zero))
            gap = abs(a.dot(Rv, Uv))
            comp = _ratio(gap, sc.energy)
            pd_scale = max(a.norm2(Mv), a.norm2(self.f), a.norm2(Hr))
            paper_d = _ratio(a.norm2(d_res), pd_scale)
            return Measures(dynamics=float(dyn), velocity=float(vel),
                            primal_cone=_ratio(float(np.max(prim, initial=0)) if prim.size else 0.0, R),
                            dual_cone=_ratio(float(np.max(dual, initial=0)) if dual.size else 0.0, U),
                            complementarity=float(comp), paper_dinfeas=float(paper_d),
                            paper_mu=float(gap) / max(n, 1), arithmetic=a.name)


def _ratio(num, den) -> float:
    num, den = float(num), float(den)
    if den > 0:
        return num / den
    return 0.0 if num == 0 else math.inf


def measures(problem: Problem, v, u, r, arith="float64") -> Measures:
    """The measures of a candidate (v (m,), u (5n,), r (5n,)) in the given arithmetic
    (``"float64"``, ``"longdouble"``, or an int: mpmath digits).  A missing u (None) is taken
    as Hᵀv + w in that arithmetic."""
    data = MeasureData.of(problem, arith)
    if u is None:
        with data.arith.context():
            u = data.arith.matvec(data.HT, data.arith.vector(v)) + data.w
    return data.measures(v, u, r)
