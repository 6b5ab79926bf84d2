"""The a-posteriori error bound for a *local* problem, on the file's own W and q (DESIGN §6.1b).

A local file (Siconos local ``.dat``, ``/fclib_local``) states ``u = W r + q``,
``K* ∋ u ⊥ r ∈ K``.  The solver lifts it to a global problem (M = I, HᵀH ≈ W), but that
lifting is a device: this module proves facts about the file's problem, with
W := (W + Wᵀ)/2 **exactly** and W positive semidefinite **as stored** (proven below).

Theorem.  For any r ∈ K with u(r) = W r + q ∈ K* (evaluated exactly) and any solution
(r*, u* = W r* + q),

    ‖r − r*‖²_W = (r − r*)ᵀ(u − u*) = rᵀu − rᵀu* − r*ᵀu + r*ᵀu* ≤ rᵀu,

because r*ᵀu* = 0 and rᵀu*, r*ᵀu ≥ 0 (pairs of K and K*).  So ε := √(rᵀu) ≥ ‖r − r*‖_W, and

* u* is unique and |u_k − u*_k| = |e_kᵀW(r − r*)| ≤ √(W_kk) ε (Cauchy–Schwarz in the W
  semi-inner product: no λmin needed, W may be singular);
* where u* is proven to lie in the interior of K*_i (the box u ± √(W_kk) ε inside), r*_i = 0
  for every solution (set O); on the other contacts S, with d = r − r*,
  ‖W^½ E_S d_S‖ ≤ ε + ‖W^½ E_O r_O‖, so per block b of W_SS (its connected components)
  |d_j| ≤ (ε + √(r_Oᵀ W_OO r_O))·√((W_b⁻¹)_jj) ≤ (ε + √(r_Oᵀ W_OO r_O)) / √λmin(W_b) where
  λmin(W_b) > 0 is verified (bounds of :mod:`.massbounds`, scale-invariant).  Where it
  is not, r is reported as information (not unique), never certified.

A point slightly outside K* (u = W r + q misses K*_i by rounding of the iterate) is still used
where W is proven definite with λmin ≥ λ > 0 on every component r may use: u' = u + τ e_N ∈ K*
(τ ≥ 0 per contact, the normal component raised just enough, verified exactly) and
e = u' − (W r + q) give dᵀWd ≤ rᵀu' − dᵀe, hence ‖d‖₂ ≤ δ := (‖e‖ + √(‖e‖² + 4λ rᵀu'))/(2λ)
and ‖d‖²_W ≤ ε² := rᵀu' + ‖e‖δ; then |u_k − u*_k| ≤ √(W_kk) ε for u = W r + q, and
|r_k − r*_k| ≤ δ.

A second, linear bound (:func:`_active_set_refinement`) where W is definite with λ > 0 on every
component r may use: on contacts proven open r*_i = 0, on contacts whose ball r_p,i ± ‖d‖₂ lies in
the relative interior of K_i u*_i = 0 on K_i's span, so dᵀWd = dᵀ(u_p − u*) is at most
‖d‖₂·‖u_p on the stuck contacts‖ plus the rest's rᵀu — with ‖d‖₂ ≤ ‖d‖_W/√λ a quadratic
inequality in ‖d‖_W, linear in the stuck contacts' u instead of √(rᵀu).  A pile at rest, whose
u* is far below its data scale, gets its relative digits of u this way.

Hypothesis check.  W ⪰ 0 is needed; it is proven by the verified floating-point bounds of
:mod:`.massbounds` (W definite on its nonzero rows) or, for blocks up to
:data:`EXACT_PSD_ROWS` rows where that fails (W singular: a rank-deficient Delassus matrix),
by an exact rational LDLᵀ with diagonal pivoting.  A W that is indefinite as stored (rounding
of a singular W usually makes it so) is refused: the problem in the file is then not convex,
and nothing about it is certified.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import scipy.sparse as sp

from ..model.definiteness import exact_ldlt
from ..model.problem import SPACEDIM, LocalForm, Problem
from ..model.directed import bound_text
from .bound import Proof, cone_violations, cones_failure, eps_M_upper, invalid_proof
from .quantity import DATA_SCALE_NAMES_LOCAL, QuantityBound, down, quantity_bound, up, up_times, validate_digits
from .reactions import proven_open
from .dyadic import Dyadic, DyadicCSR, fraction_upper_float, sqrt_upper
from .massbounds import MassBounds, inflate, upper_sum, verify_mass_matrix

EXACT_PSD_ROWS = 120
"""Largest block of W whose positive semidefiniteness is decided in exact rational arithmetic
when the verified floating-point test cannot prove it (measured: 0.002 s for the 10 × 10 W of
the bundled cube; the cost grows like rows³ with rationals of growing size)."""

THEOREM_LOCAL = ("Local problem u = Wr + q with W = (W+W^T)/2 positive semidefinite as stored: for any r in K "
                 "with u = Wr + q in K* (exact), ||r - r*||_W^2 <= r^T u; |u_k - u*_k| <= sqrt(W_kk) ||r - r*||_W; "
                 "r bounded through verified lambda_min of W on the contacts that may carry load (DESIGN 6.1b); where W "
                 "is definite, ||r - r*||_W^2 <= ||d_S|| ||u_S|| + r_O^T u_O + r_R^T u_R on stuck (S), open (O) and other "
                 "(R) contacts, a bound linear in u_S.")


PSD_SHIFT_FIX = ("; --psd-shift (Python rfverify.shift_to_psd) proves W + D instead, D ≥ 0 a small diagonal: a "
                 "backward error of D r on q")


@dataclass
class LocalFacts:
    """What is proven about W once per problem: ``psd`` (True: W ⪰ 0 proven), ``why`` (the
    reason when not), ``how`` (which test proved it), ``w_diag`` (W_kk, exact floats)."""

    psd: bool
    why: str
    how: str
    w_diag: np.ndarray
    lam_lower: float = 0.0
    """> 0: λmin((W + Wᵀ)/2) ≥ lam_lower on its nonzero rows (verified); 0 when not proven."""
    nonzero_rows: np.ndarray | None = None
    """Rows of W with a nonzero diagonal (the rows ``lam_lower`` is about)."""


class LocalExact:
    """The local data as exact dyadic matrices, and the verified facts about W."""

    def __init__(self, problem: Problem):
        local: LocalForm = problem.local
        self.problem = problem
        self.local = local
        self.W = DyadicCSR.from_scipy(local.W)
        self.WT = self.W.transpose()
        self.q = Dyadic.from_float(local.q)
        self.mu = Dyadic.from_float(problem.mu)
        self.mu_r = Dyadic.from_float(problem.mu_r)
        self.facts = prove_psd(local.W)

    def u_of(self, r: Dyadic, stored: bool = False) -> Dyadic:
        """u = (W + Wᵀ)/2 · r + q, or W r + q with W as stored (``stored``), exactly."""
        if stored:
            return self.W.matvec(r) + self.q
        return (self.W.matvec(r) + self.WT.matvec(r)).scale2(-1) + self.q

    def skew_row_norms_upper(self) -> np.ndarray:
        """Upper bounds of ‖row k of (W − Wᵀ)/2‖₂ (each difference rounded up)."""
        W = sp.csr_matrix(self.local.W)
        D = (W - W.T).tocsr()
        D.data = up(np.abs(D.data) * 0.5 * (1 + 2.0 ** -52))
        sq = D.multiply(D)
        k = int(np.max(np.diff(D.indptr), initial=1)) + 2
        return up(np.sqrt(inflate(np.asarray(sq.sum(axis=1)).ravel(), k)))

    def quad(self, r: Dyadic) -> Fraction:
        """rᵀ (W + Wᵀ)/2 r = rᵀ W r, exactly."""
        return r.dot(self.W.matvec(r))


def prove_psd(W: sp.spmatrix) -> LocalFacts:
    """Prove (W + Wᵀ)/2 ⪰ 0 for the stored W, or say why not."""
    W = sp.csr_matrix(W, dtype=np.float64)
    diag = W.diagonal()
    if np.any(diag < 0):
        k = int(np.flatnonzero(diag < 0)[0])
        return LocalFacts(False, f"W has a negative diagonal entry W[{k},{k}] = {diag[k]:.3e}", "", diag)
    zero = diag == 0
    if zero.any():
        # A PSD matrix with W_kk = 0 has a zero row k: check the symmetrised rows exactly
        # (W_kj + W_jk = 0 in exact arithmetic ⟺ W_kj == −W_jk in floats).
        Z = sp.csr_matrix(W[zero])
        ZT = sp.csr_matrix(W.T[zero])
        S = (Z + ZT).tocoo()  # a float sum is 0 exactly when the exact sum is 0
        S.eliminate_zeros()
        if S.nnz:
            k = int(np.flatnonzero(zero)[S.row[0]])
            return LocalFacts(False, f"W[{k},{k}] = 0 but row {k} of (W + Wᵀ)/2 is not zero (column "
                                     f"{int(S.col[0])}): W is not positive semidefinite", "", diag)
    rows = np.flatnonzero(~zero)
    if rows.size == 0:
        return LocalFacts(True, "", "W = 0", diag)
    A_raw = W[rows][:, rows]
    mass = verify_mass_matrix(A_raw)
    if mass.proven:
        lam = float(np.nanmin(mass.lam_lower))
        return LocalFacts(True, "", f"verified λmin((W + Wᵀ)/2) ≥ {bound_text(lam, 3, upper=False)} > 0 "
                                    "on its nonzero rows (floating point with rounding-error bounds)", diag,
                          lam_lower=lam, nonzero_rows=rows)
    for fb in mass.failures:
        idx = np.asarray(fb.dofs)
        if idx.size > EXACT_PSD_ROWS:
            return LocalFacts(False, f"W is not proven positive semidefinite: a block of {idx.size} rows "
                                     f"({fb.reason}); the exact test is limited to {EXACT_PSD_ROWS} rows"
                                     f"{PSD_SHIFT_FIX}", "", diag)
        verdict = exact_psd(A_raw[idx][:, idx])
        if verdict == "indefinite":
            return LocalFacts(False, f"W = (W + Wᵀ)/2 as stored is not positive semidefinite (exact rational "
                                     f"LDLᵀ of its block of rows {rows[idx][:6].tolist()}"
                                     f"{'…' if idx.size > 6 else ''} has a negative pivot): the local problem "
                                     f"of the file is not convex{PSD_SHIFT_FIX}", "", diag)
    return LocalFacts(True, "", "(W + Wᵀ)/2 ⪰ 0 proven: verified floating point on its definite blocks, exact "
                                "rational LDLᵀ on the others", diag)


def exact_psd(A: sp.spmatrix) -> str:
    """"definite", "semidefinite" or "indefinite" for the exact (A + Aᵀ)/2 of a small float
    matrix: LDLᵀ in rationals with the largest remaining diagonal as pivot (a PSD matrix whose
    largest remaining diagonal is 0 has a zero remainder; :func:`rfverify.model.definiteness.exact_ldlt`)."""
    D = np.asarray(sp.csr_matrix(A).toarray(), dtype=np.float64)
    n = D.shape[0]
    F = [[(Fraction(float(D[i, j])) + Fraction(float(D[j, i]))) / 2 for j in range(n)] for i in range(n)]
    return exact_ldlt(F)[0]


def local_data_scales(problem: Problem) -> dict:
    """Non-vanishing data scales of a local problem: ‖q‖∞ for u (u at r = 0, exact), and
    ‖q‖∞ / max_k W_kk for r (rounded down: a proven lower bound, as every scale that decides an
    absolute-mode acceptance must be)."""
    q_inf = float(np.max(np.abs(problem.local.q), initial=0.0))
    wmax = float(np.max(problem.local.W.diagonal(), initial=0.0))
    return {"u": q_inf, "r": float(np.nextafter(q_inf / wmax, 0.0)) if wmax > 0 else 0.0}


def prove_local(problem: Problem, point_r: Dyadic, u, r, *, requested: int = 10, exact: LocalExact | None = None,
                scales: dict | None = None, relative: bool = False) -> Proof:
    """Evaluate the local bound at the point r_p (exact, 5n) and carry it to the returned float64
    (u (5n,), r (5n,)).  Quantities: u and r (v of the lifting is not a quantity of the file).

    For ``problem.as_stored`` (an unsymmetric W, its stored equations) u = W r + q uses the
    stored W; (r − r*)ᵀW(r − r*) = (r − r*)ᵀW_s(r − r*), so ε and the r bound are unchanged, and
    |u_k − u*_k| ≤ √(W_kk)·ε + ‖row k of (W − Wᵀ)/2‖₂·ε/√λmin(W_s), which needs W_s proven definite
    on every component r may use (else u is reported as information)."""
    t0 = time.perf_counter()
    requested = validate_digits(requested)
    n = problem.n_contacts
    u, r = (np.asarray(x, dtype=np.float64).ravel() for x in (u, r))
    for name, arr in (("u", u), ("r", r)):
        if arr.size != SPACEDIM * n:
            from ..errors import InvalidProblemError

            raise InvalidProblemError(f"solution.{name}", f"has {arr.size} entries, the problem needs {SPACEDIM * n}",
                                      fix="certify a solution of this problem")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(r))):
        return invalid_proof(requested, "the solution contains NaN or Inf", t0, theorem=THEOREM_LOCAL, statement=problem.statement)
    ex = exact or LocalExact(problem)
    scales = scales or local_data_scales(problem)
    if not ex.facts.psd:
        return invalid_proof(requested, ex.facts.why, t0, theorem=THEOREM_LOCAL, statement=problem.statement)
    if len(point_r) != SPACEDIM * n:
        raise ValueError("the point does not match the problem's sizes")

    stored = problem.as_stored
    named = {"statement": problem.statement, "equations": "stored" if stored else "symmetrised"}
    u_p = ex.u_of(point_r, stored)
    outside = cones_failure(ex, u_p, point_r, "u = Wr + q")
    shifted = None
    if outside:
        shifted = _shift_into_dual_cone(problem, ex, u_p, point_r)
        if shifted is None:
            return invalid_proof(requested, outside, t0, theorem=THEOREM_LOCAL, statement=problem.statement)
    sqrtW = up(np.sqrt(ex.facts.w_diag))
    if shifted is None:
        gap = point_r.dot(u_p)  # ≥ 0: pairs of K and K*
        gap_up = fraction_upper_float(gap)
        eps = eps_M_upper(0.0, gap_up)  # the global theorem's ε with g = 0: √(rᵀu)
        terms = {"eps_W": eps, "gap_rTu": gap_up}
    else:
        u_shift, e_norm = shifted
        gap_up = fraction_upper_float(point_r.dot(u_shift))
        lam = ex.facts.lam_lower
        disc = float(up(float(up(e_norm * e_norm)) + float(up(4 * lam * gap_up))))
        root = float(up(math.sqrt(disc)))
        delta = float(up(float(up(e_norm + root)) / float(np.nextafter(2 * lam, 0))))
        eps = float(up(math.sqrt(float(up(gap_up + float(up(e_norm * delta)))))))
        terms = {"eps_W": eps, "gap_rTu": gap_up, "dual_shift_2norm": e_norm, "r_dist_2norm_upper": delta,
                 "lam_min_W_lower": lam}
    if ex.facts.lam_lower > 0:
        refined = _active_set_refinement(problem, ex, u_p, point_r, sqrtW, eps,
                                         delta if shifted is not None else None, shifted)
        if refined is not None and refined[0] < eps:
            eps, x_delta, refined_terms = refined
            terms.update({**refined_terms, "eps_W": eps})
            if shifted is not None:
                delta = min(delta, x_delta)
                terms["r_dist_2norm_upper"] = delta
    e_u = upper_sum((Dyadic.from_float(u) - u_p).abs_upper(), up_times(sqrtW, eps))
    terms.update({"max_sqrt_W_kk": float(np.max(sqrtW, initial=0.0)), "W_psd": ex.facts.how})
    u_note = ""
    if stored:
        skew_gain = _skew_gain(problem, ex)
        if skew_gain is None:
            u_note = ("W as stored is unsymmetric and (W + Wᵀ)/2 is not proven definite on every component r may "
                      "use: its skew part is not bounded, u is not")
            e_u = np.full(e_u.size, np.inf)
        else:
            e_u = upper_sum(e_u, up_times(skew_gain, eps))
    q = {"u": quantity_bound("u", e_u, u, scales, requested, names=DATA_SCALE_NAMES_LOCAL, relative=relative,
                        note=u_note)}
    if shifted is None:
        e_r, note, r_terms = _local_r_bound(problem, ex, u_p, sqrtW * eps, point_r, eps, r)
    else:  # ‖r_p − r*‖₂ ≤ δ on every component
        e_r = upper_sum((Dyadic.from_float(r) - point_r).abs_upper(), np.full(r.size, delta))
        note, r_terms = (f"unique: W definite (verified λmin ≥ {bound_text(ex.facts.lam_lower, upper=False)}); u = Wr + q raised into "
                         f"K* by ‖e‖₂ ≤ {bound_text(e_norm, 1)}"), {}
        rows = ex.facts.nonzero_rows
        only_by_shift = _unique_only_by_the_shift(problem, sp.csr_matrix(ex.local.W)[rows][:, rows])
        if only_by_shift:  # bounded (the backward error needs it), but no claim about the file
            note, r_terms = f"{only_by_shift} (W + D's r* is bounded: {note})", {R_INFORMATION_ONLY: True}
    info_only = r_terms.pop(R_INFORMATION_ONLY, False)
    terms.update(r_terms)
    if e_r is None or info_only:
        bound = math.nan if e_r is None else float(np.max(e_r, initial=0.0))
        q["r"] = QuantityBound("r", bound, float(np.max(np.abs(r), initial=0.0)), 0.0, scales["r"],
                               DATA_SCALE_NAMES_LOCAL["r"], None, "information", False, note)
    else:
        q["r"] = quantity_bound("r", e_r, r, scales, requested, note=note, names=DATA_SCALE_NAMES_LOCAL,
                           relative=relative)
    return Proof(True, requested, eps, q, terms, seconds=time.perf_counter() - t0, theorem=THEOREM_LOCAL,
                 statement=problem.statement, equations=named["equations"],
                 arithmetic=("exact dyadic rationals (Python integers) for u = Wr + q, rᵀu and the cones; "
                             "verified float64 (or exact rationals) for W ⪰ 0 and λmin"))


def _skew_gain(problem, ex: LocalExact):
    """‖row k of (W − Wᵀ)/2‖₂ / √λmin(W_s) per row (an upper bound), or None when λmin(W_s) is not
    proven positive on every component r may use (then ‖r − r*‖₂ is not bounded by ‖·‖_{W_s})."""
    facts = ex.facts
    if not _definite_where_r_may_be(problem, facts):
        return None
    root = float(np.nextafter(np.sqrt(facts.lam_lower) * (1 - 4 * 2.0 ** -53), 0))
    return up(ex.skew_row_norms_upper() / root)


def _shift_into_dual_cone(problem, ex: LocalExact, u_p: Dyadic, point_r: Dyadic):
    """(u' = u_p + τ e_N ∈ K* exactly, an upper bound of ‖τ‖₂) when r ∈ K and W is proven
    definite on every component r may use, else None (the residual theorem does not apply)."""
    facts = ex.facts
    n = problem.n_contacts
    _, bad_primal = cone_violations(ex, u_p, point_r)
    if bad_primal.size or not _definite_where_r_may_be(problem, facts):
        return None
    mu, mur = problem.mu, problem.mu_r
    mag = np.maximum(np.abs(u_p.lower()), np.abs(u_p.upper())).reshape(n, SPACEDIM)
    need = inflate(mu * up(np.hypot(mag[:, 1], mag[:, 2])) + mur * up(np.hypot(mag[:, 3], mag[:, 4])), 6)
    tau = np.maximum(up(need - u_p.lower().reshape(n, SPACEDIM)[:, 0]), 0.0)
    tau = np.where(tau > 0, up(tau * (1 + 2.0 ** -40)), 0.0)
    full = np.zeros(SPACEDIM * n)
    full[0::SPACEDIM] = tau
    u_shift = u_p + Dyadic.from_float(full)
    bad_dual, _ = cone_violations(ex, u_shift, point_r)
    if bad_dual.size:
        return None
    return u_shift, float(up(np.sqrt(float(up(np.sum(up(tau * tau)) * (1 + 2.0 ** -40))))))


def _kept_components(problem) -> np.ndarray:
    """(n, 5) mask of the components K does not force to 0 (N; T where μ > 0; R where μr > 0)."""
    n = problem.n_contacts
    kept = np.zeros((n, SPACEDIM), dtype=bool)
    kept[:, 0] = True
    kept[:, 1:3] = (problem.mu > 0)[:, None]
    kept[:, 3:5] = (problem.mu_r > 0)[:, None]
    return kept


def _definite_where_r_may_be(problem, facts: LocalFacts) -> bool:
    """W is proven definite (λmin ≥ ``facts.lam_lower`` > 0) on every component r may use: each
    component K does not force to 0 is a row with a nonzero diagonal, so ‖d‖₂ ≤ ‖d‖_W/√λ."""
    if not facts.lam_lower > 0 or facts.nonzero_rows is None:
        return False
    in_F = np.zeros(SPACEDIM * problem.n_contacts, dtype=bool)
    in_F[facts.nonzero_rows] = True
    return bool(np.all(in_F[_kept_components(problem).ravel()]))


def _active_set_refinement(problem, ex: LocalExact, u_p: Dyadic, point_r: Dyadic, sqrtW, eps: float, delta,
                           shifted):
    """A second, linear bound on ‖d‖_W (d = r_p − r*) where W is definite (λ > 0) on every
    component r may use, from the contacts the first bound classifies (module docstring), or None.

    O: contacts proven open (u* ∈ int K*_i, so r*_i = 0); S: contacts whose ball r_p,i ± δ₁ lies
    in the relative interior of K_i (δ₁ ≥ ‖d‖₂, the first bound), so u*_i = 0 on K_i's span C
    (r* − t·u*_C ∈ K for small t, and (r* − t·u*_C)ᵀu* = −t‖u*_C‖² ≥ 0); R: the rest.  Then
    dᵀWd = dᵀ(u_p − u*) ≤ ‖d_S‖₂‖u_p,S,C‖₂ + r_Oᵀu_p,O + r_Rᵀu'_R + ‖d‖₂‖e‖₂ (u' = u_p + e ∈ K*
    the point raised into K*, e = 0 when it is there), and ‖d‖₂ ≤ x/√λ with x = ‖d‖_W, so
    x² ≤ a·x + c with a = (‖u_p,S,C‖₂ + ‖e‖₂)/√λ, c = r_Oᵀu_p,O + r_Rᵀu'_R: x ≤ (a + √(a² + 4c⁺))/2.
    No cone test on u_p,S or u_p,O is needed.  Where the point's u_p on its stuck contacts is at
    the rounding level of an extended-precision solve (1e-32), this is ~√λ-times that, where the
    first bound, √(rᵀu), is only its square root.  Returns (x, x/√λ, terms)."""
    facts = ex.facts
    n = problem.n_contacts
    if n == 0 or not _definite_where_r_may_be(problem, facts):
        return None
    kept = _kept_components(problem)
    _, bad_primal = cone_violations(ex, u_p, point_r)
    if bad_primal.size:
        return None
    lam = float(np.nextafter(facts.lam_lower * (1 - 4 * 2.0 ** -53), 0))
    root = float(np.nextafter(math.sqrt(lam) * (1 - 4 * 2.0 ** -53), 0))
    mu, mur = problem.mu, problem.mu_r
    open_ = proven_open(u_p, up_times(sqrtW, eps), mu, mur, n)
    if delta is None:  # ‖d‖₂ ≤ ‖d‖_W/√λ ≤ ε/√λ
        delta = float(up(eps / root))
    lo, hi = point_r.lower().reshape(n, SPACEDIM), point_r.upper().reshape(n, SPACEDIM)
    mag = np.maximum(np.abs(lo), np.abs(hi))
    rN = down(lo[:, 0] - delta)
    nT, nR = up(up(np.hypot(mag[:, 1], mag[:, 2])) + delta), up(up(np.hypot(mag[:, 3], mag[:, 4])) + delta)
    inside_T = (mu == 0) | (down(down(mu * rN) * (1 - 4 * 2.0 ** -53)) > nT)
    inside_R = (mur == 0) | (down(down(mur * rN) * (1 - 4 * 2.0 ** -53)) > nR)
    stuck = (rN > 0) & inside_T & inside_R & ~open_
    if not stuck.any():
        return None
    comp = np.repeat(np.arange(n), SPACEDIM)
    S_cols = np.flatnonzero(stuck[comp] & kept.ravel())
    u_S = u_p[S_cols].abs_upper()
    uS_norm = float(up(np.sqrt(float(inflate(np.sum(up(u_S * u_S)), u_S.size)))))
    rest = np.flatnonzero(~stuck[comp])
    open_cols = np.flatnonzero(open_[comp])
    u_rest = u_p if shifted is None else shifted[0]
    c = point_r[open_cols].dot(u_p[open_cols]) if open_cols.size else Fraction(0)
    R_cols = np.setdiff1d(rest, open_cols)
    if R_cols.size:
        c += point_r[R_cols].dot(u_rest[R_cols])
    e_norm = 0.0 if shifted is None else shifted[1]
    a = float(up(float(up(uS_norm + e_norm)) / root))
    c_up = fraction_upper_float(max(c, Fraction(0)))
    x = float(up(float(up(a + float(up(math.sqrt(float(up(float(up(a * a)) + float(up(4 * c_up))))))))) / 2))
    return x, float(up(x / root)), {"active_set_stuck": int(stuck.sum()), "active_set_open": int(open_.sum()),
                                    "active_set_rest": int(n - stuck.sum() - open_.sum()),
                                    "eps_W_first": eps}


R_INFORMATION_ONLY = "r_information_only"
"""A key of ``_local_r_bound``'s terms: r is bounded but claimed as information only."""


