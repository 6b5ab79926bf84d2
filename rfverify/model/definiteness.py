"""Verified positive definiteness of a symmetric matrix, block by block, whatever its scale.

The matrix A (the symmetrised mass matrix M_s = (M + Mᵀ)/2, or a local W) is split into the
connected components of its sparsity graph (bodies); each block is decided on its
**equilibrated** form S A S, S = diag(2^e_j) with 2^(2e_j)·A_jj in [1/2, 2) (Jacobi scaling
rounded to powers of two).  Multiplying by powers of two is exact (checked entry by entry:
only an underflow could lose bits, and it is accounted for), so S A S is positive definite
exactly when A is, and every bound on it carries back through the exact S:

    λmin(A_b) ≥ λmin(S A_b S) / max_j s_j²,    (A⁻¹)_jj = s_j² ((SAS)⁻¹)_jj,
    hᵀA⁻¹h = (Sh)ᵀ(SAS)⁻¹(Sh).

A rigid body in badly chosen units (masses ~1e6, inertias ~1e-6) is therefore as easy as one
in good units; testing the unscaled block would lose every digit to rounding (a rounding error
of u‖A‖ swamps λmin(A) once cond(S) is large).

Per block, in order:

1. **Verified floating point** (the approach of Rump's verified linear algebra, as in INTLAB's
   ``isspd``): pick τ just below a floating estimate of λmin and any floating G with
   A − τI ≈ GGᵀ (from ``eigh`` for small blocks, from a sparse LDLᵀ for large ones); then
   A = τI + GGᵀ + E exactly, GGᵀ ⪰ 0 for *any* real G, so λmin(A) ≥ τ − ‖E‖₂, with ‖E‖₂
   bounded by an entrywise a-priori rounding-error bound.  No assumption on how G was
   computed (operation order, FMA): the residual is bounded, not the algorithm.
2. **Exact rational LDLᵀ** (blocks of at most :data:`EXACT_LIMIT` dofs, at most
   :data:`EXACT_BLOCKS` blocks) where 1. proves nothing: it decides definiteness exactly, and
   gives a rigorous λmin bound (Sylvester on A − cI, or d_min/‖L⁻¹‖²).
3. **Exact witnesses of indefiniteness**: a 2×2 principal minor A_ii A_jj − A_ij² ≤ 0, or
   xᵀAx ≤ 0 for the computed eigenvector x of the smallest eigenvalue, both evaluated in
   rationals on the exact symmetrisation of the data.

A block is called *not positive definite* only on an exact proof (a non-positive pivot of 2.,
a witness of 3.); otherwise a failure says that positive definiteness *could not be verified*
and what was tried.  :func:`verify_definite` returns the facts; :mod:`rfverify.model.massmatrix`
turns a failure into the refusal of a problem, :mod:`rfverify.proof.massbounds` the facts into
the proof's norms of M⁻¹.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

U = 2.0 ** -53  # unit roundoff of float64
ETA = 2.0 ** -1074  # smallest subnormal: absolute error of an underflowing product
DENSE_LIMIT = 400
"""Blocks up to this many dofs are verified densely (batched by size); larger ones sparsely."""
EXACT_LIMIT = 48
"""Largest block decided by exact rational LDLᵀ where the floating-point test proves nothing
(a 6-dof rigid body takes about 1 ms; the cost grows like dofs³ with growing rationals)."""
EXACT_BLOCKS = 256
"""At most this many blocks of one matrix go to the exact test (the rest, if any, are reported
as not verified)."""
WITNESS_NNZ = 400_000
"""Largest block (stored entries) whose eigenvector witness xᵀAx is evaluated exactly."""


# ---------------------------------------------------------------------- directed float64 helpers
def gamma(k: int) -> float:
    """γ_k = k·u/(1 − k·u), rounded up generously."""
    return 2.0 * k * U / (1.0 - 2.0 * k * U)


U_LONG = float(np.finfo(np.longdouble).eps) / 2
"""Unit roundoff of numpy's long double (2⁻⁶⁴ on x86, = U where it is a double)."""
HAS_LONG_DOUBLE = U_LONG <= U * 2.0 ** -8


