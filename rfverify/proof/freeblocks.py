"""The blocks of M that no contact touches, solved exactly by a verified inverse (DESIGN §6.1).

A diagonal block b of the posed M (a body, or a mesh) whose rows of H are all zero and which
no entry of the stored M links to another block is *free*: there the equations of every
solution read M_b v*_b = f_b, so d_b = v_b − v*_b obeys M_b d_b = g_b (g = M v − H r − f of any
point), whatever r and the cones.  So

    |d_b| = |M_b⁻¹ g_b|,

bounded componentwise through the posed block's own inverse (stored and unsymmetric, or
(M + Mᵀ)/2 exactly) — no Cauchy–Schwarz, no norm of the other blocks' residuals — by a
verified approximate inverse X_b with ρ_b ≥ ‖I − X_b M_b‖∞ < 1
(:func:`.massbounds.verified_left_inverses`, :func:`.massbounds.solve_upper`), on the block
equilibrated by the exact powers of two S of :mod:`.massbounds` (d_b = S (S M_b S)⁻¹ S g_b).

The rest of the theorem then needs only the other blocks (C): with M_FC = M_CF = 0 and H_F = 0,
M_C d_C − H_C(r − r*) = g_C and Hᵀd = H_Cᵀd_C = u − u*, so ‖d_C‖_{M_s} ≤ ε_C, the ε of §6.1
evaluated with g_C alone (:mod:`.bound`).  Blocks where the verified inverse is not available
(larger than :data:`~rfverify.model.definiteness.DENSE_LIMIT`, or ρ ≥ 1) simply stay in C.

Where the free blocks' equations differ between the stored M and (M + Mᵀ)/2 — the bundled
Chute's free bodies have unsymmetric inertia blocks — this is what bounds how far the
symmetrised answer is from the stored equations' solution: the Cauchy–Schwarz bound put every
free body's error into one ε shared by all dofs and contacts (0.7 proven digits of the stored
equations' solution on the Chute, against 3.1 true ones; docs/DECISIONS.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..model.definiteness import DENSE_LIMIT, ETA, U, ldexp_up, scale_symmetric
from .dyadic import Dyadic
from .massbounds import MassBounds, solve_upper, verified_left_inverses

BATCH_ENTRIES = 4_000_000
"""Dense block entries handled at once (memory: three such stacks of float64)."""


@dataclass
class FreeBlocks:
    """The free blocks of one posed M with a verified inverse (module docstring).

    ``dofs``: their dofs (sorted); ``coupled``: mask (m,) of every other dof (the part C whose
    ε is evaluated with g_C); ``groups``: per batch of equal-size blocks, (dofs (nb, s), X
    (nb, s, s) of S M_b S, row sums of the residual bound (nb, s), ρ (nb,))."""

    dofs: np.ndarray
    coupled: np.ndarray
    exponents: np.ndarray
    groups: list = field(default_factory=list)

    @property
    def count(self) -> int:
        return int(sum(g[0].shape[0] for g in self.groups))

    def bound(self, g: Dyadic) -> np.ndarray:
        """Upper bounds (m,) of |(M_F⁻¹ g_F)_j| on the free dofs (∞ where a block's verified
        solve fails, 0 on the other dofs, which this bound does not cover)."""
        out = np.zeros(self.coupled.size)
        for dofs, X, rows, rho in self.groups:
            flat = dofs.ravel()
            e = self.exponents[flat]
            gs = g[flat] * Dyadic.from_float(np.ldexp(1.0, e))  # S g, exact
            with np.errstate(all="ignore"):
                hi, lo = gs.upper(), gs.lower()
                mid = np.where(hi == lo, hi, lo + (hi - lo) / 2)
                rad = np.nextafter(hi - lo, np.inf)  # ≥ |Sg − mid|: both lie in [lo, hi]
            shape = dofs.shape
            d_scaled = solve_upper(X, rows, rho, mid.reshape(shape), rad.reshape(shape))
            out[flat] = ldexp_up(d_scaled.ravel(), e)  # d = S (S M S)⁻¹ S g, |d_j| = s_j |d'_j|
        out[~np.isfinite(out)] = np.inf
        return out


def free_blocks(problem, mass: MassBounds, stored: bool) -> FreeBlocks:
    """The :class:`FreeBlocks` of ``problem``'s M (as stored when ``stored``, else (M + Mᵀ)/2
    exactly), on the blocks of ``mass`` (connected components of M_s's pattern).  The
    structure is verified exactly on the data: no nonzero of H in a free block's rows, no
    nonzero of the stored M linking it to another block."""
    m = problem.n_dofs
    labels = mass.labels
    nb = int(labels.max()) + 1 if m else 0
    exps = np.asarray(mass.exponents)
    none = FreeBlocks(np.zeros(0, dtype=np.int64), np.ones(m, dtype=bool), exps)
    if m == 0 or not mass.proven:
        return none
    H = sp.coo_matrix(problem.H)
    touched = np.zeros(nb, dtype=bool)
    touched[labels[H.row[H.data != 0]]] = True
    Mc = sp.coo_matrix(problem.M)
    nz = Mc.data != 0
    cross = labels[Mc.row[nz]] != labels[Mc.col[nz]]
    touched[labels[Mc.row[nz][cross]]] = True  # linked to another block: not decoupled
    touched[labels[Mc.col[nz][cross]]] = True
    sizes = np.bincount(labels, minlength=nb)
    order = np.argsort(labels, kind="stable")
    starts = np.concatenate(([0], np.cumsum(sizes)))
    symmetric = bool(problem.matrix_is_symmetric)
    # The posed block: the stored M, or the float (M + Mᵀ)/2 within 2u|·| + ETA of the exact one.
    A, inexact = scale_symmetric(problem.M if stored else problem.M_sym, exps)
    A = A.tocsr()
    groups, dofs_used = [], []
    for s in np.unique(sizes):
        if s > DENSE_LIMIT:
            continue
        ids = np.flatnonzero((sizes == s) & ~touched)
        per = max(1, BATCH_ENTRIES // int(s * s))
        for k in range(0, ids.size, per):
            batch = ids[k:k + per]
            dofs = order[starts[batch][:, None] + np.arange(s)[None, :]]
            blocks, outside = _gather(A, dofs)
            err = None
            if inexact.any() or not (stored or symmetric):
                bad = sp.csr_matrix((inexact.astype(np.float64), A.indices, A.indptr), shape=A.shape)
                err = _gather(bad, dofs)[0] * ETA
                if not (stored or symmetric):
                    # the rounding of M/2 + Mᵀ/2 underflows by ETA in the data's units: 2^(e_i + e_j) here
                    e = exps[dofs]
                    with np.errstate(over="ignore"):  # (inf: the block is not used)
                        eta = np.ldexp(ETA, e[:, :, None] + e[:, None, :])
                    err = err + 2 * U * np.abs(blocks) + eta
            X, rows, rho = verified_left_inverses(blocks, err)
            good = (rho < 1) & ~outside
            if good.any():
                groups.append((dofs[good], X[good], rows[good], rho[good]))
                dofs_used.append(dofs[good].ravel())
    used = np.sort(np.concatenate(dofs_used)) if dofs_used else np.zeros(0, dtype=np.int64)
    coupled = np.ones(m, dtype=bool)
    coupled[used] = False
    return FreeBlocks(used, coupled, exps, groups)


def _gather(csr: sp.csr_matrix, dofs: np.ndarray):
    """Dense (nb, s, s) stack of the blocks csr[dofs[b]][:, dofs[b]], and a mask of the blocks
    with a nonzero entry outside their own block (none where the structure check holds; such
    a block is not used)."""
    count, s = dofs.shape
    owner = np.full(csr.shape[1], -1, dtype=np.int64)
    pos = np.zeros(csr.shape[1], dtype=np.int64)
    owner[dofs.ravel()] = np.repeat(np.arange(count), s)
    pos[dofs.ravel()] = np.tile(np.arange(s), count)
    sub = csr[dofs.ravel()].tocoo()
    block = sub.row // s
    inside = owner[sub.col] == block
    stack = np.zeros((count, s, s))
    stack[block[inside], sub.row[inside] % s, pos[sub.col[inside]]] = sub.data[inside]
    outside = np.zeros(count, dtype=bool)
    outside[block[~inside & (sub.data != 0)]] = True
    return stack, outside
