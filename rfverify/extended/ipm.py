"""The extended-precision phase: Algorithm 1 continued in double-double arithmetic.

Started from an interior iterate of the double solver (or from a candidate solution pushed
into the interior), it drives μ from ~1e-10 to ~1e-30, where the error bound of
:mod:`rfverify.proof` can prove 10 or more digits of the rounded solution.  It differs from
the double solver in three places, each for a reason measured on the reference (DESIGN §5):

* every operation is double-double (≈ 32 digits): data (H̃ = P Hᵀ, w̃, (M + Mᵀ)/2) exactly,
  Jordan algebra, factorisation (:mod:`.ldl`), residuals;
* each Newton solve is refined against the unreduced three-block system (dual, primal,
  complementarity rows).  Without it the primal residual grew like μ^-0.45 and left the
  cones at μ ≈ 1e-28 in 32-digit arithmetic; with one step it stayed at 1e-34.  Since it
  corrects whatever the reduction and the factor lose, the back end's own solves are one
  unchecked float64 solve each (:data:`.contactspace.NEWTON_REFINED_TARGET`), and it stops
  once each block's residual is :data:`NEWTON_ENOUGH` (:data:`PREDICTOR_ENOUGH` for the
  predictor) of its right-hand side: an inexact Newton method;
* the run stops when the *proof* succeeds (``until`` callback), not at a fixed μ.

The Newton system is solved by a back end of :mod:`.system` (by default the scaled
contact-space Schur complement, factored in float64 and refined in double-double).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..algorithm.interfaces import Breakdown, ReducedBackend
from ..algorithm.loop import Precision, iterate
from ..algorithm.newton import NEWTON_ENOUGH, PREDICTOR_ENOUGH, ReducedNewton
from ..algorithm.policy import UntilPolicy, extended_trace
from . import cones as C
from . import dd
from .data import ExtendedData
from .factored import NewtonBackend
from .system import choose_backend


class V:
    """A double-double vector (hi, lo) with the few operations the driver needs."""

    __slots__ = ("h", "l")

    def __init__(self, h, l=None):
        self.h = np.ascontiguousarray(h, dtype=np.float64)
        self.l = np.zeros_like(self.h) if l is None else np.ascontiguousarray(l, dtype=np.float64)

    @staticmethod
    def zeros(n):
        return V(np.zeros(n))

    def __add__(self, o):
        out = V.zeros(self.h.size)
        dd.vadd(self.h, self.l, o.h, o.l, out.h, out.l)
        return out

    def __sub__(self, o):
        out = V.zeros(self.h.size)
        dd.vsub(self.h, self.l, o.h, o.l, out.h, out.l)
        return out

    def __neg__(self):
        return V(-self.h, -self.l)

    def scaled(self, a: float):
        out = V.zeros(self.h.size)
        dd.vscale(float(a), 0.0, self.h, self.l, out.h, out.l)
        return out

    def axpy(self, a: float, x: "V"):
        """self + a·x (new vector)."""
        out = V(self.h.copy(), self.l.copy())
        dd.vaxpy(float(a), 0.0, x.h, x.l, out.h, out.l)
        return out

    def dot(self, o) -> float:
        h, l = dd.vdot(self.h, self.l, o.h, o.l)
        return h + l

    def inf(self) -> float:
        return float(np.max(np.abs(self.h), initial=0.0))

    def norm(self) -> float:
        h, l = dd.vnorm2(self.h, self.l)
        return h + l

    def longdouble(self):
        return dd.to_longdouble(self.h, self.l)


@dataclass
class Iterate:
    """The state handed to the ``until`` callback (double-double vectors)."""

    k: int
    v: V
    r_t: V
    z: V
    mu: float
    pinfeas: float
    dinfeas: float
    predicted: bool = False
    """True for the point along iteration k's predictor direction (its residuals not evaluated:
    NaN), offered to ``until`` before the corrector is solved."""


@dataclass
class ExtendedResult:
    """Outcome of :func:`run`: the last iterate (v, r̃, z as double-double), status
    ("Stopped" when ``until`` accepted an iterate, "MaxIterations", "NumericalError", "MaxTime"
    when a long kernel was stopped at the time limit), per-iteration trace and timings; ``stats``: the back end's factorisation statistics
    (:meth:`.factored.FactoredBackend.stats`)."""

    v: V
    r_t: V
    z: V
    status: str
    message: str
    nit: int
    trace: dict = field(default_factory=dict)
    backend: str = ""
    seconds: float = 0.0
    factor_seconds: float = 0.0
    stats: dict = field(default_factory=dict)
    factorisation: str = ""
    """Which factorisations ran and what they cost (a fallback named, with its reason)."""


def interior_start(data: ExtendedData, v, r, u=None, margin_rel: float = 1e-8) -> dict:
    """A strictly interior lifted point near a candidate solution (v, r) in the original
    variables: r̃ = P⁻¹r and z splitting ũ = P(Hᵀv + w) between the two cones of a contact,
    each pushed inside by ``margin_rel`` times the iterate's scale."""
    lp = data.lp
    problem = data.problem
    if data.local:  # no dofs; u = W r + q of the file's W
        v = np.zeros(0, dtype=np.longdouble)
        if u is None:
            u = problem.local.velocity(r, np.longdouble)
    v = np.asarray(v, dtype=np.longdouble)
    u = (problem.H.T.astype(np.longdouble) @ v + problem.w) if u is None else np.asarray(u, dtype=np.longdouble)
    r_t = np.asarray(r, dtype=np.longdouble)[lp.keep] / lp.scale
    u_t = u[lp.keep] * lp.scale
    scale = max(float(np.max(np.abs(r_t), initial=0.0)), float(np.max(np.abs(u_t), initial=0.0)), 1e-300)
    margin = margin_rel * scale
    z = np.zeros(lp.nz, dtype=np.longdouble)
    # kept-row positions of each cone's components: rows of J
    J = lp.J.tocsc()
    rows_of = J.indices  # z component → kept row
    # friction / rolling bars copy ũ; heads split the slack of u0 evenly
    z[:] = u_t[rows_of]
    heads3 = np.arange(lp.n3) * 3
    bar = np.hypot(z[heads3 + 1].astype(np.float64), z[heads3 + 2].astype(np.float64)).astype(np.longdouble)
    head_row = rows_of[heads3]
    used = np.zeros(lp.nk, dtype=np.longdouble)
    np.add.at(used, head_row, bar)
    count = np.bincount(head_row, minlength=lp.nk).astype(np.longdouble)
    slack = (u_t - used)
    share = np.where(count > 0, slack / np.maximum(count, 1), 0)
    z[heads3] = bar + np.maximum(share[head_row], 0) + margin
    if lp.n1:
        z[3 * lp.n3:] = np.maximum(u_t[rows_of[3 * lp.n3:]], 0) + margin
    # r̃: lift the heads so that Jᵀr̃ is inside both cones by the margin
    s = lp.J.T.astype(np.longdouble) @ r_t
    need = np.zeros(lp.nk, dtype=np.longdouble)
    sbar = np.hypot(s[heads3 + 1].astype(np.float64), s[heads3 + 2].astype(np.float64)).astype(np.longdouble)
    deficit = sbar - s[heads3] + margin
    np.maximum.at(need, head_row, np.maximum(deficit, 0))
    if lp.n1:
        one = rows_of[3 * lp.n3:]
        np.maximum.at(need, one, np.maximum(margin - s[3 * lp.n3:], 0))
    r_t = r_t + need
    return {"v": v, "r_t": r_t, "z": z}


