"""The dof-space back end: S_v = M + H̃ᵀ G⁻¹ H̃ (m × m) factored in double-double, with G⁻¹ in
closed form per contact (:func:`.blocks.contact_Ginv`).  Its pattern couples bodies that share
a contact: least fill for rigid-body scenes (:mod:`.system` says when it is used)."""

from __future__ import annotations

import numba
import numpy as np

from . import dd
from .blocks import block_apply, contact_Ginv, scatter_add, small_product
from .data import ExtendedData, contact_dof_pattern, contact_local_H
from .factored import FactoredBackend
from .ldl import DDCholesky

njit = numba.njit(cache=True)


@njit
def _assemble_dof(n, row_start, row_count, loc_dofs, loc_cnt, Hh, Hl, Gih, Gil, pos, Sh, Sl):
    """S += Σ_c H̃_cᵀ G_c⁻¹ H̃_c (upper entries only; pos[c, a, b] = -1 off the upper half)."""
    dmax = Hh.shape[2]
    tmph = np.zeros((5, dmax))
    tmpl = np.zeros((5, dmax))
    for c in range(n):
        k = row_count[c]
        d = loc_cnt[c]
        small_product(Gih[c], Gil[c], Hh[c], Hl[c], k, d, k, tmph, tmpl)  # tmp = G⁻¹ H̃_c (k × d)
        for i in range(d):
            for j in range(d):
                q = pos[c, i, j]
                if q < 0:
                    continue
                sh, sl = Sh[q], Sl[q]
                for a in range(k):
                    sh, sl = dd.fma_acc(sh, sl, Hh[c, a, i], Hl[c, a, i], tmph[a, j], tmpl[a, j])
                Sh[q] = sh
                Sl[q] = sl


class DofSpace(FactoredBackend):
    """S_v = M + H̃ᵀ G⁻¹ H̃ factored in double-double."""

    name = "dof-space (M + H̃ᵀG⁻¹H̃)"

    def __init__(self, data: ExtendedData, max_local_dofs: int = 64):
        self.data = data
        n = data.n
        CD = contact_dof_pattern(data)
        self.loc_cnt = np.diff(CD.indptr).astype(np.int64)
        dmax = int(self.loc_cnt.max(initial=1))
        self.dmax = dmax
        self.too_dense = dmax > max_local_dofs
        self.data_ok = not self.too_dense
        pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
        self.chol = DDCholesky(pattern)
        if self.too_dense:
            return
        self.loc_dofs, self.Hh, self.Hl = contact_local_H(data, CD)
        # positions of the local pairs in the upper CSC storage
        ii, jj = np.meshgrid(np.arange(dmax), np.arange(dmax), indexing="ij")
        valid = (ii[None] < self.loc_cnt[:, None, None]) & (jj[None] < self.loc_cnt[:, None, None])
        gi = np.where(valid, self.loc_dofs[:, :, None].repeat(dmax, 2), 0)
        gj = np.where(valid, self.loc_dofs[:, None, :].repeat(dmax, 1), 0)
        pi, pj = self.chol.iperm[gi], self.chol.iperm[gj]
        upper = valid & (pi <= pj)
        pos = np.full(valid.shape, -1, dtype=np.int64)
        pos[upper] = self.chol.positions(gi[upper], gj[upper])
        self.pos = pos
        mr, mc, mh, ml = data.M.coo()
        keep = self.chol.iperm[mr] <= self.chol.iperm[mc]
        self.M_pos = np.full(mr.size, -1, dtype=np.int64)
        self.M_pos[keep] = self.chol.positions(mr[keep], mc[keep])
        self.M_vals = (np.ascontiguousarray(mh), np.ascontiguousarray(ml))
        self.Gih = np.zeros((n, 5, 5))
        self.Gil = np.zeros((n, 5, 5))

    def update(self, ph, pl, pih, pil, spec) -> bool:
        d = self.data
        contact_Ginv(d.n, d.kinds, d.fric_cone, d.roll_cone, d.normal_cone, spec, self.Gih, self.Gil)
        Sh = np.zeros(self.chol.nnz_upper)
        Sl = np.zeros(self.chol.nnz_upper)
        scatter_add(self.M_pos, self.M_vals[0], self.M_vals[1], Sh, Sl)
        _assemble_dof(d.n, d.row_start, d.row_count, self.loc_dofs, self.loc_cnt, self.Hh, self.Hl,
                      self.Gih, self.Gil, self.pos, Sh, Sl)
        self.factorisations += 1
        return self.chol.factor(Sh, Sl) < 0

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (local form: (W̃ + G) dr̃ = t)."""
        d = self.data
        if d.local:
            return (np.zeros(0), np.zeros(0)), self._S_solve(np.ascontiguousarray(t[0]), np.ascontiguousarray(t[1]))
        gh, gl = np.empty(d.nk), np.empty(d.nk)
        block_apply(d.n, d.row_start, d.row_count, self.Gih, self.Gil, False, t[0], t[1], gh, gl)
        yh, yl = d.HtT.matvec(gh, gl)
        rh, rl = np.empty(d.m), np.empty(d.m)
        dd.vadd(a[0], a[1], yh, yl, rh, rl)
        dvh, dvl = self.chol.solve(rh, rl)
        hh, hl = d.Ht.matvec(dvh, dvl)
        eh, el = np.empty(d.nk), np.empty(d.nk)
        dd.vadd(t[0], t[1], -hh, -hl, eh, el)
        drh, drl = np.empty(d.nk), np.empty(d.nk)
        block_apply(d.n, d.row_start, d.row_count, self.Gih, self.Gil, False, eh, el, drh, drl)
        return (dvh, dvl), (drh, drl)