def _unique_only_by_the_shift(problem, A) -> str:
    """Where W was shifted to W + D (``--psd-shift``) and W itself is not proven definite on the
    possibly loaded contacts (A is W + D there), r* of W + D is unique only through D: its
    digits would be about the shift, not the file, so r is information (the reason, else "").
    Either answer is sound (every bound is W + D's); this only decides what is claimed."""
    shift = problem.provenance.get("psd_shift")
    if not shift:
        return ""
    A0 = sp.csr_matrix(A) - shift["largest_change"] * sp.identity(A.shape[0], format="csr")
    if verify_mass_matrix(A0).proven:
        return ""
    return ("W before its diagonal shift D is not proven definite on the possibly loaded contacts: r* of W + D is "
            "unique only through D, so r is no quantity of the file; u is")


def _local_r_bound(problem, ex: LocalExact, u_p: Dyadic, u_radius, point_r: Dyadic, eps: float, r):
    n = problem.n_contacts
    mu, mur = problem.mu, problem.mu_r
    open_ = proven_open(u_p, u_radius, mu, mur, n)
    S = np.flatnonzero(~open_)
    terms = {"contacts_proven_open": int(open_.sum()), "contacts_possibly_loaded": int(S.size)}
    kept = [np.ones(S.size, dtype=bool), mu[S] > 0, mu[S] > 0, mur[S] > 0, mur[S] > 0]
    cols = np.sort(np.concatenate([SPACEDIM * S[kept[k]] + k for k in range(SPACEDIM)])) if S.size \
        else np.zeros(0, dtype=np.int64)
    e = np.abs(r).astype(np.float64)  # off S (r* = 0: open contacts, components K forces to 0)
    if cols.size == 0:
        return e, f"unique: all {n} contacts proven open (r* = 0)", terms
    A = problem.local.W[cols][:, cols]
    mass: MassBounds = verify_mass_matrix(A)
    if not mass.proven:
        fb = mass.failures[0]
        return None, (f"W on the {S.size} possibly loaded contacts is not proven definite ({fb.reason}): "
                      "r may not be unique, u is"), terms
    # r_O: the point's r off the loaded columns (r* = 0 there); its W-norm widens the bound on S.
    r_O = point_r.ints.copy()
    r_O[cols] = 0
    rO = Dyadic(r_O, point_r.exp)
    t = sqrt_upper(max(ex.quad(rO), Fraction(0)))
    radius = 0.0 if eps == 0 and t == 0 else float(up(eps + t))
    only_by_shift = _unique_only_by_the_shift(problem, A)
    lam = mass.lam_lower[mass.labels]  # per column of the loaded set
    d_r = (Dyadic.from_float(r[cols]) - point_r[cols]).abs_upper()
    # |d_j| ≤ √((W_b⁻¹)_jj)·‖W_b^½ d_b‖ (Cauchy–Schwarz), never more than ‖d_b‖₂ ≤ ‖W_b^½ d_b‖/√λmin(W_b)
    per = np.minimum(up(np.sqrt(mass.minv_diag_upper)),
                     up(1.0 / np.nextafter(np.sqrt(lam) * (1 - 4 * 2.0 ** -53), 0)))
    e[cols] = upper_sum(d_r, up(radius * per) if radius else np.zeros(cols.size))
    terms.update({"lam_min_W_S_lower": float(np.min(lam)), "W_norm_r_open": t})
    note = (f"unique: {int(open_.sum())} contacts proven open (r* = 0), W definite on the other {S.size} "
            f"(verified λmin ≥ {bound_text(float(np.min(lam)), upper=False)})")
    if only_by_shift:  # a bound on W + D's r* (the backward error needs it), but no claim
        terms[R_INFORMATION_ONLY] = True
        note = f"{only_by_shift} (W + D's r* is bounded: {note})"
    return e, note, terms
