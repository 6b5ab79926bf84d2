"""A local rolling-friction problem ``u = W r + q`` (W the Delassus matrix) lifted to global
form, as both local file formats need it: a Siconos local ``.dat`` file (:mod:`.siconos_dat`)
and an FCLIB ``/fclib_local`` group (:mod:`.fclib3d`).

:func:`factor_delassus` factors W = HᵀH (symmetric eigendecompositions of W's connected blocks,
the numerical rank kept) and reports what it did (:class:`LiftReport`); :func:`lift_local` builds the global
:class:`~rfverify.model.problem.Problem` M = I, H, f = 0, w = q.  The lifting is a solver device: the
extended phase and the proof work on the file's own W (``Problem.local``, DESIGN §6.1b).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidProblemError
from ..model.problem import DEFAULT_MAX_ASYMMETRY, Problem, SymmetryReport, asymmetry_error

_TINY = np.finfo(float).tiny

LOCAL_DENSE_LIMIT = 10000
"""Largest W (rows) of a local problem: the lifting holds W as a dense array (and factors each
connected block of it densely)."""


@dataclass(frozen=True)
class LocalProblem:
    """A local (reduced) rolling-friction problem ``u = W r + q``, ``K* ∋ u ⊥ r ∈ K``.

    W (5n×5n, symmetric positive semidefinite up to data precision), q (5n,), mu, mu_r (n,).
    ``significant_digits`` is the precision of the printed data (None = full double).
    """

    W: np.ndarray
    q: np.ndarray
    mu: np.ndarray
    mu_r: np.ndarray
    significant_digits: int | None = None

    @property
    def n_contacts(self) -> int:
        return int(self.mu.size)


@dataclass(frozen=True)
class LiftReport:
    """What :func:`lift_local` did: W = HᵀH with H = Λ^{1/2}Vᵀ on the kept eigenpairs."""

    rank: int
    dropped: int
    min_eigenvalue: float
    max_eigenvalue: float
    rank_tol: float
    asymmetry: float
    """Entrywise max |W_ij − W_ji|/sqrt(W_ii W_jj) (thresholded by ``max_asymmetry``)."""
    asymmetry_normwise: float = 0.0
    """‖W − Wᵀ‖_F/‖W‖_F (information)."""
    asymmetry_at: list | None = None
    """(row, col) where the entrywise asymmetry is attained (None: W exactly symmetric)."""


def lift_local(local: LocalProblem, *, rank_tol: float | None = None,
               max_asymmetry: float = DEFAULT_MAX_ASYMMETRY):
    """Lift a local problem (W, q) to global form: M = I_m, H = Λ^{1/2}Vᵀ (m×5n), f = 0, w = q.

    W is symmetrised and factored as W = V Λ Vᵀ (a dense symmetric eigendecomposition of each
    connected block of W, so H is as sparse as W's blocks: fine for the few-thousand-row local
    problems Siconos prints; one connected pile of them gives a dense H).  Eigenvalues
    ≤ 100·eps·5n·‖W‖₂ (the eigensolver's rounding) are dropped (W is often singular; m = the numerical rank), so
    HᵀH = W up to rounding, and u = HᵀH r + q ≈ W r + q.  The lifting is a *solver device*:
    the extended phase and the proof work on the file's W itself (``Problem.local``,
    DESIGN §6.1b), never on HᵀH.

    ``rank_tol`` (default: the data precision) is the refusal threshold: an eigenvalue below
    −rank_tol·‖W‖ is refused as not PSD.  A print-out rounded to d significant digits perturbs
    each entry by |E_ij| ≤ ½·10^(1−d)·|W_ij|, so every eigenvalue moves by at most
    ½·10^(1−d)·‖|W|‖₂: a printed singular W may be that far from PSD and is still read (the
    certificate then says whether the printed W is PSD).  A ``rank_tol`` given explicitly is
    also the drop threshold.  See :func:`factor_delassus`.

    Raises
    ------
    InvalidProblemError
        field ``"W"``: asymmetric beyond ``max_asymmetry``, non-finite, or with an eigenvalue
        below −rank_tol·‖W‖ (not positive semidefinite).
    """
    # q, mu, mu_r become w, mu, mu_r of the lifted problem: check them under their own names.
    for name, vec in (("q", local.q), ("mu", local.mu), ("mu_r", local.mu_r)):
        check_finite(name, vec)
    dim = np.asarray(local.W).shape[0]
    H, report = factor_delassus(local.W, significant_digits=local.significant_digits,
                                rank_tol=rank_tol, max_asymmetry=max_asymmetry)
    m = H.shape[0]
    problem = Problem.from_arrays(
        sp.identity(m, format="csc"), sp.csc_matrix(H), np.zeros(m), local.q, local.mu, local.mu_r,
        title="lifted local rolling problem",
        description=(f"local problem (W {dim}×{dim}, rank {m}) lifted to global form: M = I, "
                     f"H = Λ^1/2 Vᵀ from W = V Λ Vᵀ, f = 0, w = q"),
        storage={"M": "csc", "H": "csc"},
    )
    return problem, report


def check_finite(name: str, vec) -> None:
    """InvalidProblemError naming ``name`` and the first index when ``vec`` holds NaN/Inf."""
    vec = np.asarray(vec, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(vec))
    if bad.size:
        raise InvalidProblemError(name, f"contains a non-finite value ({vec[bad[0]]!r}) at index "
                                        f"{bad[0]} ({bad.size} in all)", index=int(bad[0]),
                                  fix="remove NaN/Inf from the data")


def factor_delassus(W, *, significant_digits: int | None = None, rank_tol: float | None = None,
                    max_asymmetry: float = DEFAULT_MAX_ASYMMETRY):
    """The factor H (m × dim, m = numerical rank) with HᵀH = (W + Wᵀ)/2 up to ``rank_tol``, and
    its :class:`LiftReport`: the lifting of :func:`lift_local`, on any square W (the 5n×5n W of a
    rolling problem or the 3n×3n W of an FCLIB ``/fclib_local`` problem).

    The asymmetry of W is measured entrywise (max |W_ij − W_ji|/sqrt(W_ii W_jj), thresholded by
    ``max_asymmetry``) and normwise (‖W − Wᵀ‖_F/‖W‖_F, reported).
    """
    W = np.asarray(W, dtype=np.float64)
    dim = W.shape[0]
    if not np.all(np.isfinite(W)):
        i, j = np.argwhere(~np.isfinite(W))[0]
        raise InvalidProblemError("W", f"contains a non-finite value ({float(W[i, j])!r})", index=(int(i), int(j)),
                                  fix="remove NaN/Inf from the data")
    d = np.sqrt(np.abs(np.diag(W)))
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        asym = np.abs(W - W.T)  # an overflow here is an asymmetry too large to accept
        scaled = np.where(asym > 0, asym / np.outer(d, d), 0.0)
    scaled[np.isnan(scaled)] = np.inf
    asymmetry = float(scaled.max()) if scaled.size else 0.0
    big = float(np.abs(W).max()) if W.size else 0.0
    normwise = 0.0
    if big > 0:  # Frobenius norms of W / max|W|: squares of entries near 1e154 would overflow
        with np.errstate(over="ignore", invalid="ignore"):
            normwise = float(np.linalg.norm(W / big - W.T / big) / np.linalg.norm(W / big))
    at = None
    if asymmetry > 0:
        i, j = np.unravel_index(np.argmax(scaled), scaled.shape)
        at = (int(i), int(j))
    if not asymmetry <= max_asymmetry:
        raise asymmetry_error("W", SymmetryReport(asymmetry, normwise, *(at or (None, None))),
                              max_asymmetry)
    if big == 0.0:
        raise InvalidProblemError("W", "is zero", fix="a local problem needs a non-zero Delassus matrix")
    # Work on W / 2^k ≤ 1 (exact scaling): entries near 1e308 would overflow W + Wᵀ and the
    # eigensolver's norms.
    exp = int(np.frexp(big)[1])
    Ws = 0.5 * (np.ldexp(W, -exp) + np.ldexp(W.T, -exp))
    lam, vecs, rows, cols, abs_norm_s = _blockwise_eigh(Ws, abs_norm=bool(significant_digits) and rank_tol is None)
    norm_s = float(np.max(np.abs(lam)))
    norm = float(np.ldexp(norm_s, exp))
    # Two thresholds: an eigenvalue below −psd_tol·‖W‖ is refused (not PSD even allowing for the
    # print precision); eigenvalues above keep_tol·‖W‖ are kept.  The printed numbers are the
    # data exactly (DESIGN §6), so keep_tol is the eigensolver's rounding, not the print precision.
    keep_tol = 100 * np.finfo(float).eps * dim if rank_tol is None else rank_tol
    if rank_tol is None:
        if significant_digits:
            rank_tol = 0.5 * 10.0 ** (1 - significant_digits) * abs_norm_s / max(norm_s, _TINY)
        else:
            rank_tol = keep_tol
    if norm_s == 0.0:
        raise InvalidProblemError("W", "is zero to working precision",
                                  fix="a local problem needs a non-zero Delassus matrix")
    lowest = float(lam.min())
    if lowest < -rank_tol * norm_s:
        raise InvalidProblemError(
            "W", f"is not positive semidefinite: eigenvalue {np.ldexp(lowest, exp):.3e} < -{rank_tol:.1e}·‖W‖ "
                 f"(‖W‖ = {norm:.3e})",
            fix=f"a Delassus matrix W = H M⁻¹ Hᵀ is PSD, and this one is farther from it than the rounding of the "
                f"file's values explains ({rank_tol:.1e}·‖W‖): check the data (--psd-shift, which covers "
                f"rounding, does not apply to a W refused here)")
    keep = lam > keep_tol * norm_s
    kept = np.flatnonzero(keep)
    scale = np.sqrt(np.ldexp(lam[kept], exp))
    # Row k of H is sqrt(λ_k)·v_kᵀ, nonzero only on its block's columns.
    entry = np.isin(rows, kept)
    new_row = np.searchsorted(kept, rows[entry])
    H = sp.csr_matrix((vecs[entry] * scale[new_row], (new_row, cols[entry])), shape=(kept.size, dim))
    m = H.shape[0]
    report = LiftReport(rank=int(m), dropped=int(dim - m), min_eigenvalue=float(np.ldexp(lowest, exp)),
                        max_eigenvalue=float(np.ldexp(lam.max(), exp)), rank_tol=float(keep_tol),
                        asymmetry=asymmetry, asymmetry_normwise=normwise,
                        asymmetry_at=None if at is None else list(at))
    return H, report


def eigenvalue_range(W) -> tuple[float, float]:
    """(smallest, largest) eigenvalue of (W + Wᵀ)/2 (W square, dense or sparse), computed in
    float64 block by block (:func:`_blockwise_eigh`): an estimate, not a bound."""
    W = np.asarray(sp.csr_matrix(W).toarray() if sp.issparse(W) else W, dtype=np.float64)
    lam = _blockwise_eigh(0.5 * (W + W.T))[0]
    return float(lam.min(initial=0.0)), float(lam.max(initial=0.0))


def _blockwise_eigh(Ws: np.ndarray, *, abs_norm: bool = False):
    """Eigenpairs of the symmetric ``Ws`` (dim × dim) block by block: the connected components of
    its sparsity graph, each a dense ``eigh`` (components of one size in one stacked call).  A
    Delassus matrix couples only contacts that share a body (Siconos's local files of separate
    piles have dozens of components), so the factor stays as sparse as W's blocks, and the same
    eigenpairs as one dense ``eigh`` of the whole (the matrix is block diagonal up to a
    permutation).  Returns (λ, entries, eigenpair index, column) with λ (dim,) and the
    eigenvector entries as coordinates: entry e belongs to eigenpair ``rows[e]`` at column
    ``cols[e]``, and ‖|Ws|‖₂ (the largest over the blocks) where ``abs_norm``, else None."""
    from scipy.sparse.csgraph import connected_components

    dim = Ws.shape[0]
    _, label = connected_components(sp.csr_matrix(Ws != 0), directed=False)
    order = np.argsort(label, kind="stable")
    size = np.bincount(label)
    lam, vecs, rows, cols = [], [], [], []
    first, norm_abs = 0, 0.0
    members = np.split(order, np.cumsum(size)[:-1])  # each component's rows, in label order
    for s in np.unique(size):
        group = np.array([idx for idx in members if idx.size == s])  # (count, s)
        blocks = Ws[group[:, :, None], group[:, None, :]]  # (count, s, s)
        w, V = np.linalg.eigh(blocks)  # V[c, :, j]: eigenvector j of block c
        if abs_norm:
            norm_abs = max(norm_abs, float(np.abs(np.linalg.eigvalsh(np.abs(blocks))).max()))
        count = group.shape[0]
        pair = first + np.arange(count * s).reshape(count, s)  # eigenpair index of (c, j)
        lam.append(w.ravel())
        vecs.append(V.transpose(0, 2, 1).ravel())  # (c, j, i) order: eigenvector j's entries
        rows.append(np.repeat(pair.ravel(), s))
        cols.append(np.repeat(group, s, axis=0).ravel())
        first += count * s
    assert first == dim
    return (np.concatenate(lam), np.concatenate(vecs), np.concatenate(rows).astype(np.int64),
            np.concatenate(cols).astype(np.int64), norm_abs if abs_norm else None)