def _shared_heads(J, n3: int):
    """For the lifting's J (kept rows × z, one 1 per column): the row each component of z
    reads, and the (friction head, rolling head) pairs of z that share a row (a full contact's
    normal row).  ValueError on any other structure, which :meth:`DDSpace.lift` does not solve."""
    J = sp.csr_matrix(J)
    Jc = J.tocsc()
    per_row = np.diff(J.indptr)
    if (np.diff(Jc.indptr) != 1).any() or (J.data != 1).any() or (per_row > 2).any():
        raise ValueError("the lifting's J is not a selection with at most two cone components per row")
    shared = np.flatnonzero(per_row == 2)
    first, second = J.indices[J.indptr[shared]], J.indices[J.indptr[shared] + 1]
    heads = (first, second)
    if shared.size and ((np.concatenate(heads) % 3 != 0).any() or (np.concatenate(heads) >= 3 * n3).any()):
        raise ValueError("a row of the lifting's J is shared by components that are not heads of 3-cones")
    return Jc.indices.astype(np.int64), heads


class _DDOperator:
    """A :class:`.data.DDMatrix` applied to double-double vectors by ``@``."""

    __slots__ = ("A",)

    def __init__(self, A):
        self.A = A

    def __matmul__(self, x: V) -> V:
        return V(*self.A.matvec(x.h, x.l))


