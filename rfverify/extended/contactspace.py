"""The contact-space back end: S_r = W̃ + G (nk × nk), W̃ = H̃ M⁻¹ H̃ᵀ built once, factored in its
scaled form I + F⁻¹W̃F⁻ᵀ (F_c F_cᵀ = G_c, :func:`.blocks.contact_factor_inverse`) — the
default of the extended phase (:func:`.system.choose_backend`).  The factorisation is float64
refined in double-double (QDLDL's LDLᵀ or CHOLMOD: :func:`resolve_engine`) or
double-double throughout (:mod:`.ldl`)."""

from __future__ import annotations

import math

import numba
import numpy as np
import scipy.sparse as sp

from . import dd
from .blocks import applied_blocks, contact_factor_inverse_threaded, scatter_add
from .data import ExtendedData
from .factored import FactoredBackend
from .ldl import DDCholesky
from ..engines.factor import cholmod_available, cholmod_missing_message
from .mixed import CholmodMixed, MixedCholesky
from .scaled_operator import ScaledProduct, block_system, build_z, dense_half, multiply_adds
from .workers import split

njit = numba.njit(cache=True, nogil=True)  # nogil: run on threads by .workers
NEWTON_REFINED_TARGET = math.inf
"""Componentwise backward error to which the extended IPM's contact-space solves are refined:
none — one float64 solve each, unchecked.  The Newton driver refines every solve against the
unreduced three-block system and checks each residual itself
(:func:`rfverify.algorithm.rules.refined_newton`); a solve it cannot refine is solved again
with checked solves (:meth:`ContactSpace.retry_solve`; docs/DECISIONS.md, "Refinement once")."""
STRICT_AFTER = 1e-18
"""A Newton solve whose refinement stalls short of its η (:data:`.ipm.NEWTON_ENOUGH`) with a
relative residual above this is solved again with the contact-space solves refined to
double-double accuracy (``backward_target`` 1e-29), as are all later ones.  The attainable relative residual grows as μ falls (the right-hand side shrinks,
the error floor does not): from ~1e-29 to ~1e-21 at μ ≈ 1e-30 on a bed, a Chute and a random
problem, the same with one-step and with fully refined solves; a float64 factor that fails
leaves ~1e-16 or worse."""
DENSE_BLOCK = 200  # blocks of M up to this size are inverted densely when forming W̃
DENSE_Y_ENTRIES = 2e7  # largest m × nk of a dense Y = blockdiag(L_b⁻¹)Hᵀ (2 float64 each: 320 MB)


@njit
def _row_gram(Ah, Al, Wh, Wl):
    """W = A Aᵀ (double-double) over the rows of A, each pair once: rows are contiguous, so
    this is the cache-friendly form for a tall Y stored transposed."""
    k = Ah.shape[0]
    for a in range(k):
        for b in range(a, k):
            sh, sl = 0.0, 0.0
            for i in range(Ah.shape[1]):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, i], Al[a, i], Ah[b, i], Al[b, i])
            Wh[a, b], Wl[a, b] = sh, sl
            Wh[b, a], Wl[b, a] = sh, sl


@njit
def _dense_schur(Mh, Ml, Hh, Hl, Wh, Wl):
    """W = H M⁻¹ Hᵀ for a small dense SPD M (Y = L⁻¹Hᵀ, W = YᵀY).  Returns False if M is not
    positive definite."""
    Yh = np.zeros((Mh.shape[0], Hh.shape[0]))
    Yl = np.zeros((Mh.shape[0], Hh.shape[0]))
    if not dense_half(Mh, Ml, Hh, Hl, Yh, Yl):
        return False
    YTh = np.zeros((Hh.shape[0], Mh.shape[0]))  # Yᵀ, copied by hand (np.ascontiguousarray
    YTl = np.zeros((Hh.shape[0], Mh.shape[0]))  # would be one more compilation)
    for i in range(Mh.shape[0]):
        for c in range(Hh.shape[0]):
            YTh[c, i], YTl[c, i] = Yh[i, c], Yl[i, c]
    _row_gram(YTh, YTl, Wh, Wl)
    return True


