"""The a-posteriori error bound of DESIGN §6, evaluated rigorously.

Theorem (convex relaxation; M_s := (M + Mᵀ)/2 ≻ 0; the posed M is M_s, or M as stored for an
``as_stored`` problem — DESIGN §6.1).  For any v with u(v) = Hᵀv + w ∈ K* and any r ∈ K, with
g = Mv − Hr − f and d = v − v*, subtracting the equations of a solution gives
M d − H(r − r*) = g, so (xᵀM x = xᵀM_s x for any M)

    ‖d‖²_{M_s} = dᵀg + (u − u*)ᵀ(r − r*) ≤ ‖g‖_{M_s⁻¹} ‖d‖_{M_s} + rᵀu(v)

(u*ᵀr* = 0; uᵀr*, u*ᵀr ≥ 0 as pairs of K* and K), hence

    ‖v − v*‖_{M_s} ≤ ε := (√(gᵀM_s⁻¹g) + √(gᵀM_s⁻¹g + 4 rᵀu(v))) / 2.

(For a symmetric M this is never weaker than √(gᵀM⁻¹g + 2rᵀu) of strong duality, and it
needs no objective, so the stored, unsymmetric equations are covered by the same lines.)
Consequences, per component (Cauchy–Schwarz in the M_s inner product):

* |v_j − v*_j| ≤ √((M_s⁻¹)_jj) ε;
* u − u* = Hᵀ(v − v*):  |u_k − u*_k| ≤ √(h_kᵀM_s⁻¹h_k) ε  (h_k = column k of H);
* Hr* = Mv* − f:  Hr − Hr* = −g + M(v − v*), so |(Hr − Hr*)_i| ≤ |g_i| + √(m_iᵀM_s⁻¹m_i) ε
  (m_i = row i of the posed M; √(M_ii) when it is symmetric);
* r* is unique on the contacts that can carry load when H restricted to their (kept) columns
  has full column rank: if u* is proven to lie in the interior of K*_i, then r*_i = 0 for
  every solution; on the others (set S), ‖r_S − r*_S‖₂ ≤ ‖H_S r_S − Hr*‖₂ / σmin(H_S).

Free blocks (:mod:`.freeblocks`).  Let F be the diagonal blocks of the posed M that no contact
touches (H's rows zero there) and that no nonzero of the stored M links to another block —
both verified exactly on the data — and whose inverse is verified (ρ_b ≥ ‖I − X_b M_b‖∞ < 1
for a float approximate inverse X_b); C the other dofs.  Every solution has M_b v*_b = f_b on
F, so d_b = M_b⁻¹ g_b exactly: |d_b| ≤ |X_b g_b| + (row sums of |I − X_b M_b|)·‖X_b g_b‖∞/(1 − ρ_b),
every rounding bounded outward.  On C, M_C d_C − H_C(r − r*) = g_C and Hᵀd = H_Cᵀd_C, so the
lines above hold with g_C alone: ‖d_C‖_{M_s} ≤ ε_C (ε with g_C), and

* |v_j − v*_j| ≤ √((M_s⁻¹)_jj)·ε_C on C, and on F the smaller of the verified solve and
  √((M_s⁻¹)_jj)·ε;
* |u_k − u*_k| ≤ √(h_kᵀM_s⁻¹h_k)·ε_C (h_k vanishes on F);
* |(Hr − Hr*)_i| ≤ |g_i| + √(m_iᵀM_s⁻¹m_i)·ε_C, and 0 on the rows of H that are zero;
* the r bound with ‖g_C‖₂ and ε_C (H r_p − Hr* = −g + M d vanishes on F).

(F empty gives the lines above: ε_C = ε.)  Where the stored M is unsymmetric only in blocks
no contact touches — the Siconos Chute — this bounds the distance to the stored equations'
solution through the stored blocks' own inverses instead of one ε shared by every dof.

A *point* (v_p, r_p) — an extended-precision interior-point iterate — is evaluated **exactly**
(dyadic rationals, :mod:`.dyadic`): cone membership by comparing squares, g, rᵀu; the
norms of M_s⁻¹ come from :mod:`.massbounds` (verified floating point).  The triangle inequality
then carries the bound to the returned double solution (v, u, r):
|v_j − v*_j| ≤ |v_j − v_p,j| + √((M_s⁻¹)_jj) ε, and likewise for u, Hr and r.  Every float
that enters a bound is rounded upwards (``np.nextafter`` after each operation, or the
a-priori factors of :mod:`.massbounds`).

Digits.  For each quantity x the certificate states the proven absolute bound
‖x − x*‖∞ ≤ e, a rigorous lower bound s of ‖x*‖∞ (‖x‖∞ − e), and digits = −log10(e / s), a
lower bound on the correct significant digits relative to ‖x*‖∞ (e = 0: x is x* exactly).
When s ≤ e (x* = 0: all contacts sticking give u* = 0 and often v* = 0; all contacts open
give r* = 0) no relative digits exist; the absolute bound is reported against a stated *data
scale* (‖M⁻¹f‖∞ for v, ‖Hᵀ M⁻¹f + w‖∞ for u, ‖f‖∞ for Hr, ‖f‖∞ / max_k ‖h_k‖₂ for r: each a
proven lower bound, never a float sum), and x is certified to k digits in that sense when
‖x‖∞ + e ≤ 10⁻ᵏ·scale (x* is zero at the requested accuracy) and e ≤ 10⁻ᵏ·scale.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..model.problem import SPACEDIM, Problem
from .dyadic import Dyadic, DyadicCSR, Quotient, divide_upper, fraction_upper_float
from .quantity import (DATA_SCALE_NAMES, QuantityBound, down, quantity_bound, up, up_times, validate_digits)
from .reactions import r_bound
from .massbounds import MassBounds, inflate, upper_sum, verify_mass_matrix

THEOREM_GLOBAL = ("Global problem, M_s = (M+M^T)/2 positive definite, M the posed matrix (M_s, or M as stored): for "
                  "any v with u(v) = H^T v + w in K* and any r in K, with g = Mv - Hr - f: ||v - v*||_Ms^2 <= "
                  "g^T(v - v*) + r^T u(v), so ||v - v*||_Ms <= (sqrt(g^T Ms^-1 g) + sqrt(g^T Ms^-1 g + 4 r^T u(v)))/2 "
                  "(monotonicity of the convex relaxation); per-component bounds by Cauchy-Schwarz in the M_s inner "
                  "product, with g restricted to the blocks of M that touch a contact; on the blocks no contact "
                  "touches (decoupled, verified), v - v* = M_b^-1 g_b bounded by a verified inverse; carried to the "
                  "stored solution by the triangle inequality (DESIGN 6.1).")


@dataclass
class Proof:
    """Outcome of :func:`prove` (or :func:`rfverify.proof.local.prove_local`).  ``valid`` is False
    when a hypothesis of the theorem could not be verified (point outside a cone, M not proven
    positive definite, W not proven semidefinite); then ``failure`` says which and no quantity
    is certified.  ``eps_M`` ≥ ‖v_p − v*‖_M (for a local problem: ≥ ‖r_p − r*‖_W); ``terms``
    keeps every intermediate norm (for the certificate file); ``theorem`` states which
    theorem, on which problem, was evaluated."""

    valid: bool
    requested: int
    eps_M: float
    quantities: dict
    terms: dict
    failure: str = ""
    seconds: float = 0.0
    arithmetic: str = ("exact dyadic rationals (Python integers) for the point's residuals; "
                       "verified float64 with a-priori rounding-error bounds for M and H norms")
    theorem: str = THEOREM_GLOBAL
    statement: str = ""
    """The problem this proof is about, in words (:meth:`rfverify.Problem.statement`)."""
    equations: str = "symmetrised"
    """"symmetrised" ((M + Mᵀ)/2) or "stored" (M as stored): the matrix of the posed equations."""
    face: object = None
    """A :class:`.face.FaceRepair` when the point was moved exactly onto the face that a verified
    self-stress forces (DESIGN §6.8), else None."""
    stored_equations: "Proof | None" = None
    """For a proof of the symmetrised equations of a problem whose stored M is unsymmetric: the
    same point and solution proven against the stored equations (how many digits of *their*
    solution the answer has), else None."""

    @property
    def certified(self) -> bool:
        return self.valid and all(q.certified for q in self.quantities.values() if q.mode != "information")

    @property
    def local(self) -> bool:
        """True when this is the local theorem (quantities u and r of the file's local problem)."""
        return self.theorem != THEOREM_GLOBAL

    def weakest(self) -> str | None:
        """The uncertified quantity with the fewest proven digits (None: all certified)."""
        bad = [q for q in self.quantities.values() if q.mode != "information" and not q.certified]
        if not bad:
            return None
        return min(bad, key=lambda q: -math.inf if q.digits is None else q.digits).name

    def fewest_digits(self) -> float | None:
        """The smallest relative digits over the quantities judged in relative digits (one proven
        zero within a bound, in absolute terms, has none by design and is not counted; None: one
        judged relatively has none, none is, or the proof is invalid)."""
        if not self.valid:
            return None
        vals = [q.digits for q in self.quantities.values() if q.mode == "relative"]
        return None if any(d is None for d in vals) or not vals else min(vals)

    def summary(self) -> str:
        if not self.valid:
            return f"no proof: {self.failure}"
        return ", ".join(q.short() for q in self.quantities.values())


class ExactData:
    """The problem data as exact dyadic matrices/vectors, built once per problem."""

    def __init__(self, problem: Problem):
        self.problem = problem
        self.H = DyadicCSR.from_scipy(problem.H)
        self.HT = self.H.transpose()
        self.M = DyadicCSR.from_scipy(problem.M)
        self.MT = self.M.transpose()
        Hc = sp.csr_matrix(problem.H)
        self.H_row_zero = _rows_without_nonzeros(Hc)  # (Hr)_i = 0 for every r there
        self.f = Dyadic.from_float(problem.f)
        self.w = Dyadic.from_float(problem.w)
        self.mu = Dyadic.from_float(problem.mu)
        self.mu_r = Dyadic.from_float(problem.mu_r)
        self._row_quad = None
        self._skew_norm = None
        self._free = {}
        from .face import FaceSearch

        self.face_search = FaceSearch()  # self-stresses found near failing contacts, per problem

    def M_sym_apply(self, v: Dyadic) -> Dyadic:
        """(M + Mᵀ)/2 · v exactly."""
        return (self.M.matvec(v) + self.MT.matvec(v)).scale2(-1)

    def M_apply(self, v: Dyadic, stored: bool) -> Dyadic:
        """M v of the posed equations exactly: M as stored (``stored``) or (M + Mᵀ)/2."""
        return self.M.matvec(v) if stored else self.M_sym_apply(v)

    def free_blocks(self, mass: MassBounds, stored: bool):
        """The blocks no contact touches, with their verified inverses, of the posed M (as
        stored, or (M + Mᵀ)/2): :func:`.freeblocks.free_blocks`, built once per posing."""
        if stored not in self._free:
            from .freeblocks import free_blocks

            self._free[stored] = free_blocks(self.problem, mass, stored)
        return self._free[stored]

    def row_quad_upper(self, mass: MassBounds) -> np.ndarray:
        """Upper bounds of m_iᵀ M_s⁻¹ m_i for the rows m_i of the stored M (the Hr bound of the
        stored equations: |e_iᵀM d| ≤ ‖M_s^-½ Mᵀe_i‖₂ ‖d‖_{M_s})."""
        if self._row_quad is None:
            self._row_quad = mass.quad_upper_columns(sp.csc_matrix(self.problem.M).T)
        return self._row_quad

    def skew_norm_upper(self) -> float:
        """Upper bound of ‖(M − Mᵀ)/2‖₂ ≤ √(‖·‖₁‖·‖∞) (rows and columns of |M − Mᵀ|/2, each
        difference rounded up)."""
        if self._skew_norm is None:
            M = sp.csr_matrix(self.problem.M)
            D = (M - M.T).tocsr()
            D.data = up(np.abs(D.data) * 0.5 * (1 + 2.0 ** -52))
            k = int(np.max(np.diff(D.indptr), initial=1)) + 2
            rows = inflate(np.asarray(D.sum(axis=1)).ravel(), k)
            cols = inflate(np.asarray(D.sum(axis=0)).ravel(), k)
            self._skew_norm = float(up(math.sqrt(float(up(float(np.max(rows, initial=0.0))
                                                            * float(np.max(cols, initial=0.0)))))))
        return self._skew_norm


def _rows_without_nonzeros(A: sp.csr_matrix) -> np.ndarray:
    """Mask of the rows of A with no nonzero entry (explicitly stored zeros do not count)."""
    nonzero = np.zeros(A.shape[0], dtype=bool)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    nonzero[rows[A.data != 0]] = True
    return ~nonzero


def cone_violations(data: ExactData, u: Dyadic, r: Dyadic):
    """Exact membership tests: indices of contacts with u_i ∉ K*_i and with r_i ∉ K_i."""
    n = data.problem.n_contacts
    idx = np.arange(n) * SPACEDIM
    uN, uT1, uT2, uR1, uR2 = (u[idx + k] for k in range(SPACEDIM))
    rN, rT1, rT2, rR1, rR2 = (r[idx + k] for k in range(SPACEDIM))
    mu2, mur2 = data.mu.square(), data.mu_r.square()
    # K: r_N ≥ 0, ‖r_T‖² ≤ μ² r_N², ‖r_R‖² ≤ μr² r_N² (μ = 0 forces r_T = 0 exactly).
    rN2 = rN.square()
    k_bad = (rN.sign() < 0) | ((mu2 * rN2 - (rT1.square() + rT2.square())).sign() < 0) \
        | ((mur2 * rN2 - (rR1.square() + rR2.square())).sign() < 0)
    # K*: u_N ≥ μ‖u_T‖ + μr‖u_R‖  ⟺  u_N ≥ 0, c = u_N² − a − b ≥ 0 and c² ≥ 4ab,
    # with a = μ²‖u_T‖², b = μr²‖u_R‖² (squares only, exact).
    a = mu2 * (uT1.square() + uT2.square())
    b = mur2 * (uR1.square() + uR2.square())
    c = uN.square() - a - b
    ks_bad = (uN.sign() < 0) | (c.sign() < 0) | ((c.square() - (a * b).scale2(2)).sign() < 0)
    return np.flatnonzero(ks_bad), np.flatnonzero(k_bad)


def data_scales(problem: Problem, exact: ExactData | None = None, mass: MassBounds | None = None,
                w_diag: np.ndarray | None = None) -> dict:
    """Data scales that are proven **lower bounds** (they decide absolute-mode acceptances,
    DESIGN §6.3): ‖M⁻¹f‖∞ and ‖HᵀM⁻¹f + w‖∞ of the posed M, ‖f‖∞ (exact) and ‖f‖∞ / max_k ‖h_k‖₂.

    x̃ ≈ M⁻¹f is a float solve; its residual ρ = f − M x̃ is exact (dyadic), and M(x − x̃) = ρ
    gives ‖x − x̃‖_{M_s} ≤ √(ρᵀM_s⁻¹ρ) (the monotonicity step of the theorem), so
    |x_j − x̃_j| ≤ √((M_s⁻¹)_jj)·√(ρᵀM_s⁻¹ρ) and |u_k − ũ_k| ≤ √(h_kᵀM_s⁻¹h_k)·√(ρᵀM_s⁻¹ρ) with ũ
    = Hᵀx̃ + w exact: the scales are max(|x̃_j| − bound) (0 where that is negative), rounded
    down.  Without proven bounds on M the v and u scales are 0 (nothing is accepted by them)."""
    from scipy.sparse.linalg import splu

    f_inf = float(np.max(np.abs(problem.f), initial=0.0))
    Hc = sp.csc_matrix(problem.H)
    sq = Hc.multiply(Hc)
    k = int(np.max(np.diff(Hc.indptr), initial=1)) + 2
    col_sq = inflate(np.asarray(sq.sum(axis=0)).ravel(), k)
    col_max = float(up(math.sqrt(float(np.max(col_sq, initial=0.0)))))
    r_scale = float(down(f_inf / col_max)) if col_max > 0 and math.isfinite(col_max) else 0.0
    out = {"v": 0.0, "u": 0.0, "Hr": f_inf, "r": max(r_scale, 0.0)}
    if exact is None or mass is None or not mass.proven:
        return out
    try:
        with np.errstate(all="ignore"):
            x = splu(sp.csc_matrix(problem.M_eq)).solve(np.asarray(problem.f, dtype=np.float64))
    except RuntimeError:
        x = np.zeros(problem.n_dofs)
    if not np.all(np.isfinite(x)):
        x = np.zeros(problem.n_dofs)
    xd = Dyadic.from_float(x)
    rho = exact.f - exact.M_apply(xd, problem.as_stored)
    root = float(up(math.sqrt(gMinvg_upper(rho, mass))))
    e_x = up(up(np.sqrt(mass.minv_diag_upper)) * root)
    x_lo = down(np.abs(x) - e_x)
    out["v"] = max(float(np.max(x_lo, initial=0.0)), 0.0)
    if w_diag is None:
        w_diag = mass.quad_upper_columns(problem.H)
    ut = exact.HT.matvec(xd) + exact.w
    mag_lo = np.where(ut.sign() >= 0, ut.lower(), -ut.upper())  # |ũ| rounded down
    u_lo = down(mag_lo - up(up(np.sqrt(w_diag)) * root))
    out["u"] = max(float(np.max(u_lo, initial=0.0)), 0.0)
    return out


def prove(problem: Problem, point_v: Dyadic, point_r: Dyadic, v, u, r, *, requested: int = 10,
          mass: MassBounds | None = None, exact: ExactData | None = None,
          scales: dict | None = None, w_diag: np.ndarray | None = None, relative: bool = False) -> Proof:
    """Evaluate the bound for the point (point_v, point_r) and carry it to the returned float64
    solution (v (m,), u (5n,), r (5n,)), for the equations ``problem`` poses
    (``problem.equations``: (M + Mᵀ)/2, or M as stored).  Reusable pieces (``mass``, ``exact``,
    ``scales``, ``w_diag``) can be passed in when proving several points of one problem.
    ``relative``: accept only relative digits (no "zero at the data scale" mode)."""
    t0 = time.perf_counter()
    requested = validate_digits(requested)
    m, n = problem.n_dofs, problem.n_contacts
    v, u, r = _solution_arrays(problem, v, u, r)
    stored = problem.as_stored
    named = {"statement": problem.statement, "equations": "stored" if stored else "symmetrised"}
    if not (np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        return invalid_proof(requested, "the solution contains NaN or Inf", t0, **named)
    exact = exact or ExactData(problem)
    mass = mass or verify_mass_matrix(problem.M, problem.M_sym, problem.blocks)
    if not mass.proven:
        fb = mass.failures[0]
        return invalid_proof(requested, f"M_s = (M + Mᵀ)/2 is not proven positive definite: block {fb.block} "
                                   f"(dofs {fb.dofs[:6].tolist()}{'…' if fb.dofs.size > 6 else ''}): {fb.reason}",
                        t0, **named)
    if w_diag is None:
        w_diag = mass.quad_upper_columns(problem.H)
    scales = scales or data_scales(problem, exact, mass, w_diag)
    if len(point_v) != m or len(point_r) != SPACEDIM * n:
        raise ValueError("the point does not match the problem's sizes")

    # ---- exact residuals of the point
    u_p = exact.HT.matvec(point_v) + exact.w
    outside = cones_failure(exact, u_p, point_r, "u(v) = Hᵀv + w")
    face = None
    if outside:
        face, why = _onto_face(problem, exact, point_v, point_r, u_p)
        if face is None:
            return invalid_proof(requested, outside + why, t0, **named)
        point_v = face.point_v
    # A point moved onto a face is rational, v' = V / den (den = 1 otherwise): cone membership is
    # decided on the numerators (K and K* are cones), and every bound is divided by den upwards.
    V, den = (point_v.num, point_v.den) if isinstance(point_v, Quotient) else (point_v, 1)
    u_num = u_p if face is None else exact.HT.matvec(V) + exact.w.times_int(den)
    if face is not None and (why := _outside_after_face(exact, face, u_num, point_r)):
        return invalid_proof(requested, why, t0, **named)
    Hr_p = exact.H.matvec(point_r)
    g_num = exact.M_apply(V, stored) - (Hr_p + exact.f).times_int(den)
    gap = point_r.dot(u_num) / den  # ≥ 0: a sum of products of cone-dual pairs
    q_g = float(divide_upper(divide_upper(gMinvg_upper(g_num, mass), den), den))
    gap_up = fraction_upper_float(gap)
    eps = eps_M_upper(q_g, gap_up)
    # The free blocks (no contact, decoupled): d_F = M_F⁻¹ g_F, bounded through their verified
    # inverses; the rest (C) has its own ε_C from g_C alone (.freeblocks).
    free = exact.free_blocks(mass, stored)
    if free.dofs.size:
        g_C = Dyadic(np.where(free.coupled, g_num.ints, 0), g_num.exp)
        q_gC = float(divide_upper(divide_upper(gMinvg_upper(g_C, mass), den), den))
        eps_C = min(eps, eps_M_upper(q_gC, gap_up))
        d_free = divide_upper(free.bound(g_num), den)
    else:
        g_C, q_gC, eps_C, d_free = g_num, q_g, eps, None

    # ---- carry to the returned solution
    vd = Dyadic.from_float(v)
    sqrt_minv = up(np.sqrt(mass.minv_diag_upper))
    own_v = up_times(sqrt_minv, eps_C)
    if d_free is not None:  # free dofs: the verified solve, or Cauchy–Schwarz with the whole ε
        own_v = np.where(free.coupled, own_v, np.minimum(d_free, up_times(sqrt_minv, eps)))
    e_v = upper_sum(divide_upper((vd.times_int(den) - V).abs_upper(), den), own_v)
    sqrtW = up(np.sqrt(w_diag))
    e_u = upper_sum(divide_upper((Dyadic.from_float(u).times_int(den) - u_num).abs_upper(), den),
                    up_times(sqrtW, eps_C))
    Hr_ret = exact.H.matvec(Dyadic.from_float(r))
    g_abs = divide_upper(g_num.abs_upper(), den)
    # |e_iᵀM d| ≤ √(m_iᵀM_s⁻¹m_i)·ε_C; for a symmetric M that is √(M_ii)·ε_C.  A row of H that is
    # zero has (Hr)_i = (Hr*)_i = 0 exactly: no bound there.
    row_norm = up(np.sqrt(exact.row_quad_upper(mass))) if stored else up(np.sqrt(mass.m_diag_upper))
    e_Hr = upper_sum((Hr_ret - Hr_p).abs_upper(), g_abs, up_times(row_norm, eps_C))
    e_Hr = np.where(exact.H_row_zero, 0.0, e_Hr)

    terms = {"eps_M": eps, "eps_M_coupled": eps_C, "gMinvg_coupled_upper": q_gC,
             "free_blocks_solved": free.count, "free_dofs_solved": int(free.dofs.size),
             "v_point_part": float(np.max(own_v, initial=0.0)), "u_point_part": float(np.max(up_times(sqrtW, eps_C), initial=0.0)),
             "gap_rTu": gap_up, "gMinvg_upper": q_g, "g_inf": float(np.max(g_abs, initial=0.0)),
             "lam_min_M_lower": float(np.nanmin(mass.lam_lower)), "lam_max_M_upper": mass.lam_max_upper,
             "max_sqrt_Minv_jj": float(np.max(np.sqrt(mass.minv_diag_upper), initial=0.0)),
             "max_sqrt_W_kk": float(np.max(sqrtW, initial=0.0)),
             "M_blocks_dense": mass.dense_blocks, "M_blocks_sparse": mass.sparse_blocks}
    if stored:
        terms["skew_norm2_upper"] = exact.skew_norm_upper()
    q = {}
    q["v"] = quantity_bound("v", e_v, v, scales, requested, relative=relative)
    q["u"] = quantity_bound("u", e_u, u, scales, requested, relative=relative)
    Hr_float = Hr_ret.nearest()
    q["Hr"] = quantity_bound("Hr", e_Hr, Hr_float, scales, requested, relative=relative)

    if face is not None:
        terms["face_moved_v_inf"] = face.moved
    # ---- r, where it is unique
    if face is not None:
        e_r, r_note, r_terms = None, (f"r is not unique: the self-stress on contacts "
                                      f"{', '.join(s.contact_list() for s in face.stresses)} can be added to any "
                                      "solution's r (Hr is unique)"), {}
    else:
        e_r, r_note, r_terms = r_bound(problem, exact, mass, Quotient(u_num, den), sqrtW * eps_C, point_r, Hr_p,
                                        g_C, eps_C, r, stored, den=den)
    terms.update(r_terms)
    if e_r is None:
        q["r"] = QuantityBound("r", math.nan, float(np.max(np.abs(r), initial=0.0)), 0.0, scales["r"],
                               DATA_SCALE_NAMES["r"], None, "information", False, r_note)
    else:
        q["r"] = quantity_bound("r", e_r, r, scales, requested, note=r_note, relative=relative)
    return Proof(True, requested, eps, q, terms, seconds=time.perf_counter() - t0, face=face, **named)


def _solution_arrays(problem: Problem, v, u, r) -> tuple:
    """(v, u, r) as flat float64 arrays of the problem's sizes, or the error naming the one that is not."""
    v, u, r = (np.asarray(x, dtype=np.float64).ravel() for x in (v, u, r))
    m, n = problem.n_dofs, problem.n_contacts
    for name, arr, size in (("v", v, m), ("u", u, SPACEDIM * n), ("r", r, SPACEDIM * n)):
        if arr.size != size:
            from ..errors import InvalidProblemError

            raise InvalidProblemError(f"solution.{name}", f"has {arr.size} entries, the problem needs {size}",
                                      fix="certify a solution of this problem")
    return v, u, r


def _outside_after_face(exact, face, u_num: Dyadic, point_r: Dyadic) -> str:
    """Why a point moved onto a face is still outside the cones ("" when it is inside): the move
    left a neighbour outside its cone.  Where r was shifted along a self-stress, r + τy ∈ K is
    proven by the face step itself."""
    bad_dual, bad_primal = cone_violations(exact, u_num, point_r)
    shifted = np.concatenate([face.stresses[i].contacts for i in face.shifts] or [np.zeros(0, dtype=np.int64)])
    bad_primal = np.setdiff1d(bad_primal, shifted)
    if not (bad_dual.size or bad_primal.size):
        return ""
    what = [f"u(v') = Hᵀv' + w ∉ K* at {bad_dual.size} contact(s), first {int(bad_dual[0])}"] if bad_dual.size else []
    what += [f"r ∉ K at {bad_primal.size} contact(s), first {int(bad_primal[0])}"] if bad_primal.size else []
    return f"the point is not in the cones after it was moved onto a face ({'; '.join(what)}; {face.describe()})"


def _mass_span_hint(problem) -> str:
    """Words on M's diagonal where it spans more than 12 decades (bodies in very different units
    make an accurate point hard to reach: an audit's per-body unit changes of 3·10^±9), else ""."""
    d = np.abs(problem.M.diagonal())
    d = d[d > 0]
    if d.size == 0 or d.max() <= 1e12 * d.min():
        return ""
    return (f" (M's diagonal spans {d.max() / d.min():.0e}: bodies in very different units make the former "
            "likely)")


def _onto_face(problem, exact, point_v, point_r, u_p):
    """(FaceRepair, "") when verified self-stresses explain why the point is not in the cones
    and the point, moved onto their face (and r shifted along them where needed), may be; else
    (None, why not: words for the verdict).  The caller still tests the moved point exactly."""
    from .face import FaceRepair, find_self_stress, restore, shift_into_K

    bad_dual, bad_primal = cone_violations(exact, u_p, point_r)
    if not isinstance(point_v, Dyadic):
        return None, ""
    stresses = find_self_stress(problem, np.union1d(bad_dual, bad_primal), exact.face_search)
    if not stresses:
        return None, ("; no self-stress (y ∈ K, Hy = 0, wᵀy = 0) was found near those contacts: the point is not "
                      "accurate enough there, or the feasible set has an interior thinner than its accuracy"
                      + _mass_span_hint(problem))
    infeasible = [s for s in stresses if s.infeasible]
    if infeasible:
        return None, "; " + infeasible[0].describe()
    shifts = {}
    for i, s in enumerate(stresses):
        if np.intersect1d(bad_primal, s.contacts).size:
            tau = shift_into_K(problem, s, point_r)
            if tau is None:
                return None, f"; {s.describe()}, but r + τy ∉ K there for every τ ≥ 0 tried"
            shifts[i] = tau
    if bad_dual.size:
        repair = restore(problem, exact, point_v, stresses)
        if repair is None:
            return None, ("; " + "; ".join(s.describe() for s in stresses)
                          + ", but the point could not be moved onto that face exactly")
    else:
        repair = FaceRepair(list(stresses), Quotient(point_v, 1), 0.0)
    repair.shifts = shifts
    return repair, ""


def cones_failure(data, u_p: Dyadic, point_r: Dyadic, u_name: str) -> str:
    """"" when u_p ∈ K* and r ∈ K exactly, else the hypothesis that failed, with the contacts."""
    bad_dual, bad_primal = cone_violations(data, u_p, point_r)
    what = []
    if bad_dual.size:
        what.append(f"{u_name} ∉ K* at {bad_dual.size} contact(s), first {int(bad_dual[0])}")
    if bad_primal.size:
        what.append(f"r ∉ K at {bad_primal.size} contact(s), first {int(bad_primal[0])}")
    return "the point is not in the cones (" + "; ".join(what) + ")" if what else ""


def gMinvg_upper(g: Dyadic, mass: MassBounds) -> float:
    """Upper bound of gᵀM⁻¹g = (Sg)ᵀ(SMS)⁻¹(Sg) ≤ Σ_b ‖(Sg)_b‖² / λmin(S M_b S) (S the exact
    power-of-two equilibration of :mod:`.massbounds`; exact squares, rounded up)."""
    if not any(g.ints):  # g = 0 exactly (an exact point): the bound is 0, not a rounding of it
        return 0.0
    g_sq = (g * Dyadic.from_float(np.ldexp(1.0, mass.exponents))).square()
    order = np.argsort(mass.labels, kind="stable")
    nb = mass.lam_scaled.size
    counts = np.bincount(mass.labels, minlength=nb)
    starts = np.concatenate(([0], np.cumsum(counts)))[:-1]
    per_block = g_sq[order].segment_sums(starts, starts + counts).abs_upper()
    return float(up(math.fsum(up(per_block / mass.lam_scaled).tolist())))


def eps_M_upper(q_g: float, gap_up: float) -> float:
    """ε ≥ (√(gᵀM_s⁻¹g) + √(gᵀM_s⁻¹g + 4rᵀu))/2 ≥ ‖v − v*‖_{M_s}, from upper bounds of both terms."""
    if q_g == 0 and gap_up == 0:  # g = 0 and rᵀu = 0 exactly: the point is the solution
        return 0.0
    root_q = float(up(math.sqrt(q_g)))
    # (a negative gap is impossible for r ∈ K, u ∈ K*: only a broken cone test gets here)
    root_all = float(up(math.sqrt(max(float(up(q_g + float(up(4.0 * gap_up)))), 0.0))))
    return float(up(float(up(root_q + root_all)) * 0.5))


def invalid_proof(requested, why, t0, theorem: str = THEOREM_GLOBAL, **named) -> Proof:
    return Proof(False, requested, math.inf, {}, {}, failure=why, seconds=time.perf_counter() - t0, theorem=theorem,
                 **named)