class DDSpace:
    """The lifted problem in double-double (:class:`~rfverify.algorithm.interfaces.Space`)."""

    tiny = 1e-300

    def __init__(self, data: ExtendedData):
        # M of the posed equations (stored, for an as_stored problem): residuals and refinement.
        self.M, self.H, self.HT = _DDOperator(data.M_eq), _DDOperator(data.Ht), _DDOperator(data.HtT)
        self.J, self.JT = _DDOperator(data.J), _DDOperator(data.JT)
        self.W = _DDOperator(data.Wt) if data.local else None  # ũ = W̃r̃ + q̃ of the file's W (no dofs)
        self.f, self.w = V(*data.f), V(*data.w_t)
        self._row_of_z, self._heads = _shared_heads(data.lp.J, data.n3)
        f, r = self._heads
        self._split = np.zeros(data.nz)  # J g = 0: moves a shared row's e_N from one head to the other
        self._split[f], self._split[r] = -1.0, 1.0
        self._pair_cones = np.concatenate((f[:, None] + np.arange(3), r[:, None] + np.arange(3)), axis=1)

    def lift(self, e: V, scaling: "DDScaling") -> V:
        """δ with Jδ = e, the one of least ‖Q_p δ‖ (Q_p of ``scaling``): Q_{p⁻²}JᵀG⁻¹e, computed
        without G.  A component of z that alone reads its row of J takes that row's e; a full
        contact's normal row is read by the heads of both its cones, and its split, e_N − s to one
        head and s to the other, takes the s that minimises ‖Q_p δ‖ over the two cones (a quadratic
        in s, minimised from float64 inner products: an error ε in s adds only O(ε²) to ‖Q_p δ‖,
        tests/test_lift.py).  Jδ = e holds to double-double rounding however
        ill-conditioned G is; through G⁻¹ = F⁻ᵀF⁻¹ it held only to about 1e-32·cond(G), and with
        cond(G) ≳ 1e30 near the end δ came out worse than e (docs/DECISIONS.md, "An exact lift")."""
        h, lo = e.h[self._row_of_z], e.l[self._row_of_z]
        f, r = self._heads
        h[r], lo[r] = 0.0, 0.0  # the whole normal row to the first head, then the split
        delta = V(h, lo)
        if not f.size:
            return delta
        cones = self._pair_cones
        Qg = scaling.quad(1, V(self._split)).h[cones]
        gg = np.einsum("ij,ij->i", Qg, Qg)
        Qd = scaling.quad(1, delta).h[cones]
        with np.errstate(invalid="ignore", divide="ignore"):
            split = -np.einsum("ij,ij->i", Qg, Qd) / gg
        split[~np.isfinite(split)] = 0.0
        step = np.zeros(h.size)
        step[f], step[r] = -split, split
        delta = delta + V(step)
        return delta

    def velocity(self, v, r):
        return self.W @ r if self.W is not None else self.H @ v

    @staticmethod
    def dot(x, y):
        return x.dot(y)

    @staticmethod
    def norm2(x):
        return x.norm()

    @staticmethod
    def axpy(x, a, y):
        return x.axpy(a, y)

    move = axpy


class DDScaling:
    """The NT scaling of one double-double iterate (:mod:`.cones`)."""

    def __init__(self, n3: int, nz: int, n_cones: int, e: V, z: V, s: V):
        self.n3, self.e, self.z, self.s = n3, e, z, s
        self.limit = None  # set by max_step
        self.ph, self.pl, self.pih, self.pil, lh, ll = (np.zeros(nz) for _ in range(6))
        self.spec = np.zeros((n_cones, 8))
        self._tables = {}  # k → eigenvalues of Q_{p^k} (cones.spectral_table)
        try:
            bad = C.nt_scaling_threaded(n3, z.h, z.l, s.h, s.l, self.ph, self.pl, self.pih, self.pil, lh, ll, self.spec)
        except ZeroDivisionError:  # a cone's determinant is exactly 0: the iterate reached the boundary
            bad = max(0, min(C.min_lambda2(n3, z.h, z.l), C.min_lambda2(n3, s.h, s.l))[1])
        if bad >= 0:
            raise Breakdown(f"cone {bad} is not strictly interior")
        self.lam = V(lh, ll)

    def describe(self) -> dict:
        return {}

    def _cone(self, fn, x, y):
        out = V.zeros(x.h.size)
        fn(self.n3, x.h, x.l, y.h, y.l, out.h, out.l)
        return out

    def quad(self, k: int, y: V) -> V:
        table = self._tables.get(k)
        if table is None:
            table = self._tables[k] = np.zeros((self.spec.shape[0], 6))
            C.spectral_table(self.n3, k, self.spec, table)
        out = V.zeros(y.h.size)
        C.quad_spectral_threaded(self.n3, table, self.spec, y.h, y.l, out.h, out.l)
        return out

    def affine_rhs(self):
        return -self.lam

    def corrector_rhs(self, target, dz_aff, ds_aff):
        xi = (self.e.scaled(target) - self._cone(C.product, self.lam, self.lam)
              - self._cone(C.product, self.quad(1, dz_aff), self.quad(-1, ds_aff)))
        return self._cone(C.arrow_solve, self.lam, xi)

    def max_step(self, dz, ds) -> float:
        """The largest α keeping z + α dz and s + α ds in their cones; :attr:`limit` is then
        (cone, "z" or "s") of the cone that sets it, the z side on a tie (None when unbounded)."""
        step_z, cone_z = C.max_step_at_threaded(self.n3, self.z.h, self.z.l, dz.h, dz.l)
        step_s, cone_s = C.max_step_at_threaded(self.n3, self.s.h, self.s.l, ds.h, ds.l)
        step = min(step_z, step_s)
        self.limit = None if step == math.inf else ((cone_z, "z") if step_z <= step_s else (cone_s, "s"))
        return step