@njit
def _dense_gram(Ah, Al, Bh, Bl, Wh, Wl):
    """W = A Bᵀ (double-double, rows of A and B)."""
    for a in range(Ah.shape[0]):
        for b in range(Bh.shape[0]):
            sh, sl = 0.0, 0.0
            for i in range(Ah.shape[1]):
                sh, sl = dd.fma_acc(sh, sl, Ah[a, i], Al[a, i], Bh[b, i], Bl[b, i])
            Wh[a, b], Wl[a, b] = sh, sl


@njit
def _scaled_blocks(pc, pd, Wh, Wl, row_count, Fh, Fl, pos, Sh, Sl):
    """S' = F⁻¹ W̃ F⁻ᵀ + I, block pair by block pair (p: contacts pc[p] ≤ pd[p]).  Row a of
    F_c⁻¹ is summed only up to its last nonzero (``width``): a full contact's F_c⁻¹ = (R⁻¹)ᵀ is
    lower triangular, which skips 40% of the products."""
    Th = np.zeros((5, 5))
    Tl = np.zeros((5, 5))
    width = np.zeros((Fh.shape[0], 5), dtype=np.int64)
    for c in range(Fh.shape[0]):
        for a in range(row_count[c]):
            for b in range(row_count[c]):
                if Fh[c, a, b] != 0.0 or Fl[c, a, b] != 0.0:
                    width[c, a] = b + 1
    for p in range(pc.size):
        c = pc[p]
        d = pd[p]
        kc = row_count[c]
        kd = row_count[d]
        for a in range(kc):  # T = F_c⁻¹ W̃_cd
            for j in range(kd):
                sh, sl = 0.0, 0.0
                for b in range(width[c, a]):
                    sh, sl = dd.fma_acc(sh, sl, Fh[c, a, b], Fl[c, a, b], Wh[p, b, j], Wl[p, b, j])
                Th[a, j] = sh
                Tl[a, j] = sl
        for a in range(kc):
            for b in range(kd):
                q_ = pos[p, a, b]
                if q_ < 0:
                    continue
                sh, sl = (1.0, 0.0) if (c == d and a == b) else (0.0, 0.0)
                for q in range(width[d, b]):
                    sh, sl = dd.fma_acc(sh, sl, Th[a, q], Tl[a, q], Fh[d, b, q], Fl[d, b, q])
                Sh[q_] = sh
                Sl[q_] = sl


@njit
def _scatter_pairs(pidx, a, b, vh, vl, Wh, Wl):
    for k in range(pidx.size):
        p = pidx[k]
        Wh[p, a[k], b[k]], Wl[p, a[k], b[k]] = dd.add(Wh[p, a[k], b[k]], Wl[p, a[k], b[k]], vh[k], vl[k])


@njit
def _small_blocks_W(blocks, dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds, rows_all,
                    h_dofs, h_hi, h_lo, contact_of_row, row_local, pair_keys, n, local, Wh, Wl):
    """W̃ += H_b M_b⁻¹ H_bᵀ for each block b of ``blocks`` (dense double-double Cholesky of M_b,
    :func:`_dense_schur`), scattered into the pair blocks — the loop of
    :meth:`ContactSpace._build_W` over the small blocks, compiled: a granular medium has one
    block per body, 20 250 on a 9675-contact bed.  ``order[bounds[b]:bounds[b + 1]]``: the
    nonzeros of H̃ in block b, by row.  Returns the first block whose M_b is not positive
    definite, or -1."""
    for b in blocks:
        if bounds[b + 1] == bounds[b]:
            continue
        rows, Hbh, Hbl, Mbh, Mbl = block_system(b, dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order,
                                                bounds, rows_all, h_dofs, h_hi, h_lo, local)
        r = rows.size
        Wbh, Wbl = np.zeros((r, r)), np.zeros((r, r))
        if not _dense_schur(Mbh, Mbl, Hbh, Hbl, Wbh, Wbl):
            return b
        for i in range(r):
            ci = contact_of_row[rows[i]]
            for j in range(r):
                cj = contact_of_row[rows[j]]
                if ci > cj:
                    continue
                p = np.searchsorted(pair_keys, ci * n + cj)
                a, c = row_local[rows[i]], row_local[rows[j]]
                Wh[p, a, c], Wl[p, a, c] = dd.add(Wh[p, a, c], Wl[p, a, c], Wbh[i, j], Wbl[i, j])
    return -1


