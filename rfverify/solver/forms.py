"""The linear-system forms of Algorithm 1 (DESIGN §4), one :class:`~.kkt.KKTSystem` each:
what matrix a form factors, which :mod:`.engines` engine factors it (QDLDL for the
quasi-definite forms, SuperLU for ``noscaling``, CHOLMOD for ``schur`` where it is installed
and QDLDL without it), and how one solve
recovers (dv, dr̃, dz) from it.
The unreduced system they all solve, its refinement and regularisation are :mod:`.kkt`'s;
:data:`FORMS` maps method names to them (see :mod:`.kkt` for each form's matrix)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..engines.factor import SuperLUEngine, schur_engine
from .kkt import KKTSystem, SparseAssembler


class JQinvSystem(KKTSystem):
    """Form (14): unknowns (dv, dr̃, y = Q_p dz)."""

    name = "jqinv"
    regularisable = True

    def _set_form_pattern(self):
        m, nk, cones = self.m, self.nk, self.cones
        y = m + nk + np.arange(self.nz)
        # Q_{p⁻¹} block at (J row of its Q row, y column), then the identity on y
        self._set_quasidefinite_pattern([m + self.rho[cones.bd_rows], y], [m + nk + cones.bd_cols, y], y.size + m + nk)

    def factor(self):
        self._factor_quasidefinite(self.Qp_inv_blocks, np.ones(self.nz))

    def solve_once(self, rhs):
        x = self.engine.solve(rhs)
        mk = self.m + self.nk
        x[mk:] = self.Qp_inv64(x[mk:])  # y = Q_p dz
        return x


class QP2System(KKTSystem):
    """Form (11): unknowns (dv, dr̃, dz); third row multiplied by Q_p: Jᵀdr̃ + Q_{p²} dz = Q_p c."""

    name = "qp2"
    regularisable = True

    def _set_form_pattern(self):
        m, nk, cones = self.m, self.nk, self.cones
        self._upper = upper = cones.bd_rows <= cones.bd_cols
        # J at (its row, dz column), then the upper triangle of Q_{p²} on dz
        self._set_quasidefinite_pattern([m + self.rho, m + nk + cones.bd_rows[upper]],
                                        [m + nk + np.arange(self.nz), m + nk + cones.bd_cols[upper]], m + nk + self.nz)

    def factor(self):
        q2 = self.cones.quad_blocks(self.cones.power(self.p, 2))[self._upper]
        self._factor_quasidefinite(np.ones(self.nz), q2)

    def solve_once(self, rhs):
        rhs = np.array(rhs, dtype=np.float64)
        mk = self.m + self.nk
        rhs[mk:] = self.Qp64(rhs[mk:])
        return self.engine.solve(rhs)


class ReducedSystem(KKTSystem):
    """Form (15): [[M, −H̃ᵀ], [−H̃, −G]], G = J Q_{p⁻²} Jᵀ; dz = Q_{p⁻¹}c − Q_{p⁻²}Jᵀdr̃."""

    name = "reduced"
    regularisable = True

    def _set_form_pattern(self):
        gr, gc = self.rho[self.cones.bd_rows], self.rho[self.cones.bd_cols]
        self._upper = upper = gr <= gc  # the upper triangle of G = J Q_{p⁻²} Jᵀ on dr̃
        self._set_quasidefinite_pattern([self.m + gr[upper]], [self.m + gc[upper]], self.m + self.nk)

    def factor(self):
        p_inv2 = self.cones.power(self.p, -2)
        self.Qp_inv2_64 = self.cones.quad_operator(np.asarray(p_inv2, dtype=np.float64))
        self._factor_quasidefinite(-self.cones.quad_blocks(p_inv2)[self._upper])

    def solve_once(self, rhs):
        rhs = np.asarray(rhs, dtype=np.float64)
        m, mk = self.m, self.m + self.nk
        qc = self.Qp_inv64(rhs[mk:])
        x = self.engine.solve(np.concatenate((rhs[:m], rhs[m:mk] - self.J @ qc)))
        dz = qc - self.Qp_inv2_64(self.J.T @ x[m:])
        return np.concatenate((x, dz))


class NoScalingSystem(KKTSystem):
    """Form (6): unsymmetric, Arw blocks, SuperLU with partial pivoting each iteration."""

    name = "noscaling"
    symmetric = False

    def _set_form_pattern(self):
        m, nk, nz = self.m, self.nk, self.nz
        cones = self.cones
        Mf = self.M.tocoo()
        Hc = self._Hcoo
        rows = [Mf.row, Hc.col, m + Hc.row, m + self.rho, m + nk + cones.bd_rows,
                m + nk + cones.bd_rows]
        cols = [Mf.col, m + Hc.row, Hc.col, m + nk + np.arange(nz), m + self.rho[cones.bd_cols],
                m + nk + cones.bd_cols]
        self._set_pattern(rows, cols, m + nk + nz)
        self._fixed = (Mf.data, -Hc.data, -Hc.data, np.ones(nz))

    def _new_engine(self):
        return SuperLUEngine()

    def factor(self):
        arw_z = self.cones.arrow_blocks(self.z)
        arw_s = self.cones.arrow_blocks(self.s)
        self.engine.factor(self.asm.matrix(np.concatenate((*self._fixed, arw_z, arw_s))))

    def solve_once(self, rhs):
        return self.engine.solve(rhs)


class ReducedFactoredSystem(KKTSystem):
    """Form (16): the reduced form with G = J Q_{p⁻²} Jᵀ = P Pᵀ, P = J Q_{p⁻¹}, and dr̃ = L⁻ᵀ y
    where G = L Lᵀ:

        [[M, −Bᵀ], [−B, −I]] [dv; y] = [a; L⁻¹(b − J Q_{p⁻¹} c)],   B = L⁻¹ H̃,

    quasi-definite with an identity block, so it needs no regularisation; then
    dr̃ = L⁻ᵀ y and dz = Q_{p⁻¹}c − Q_{p⁻²}Jᵀdr̃.  G is block diagonal by contact (5×5, 3×3
    or 1×1).  L is taken from a QR factorisation of Pᵀ contact by contact (Pᵀ = QR gives
    G = RᵀR, L = Rᵀ), never from a Cholesky factorisation of G: forming G squares the
    condition number of Q_{p⁻¹} (up to 1e20 near convergence), which made a Cholesky of G
    fail in double precision in the last iterations (measured on the bundled cube problem).
    The blocks are padded to 5×5 with identity and factored by one batched QR call.
    """

    name = "reduced_factored"

    def _set_contact_blocks(self):
        """The contact blocks of G (kept rows joined through the cones they feed), their
        padding to 5 × 5, and where each entry of P = J Q_{p⁻¹} and of B = L⁻¹H̃ goes."""
        from scipy.sparse.csgraph import connected_components

        nk = self.nk
        cones = self.cones
        # Contact blocks of G: kept rows joined through the cones they feed.
        cone_of_z = np.concatenate((np.arange(3 * cones.n3) // 3, cones.n3 + np.arange(cones.n1)))
        graph = sp.coo_matrix((np.ones(self.nz), (self.rho, nk + cone_of_z)),
                              shape=(nk + cones.n_cones, nk + cones.n_cones))
        _, lab = connected_components(graph, directed=False)
        block = lab[:nk]
        _, block = np.unique(block, return_inverse=True)
        self.n_blocks = int(block.max()) + 1 if nk else 0
        order = np.argsort(block, kind="stable")
        sizes = np.bincount(block, minlength=self.n_blocks)
        if sizes.max(initial=0) > 5:
            raise ValueError("a contact block of J Q Jᵀ is larger than 5")
        first = np.concatenate(([0], np.cumsum(sizes)[:-1]))
        local = np.empty(nk, dtype=np.int64)
        local[order] = np.arange(nk) - np.repeat(first, sizes)
        self.block, self.local, self.sizes = block, local, sizes
        self.pad_idx = np.full((self.n_blocks, 5), nk, dtype=np.int64)  # nk = the zero slot
        self.pad_idx[block, local] = np.arange(nk)
        self.pad_mask = self.pad_idx < nk
        self._unpad = None
        # P = J Q_{p⁻¹} contributions (kept row, z column of the same contact), quad_blocks order,
        # with z columns numbered within their contact (≤ 6: two L3 cones).
        zblock = block[self.rho]
        zorder = np.argsort(zblock, kind="stable")
        zsizes = np.bincount(zblock, minlength=self.n_blocks)
        zlocal = np.empty(self.nz, dtype=np.int64)
        zlocal[zorder] = np.arange(self.nz) - np.repeat(np.concatenate(([0], np.cumsum(zsizes)[:-1])), zsizes)
        if zlocal.max(initial=0) > 5:
            raise ValueError("a contact has more than 6 lifted cone components")
        gr = self.rho[cones.bd_rows]
        self._g = (block[gr], local[gr], zlocal[cones.bd_cols])
        # Padding rows get a unit entry in a column the contact does not use (a contact with
        # k < 5 kept rows has exactly k cone components), so every padded block has full rank.
        pad_b, pad_l = np.nonzero(self.pad_idx == nk)
        self._pad = (pad_b, pad_l)

    def _b_pattern(self):
        """B = L⁻¹H̃ as contributions: each H̃ entry (b, j) feeds rows a of its block, value
        Linv[a, b]·H̃[b, j] (``self._b`` = block, a, b, H̃ value); returns their (row, column)."""
        Hc = self._Hcoo
        hb = self.block[Hc.row]
        la = np.tile(np.arange(5), Hc.nnz)
        rep = np.repeat(np.arange(Hc.nnz), 5)
        keep = la < self.sizes[hb[rep]]
        rep, la = rep[keep], la[keep]
        self._b = (hb[rep], la, self.local[Hc.row[rep]], Hc.data[rep])
        return self.pad_idx[hb[rep], la], Hc.col[rep]

    def _set_form_pattern(self):
        """The pattern of [[M, −Bᵀ], [−B, −I]] (upper triangle)."""
        self._set_contact_blocks()
        m, nk = self.m, self.nk
        b_rows, b_cols = self._b_pattern()
        Mc = self._Mcoo
        rows = [Mc.row, b_cols, m + np.arange(nk)]
        cols = [Mc.col, m + b_rows, m + np.arange(nk)]
        self._set_pattern(rows, cols, m + nk)

    def factor(self):
        self._factor_blocks()
        hb, la, lb, hv = self._b
        self._factor_upper(np.concatenate((self._Mcoo.data, -self.Linv[hb, la, lb] * hv, -np.ones(self.nk))))

    def _factor_blocks(self):
        """Q_{p⁻²} (float64 operator) and L⁻¹ block by block, G = J Q_{p⁻²} Jᵀ = L Lᵀ."""
        p_inv2 = self.cones.power(self.p, -2)
        self.Qp_inv2_64 = self.cones.quad_operator(np.asarray(p_inv2, dtype=np.float64))
        P = np.zeros((self.n_blocks, 5, 6))
        gb, gl, gk = self._g
        P[gb, gl, gk] = self.cones.quad_blocks(self.p_inv)  # one J entry per z: no sums
        P[self._pad[0], self._pad[1], self._pad[1]] = 1.0
        R = np.linalg.qr(np.swapaxes(P, 1, 2), mode="r")  # Pᵀ = QR, so G = P Pᵀ = RᵀR
        L = np.swapaxes(R, 1, 2)
        if not np.all(np.abs(np.diagonal(L, axis1=1, axis2=2)) > 0):
            raise ArithmeticError("a contact block of P = J Q_{p⁻¹} is rank deficient")
        self.Linv = np.linalg.solve(L, np.broadcast_to(np.eye(5), L.shape))

    def _blocks(self, x, transpose=False):
        """Apply L⁻¹ (or L⁻ᵀ) block by block to a kept-row vector."""
        padded = np.append(x, 0.0)[self.pad_idx]
        op = np.swapaxes(self.Linv, 1, 2) if transpose else self.Linv
        out = np.einsum("nij,nj->ni", op, padded)
        if self._unpad is None:
            self._unpad = np.argsort(self.pad_idx[self.pad_mask])
        return out[self.pad_mask][self._unpad]

    def solve_once(self, rhs):
        rhs = np.asarray(rhs, dtype=np.float64)
        m, mk = self.m, self.m + self.nk
        qc = self.Qp_inv64(rhs[mk:])
        x = self.engine.solve(np.concatenate((rhs[:m], self._blocks(rhs[m:mk] - self.J @ qc))))
        dr = self._blocks(x[m:], transpose=True)
        dz = qc - self.Qp_inv2_64(self.J.T @ dr)
        return np.concatenate((x[:m], dr, dz))


class SchurSystem(ReducedFactoredSystem):
    """Form (16) with its identity block eliminated: the dof-space Schur complement

        S = M + Bᵀ B = M + H̃ᵀ G⁻¹ H̃,   B = L⁻¹ H̃,   G = J Q_{p⁻²} Jᵀ = L Lᵀ,

    symmetric positive definite (M is), factored by CHOLMOD's supernodal Cholesky (cvxopt's
    wheel, a dependency): dense BLAS-3 kernels on the supernodes, where QDLDL's up-looking
    LDLᵀ — the fallback where cvxopt's CHOLMOD cannot be called — works entry by entry (24–44× slower per
    factorisation at 10⁴ contacts).  S dv = a − Bᵀ L⁻¹ b′
    with b′ = b − J Q_{p⁻¹} c, then dr̃ = −L⁻ᵀ (L⁻¹ b′ + B dv) and dz = Q_{p⁻¹}c − Q_{p⁻²}Jᵀdr̃.
    S is M + BᵀB (sparse product) put on the fixed pattern of M + |B|ᵀ|B|, in the triangle the
    engine reads, so that the ordering and symbolic analysis of the first factorisation hold
    for every later one.  Needs no δ (S is definite); refinement as for every form, against
    the unreduced operator.
    """

    name = "schur"

    def _new_engine(self):
        return schur_engine()

    def _triangle(self, A):
        return sp.tril(A, format="csc") if self.engine.triangle == "lower" else sp.triu(A, format="csc")

    def _set_form_pattern(self):
        self._set_contact_blocks()
        m, nk = self.m, self.nk
        b_rows, b_cols = self._b_pattern()
        self._basm = SparseAssembler(b_rows, b_cols, (nk, m))
        # One triangle of S's pattern, from B's and M's (all entries counted: a product of
        # positive ones cannot cancel), in CSC order = ascending key col·m + row.
        ones = sp.csc_matrix((np.ones(self._basm.nnz), self._basm.indices, self._basm.indptr), shape=(nk, m))
        pat = self._triangle(abs(self.M) + (ones.T @ ones))
        pat.sort_indices()
        self._s_indices, self._s_indptr = pat.indices, pat.indptr
        self._s_key = np.repeat(np.arange(m, dtype=np.int64), np.diff(pat.indptr)) * m + pat.indices
        self.N = m

    def factor(self):
        self._factor_blocks()
        hb, la, lb, hv = self._b
        B = self._basm.matrix(self.Linv[hb, la, lb] * hv)
        C = self._triangle(self.M + (B.T @ B))  # a numerical zero may leave C's pattern
        key = np.repeat(np.arange(self.m, dtype=np.int64), np.diff(C.indptr)) * self.m + C.indices
        data = np.zeros(self._s_key.size)
        data[np.searchsorted(self._s_key, key)] = C.data
        self.engine.factor(sp.csc_matrix((data, self._s_indices, self._s_indptr), shape=(self.m, self.m)))

    def solve_once(self, rhs):
        rhs = np.asarray(rhs, dtype=np.float64)
        m, mk = self.m, self.m + self.nk
        qc = self.Qp_inv64(rhs[mk:])
        y = self._blocks(rhs[m:mk] - self.J @ qc)
        dv = self.engine.solve(rhs[:m] - self.H_t.T @ self._blocks(y, transpose=True))
        dr = -self._blocks(y + self._blocks(self.H_t @ dv), transpose=True)
        dz = qc - self.Qp_inv2_64(self.J.T @ dr)
        return np.concatenate((dv, dr, dz))


FORMS = {"jqinv": JQinvSystem, "qp2": QP2System, "reduced": ReducedSystem,
         "reduced_factored": ReducedFactoredSystem, "noscaling": NoScalingSystem, "schur": SchurSystem}