class DDCones:
    def __init__(self, data: ExtendedData):
        self.n3, self.nz, self.n_cones = data.n3, data.nz, data.n3 + data.n1
        self.e = V(C.identity(data.n3, data.nz))

    def scaling(self, z, s):
        return DDScaling(self.n3, self.nz, self.n_cones, self.e, z, s)


class DDBackend(ReducedBackend):
    """A back end of :mod:`.system` (a :class:`.factored.NewtonBackend`) seen through
    double-double vectors."""

    projects_primal = True

    def __init__(self, backend: NewtonBackend):
        self.backend = backend
        self.name = backend.name

    def observe(self, k: int, mu: float, solve_residual: float | None) -> None:
        self.backend.observe(k, mu, solve_residual)

    def retry_solve(self, residual: float) -> bool:
        return self.backend.retry_solve(residual)

    def set_accuracy(self, residual_norm: float | None) -> None:
        self.backend.set_accuracy(residual_norm)

    def update(self, sc: DDScaling) -> bool:
        return self.backend.update(sc.ph, sc.pl, sc.pih, sc.pil, sc.spec)

    def solve(self, a: V, t: V):
        dv, dr = self.backend.solve((a.h, a.l), (t.h, t.l))
        return V(*dv), V(*dr)


def run(data: ExtendedData, start: dict, *, until=None, max_iter: int = 60, backend=None,
        refine_max: int = 12, gamma_max: float = 0.99, progress=None,
        enough: float | None = NEWTON_ENOUGH, predictor_enough: float | None = PREDICTOR_ENOUGH,
        offer_predicted: bool = False) -> ExtendedResult:
    """Algorithm 1 (:func:`rfverify.algorithm.loop.iterate`) in double-double from ``start`` =
    {"v", "r_t", "z"} (any float dtype; converted exactly).  ``until(iterate)`` is called at
    every iterate (before the step); returning True stops the run with status "Stopped".  With
    ``offer_predicted`` it is also called, before each corrector, with the point along the
    predictor's direction (``Iterate.predicted``; :meth:`.algorithm.policy.UntilPolicy.after_predictor`),
    and accepting it stops the run there, with that point as the last iterate.
    ``gamma_max`` caps the step-to-boundary fraction γ = 0.9 + 0.09α (the paper's rule) from
    above.  ``refine_max`` bounds the refinement steps of each Newton solve against the
    unreduced system (each stops earlier when it no longer halves the residual, or once each
    block's residual is ``enough`` — ``predictor_enough`` for the predictor — times its right-hand
    side; ``enough=None`` refines every solve to the floor, 1e-31): one to four steps with the
    default back end's unchecked float64 solves on the problems measured, up to twelve where M is
    solved as stored (the reduction uses (M + Mᵀ)/2, refinement the stored M)."""
    t0 = time.perf_counter()
    backend = backend or choose_backend(data)
    space = DDSpace(data)
    newton = ReducedNewton(space, DDBackend(backend), refine_max=refine_max, floor=1e-31, inf=V.inf,
                           enough=enough, predictor_enough=predictor_enough)
    policy = UntilPolicy(until, progress, max_iter,
                         lambda k, it, res: Iterate(k, *it, res.mu, res.pinfeas, res.dinfeas),
                         gamma_max, "accepted",
                         make_predicted=(lambda k, it, mu: Iterate(k, *it, mu, math.nan, math.nan, predicted=True))
                         if offer_predicted else None)
    begin = tuple(V(*dd.from_longdouble(start[key])) for key in ("v", "r_t", "z"))
    out = iterate(Precision(space, DDCones(data), newton), policy, begin, n_contacts=data.n,
                  n_cones=data.n3 + data.n1, clock_origin=t0)
    status, message = out.verdict
    cost = backend.describe_cost()
    return ExtendedResult(*out.iterate, status, message, out.k, extended_trace(out.records), backend.name,
                          time.perf_counter() - t0, out.timings["factor"], _stats(backend), cost)


def _stats(backend) -> dict:
    """The back end's factorisation statistics (benchmarks); {} where it has none."""
    return backend.stats()