def gamma_long(k: int) -> float:
    """γ_k for long-double arithmetic, rounded up generously (a float64 bound)."""
    return 2.0 * k * U_LONG / (1.0 - 2.0 * k * U_LONG)


def inflate(x, k: int):
    """x (≥ 0, computed with k roundings) times 1 + 8(k+4)u: a rigorous upper bound."""
    return np.nextafter(np.asarray(x, dtype=np.float64) * (1.0 + 8.0 * (k + 4) * U), np.inf)


def deflate(x, k: int):
    """x (> 0, computed with k roundings) times 1 − 8(k+4)u: a rigorous lower bound."""
    return np.nextafter(np.asarray(x, dtype=np.float64) * (1.0 - 8.0 * (k + 4) * U), -np.inf)


def upper_sum(*terms):
    """Rigorous upper bound of the exact sum of float terms (arrays broadcast), any signs:
    |fl(Σt) − Σt| ≤ γ_n Σ|t|."""
    total = np.zeros(np.broadcast(*terms).shape) if len(terms) > 1 else np.asarray(terms[0], dtype=np.float64)
    mag = np.zeros_like(total)
    for t in terms:
        total = total + t
        mag = mag + np.abs(t)
    # Where every term is exactly 0 (mag = 0: a sum of magnitudes vanishes only then) the sum is 0.
    return np.where(mag == 0, 0.0, np.nextafter(total + inflate(gamma(len(terms) + 1) * mag, len(terms) + 2), np.inf))


def ldexp_up(x, e):
    """x·2^e rounded up (exact unless it underflows; then the next float above; +inf where it
    overflows, still an upper bound)."""
    x = np.asarray(x, dtype=np.float64)
    with np.errstate(over="ignore"):
        y = np.ldexp(x, e)
    with np.errstate(invalid="ignore"):
        lost = np.ldexp(y, -np.asarray(e)) != x
    return np.where(lost & np.isfinite(x), np.nextafter(y, np.inf), y)