class ContactSpace(FactoredBackend):
    """The contact-space system S = W̃ + G with W̃ = H̃ M⁻¹ H̃ᵀ (built once), factored in its
    scaled form S' = F⁻¹ S F⁻ᵀ = F⁻¹ W̃ F⁻ᵀ + I, where F = blockdiag(F_c), F_c F_cᵀ = G_c.

    G's eigenvalues run from about μ to 1/μ inside one contact block (sliding contacts); the
    Cholesky factor of S then loses definiteness in double-double near μ = 1e-20 (measured
    on a 1368-contact Chute).  S' has every eigenvalue ≥ 1, and F_c comes from the
    Jordan-algebra factors without squaring a condition number.
    """

    @property
    def name(self) -> str:
        how = "double-double factor"
        if getattr(self.chol, "precision", "double-double") == "mixed":
            engine = "CHOLMOD" if isinstance(self.chol, CholmodMixed) else "QDLDL"
            how = f"float64 {engine} factor refined in double-double"
            if self.chol.shifted_from is not None:
                how = (f"float64 {engine} factor, shifted from factorisation {self.chol.shifted_from} "
                       f"({self.chol.shift_reason}), solved by conjugate gradients in double-double")
            elif self.chol.cg_from is not None:
                how = (f"float64 {engine} factor, solved by conjugate gradients in double-double from "
                       f"factorisation {self.chol.cg_from} ({self.chol.cg_reason})")
        reason = getattr(self.chol, "fallback_reason", "")
        if reason and getattr(self.chol, "fallback_at", None) is not None:
            reason = f"from factorisation {self.chol.fallback_at}: {reason}"
        if self.tightened_at is not None and not reason:
            reason = f"solves refined to double-double accuracy from factorisation {self.tightened_at}"
        form = "I + F⁻¹W̃F⁻ᵀ, W̃ = P W P of the local file" if self.data.local else "I + F⁻¹H̃M⁻¹H̃ᵀF⁻ᵀ"
        return f"contact-space, scaled ({form}), {how}" + (f" ({reason})" if reason else "")

    def __init__(self, data: ExtendedData, mixed: bool = True, engine: str = "auto",
                 backward_target: float = 1e-29):
        """``backward_target``: the componentwise backward error the float64 factor's solves are
        refined to (:meth:`.mixed._RefinedFloat64Factor.set_backward_target`): 1e-29, double-double
        accuracy, by default; :data:`NEWTON_REFINED_TARGET` under a driver that refines each
        Newton solve itself (:func:`.system.choose_backend`), which :meth:`retry_solve` tightens
        to 1e-29 if a Newton solve then refines badly."""
        from scipy.sparse.csgraph import connected_components

        self.data = data
        m, nk, n = data.m, data.nk, data.n
        self.contact_of_row = np.repeat(np.arange(n), data.row_count)
        C = sp.csr_matrix((np.ones(nk), (self.contact_of_row, np.arange(nk))), shape=(n, nk))
        if data.local:  # W̃ is given: contacts are coupled where it has entries
            self.Mchol = None
            Wp = sp.csr_matrix((np.ones_like(data.Wt.hi), data.Wt.indices, data.Wt.indptr), shape=(nk, nk))
            CW = (C @ Wp @ C.T).tocsr()
            CW.data[:] = 1
            CC = sp.triu(CW + sp.identity(n), format="coo")
        else:
            Mp = sp.csr_matrix((np.ones_like(data.M.hi), data.M.indices, data.M.indptr), shape=(m, m))
            self.Mchol = DDCholesky(Mp)
            nb, labels = connected_components(Mp, directed=False)
            self.n_blocks, self.labels = nb, labels
            Ht = sp.csr_matrix((np.ones_like(data.Ht.hi), data.Ht.indices, data.Ht.indptr), shape=data.Ht.shape)
            B = sp.csr_matrix((np.ones(m), (np.arange(m), labels)), shape=(m, nb))
            CB = (C @ Ht @ B).tocsr()
            CB.data[:] = 1
            CC = sp.triu(CB @ CB.T + sp.identity(n), format="coo")
        order = np.lexsort((CC.col, CC.row))
        self.pc = CC.row[order].astype(np.int64)
        self.pd = CC.col[order].astype(np.int64)
        self._pair_keys = self.pc * n + self.pd
        # kept-row pattern: every pair block is dense
        ii, jj = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
        kc = data.row_count[self.pc][:, None, None]
        kd = data.row_count[self.pd][:, None, None]
        valid = (ii[None] < kc) & (jj[None] < kd)
        gi = np.where(valid, data.row_start[self.pc][:, None, None] + ii[None], 0)
        gj = np.where(valid, data.row_start[self.pd][:, None, None] + jj[None], 0)
        same = (self.pc == self.pd)[:, None, None]
        take = valid & (~same | (ii[None] <= jj[None]))
        pattern = sp.coo_matrix((np.ones(int(take.sum())), (gi[take], gj[take])), shape=(nk, nk))
        self.engine = resolve_engine(engine, nk) if mixed else "ldl"
        if not mixed:
            self.chol = DDCholesky(pattern)
        elif self.engine == "cholmod":
            self.chol = CholmodMixed(pattern, backward_target=backward_target)
        else:
            self.chol = MixedCholesky(pattern, backward_target=backward_target)
        self.tightened_at = None  # the factorisation from which solves refine to 1e-29 again
        self.pos = np.full(valid.shape, -1, dtype=np.int64)
        self.pos[take] = self.chol.positions(gi[take], gj[take])
        self._W = None
        self.dense_W = None  # None: choose the construction of W̃ by its cost; True/False: force it
        self.dense_W_used = None
        self.Fh = np.zeros((n, 5, 5))
        self.Fl = np.zeros((n, 5, 5))

    def describe_cost(self) -> str:
        """The factorisations that ran and their cost (:meth:`.mixed._RefinedFloat64Factor.describe_cost`)."""
        if isinstance(self.chol, (CholmodMixed, MixedCholesky)):
            return self.chol.describe_cost()
        return super().describe_cost()

    def _pair_index(self, c, d):
        return np.searchsorted(self._pair_keys, c * self.data.n + d)

    def _build_W_local(self):
        """W̃ of a local problem, copied into pair blocks from the file's (scaled) W."""
        d = self.data
        Wh = np.zeros((self.pc.size, 5, 5))
        Wl = np.zeros((self.pc.size, 5, 5))
        rows = np.repeat(np.arange(d.nk), np.diff(d.Wt.indptr))
        cols = d.Wt.indices
        ci, cj = self.contact_of_row[rows], self.contact_of_row[cols]
        keep = ci <= cj
        pidx = self._pair_index(ci[keep], cj[keep])
        a = (rows - d.row_start[ci])[keep]
        b = (cols - d.row_start[cj])[keep]
        Wh[pidx, a, b] = d.Wt.hi[keep]
        Wl[pidx, a, b] = d.Wt.lo[keep]
        self._W = (Wh, Wl)

    def _build_W(self):
        """W̃ = H̃ M⁻¹ H̃ᵀ in pair blocks, block by block of M: W̃ += H_b M_b⁻¹ H_bᵀ over the
        rows touching block b (dense double-double Cholesky of M_b up to DENSE_BLOCK dofs,
        the sparse factor of M above)."""
        d = self.data
        if d.local:
            self._build_W_local()
            return
        Wh = np.zeros((self.pc.size, 5, 5))
        Wl = np.zeros((self.pc.size, 5, 5))
        ix = self._block_index()
        dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds, rows_all = ix[:11]
        blk_of_nz = self.labels[d.Ht.indices]
        local = np.empty(d.m, dtype=np.int64)
        row_local = np.arange(d.nk) - d.row_start[self.contact_of_row]
        # rows touching each block: Σ rows_b² is what the block-by-block scatter costs; where a
        # few blocks touch most rows (a dense H, as in a lifted local problem with M = I), one
        # dense Y = blockdiag(L_b⁻¹)Hᵀ and W̃ = YᵀY is far cheaper (DECISIONS, "dense W̃")
        touching = np.unique(blk_of_nz.astype(np.int64) * d.nk + rows_all)
        rows_per_block = np.bincount(touching // d.nk, minlength=self.n_blocks).astype(np.float64)
        block_sizes = np.diff(dof_bounds)
        dense_Y = (float(np.sum(rows_per_block ** 2)) > 4.0 * d.nk * d.nk and d.m * d.nk <= DENSE_Y_ENTRIES
                   and int(block_sizes.max(initial=0)) <= DENSE_BLOCK)
        if self.dense_W is not None:  # tests compare both constructions
            dense_Y = bool(self.dense_W) and int(block_sizes.max(initial=0)) <= DENSE_BLOCK
        self.dense_W_used = dense_Y
        if dense_Y:
            YTh, YTl = np.zeros((d.nk, d.m)), np.zeros((d.nk, d.m))  # Yᵀ: rows = kept rows of H̃
            by_python = np.arange(self.n_blocks)
        else:
            small = block_sizes <= DENSE_BLOCK
            bad = _small_blocks_W(np.flatnonzero(small), dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml,
                                  order, bounds, rows_all, d.Ht.indices, d.Ht.hi, d.Ht.lo, self.contact_of_row,
                                  row_local, self._pair_keys, d.n, local, Wh, Wl)
            if bad >= 0:
                raise ArithmeticError(f"block {bad} of M is not positive definite in double-double")
            by_python = np.flatnonzero(~small)
        for b in by_python:
            sel = order[bounds[b]:bounds[b + 1]]
            if sel.size == 0:
                continue
            dofs = dof_order[dof_bounds[b]:dof_bounds[b + 1]]
            s_ = dofs.size
            local[dofs] = np.arange(s_)
            rows = np.unique(rows_all[sel])
            rl = np.searchsorted(rows, rows_all[sel])
            Hbh = np.zeros((rows.size, s_))
            Hbl = np.zeros((rows.size, s_))
            Hbh[rl, local[d.Ht.indices[sel]]] = d.Ht.hi[sel]
            Hbl[rl, local[d.Ht.indices[sel]]] = d.Ht.lo[sel]
            if s_ > DENSE_BLOCK:
                Wbh, Wbl = self._schur_sparse(Hbh, Hbl, dofs)
            else:
                ms = m_order[m_bounds[b]:m_bounds[b + 1]]
                Mbh = np.zeros((s_, s_))
                Mbl = np.zeros((s_, s_))
                Mbh[local[mr[ms]], local[mc[ms]]] = mh[ms]
                Mbl[local[mr[ms]], local[mc[ms]]] = ml[ms]
                if dense_Y:
                    Ybh, Ybl = np.zeros((s_, rows.size)), np.zeros((s_, rows.size))
                    if not dense_half(Mbh, Mbl, Hbh, Hbl, Ybh, Ybl):
                        raise ArithmeticError(f"block {b} of M is not positive definite in double-double")
                    YTh[np.ix_(rows, dofs)], YTl[np.ix_(rows, dofs)] = Ybh.T, Ybl.T
                    continue
                Wbh, Wbl = np.zeros((rows.size, rows.size)), np.zeros((rows.size, rows.size))
                if not _dense_schur(Mbh, Mbl, Hbh, Hbl, Wbh, Wbl):
                    raise ArithmeticError(f"block {b} of M is not positive definite in double-double")
            ii, jj = np.meshgrid(np.arange(rows.size), np.arange(rows.size), indexing="ij")
            ci, cj = self.contact_of_row[rows[ii]], self.contact_of_row[rows[jj]]
            keep = ci <= cj
            pidx = self._pair_index(ci[keep], cj[keep])
            _scatter_pairs(pidx, row_local[rows[ii]][keep], row_local[rows[jj]][keep],
                           np.ascontiguousarray(Wbh[keep]), np.ascontiguousarray(Wbl[keep]), Wh, Wl)
        if dense_Y:
            Gh, Gl = np.zeros((d.nk, d.nk)), np.zeros((d.nk, d.nk))
            _row_gram(YTh, YTl, Gh, Gl)
            ii, jj = np.meshgrid(np.arange(5), np.arange(5), indexing="ij")
            valid = (ii[None] < d.row_count[self.pc][:, None, None]) & (jj[None] < d.row_count[self.pd][:, None, None])
            gi = d.row_start[self.pc][:, None, None] + ii[None]
            gj = d.row_start[self.pd][:, None, None] + jj[None]
            Wh[valid], Wl[valid] = Gh[gi[valid], gj[valid]], Gl[gi[valid], gj[valid]]
        self._W = (Wh, Wl)
        self._offer_scaled_product(ix, rows_per_block, block_sizes, dense_Y)

    def _offer_scaled_product(self, index: tuple, rows_per_block: np.ndarray, block_sizes: np.ndarray,
                              dense_Y: bool) -> None:
        """Give the float64 factor's conjugate gradients the product through the factors
        (:class:`.scaled_operator.ScaledProduct`) where it takes fewer multiply-adds than the
        stored upper triangle of S' (each off-diagonal entry used twice) and every block of M is
        small enough to be factored densely."""
        d = self.data
        if dense_Y or not isinstance(self.chol, (CholmodMixed, MixedCholesky)) or block_sizes.max(initial=0) > DENSE_BLOCK:
            return
        blocks = np.flatnonzero(rows_per_block > 0)
        z_entries = int(np.sum(rows_per_block[blocks] * block_sizes[blocks]))
        if multiply_adds(z_entries, d.row_count) >= 2 * self.chol.nnz_upper:
            return

        def make_z():
            Z = build_z(index, blocks, rows_per_block.astype(np.int64), (d.nk, d.m))
            if Z is None:  # _build_W factored the same blocks: not reached
                raise ArithmeticError("a block of M is not positive definite in double-double")
            return Z

        self.chol.operator = ScaledProduct(d, self.Fh, self.Fl, make_z)

    def _block_index(self) -> tuple:
        """The arrays by which the compiled kernels walk M block by block (its connected
        components): (dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds,
        rows_all, h_dofs, h_hi, h_lo) — the dofs, M's entries and H̃'s nonzeros sorted by block
        (``order[bounds[b]:bounds[b + 1]]``: block b's nonzeros of H̃, by row; rows_all: the row
        of each nonzero), as :func:`.scaled_operator.block_system` reads them."""
        d = self.data
        mr, mc, mh, ml = d.M.coo()
        rows_all = np.repeat(np.arange(d.nk), np.diff(d.Ht.indptr))
        blk_of_nz = self.labels[d.Ht.indices]
        order = np.lexsort((rows_all, blk_of_nz))
        bounds = np.searchsorted(blk_of_nz[order], np.arange(self.n_blocks + 1))
        m_blk = self.labels[mr]
        m_order = np.argsort(m_blk, kind="stable")
        m_bounds = np.searchsorted(m_blk[m_order], np.arange(self.n_blocks + 1))
        dof_order = np.argsort(self.labels, kind="stable")
        dof_bounds = np.searchsorted(self.labels[dof_order], np.arange(self.n_blocks + 1))
        return (dof_order, dof_bounds, m_order, m_bounds, mr, mc, mh, ml, order, bounds, rows_all,
                d.Ht.indices, d.Ht.hi, d.Ht.lo)

    def _schur_sparse(self, Hbh, Hbl, dofs):
        """H_b M_b⁻¹ H_bᵀ for a large block through the sparse factor of M (one solve per row)."""
        m = self.data.m
        k = Hbh.shape[0]
        Xh, Xl = np.zeros((k, dofs.size)), np.zeros((k, dofs.size))
        for a in range(k):
            bh, bl = np.zeros(m), np.zeros(m)
            bh[dofs], bl[dofs] = Hbh[a], Hbl[a]
            xh, xl = self.Mchol.solve(bh, bl)
            Xh[a], Xl[a] = xh[dofs], xl[dofs]
        Wh, Wl = np.zeros((k, k)), np.zeros((k, k))
        _dense_gram(Hbh, Hbl, Xh, Xl, Wh, Wl)
        return Wh, Wl

    def _M_upper(self):
        d = self.data
        mr, mc, mh, ml = d.M.coo()
        keep = self.Mchol.iperm[mr] <= self.Mchol.iperm[mc]
        pos = self.Mchol.positions(mr[keep], mc[keep])
        h = np.zeros(self.Mchol.nnz_upper)
        lo = np.zeros(self.Mchol.nnz_upper)
        scatter_add(pos, np.ascontiguousarray(mh[keep]), np.ascontiguousarray(ml[keep]), h, lo)
        return h, lo

    def retry_solve(self, residual: float) -> bool:
        """Asked by the Newton driver after a solve whose refinement against the unreduced
        system stopped at relative residual ``residual``: above :data:`STRICT_AFTER` (a float64
        factor too inaccurate for one-step solves), every solve from now on — this one again
        included — is refined to double-double accuracy (and falls back to a double-double
        factor where that stalls).  Asked again where those checked solves ran by conjugate
        gradients and the Newton solve still stalls above it: the next shifted float64 factor, or
        after the last the double-double factor from now on
        (:meth:`.mixed._RefinedFloat64Factor.escalate`); until then a checked conjugate-gradient
        solve short of 1e-20 is used as it is, since this driver's own refinement judges it.
        True when anything changed."""
        chol = self.chol
        if residual <= STRICT_AFTER or not isinstance(chol, (CholmodMixed, MixedCholesky)):
            return False
        if chol.backward_target > 1e-29:
            chol.set_backward_target(1e-29)
            chol.judged_by_caller = True  # this driver judges every solve: see escalate below
            self.tightened_at = self.factorisations
            return True
        # checked solves by conjugate gradients that still leave the Newton system unrefined: the
        # next shift, else the double-double factor (a checked solve by refinement falls back on its own)
        return chol.escalate(f"the Newton solve refined only to relative residual {residual:.1e} "
                             "with checked conjugate-gradient solves")

    def set_accuracy(self, residual_norm: float | None) -> None:
        """The coming solves' conjugate gradients, where the float64 factor needs them, may stop
        once they leave the complementarity row within ``residual_norm`` (‖·‖∞; None: at their own
        backward error).  That row keeps B r' after the primal projection, r' = F⁻¹r − S'y the
        scaled residual and B = Q_{p⁻¹}JᵀF⁻ᵀ with orthonormal columns, block by contact: a row of
        B has norm ≤ 1 and meets ≤ 5 entries of r', so ‖B r'‖∞ ≤ √5‖r'‖∞.  The Newton driver
        refines against the unreduced system itself (:data:`rfverify.algorithm.newton.INNER_FRACTION`)."""
        if isinstance(self.chol, (CholmodMixed, MixedCholesky)):
            self.chol.residual_target = None if residual_norm is None else residual_norm / math.sqrt(5)

    def prepare(self) -> None:
        """What the first :meth:`update` does that needs no iterate — M factored in
        double-double, W̃ = H̃M⁻¹H̃ᵀ, the float64 engine's symbolic analysis — done ahead (the
        k-digit path runs it beside the double solve, :mod:`rfverify.verify.digits`).  Optional: an
        update does whatever is still missing, and where M fails here it stops (no W̃), so that
        the update meets the failure again and reports it where it always did."""
        if not self._ensure_W():
            return
        self.chol.prepare()

    def _ensure_W(self) -> bool:
        """M factored in double-double and W̃ built, once; False when M is not positive
        definite in double-double (nothing is kept, so that a later call meets it again)."""
        if self._W is None:
            if self.Mchol is not None and self.Mchol.factor(*self._M_upper()) >= 0:
                return False
            self._build_W()
        return True

    def update(self, ph, pl, pih, pil, spec) -> bool:
        d = self.data
        if not self._ensure_W():
            raise ArithmeticError("M is not positive definite in double-double")
        if contact_factor_inverse_threaded(d.n, d.kinds, d.fric_cone, d.roll_cone, d.normal_cone, spec,
                                           self.Fh, self.Fl) >= 0:
            return False
        Sh = np.zeros(self.chol.nnz_upper)
        Sl = np.zeros(self.chol.nnz_upper)
        Wh, Wl = self._W

        def pairs(lo, hi):  # block pairs lo … hi write disjoint entries of S'
            _scaled_blocks(self.pc[lo:hi], self.pd[lo:hi], Wh[lo:hi], Wl[lo:hi], d.row_count, self.Fh, self.Fl,
                           self.pos[lo:hi], Sh, Sl)

        split(self.pc.size, pairs, min_items=512)
        self.factorisations += 1
        return self.chol.factor(Sh, Sl) < 0

    def _F_inverse(self, xh, xl, transpose: bool):
        """F⁻¹x, or F⁻ᵀx with ``transpose`` (double-double (hi, lo), kept rows)."""
        return applied_blocks(self.data, self.Fh, self.Fl, transpose, xh, xl, threaded=True)

    def _S_solve(self, rh, rl):
        """S⁻¹ r = F⁻ᵀ S'⁻¹ F⁻¹ r."""
        return self._F_inverse(*self.chol.solve(*self._F_inverse(rh, rl, False)), True)

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (local form: (W̃ + G) dr̃ = t)."""
        d = self.data
        if d.local:
            return (np.zeros(0), np.zeros(0)), self._S_solve(np.ascontiguousarray(t[0]), np.ascontiguousarray(t[1]))
        yh, yl = self.Mchol.solve(a[0], a[1])
        hh, hl = d.Ht.matvec(yh, yl)
        rh, rl = np.empty(d.nk), np.empty(d.nk)
        dd.vadd(t[0], t[1], -hh, -hl, rh, rl)
        drh, drl = self._S_solve(rh, rl)
        gh, gl = d.HtT.matvec(drh, drl)
        sh, sl = np.empty(d.m), np.empty(d.m)
        dd.vadd(a[0], a[1], gh, gl, sh, sl)
        dvh, dvl = self.Mchol.solve(sh, sl)
        return (dvh, dvl), (drh, drl)


ENGINES = ("auto", "ldl", "cholmod")
CHOLMOD_MIN_ROWS = 0
"""Smallest contact-space matrix (kept rows) ``engine="auto"`` factors with CHOLMOD when it is
installed: 0, since no size was measured where an LDLᵀ engine is faster (164 to 9675 contacts
against the compiled LDLᵀ of the time, docs/DECISIONS.md "The 10-digit path at scale"; QDLDL,
which replaced it, spent 20–22 s in float64 factorisations of the 10-digit path on a
2269-contact random problem where CHOLMOD spent 1.0 s)."""


def resolve_engine(engine: str, rows: int) -> str:
    """"cholmod" or "ldl": the float64 factorisation engine of the contact-space form.
    ``auto`` takes CHOLMOD (cvxopt, a dependency) when it imports and the matrix has at least
    :data:`CHOLMOD_MIN_ROWS` rows, else QDLDL's up-looking LDLᵀ;
    ``cholmod`` demands it (ImportError, saying what to install, when absent)."""
    if engine not in ENGINES:
        raise ValueError(f"engine {engine!r} is not one of {', '.join(ENGINES)}")
    if engine == "ldl":
        return "ldl"
    if engine == "cholmod":
        if not cholmod_available():
            raise ImportError(cholmod_missing_message("the cholmod engine"))
        return "cholmod"
    return "cholmod" if rows >= CHOLMOD_MIN_ROWS and cholmod_available() else "ldl"
