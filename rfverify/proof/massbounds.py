"""Verified bounds on the mass matrix M = (M + Mᵀ)/2 (exact symmetrisation of the data).

The certificate (DESIGN §6) needs, rigorously:

* M ≻ 0, with a positive lower bound λ_b ≤ λmin(M_b) for every diagonal block M_b
  (connected component of the sparsity graph: a body, or an FE mesh);
* upper bounds on (M⁻¹)_jj (to turn ‖v − v*‖_M into per-dof bounds), on hᵀM⁻¹h for the
  columns h of H (per contact-velocity component) and on gᵀM⁻¹g;
* an upper bound on λmax(M).

Everything is proven on the **equilibrated** blocks S M_b S, S = diag(2^e_j) exact
(:mod:`rfverify.model.definiteness`: verified floating point with a-priori rounding-error bounds,
exact rationals where that cannot decide), and carried back through the exact S:
(M⁻¹)_jj = s_j²((SMS)⁻¹)_jj, hᵀM⁻¹h = (Sh)ᵀ(SMS)⁻¹(Sh) ≤ ‖Sh‖²/λmin(SMS), λmin(M_b) ≥
λmin(S M_b S)/max s_j².  So the bounds do not depend on the units of the dofs: a body whose
translations are in grams and rotations in g·mm² is bounded as well as one in SI units.

For blocks of at most ``DENSE_LIMIT`` dofs an approximate inverse Z of A = S M_b S tightens
them: with ρ ≥ ‖I − AZ‖₂ (bounded the same way), ‖A⁻¹ − Z‖₂ ≤ ρ/λ, so for any vector h
hᵀA⁻¹h ≤ hᵀZh + ‖h‖²ρ/λ, and always hᵀA⁻¹h ≤ ‖h‖²/λ.  Larger blocks use the latter.

The constants are deliberately generous (each is inflated by a factor 1 + 8(k+4)u for a
computation with k roundings); they cost nothing, because they only guard λ against an
error of order 1e-15‖A‖.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..model.definiteness import (DENSE_LIMIT, ETA, U, BlockFailure, Definiteness, deflate, gamma, gather_blocks,
                            inflate, ldexp_up, scale_rows, scale_symmetric, sparse_lambda_lower, upper_sum,
                            verify_definite)

__all__ = ["MassBounds", "verify_mass_matrix", "verify_lambda_min_sparse", "BlockFailure", "gamma", "inflate",
           "deflate", "upper_sum", "U", "ETA", "DENSE_LIMIT"]


@dataclass
class MassBounds:
    """Verified facts about M = (M + Mᵀ)/2, block by block.

    ``labels[j]`` block of dof j; ``exponents[j]`` its equilibration (s_j = 2^e_j);
    ``lam_scaled[b]`` > 0 with λmin(S M_b S) ≥ it and ``lam_lower[b]`` with λmin(M_b) ≥ it (NaN
    where the proof failed, see ``failures``); ``minv_diag_upper[j]`` ≥ (M⁻¹)_jj;
    ``m_diag_upper[j]`` ≥ M_jj; ``lam_max_upper`` ≥ λmax(M).
    """

    labels: np.ndarray
    lam_lower: np.ndarray
    minv_diag_upper: np.ndarray
    m_diag_upper: np.ndarray
    lam_max_upper: float
    failures: list = field(default_factory=list)
    exponents: np.ndarray | None = None
    lam_scaled: np.ndarray | None = None
    # size → (blocks with an approximate inverse, Z stacked (nb, s, s), ρ ≥ ‖I − A_b Z_b‖₂), A = SMS
    _groups: dict = field(default_factory=dict, repr=False)
    _local: np.ndarray | None = field(default=None, repr=False)
    dense_blocks: int = 0
    sparse_blocks: int = 0

    def __post_init__(self):
        if self.exponents is None:  # unscaled facts (built by hand): S = I
            self.exponents = np.zeros(self.labels.size, dtype=np.int64)
        if self.lam_scaled is None:
            self.lam_scaled = self.lam_lower

    @property
    def proven(self) -> bool:
        return not self.failures

    def quad_upper_columns(self, H: sp.spmatrix) -> np.ndarray:
        """Upper bounds of h_kᵀ M⁻¹ h_k = (Sh_k)ᵀ(SMS)⁻¹(Sh_k) for every column h_k of H (m × K),
        rigorous."""
        Hc, inexact = scale_rows(H, self.exponents)
        K = Hc.shape[1]
        out = np.zeros(K, dtype=np.float64)
        if Hc.nnz == 0:
            return out
        nb = int(self.labels.max()) + 1
        blk = self.labels[Hc.row]
        # Group the nonzeros by (column, block) pairs.
        key = Hc.col.astype(np.int64) * nb + blk
        pairs, inv = np.unique(key, return_inverse=True)
        pair_col = pairs // nb
        pair_blk = pairs % nb
        # An entry of Sh that underflowed is within ETA of the exact one: its magnitude bound grows
        # by ETA, and its pair takes the crude bound (the approximate inverse needs exact entries).
        mag = np.abs(Hc.data) + np.where(inexact, ETA, 0.0)
        sq = np.zeros(pairs.size)
        np.add.at(sq, inv, mag ** 2)
        per_pair = np.bincount(inv)
        # A square that underflows is low by less than ETA: one ETA per term covers it.
        sq = inflate(sq + per_pair * ETA, 2 + int(np.max(per_pair)))  # ≥ ‖(Sh)_kb‖²
        rough = np.zeros(pairs.size, dtype=bool)
        rough[inv[inexact]] = True
        crude = inflate(sq / self.lam_scaled[pair_blk], 1)  # ‖Sh‖²/λ
        best = crude.copy()
        # Tighter: hᵀZh + ‖h‖²ρ/λ for blocks with an approximate inverse, batched by size.
        for s, (blocks_s, Zs, rhos) in self._groups.items():
            if blocks_s.size == 0:
                continue
            slot = np.full(self.lam_scaled.size, -1, dtype=np.int64)
            slot[blocks_s] = np.arange(blocks_s.size)
            sel = np.flatnonzero((slot[pair_blk] >= 0) & ~rough)
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
                           inflate(sq[sel] * rho / self.lam_scaled[pair_blk[sel]], 2))
            best[sel] = np.minimum(best[sel], up)
        np.add.at(out, pair_col, best)
        counts = np.bincount(pair_col, minlength=K)
        return inflate(out, 2 + int(counts.max(initial=1)))


def verify_mass_matrix(M_raw: sp.spmatrix, M_sym: sp.spmatrix | None = None,
                       facts: Definiteness | None = None) -> MassBounds:
    """Verified bounds for the exact symmetrisation (M_raw + M_rawᵀ)/2 (see module doc).
    ``M_sym`` is its float64 rounding when already computed; ``facts`` the definiteness facts
    :func:`rfverify.model.definiteness.verify_definite` gave for it (``problem.blocks``), reused
    rather than proven again."""
    M_raw = sp.csc_matrix(M_raw, dtype=np.float64)
    if M_sym is None:
        M_sym = ((M_raw * 0.5 + M_raw.T * 0.5)).tocsc()
    M_sym = sp.csc_matrix(M_sym)
    m = M_sym.shape[0]
    if facts is None or facts.labels.size != m:
        facts = verify_definite(M_sym, M_raw)
    labels, sizes, exps = facts.labels, facts.sizes, facts.exponents
    order, starts = facts.block_dofs()
    local = np.empty(m, dtype=np.int64)
    local[order] = np.arange(m) - starts[labels[order]]
    lam_scaled = facts.lam_scaled.copy()
    proven = np.isfinite(lam_scaled) & (lam_scaled > 0)
    minv_scaled = np.full(m, np.inf)  # ≥ ((SMS)⁻¹)_jj
    dense_groups = {}  # size → (blocks with a usable approximate inverse, their Z, their ρ)
    S, _ = scale_symmetric(M_sym, exps)
    n_dense = n_sparse = 0
    for s in np.unique(sizes):
        blocks_s = np.flatnonzero(sizes == s)
        if s <= DENSE_LIMIT:
            n_dense += blocks_s.size
            good = blocks_s[proven[blocks_s]]
            if good.size == 0:
                continue
            dofs = order[(starts[good][:, None] + np.arange(s)[None, :])]
            lam = lam_scaled[good]
            crude = inflate(1.0 / lam, 1)[:, None]
            Z, rho = _approximate_inverses(gather_blocks(S.tocsr(), dofs))
            usable = rho < 1 if Z is not None else np.zeros(good.size, dtype=bool)
            bound = crude
            if usable.any():
                with np.errstate(invalid="ignore", divide="ignore"):
                    via_z = upper_sum(np.diagonal(Z, axis1=1, axis2=2), inflate(rho / lam, 1)[:, None])
                bound = np.where(usable[:, None], np.minimum(via_z, crude), crude)
            minv_scaled[dofs] = bound
            dense_groups[int(s)] = (good[usable], Z[usable] if Z is not None else None, rho[usable])
        else:
            n_sparse += blocks_s.size
            for b in blocks_s[proven[blocks_s]]:
                minv_scaled[order[starts[b]:starts[b + 1]]] = inflate(1.0 / lam_scaled[b], 1)
    minv_diag = ldexp_up(minv_scaled, 2 * exps)  # (M⁻¹)_jj = s_j²((SMS)⁻¹)_jj
    csr = M_sym.tocsr()
    row_abs = np.asarray(abs(csr).sum(axis=1)).ravel()
    lam_max = float(inflate(np.max(row_abs, initial=0.0) * (1 + 4 * U), 2 + int(np.max(np.diff(csr.indptr), initial=1))))
    return MassBounds(labels=labels, lam_lower=facts.lam_lower, minv_diag_upper=minv_diag,
                      m_diag_upper=inflate(np.abs(M_sym.diagonal()), 1), lam_max_upper=lam_max,
                      failures=list(facts.failures), exponents=exps, lam_scaled=lam_scaled,
                      _groups=dense_groups, _local=local, dense_blocks=n_dense, sparse_blocks=n_sparse)


def _approximate_inverses(A: np.ndarray):
    """Approximate inverses Z of equal-size dense blocks A (nb, s, s) (proven definite) and
    ρ ≥ ‖I − AZ‖₂ (rigorous); (None, ones) where inversion fails."""
    nb, s, _ = A.shape
    eye = np.eye(s)
    try:
        with np.errstate(all="ignore"):
            Z = np.linalg.inv(A)
        if not np.all(np.isfinite(Z)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        return None, np.ones(nb)
    absZ = np.abs(Z)
    R = eye - A @ Z
    BR = np.abs(R) + (gamma(s + 2) + 2 * U) * (eye + np.abs(A) @ absZ) + (s + 2) * ETA
    BR = inflate(BR, s + 6)
    rho = inflate(np.maximum(BR.sum(axis=1).max(axis=1), BR.sum(axis=2).max(axis=1)), s + 2)
    return Z, rho


def verify_lambda_min_sparse(A: sp.csc_matrix, A_err: sp.spmatrix, tau: float | None = None,
                             attempts: int = 4):
    """Rigorous lower bound of λmin(A_exact) for a sparse symmetric float matrix A with
    |A − A_exact| ≤ A_err entrywise.  Returns (λ_lower, "") or (nan, reason)."""
    lam, why, _ = sparse_lambda_lower(A, A_err, tau, attempts)
    if why:
        why = f"positive definiteness could not be proven in double precision ({why})"
    return lam, why


def verified_left_inverses(A: np.ndarray, dA: np.ndarray | None = None):
    """Approximate inverses X of equal-size dense float blocks A (nb, s, s), any symmetry, and
    rigorous entrywise bounds of the left residual: ``rows[b, i]`` ≥ Σ_j |I − X_b A_b^ex|_ij
    for every exact block with |A_b^ex − A_b| ≤ ``dA`` entrywise (None: A is exact), and
    ``rho[b]`` ≥ ‖I − X_b A_b^ex‖∞ (the largest of those row sums).  Where the inverse fails,
    X is NaN and ρ = ∞.  With ρ < 1, d = (A^ex)⁻¹g obeys d = Xg + (I − XA^ex)d, so
    ‖d‖∞ ≤ ‖Xg‖∞/(1 − ρ) and |d_i| ≤ |Xg|_i + rows_i·‖d‖∞ (:func:`solve_upper`).

    Rounding: P = fl(XA) has |P − XA| ≤ γ_s|X||A| (+ an underflow per product, ≤ s·ETA), and
    R = fl(I − P) one more rounding, so |I − XA| ≤ |R| + (γ_{s+2} + 2u)(I + |X||A|) + (s+2)·ETA;
    the data's own uncertainty adds |X|·dA.  Every product of these bounds is inflated for its
    own roundings."""
    nb, s, _ = A.shape
    eye = np.eye(s)
    with np.errstate(all="ignore"):
        try:
            X = np.linalg.inv(A)
        except np.linalg.LinAlgError:  # some block is singular in float64: none of the batch
            X = np.full_like(A, np.nan)
        ok = np.all(np.isfinite(X), axis=(1, 2))
        X = np.where(ok[:, None, None], X, 0.0)
        absX = np.abs(X)
        R = eye - X @ A
        BE = np.abs(R) + (gamma(s + 2) + 2 * U) * (eye + absX @ np.abs(A)) + (s + 2) * ETA
        if dA is not None:
            BE = BE + absX @ dA
        BE = inflate(BE, s + 6)
        rows = inflate(BE.sum(axis=2), s + 2)
        rho = np.where(ok & np.all(np.isfinite(rows), axis=1), rows.max(axis=1, initial=0.0), np.inf)
    X = np.where(ok[:, None, None], X, np.nan)
    return X, rows, rho


def solve_upper(X: np.ndarray, rows: np.ndarray, rho: np.ndarray, g_mid: np.ndarray, g_rad: np.ndarray) -> np.ndarray:
    """Rigorous upper bounds (nb, s) of |(A^ex)⁻¹ g| per block for every g with |g − g_mid| ≤
    g_rad, from :func:`verified_left_inverses` (X, rows, ρ): t ≥ |Xg| (X g_mid in float64, its
    rounding γ_{s+1}|X||g_mid| + s·ETA, and |X|g_rad), then |d| ≤ t + rows·‖t‖∞/(1 − ρ).
    Blocks with ρ ≥ 1 (or non-finite data) get ∞."""
    nb, s = g_mid.shape
    with np.errstate(all="ignore"):
        absX = np.abs(X)
        y = np.einsum("bij,bj->bi", X, g_mid)
        t = np.abs(y) + gamma(s + 1) * np.einsum("bij,bj->bi", absX, np.abs(g_mid)) \
            + np.einsum("bij,bj->bi", absX, g_rad) + s * ETA
        t = inflate(t, s + 4)
        one_minus = np.nextafter(1.0 - rho, -np.inf)  # ≤ 1 − ρ (one subtraction, rounded down)
        D = np.nextafter(t.max(axis=1, initial=0.0) / one_minus, np.inf)  # ≥ ‖d‖∞
        out = inflate(t + rows * D[:, None], 2)
        good = (rho < 1) & np.all(np.isfinite(out), axis=1)
    return np.where(good[:, None], out, np.inf)