def ldexp_down(x, e):
    """x·2^e rounded down (exact unless it underflows; then the next float below)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.ldexp(x, e)
    with np.errstate(invalid="ignore"):
        lost = np.ldexp(y, -np.asarray(e)) != x
    return np.where(lost & np.isfinite(x), np.nextafter(y, -np.inf), y)


def fraction_down(q: Fraction) -> float:
    """The largest float64 ≤ q (q finite, within range)."""
    f = float(q)  # correctly rounded
    return f if Fraction(f) <= q else math.nextafter(f, -math.inf)


# ---------------------------------------------------------------------- equilibration
def equilibration_exponents(diag) -> np.ndarray:
    """e_j with 2^(2e_j)·d_j in [1/2, 2) for d_j > 0 (0 elsewhere): the Jacobi scaling
    1/√d_j rounded to a power of two, so that scaling by it is exact."""
    d = np.asarray(diag, dtype=np.float64)
    e = np.zeros(d.size, dtype=np.int64)
    ok = np.isfinite(d) & (d > 0)
    E = np.frexp(d[ok])[1].astype(np.int64)
    e[ok] = -(E // 2)  # d = m·2^E, m in [1/2, 1): 2^(E − 2⌊E/2⌋)·m in [1/2, 2)
    return e


def scale_symmetric(A: sp.spmatrix, exponents: np.ndarray) -> tuple[sp.csr_matrix, np.ndarray]:
    """S A S (CSR) for S = diag(2^exponents), and a mask of the stored entries where the scaling
    was not exact (an underflow; the error there is below ETA/2)."""
    A = sp.csr_matrix(A, dtype=np.float64, copy=True)
    rows = np.repeat(np.arange(A.shape[0]), np.diff(A.indptr))
    shift = exponents[rows] + exponents[A.indices]
    orig = A.data
    with np.errstate(over="ignore", invalid="ignore"):
        A.data = np.ldexp(orig, shift)
        inexact = np.ldexp(A.data, -shift) != orig
    return A, inexact


def scale_rows(H: sp.spmatrix, exponents: np.ndarray) -> tuple[sp.coo_matrix, np.ndarray]:
    """S H (COO) for S = diag(2^exponents), and the mask of entries that underflowed."""
    Hc = sp.coo_matrix(H, dtype=np.float64)
    out = sp.coo_matrix((np.ldexp(Hc.data, exponents[Hc.row]), (Hc.row, Hc.col)), shape=Hc.shape)
    with np.errstate(over="ignore", invalid="ignore"):
        inexact = np.ldexp(out.data, -exponents[Hc.row]) != Hc.data
    return out, inexact


# ---------------------------------------------------------------------- the facts
@dataclass
class BlockFailure:
    """A block whose positive definiteness was not proven.  ``proven`` is True when it is
    proven **not** positive definite (an exact witness, named in ``reason``); False when it
    could not be decided (``reason`` says what was tried)."""

    block: int
    dofs: np.ndarray
    reason: str
    proven: bool = False


@dataclass
class Definiteness:
    """Connected components of the sparsity graph of a symmetric matrix A (bodies, for
    rigid-body problems) and what is proven about each.

    ``labels[j]`` is the block of dof j, ``sizes[b]`` its number of dofs; ``exponents[j]`` the
    equilibration e_j (s_j = 2^e_j); ``lam_scaled[b]`` > 0 a proven lower bound of
    λmin(S A_b S) (NaN where not proven: see ``failures``); ``lam_direct[b]`` the same test's
    bound on the unscaled block (dense blocks only; NaN where it proves nothing, as it does for a
    badly scaled block); :attr:`lam_lower` the better bound on λmin(A_b) itself;
    ``exact_blocks`` how many blocks the exact rational test decided.
    """

    labels: np.ndarray
    sizes: np.ndarray
    exponents: np.ndarray
    lam_scaled: np.ndarray
    lam_direct: np.ndarray | None = None
    failures: list = field(default_factory=list)
    exact_blocks: int = 0

    @property
    def count(self) -> int:
        return int(self.sizes.size)

    @property
    def proven(self) -> bool:
        """True when every block is proven positive definite."""
        return not self.failures

    @property
    def lam_lower(self) -> np.ndarray:
        """Per block, a proven lower bound of λmin(A_b): λmin(S⁻¹(SAS)S⁻¹) ≥ λmin(SAS)/max s_j², or
        the direct bound where that is better (up to 4× for a well-scaled block whose diagonal
        spans a factor 4 between powers of two); NaN where not proven."""
        top = np.full(self.count, np.iinfo(np.int64).min, dtype=np.int64)
        np.maximum.at(top, self.labels, self.exponents)
        with np.errstate(invalid="ignore"):
            via_s = ldexp_down(self.lam_scaled, -2 * top)
        if self.lam_direct is None:
            return via_s
        direct = np.where(np.isfinite(self.lam_scaled) & (self.lam_direct > 0), self.lam_direct, np.nan)
        return np.fmax(via_s, direct)

    def block_dofs(self) -> tuple[np.ndarray, np.ndarray]:
        """(order, starts): dofs grouped by block (increasing within a block); block b is
        order[starts[b]:starts[b + 1]]."""
        order = np.argsort(self.labels, kind="stable")
        starts = np.concatenate(([0], np.cumsum(self.sizes)))
        return order, starts


def verify_definite(A_sym: sp.spmatrix, A_raw: sp.spmatrix | None = None, *, exact: bool = True) -> Definiteness:
    """Decide the positive definiteness of the exact symmetrisation (A_raw + A_rawᵀ)/2 block by
    block (module docstring).  ``A_sym`` is its float64 rounding (the matrix the solvers use:
    one rounding per entry, as :func:`rfverify.model.massmatrix.symmetrise` computes it); ``A_raw``
    the data it came from (None: ``A_sym`` is the data, exactly symmetric).  ``exact=False``
    skips the exact rational test (step 2)."""
    A_sym = sp.csr_matrix(A_sym, dtype=np.float64)
    m = A_sym.shape[0]
    n_blocks, labels = connected_components(A_sym, directed=False)
    sizes = np.bincount(labels, minlength=n_blocks)
    exps = equilibration_exponents(A_sym.diagonal())
    S, inexact = scale_symmetric(A_sym, exps)
    facts = Definiteness(labels=labels, sizes=sizes, exponents=exps, lam_scaled=np.full(n_blocks, np.nan),
                         lam_direct=np.full(n_blocks, np.nan))
    order, starts = facts.block_dofs()
    pending = []  # (block, dofs, λmin estimate of SAS, rounding-error bound)
    for s in np.unique(sizes):
        ids = np.flatnonzero(sizes == s)
        if s <= DENSE_LIMIT:
            dofs = order[starts[ids][:, None] + np.arange(s)[None, :]]
            lam, est, normE = dense_lambda_lower(gather_blocks(S, dofs))
            ok = lam > 0
            facts.lam_scaled[ids[ok]] = lam[ok]
            if np.any(exps[dofs] != exps[dofs[:, :1]]):  # some block not uniformly scaled: try it unscaled too
                facts.lam_direct[ids] = dense_lambda_lower(gather_blocks(A_sym, dofs))[0]
            else:  # S = 2^e I on every block: the direct bound is the scaled one, scaled back exactly
                facts.lam_direct[ids] = np.nan
            pending += [(int(ids[k]), dofs[k], float(est[k]), float(normE[k])) for k in np.flatnonzero(~ok)]
        else:
            for b in ids:
                d = order[starts[b]:starts[b + 1]]
                A = S[d][:, d].tocsc()
                err = abs(A) * (2 * U)
                bad = inexact_block(S, inexact, d)
                if bad is not None:
                    err = err + bad
                lam, why, est = sparse_lambda_lower(A, err)
                if why:
                    pending.append((int(b), d, est, math.nan))
                else:
                    facts.lam_scaled[b] = lam
    if pending:
        _settle(facts, pending, A_sym, A_raw, exact, m)
    return facts


def inexact_block(S: sp.csr_matrix, inexact: np.ndarray, dofs: np.ndarray) -> sp.csc_matrix | None:
    """ETA on the entries of block ``dofs`` of S whose scaling underflowed (None: none did)."""
    if not inexact.any():
        return None
    mask = sp.csr_matrix((inexact.astype(np.float64) * ETA, S.indices, S.indptr), shape=S.shape)
    sub = mask[dofs][:, dofs].tocsc()
    return sub if sub.nnz else None


def gather_blocks(csr: sp.csr_matrix, dofs: np.ndarray) -> np.ndarray:
    """Dense (count, s, s) stack of the diagonal blocks A[dofs[b]][:, dofs[b]] (the blocks are
    connected components, so no entry links two of them)."""
    count, s = dofs.shape
    pos = np.empty(csr.shape[1], dtype=np.int64)
    pos[dofs.ravel()] = np.tile(np.arange(s), count)
    sub = csr[dofs.ravel()].tocoo()  # rows of all blocks, all columns
    stack = np.zeros((count, s, s))
    stack[sub.row // s, sub.row % s, pos[sub.col]] = sub.data
    return stack


# ---------------------------------------------------------------------- step 1: verified float64
def dense_lambda_lower(A: np.ndarray):
    """Batched rigorous lower bounds of λmin for equal-size symmetric float blocks A (nb, s, s)
    whose exact counterparts differ from them by at most 2u|A| + ETA entrywise.  Returns
    (bounds (≤ 0 or NaN: not proven), floating λmin estimates, rounding-error bounds ‖E‖₂)."""
    nb, s, _ = A.shape
    finite = np.all(np.isfinite(A), axis=(1, 2))
    if not finite.all():
        A = np.where(finite[:, None, None], A, np.eye(s))
    lam, V = np.linalg.eigh(A)
    lmin = lam[:, 0]
    eye = np.eye(s)

    def lower_bound(tau, extended=False):
        # A = τI + GGᵀ + E exactly for any τ and G (GGᵀ ⪰ 0), so λmin(A) ≥ τ − ‖E‖₂ whatever τ is.
        d = np.sqrt(np.maximum(lam - tau[:, None], 0.0))
        G = V * d[:, None, :]
        absG = np.abs(G)
        if extended:  # E evaluated in long double: its a-priori rounding bound shrinks by U / U_LONG
            GL = G.astype(np.longdouble)
            FL = (A.astype(np.longdouble) - tau.astype(np.longdouble)[:, None, None] * eye) - GL @ np.swapaxes(GL, 1, 2)
            F, g = FL.astype(np.float64), gamma_long(s + 4)
            absF = inflate(np.abs(F), 1)  # the conversion to float64 is one more rounding
        else:
            F, g = (A - tau[:, None, None] * eye) - G @ np.swapaxes(G, 1, 2), gamma(s + 4)
            absF = np.abs(F)
        B = absF + g * (absG @ np.swapaxes(absG, 1, 2) + np.abs(A) + np.abs(tau)[:, None, None] * eye) \
            + 2 * U * np.abs(A) + (s + 4) * ETA
        B = inflate(B, s + 6)
        normE = inflate(np.maximum(B.sum(axis=1).max(axis=1), B.sum(axis=2).max(axis=1)), s + 2)
        return deflate(tau - normE, 2), normE

    # τ just below the computed λmin makes the bound nearly λmin itself; τ = λmin/2 is the
    # fallback where rounding makes the first useless.
    lam_near, normE = lower_bound(lmin * (1 - 2.0 ** -20))
    lam_half, normE_half = lower_bound(lmin * 0.5)
    lam_lower = np.fmax(lam_near, lam_half)
    normE = np.where(lam_near >= lam_half, normE, normE_half)
    # A nearly singular block (a rank-deficient W plus a tiny diagonal, --psd-shift) has λmin
    # below float64's a-priori bound γ·‖|G||G|ᵀ‖ ≈ s²u·max A_kk: evaluate its residual again in
    # long double, where the platform has one (x86: 64-bit significand), which leaves |E| itself.
    retry = finite & ~(lam_lower > 0) & (lmin > 0)
    if HAS_LONG_DOUBLE and retry.any():
        lam_x, normE_x = lower_bound(lmin * (1 - 2.0 ** -20), extended=True)
        better = retry & (lam_x > np.nan_to_num(lam_lower, nan=-np.inf))
        lam_lower = np.where(better, lam_x, lam_lower)
        normE = np.where(better, normE_x, normE)
    lam_lower = np.where(finite, lam_lower, np.nan)
    return lam_lower, np.where(finite, lmin, np.nan), np.where(finite, normE, np.nan)


def sparse_lambda_lower(A: sp.csc_matrix, A_err: sp.spmatrix, tau: float | None = None, attempts: int = 4):
    """Rigorous lower bound of λmin(A_exact) for a sparse symmetric float matrix A with
    |A − A_exact| ≤ A_err entrywise.  Returns (λ_lower, "", estimate) or (nan, reason,
    estimate); the estimate is the floating λmin the shifts were chosen from (NaN: none)."""
    from scipy.sparse.linalg import eigsh, splu

    A = sp.csc_matrix(A, dtype=np.float64)
    n = A.shape[0]
    if not np.all(np.isfinite(A.data)):
        return np.nan, "non-finite entries", np.nan
    est = np.nan
    if tau is None:
        try:
            if n < 3:  # ARPACK needs k < n - 1: a tiny matrix is solved densely
                est = float(np.linalg.eigvalsh(A.toarray())[0])
            else:
                est = float(eigsh(A, k=1, sigma=0, which="LM", return_eigenvectors=False, tol=1e-4)[0])
        except Exception:  # singular or not converged: fall back to a diagonal-based guess
            est = float(np.min(A.diagonal())) * 1e-3
        if not est > 0:
            return np.nan, f"the floating-point estimate of λmin is {est:.3e}", est
        tau = est * (1 - 1e-3)  # just below the estimate (ARPACK's tol 1e-4): the bound is then ≈ λmin
    absA = abs(A)
    last = ""
    taus = [tau, tau * 0.5] + [tau * 0.5 / 16 ** k for k in range(1, attempts)]
    for tau in taus:
        B = (A - tau * sp.identity(n, format="csc")).tocsc()
        try:
            lu = splu(B, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                      options=dict(SymmetricMode=True))
        except RuntimeError as exc:
            last = f"factorisation of A − τI failed ({exc})"
            continue
        if not np.array_equal(lu.perm_r, lu.perm_c):
            last = "the factorisation pivoted off the diagonal"
            continue
        dU = lu.U.diagonal()
        if not np.all(dU > 0):
            last = "a non-positive pivot"
            continue
        p = np.argsort(lu.perm_c)  # Pr·A·Pc = A[p][:, p] = L·U when perm_r = perm_c
        G = (lu.L @ sp.diags(np.sqrt(dU))).tocsr()
        Bp = B[p][:, p].tocsr()
        GG = (G @ G.T).tocsr()
        F = (Bp - GG).tocsr()
        absG = abs(G)
        k = int(np.max(np.diff(G.indptr), initial=1))
        Ap = absA[p][:, p]
        errp = sp.csr_matrix(A_err)[p][:, p]
        bound = abs(F) + gamma(k + 4) * (absG @ absG.T + Ap + tau * sp.identity(n)) + 2 * U * Ap + errp
        rows = inflate(np.asarray(bound.sum(axis=1)).ravel() + (k + 4) * ETA * n, k + 8)
        normE = float(inflate(rows.max(initial=0.0), int(np.max(np.diff(bound.tocsr().indptr), initial=1)) + 2))
        lam = float(deflate(tau - normE, 2))
        if lam > 0:
            return lam, "", est
        last = f"rounding-error bound {normE:.3e} ≥ τ = {tau:.3e}"
    return np.nan, last, est


# ---------------------------------------------------------------------- steps 2 and 3: exact
def exact_symmetric_block(A_sym: sp.csr_matrix, A_raw: sp.spmatrix | None, dofs: np.ndarray) -> list:
    """The block (A_raw + A_rawᵀ)/2 [dofs][:, dofs] as rows of Fractions, exactly (A_sym itself
    when there is no A_raw: then it is the data, symmetric)."""
    if A_raw is None:
        D = A_sym[dofs][:, dofs].toarray()
        return [[Fraction(float(x)) for x in row] for row in D]
    R = sp.csr_matrix(A_raw)
    D = R[dofs][:, dofs].toarray()
    return [[(Fraction(float(D[i, j])) + Fraction(float(D[j, i]))) / 2 for j in range(len(dofs))]
            for i in range(len(dofs))]


def exact_ldlt(F: list) -> tuple[str, int, Fraction | None, list]:
    """LDLᵀ of the symmetric rational matrix F (rows of Fractions; modified in place) with the
    largest remaining diagonal as pivot.  Returns (verdict, step, pivot, pivots): "definite"
    (every pivot > 0), "semidefinite" (a zero pivot with a zero remainder) or "indefinite" (a
    negative pivot, or a zero one with a nonzero remainder), the step and pivot that decided,
    and the pivots met so far."""
    n = len(F)
    left = list(range(n))
    pivots = []
    step = 0
    while left:
        p = max(left, key=lambda i: F[i][i])
        piv = F[p][p]
        if piv < 0:
            return "indefinite", step, piv, pivots
        if piv == 0:
            zero = all(F[i][j] == 0 for i in left for j in left)
            return ("semidefinite" if zero else "indefinite"), step, piv, pivots
        pivots.append(piv)
        left.remove(p)
        row = F[p]
        for i in left:
            if F[i][p] != 0:
                f = F[i][p] / piv
                Fi = F[i]
                for j in left:
                    if row[j] != 0:
                        Fi[j] -= f * row[j]
        step += 1
    return "definite", step, None, pivots


def _exact_lambda_lower(F: list, pivots: list, estimate: float) -> Fraction:
    """A proven lower bound of λmin of the definite rational matrix F (rows of Fractions) whose
    pivoted LDLᵀ had ``pivots``: with diagonal pivoting |L_ij| ≤ 1, so |(L⁻¹)_ij| ≤ 2^(i−j−1)
    and λmin ≥ d_min/‖L⁻¹‖²_F; better, when A − cI is still definite (Sylvester) for c just
    below the floating ``estimate``, λmin ≥ c."""
    n = len(F)
    frob = n + sum((n - k) * 4 ** (k - 1) for k in range(1, n))  # ≥ ‖L⁻¹‖²_F
    best = min(pivots) / frob
    if estimate > 0 and math.isfinite(estimate):
        for c in (Fraction(estimate) * (1 - Fraction(1, 256)), Fraction(estimate) / 2):
            if c <= best:
                break
            shifted = [[F[i][j] - (c if i == j else 0) for j in range(n)] for i in range(n)]
            if exact_ldlt(shifted)[0] == "definite":
                return c
    return best


def _settle(facts: Definiteness, pending: list, A_sym: sp.csr_matrix, A_raw, exact: bool, m: int) -> None:
    """Steps 2 and 3 for the blocks step 1 left undecided."""
    budget = EXACT_BLOCKS if exact else 0
    for b, dofs, est, normE in pending:
        tried = ["a verified floating-point test on the equilibrated block (rows and columns scaled by "
                 "powers of two, exactly; a-priori rounding-error bound)"
                 + (f": λmin ≈ {est:.3e} of the scaled block, rounding-error bound {normE:.3e}"
                    if math.isfinite(est) and math.isfinite(normE) else
                    (f": λmin ≈ {est:.3e} of the scaled block" if math.isfinite(est) else ""))]
        witness = _diagonal_witness(A_sym, dofs) or _minor_witness(A_sym, A_raw, dofs)
        if witness:
            facts.failures.append(BlockFailure(b, dofs, witness, proven=True))
            continue
        if dofs.size <= EXACT_LIMIT and budget > 0:
            budget -= 1
            facts.exact_blocks += 1
            F = exact_symmetric_block(A_sym, A_raw, dofs)
            verdict, step, piv, pivots = exact_ldlt([row[:] for row in F])
            if verdict == "definite":
                # λmin of the scaled block S F S (the facts are about the scaled blocks).
                e = facts.exponents[dofs]
                G = [[F[i][j] * Fraction(2) ** int(e[i] + e[j]) for j in range(len(F))] for i in range(len(F))]
                lam = _exact_lambda_lower(G, exact_ldlt([row[:] for row in G])[3], est)
                facts.lam_scaled[b] = fraction_down(lam)
                if not facts.lam_scaled[b] > 0:  # below the float range: definite, but no usable bound
                    facts.lam_scaled[b] = np.nan
                    facts.failures.append(BlockFailure(b, dofs, "positive definite (exact rational LDLᵀ), but its "
                                                                "smallest eigenvalue is below float64's range"))
                continue
            what = "a zero pivot" if piv == 0 else f"pivot {float(piv):.3e} < 0"
            kind = "singular, so" if verdict == "semidefinite" else "indefinite, so"
            facts.failures.append(BlockFailure(
                b, dofs, f"{kind} not positive definite: an exact rational LDLᵀ of the symmetrised block meets "
                         f"{what} at step {step + 1} of {dofs.size}", proven=True))
            continue
        if dofs.size <= EXACT_LIMIT:
            tried.append(f"the exact rational test (limited to {EXACT_BLOCKS} blocks per matrix)")
        else:
            tried.append(f"no exact rational test (the block has {dofs.size} dofs > {EXACT_LIMIT})")
        witness = _eigenvector_witness(A_sym, A_raw, dofs, facts.exponents[dofs])
        if witness:
            facts.failures.append(BlockFailure(b, dofs, witness, proven=True))
            continue
        tried.append("a search for an exact witness of indefiniteness (2×2 principal minors; xᵀMx for the "
                     "eigenvector of the smallest eigenvalue) that found none")
        facts.failures.append(BlockFailure(b, dofs, "could not verify positive definiteness; tried " + "; ".join(tried)))


def _diagonal_witness(A_sym: sp.csr_matrix, dofs: np.ndarray) -> str:
    """"" or the first diagonal entry of the block that is not positive (the diagonal of the
    float symmetrisation is the data's diagonal exactly)."""
    diag = A_sym.diagonal()[dofs]
    bad = np.flatnonzero(~(diag > 0))
    if not bad.size:
        return ""
    j = int(dofs[bad[0]])
    return f"not positive definite: its diagonal entry [{j},{j}] = {float(diag[bad[0]])!r} is not positive"


def _minor_witness(A_sym: sp.csr_matrix, A_raw, dofs: np.ndarray) -> str:
    """"" or an exact proof that a 2×2 principal minor A_ii A_jj − A_ij² of the exact
    symmetrisation is ≤ 0 (then x = A_jj e_i − A_ij e_j gives xᵀAx = A_jj·minor ≤ 0)."""
    block = sp.coo_matrix(A_sym[dofs][:, dofs])
    d = np.abs(block.diagonal())
    off = block.row < block.col
    i, j, a = block.row[off], block.col[off], block.data[off]
    with np.errstate(all="ignore"):
        near = ~(np.abs(a) < np.sqrt(d[i]) * np.sqrt(d[j]) * (1 - 2.0 ** -20))  # NaN/inf included
    raw = None if A_raw is None else sp.csr_matrix(A_raw)
    for k in np.flatnonzero(near)[:1000]:
        r, c = int(dofs[i[k]]), int(dofs[j[k]])
        if raw is None:
            aij = Fraction(float(A_sym[r, c]))
            aii, ajj = Fraction(float(A_sym[r, r])), Fraction(float(A_sym[c, c]))
        else:
            aij = (Fraction(float(raw[r, c])) + Fraction(float(raw[c, r]))) / 2
            aii, ajj = Fraction(float(raw[r, r])), Fraction(float(raw[c, c]))
        minor = aii * ajj - aij * aij
        if minor <= 0:
            return (f"not positive definite: the 2×2 principal minor of rows {r}, {c} is M_ii·M_jj − M_ij² = "
                    f"{float(minor):.3e} ≤ 0 (exact, M_ij = (M_ij + M_ji)/2 of the data)")
    return ""


def _eigenvector_witness(A_sym: sp.csr_matrix, A_raw, dofs: np.ndarray, e: np.ndarray) -> str:
    """"" or an exact proof xᵀAx ≤ 0 for x = S y, y the computed eigenvector of the smallest
    eigenvalue of the equilibrated block (x rounded to float64; the quadratic form exact)."""
    A = A_sym[dofs][:, dofs]
    if A.nnz > WITNESS_NNZ:
        return ""
    S, _ = scale_symmetric(A, e)
    try:
        if dofs.size <= DENSE_LIMIT:
            w, V = np.linalg.eigh(S.toarray())
            y = V[:, 0]
        else:
            from scipy.sparse.linalg import eigsh

            w, V = eigsh(S.tocsc(), k=1, which="SA", tol=1e-8, maxiter=20 * dofs.size)
            y = V[:, 0]
    except Exception:  # not converged, non-finite: no witness
        return ""
    if not np.all(np.isfinite(y)) or not np.any(y):
        return ""
    x = np.ldexp(y, e)
    R = sp.coo_matrix(sp.csr_matrix(A_raw)[dofs][:, dofs] if A_raw is not None else A)
    xs = [Fraction(float(t)) for t in x]
    q = sum((Fraction(float(v)) * xs[r] * xs[c] for r, c, v in zip(R.row, R.col, R.data)), Fraction(0))
    if q <= 0:
        return (f"not positive definite: xᵀMx = {float(q):.3e} ≤ 0, evaluated exactly, for x the computed "
                f"eigenvector of its smallest eigenvalue")
    return ""
