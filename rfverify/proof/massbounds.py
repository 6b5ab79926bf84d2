"""Verified bounds on the mass matrix M = (M + Mᵀ)/2 (exact symmetrisation of the data).

The certificate (DESIGN §6) needs, rigorously:

* M ≻ 0, with a positive lower bound λ_b ≤ λmin(M_b) for every diagonal block M_b
  (connected component of the sparsity graph: a body, or an FE mesh);
* upper bounds on (M⁻¹)_jj (to turn ‖v − v*‖_M into per-dof bounds) and on hᵀM⁻¹h for the
  columns h of H (per contact-velocity component);
* an upper bound on λmax(M).

Method (floating point with a-priori rounding-error bounds, no change of rounding mode; the
approach of Rump's verified linear algebra).  For a block A:

1. λmin: pick τ ≈ λ̃min/2 from a floating eigen-solver and any floating matrix G with
   A − τI ≈ GGᵀ (from ``eigh`` for small blocks, from a sparse LDLᵀ for large ones).  Then
   A = τI + GGᵀ + E exactly, with E = A − τI − GGᵀ; GGᵀ ⪰ 0 for *any* real G, so
   λmin(A) ≥ τ − ‖E‖₂.  ‖E‖₂ ≤ max(row, column sums) of an entrywise bound B ≥ |E|,
   B = |fl(A − τI − GGᵀ)| + γ·(|G||G|ᵀ + |A| + τI) + underflow terms, with γ covering every
   rounding (including the rounding of the float (M + Mᵀ)/2 against the exact one).
2. For blocks of at most ``DENSE_LIMIT`` dofs, an approximate inverse Z: with
   ρ ≥ ‖I − AZ‖₂ (bounded the same way), ‖A⁻¹ − Z‖₂ ≤ ρ/λ, so for any vector h
   hᵀA⁻¹h ≤ hᵀZh + ‖h‖²ρ/λ, and always hᵀA⁻¹h ≤ ‖h‖²/λ.  Larger blocks use the latter.

The constants are deliberately generous (each is inflated by a factor 1 + 8(k+4)u for a
computation with k roundings); they cost nothing, because they only guard λ against an
error of order 1e-15‖A‖.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

U = 2.0 ** -53  # unit roundoff of float64
ETA = 2.0 ** -1074  # smallest subnormal: absolute error of an underflowing product
DENSE_LIMIT = 400


def gamma(k: int) -> float:
    """γ_k = k·u/(1 − k·u), rounded up generously."""
    return 2.0 * k * U / (1.0 - 2.0 * k * U)


def inflate(x, k: int):
    """x (≥ 0, computed with k roundings) times 1 + 8(k+4)u: a rigorous upper bound."""
    return np.nextafter(np.asarray(x, dtype=np.float64) * (1.0 + 8.0 * (k + 4) * U), np.inf)


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


def deflate(x, k: int):
    """x (> 0, computed with k roundings) times 1 − 8(k+4)u: a rigorous lower bound."""
    return np.nextafter(np.asarray(x, dtype=np.float64) * (1.0 - 8.0 * (k + 4) * U), -np.inf)


@dataclass
class BlockFailure:
    block: int
    dofs: np.ndarray
    reason: str


@dataclass
class MassBounds:
    """Verified facts about M = (M + Mᵀ)/2, block by block.

    ``labels[j]`` block of dof j; ``lam_lower[b]`` > 0 with λmin(M_b) ≥ it (NaN where the
    proof failed, see ``failures``); ``minv_diag_upper[j]`` ≥ (M⁻¹)_jj; ``m_diag[j]`` = M_jj
    (exact float64 of the data's diagonal); ``lam_max_upper`` ≥ λmax(M).
    """

    labels: np.ndarray
    lam_lower: np.ndarray
    minv_diag_upper: np.ndarray
    m_diag_upper: np.ndarray
    lam_max_upper: float
    failures: list = field(default_factory=list)
    # size → (blocks with an approximate inverse, Z stacked (nb, s, s), ρ ≥ ‖I − M_b Z_b‖₂)
    _groups: dict = field(default_factory=dict, repr=False)
    _local: np.ndarray | None = field(default=None, repr=False)
    dense_blocks: int = 0
    sparse_blocks: int = 0

    @property
    def proven(self) -> bool:
        return not self.failures

    def quad_upper_columns(self, H: sp.spmatrix) -> np.ndarray:
        """Upper bounds of h_kᵀ M⁻¹ h_k for every column h_k of H (m × K), rigorous."""
        Hc = sp.coo_matrix(H)
        K = Hc.shape[1]
        out = np.zeros(K, dtype=np.float64)
        if Hc.nnz == 0:
            return out
        blk = self.labels[Hc.row]
        # Group the nonzeros by (column, block) pairs.
        key = Hc.col.astype(np.int64) * (int(self.labels.max()) + 1) + blk
        pairs, inv = np.unique(key, return_inverse=True)
        pair_col = pairs // (int(self.labels.max()) + 1)
        pair_blk = pairs % (int(self.labels.max()) + 1)
        sq = np.zeros(pairs.size)
        np.add.at(sq, inv, Hc.data.astype(np.float64) ** 2)
        sq = inflate(sq, 2 + int(np.max(np.bincount(inv))))  # ≥ ‖h_kb‖²
        crude = inflate(sq / self.lam_lower[pair_blk], 1)  # ‖h‖²/λ
        best = crude.copy()
        # Tighter: hᵀZh + ‖h‖²ρ/λ for blocks with an approximate inverse, batched by size.
        for s, (blocks_s, Zs, rhos) in self._groups.items():
            if blocks_s.size == 0:
                continue
            slot = np.full(self.lam_lower.size, -1, dtype=np.int64)
            slot[blocks_s] = np.arange(blocks_s.size)
            sel = np.flatnonzero(slot[pair_blk] >= 0)
            if sel.size == 0:
                continue
            dense = np.zeros((sel.size, s))
            where = np.full(pairs.size, -1, dtype=np.int64)
            where[sel] = np.arange(sel.size)
            nzsel = where[inv] >= 0
            np.add.at(dense, (where[inv[nzsel]], self._local[Hc.row[nzsel]]), Hc.data[nzsel])
            absd = np.abs(dense)
            Z = Zs[slot[pair_blk[sel]]]
            rho = rhos[slot[pair_blk[sel]]]
            hz = np.einsum("pi,pij,pj->p", dense, Z, dense)
            ahz = np.einsum("pi,pij,pj->p", absd, np.abs(Z), absd)
            up = upper_sum(hz, inflate(gamma(2 * s + 2) * ahz + s * 4 * ETA, 3),
                           inflate(sq[sel] * rho / self.lam_lower[pair_blk[sel]], 2))
            best[sel] = np.minimum(best[sel], up)
        np.add.at(out, pair_col, best)
        counts = np.bincount(pair_col, minlength=K)
        return inflate(out, 2 + int(counts.max(initial=1)))


def _blocks(M_sym: sp.csc_matrix):
    n_blocks, labels = connected_components(M_sym, directed=False)
    return n_blocks, labels


def verify_mass_matrix(M_raw: sp.spmatrix, M_sym: sp.spmatrix | None = None) -> MassBounds:
    """Verified bounds for the exact symmetrisation (M_raw + M_rawᵀ)/2 (see module doc)."""
    M_raw = sp.csc_matrix(M_raw, dtype=np.float64)
    if M_sym is None:
        M_sym = ((M_raw + M_raw.T) * 0.5).tocsc()
    M_sym = sp.csc_matrix(M_sym)
    m = M_sym.shape[0]
    n_blocks, labels = _blocks(M_sym)
    order = np.argsort(labels, kind="stable")
    sizes = np.bincount(labels, minlength=n_blocks)
    starts = np.concatenate(([0], np.cumsum(sizes)))
    local = np.empty(m, dtype=np.int64)
    local[order] = np.arange(m) - starts[labels[order]]
    lam_lower = np.full(n_blocks, np.nan)
    minv_diag = np.full(m, np.inf)
    dense_groups = {}  # size → (blocks with a usable approximate inverse, their Z, their ρ)
    failures = []
    csr = M_sym.tocsr()
    diag = M_sym.diagonal()
    # |A_float − A_exact| ≤ u|A_exact|: the float (M + Mᵀ)/2 is one rounding of the exact one.
    absA = abs(csr)
    row_abs = np.asarray(absA.sum(axis=1)).ravel()
    n_dense = n_sparse = 0
    for s in np.unique(sizes):
        blocks_s = np.flatnonzero(sizes == s)
        if s <= DENSE_LIMIT:
            n_dense += blocks_s.size
            dofs = order[(starts[blocks_s][:, None] + np.arange(s)[None, :])]
            A = np.stack([csr[d][:, d].toarray() for d in dofs]) if blocks_s.size < 64 or s > 8 \
                else _gather_dense(csr, dofs)
            lam, Z, rho, bad = _dense_blocks(A)
            ok = np.array([not msg for msg in bad], dtype=bool)
            for k in np.flatnonzero(~ok):
                failures.append(BlockFailure(int(blocks_s[k]), dofs[k], bad[k]))
            good = np.flatnonzero(ok)
            lam_lower[blocks_s[good]] = lam[good]
            usable = ok & (rho < 1) if Z is not None else np.zeros_like(ok)
            zd = np.where(usable[:, None], np.diagonal(Z, axis1=1, axis2=2) if Z is not None else np.inf, np.inf)
            with np.errstate(invalid="ignore", divide="ignore"):
                via_z = upper_sum(zd, inflate(rho / lam, 1)[:, None])
                crude = inflate(1.0 / lam, 1)[:, None]
            minv_diag[dofs[good]] = np.minimum(via_z, crude)[good]
            dense_groups[int(s)] = (blocks_s[usable], Z[usable] if Z is not None else None, rho[usable])
        else:
            for b in blocks_s:
                n_sparse += 1
                d = order[starts[b]:starts[b + 1]]
                A = csr[d][:, d].tocsc()
                lam_b, why = verify_lambda_min_sparse(A, abs(A) * (2 * U))
                if why:
                    failures.append(BlockFailure(int(b), d, why))
                    continue
                lam_lower[b] = lam_b
                minv_diag[d] = inflate(1.0 / lam_b, 1)
    lam_max = float(inflate(np.max(row_abs, initial=0.0) * (1 + 4 * U), 2 + int(np.max(np.diff(csr.indptr), initial=1))))
    return MassBounds(labels=labels, lam_lower=lam_lower, minv_diag_upper=minv_diag,
                      m_diag_upper=inflate(np.abs(diag), 1), lam_max_upper=lam_max, failures=failures,
                      _groups=dense_groups, _local=local, dense_blocks=n_dense, sparse_blocks=n_sparse)


def _gather_dense(csr: sp.csr_matrix, dofs: np.ndarray) -> np.ndarray:
    """Dense blocks A[b] = M[dofs[b]][:, dofs[b]] for many small equal-size blocks, vectorised."""
    nb, s = dofs.shape
    pos = np.full(csr.shape[0], -1, dtype=np.int64)
    pos[dofs.ravel()] = np.tile(np.arange(s), nb)
    blk = np.full(csr.shape[0], -1, dtype=np.int64)
    blk[dofs.ravel()] = np.repeat(np.arange(nb), s)
    coo = csr[dofs.ravel()].tocoo()
    rows = dofs.ravel()[coo.row]
    A = np.zeros((nb, s, s))
    ok = blk[coo.col] == blk[rows]
    np.add.at(A, (blk[rows][ok], pos[rows][ok], pos[coo.col][ok]), coo.data[ok])
    return A


def _dense_blocks(A: np.ndarray):
    """Batched verification for equal-size dense blocks A (nb, s, s).  Returns
    (λ lower bounds, approximate inverses Z or None, ρ ≥ ‖I − AZ‖₂, failure reasons)."""
    nb, s, _ = A.shape
    bad = [""] * nb
    if not np.all(np.isfinite(A)):
        return np.full(nb, np.nan), None, np.ones(nb), ["non-finite entries"] * nb
    lam, V = np.linalg.eigh(A)
    lmin = lam[:, 0]
    eye = np.eye(s)

    def lower_bound(tau):
        # A = τI + GGᵀ + E exactly for any τ and G (GGᵀ ⪰ 0), so λmin(A) ≥ τ − ‖E‖₂ whatever τ is.
        d = np.sqrt(np.maximum(lam - tau[:, None], 0.0))
        G = V * d[:, None, :]
        F = (A - tau[:, None, None] * eye) - G @ np.swapaxes(G, 1, 2)
        absG = np.abs(G)
        B = np.abs(F) + gamma(s + 4) * (absG @ np.swapaxes(absG, 1, 2) + np.abs(A) + np.abs(tau)[:, None, None] * eye) \
            + 2 * U * np.abs(A) + (s + 4) * ETA
        B = inflate(B, s + 6)
        normE = inflate(np.maximum(B.sum(axis=1).max(axis=1), B.sum(axis=2).max(axis=1)), s + 2)
        return deflate(tau - normE, 2), normE

    # τ just below the computed λmin makes the bound nearly λmin itself (the r bounds divide by
    # its root); τ = λmin/2 is the fallback where rounding makes the first useless.
    lam_near, normE = lower_bound(lmin * (1 - 2.0 ** -20))
    lam_half, normE_half = lower_bound(lmin * 0.5)
    lam_lower = np.fmax(lam_near, lam_half)
    normE = np.where(lam_near >= lam_half, normE, normE_half)
    for k in range(nb):
        if not lmin[k] > 0:
            bad[k] = f"not positive definite (smallest eigenvalue ≈ {lmin[k]:.3e})"
        elif not lam_lower[k] > 0:
            bad[k] = (f"positive definiteness could not be proven in double precision (λmin ≈ "
                      f"{lmin[k]:.3e}, rounding-error bound {normE[k]:.3e})")
    Z = None
    rho = np.ones(nb)
    try:
        with np.errstate(all="ignore"):
            Z = np.linalg.inv(A)
        if not np.all(np.isfinite(Z)):
            raise np.linalg.LinAlgError
        absZ = np.abs(Z)
        R = eye - A @ Z
        BR = np.abs(R) + (gamma(s + 2) + 2 * U) * (eye + np.abs(A) @ absZ) + (s + 2) * ETA
        BR = inflate(BR, s + 6)
        rho = inflate(np.maximum(BR.sum(axis=1).max(axis=1), BR.sum(axis=2).max(axis=1)), s + 2)
    except np.linalg.LinAlgError:
        Z = None
        rho = np.ones(nb)
    return lam_lower, Z, rho, bad


def verify_lambda_min_sparse(A: sp.csc_matrix, A_err: sp.spmatrix, tau: float | None = None,
                             attempts: int = 4):
    """Rigorous lower bound of λmin(A_exact) for a sparse symmetric float matrix A with
    |A − A_exact| ≤ A_err entrywise.  Returns (λ_lower, "") or (nan, reason)."""
    from scipy.sparse.linalg import eigsh, splu

    A = sp.csc_matrix(A, dtype=np.float64)
    n = A.shape[0]
    if not np.all(np.isfinite(A.data)):
        return np.nan, "non-finite entries"
    if tau is None:
        try:
            if n < 3:  # ARPACK needs k < n - 1: a tiny matrix is solved densely
                est = float(np.linalg.eigvalsh(A.toarray())[0])
            else:
                est = float(eigsh(A, k=1, sigma=0, which="LM", return_eigenvectors=False, tol=1e-4)[0])
        except Exception:  # singular or not converged: fall back to a diagonal-based guess
            est = float(np.min(A.diagonal())) * 1e-3
        if not est > 0:
            return np.nan, f"not positive definite (smallest eigenvalue ≈ {est:.3e})"
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
            return lam, ""
        last = f"rounding-error bound {normE:.3e} ≥ τ = {tau:.3e}"
    return np.nan, f"positive definiteness could not be proven in double precision ({last})"
