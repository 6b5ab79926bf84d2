"""The problem restricted to the face that verified self-stresses force (facial reduction),
and the map of its points back to the problem's own variables (DESIGN §6.8).

Where a self-stress y exists, every feasible velocity keeps u_F (the contacts y touches) in
the face Φ = {G s + G₀ t : s ≥ 0} of K*_F (:mod:`.face`: G the face's edges, G₀ its free
directions).  The problem is then the same as

    min ½vᵀMv − fᵀv   s.t.  u_j(v) ∈ K*_j (j ∉ F),   P (H_Fᵀv + w_F) = 0,   s(v) ≥ 0,

with P's rows spanning the complement of range[G G₀] and s(v) = C (H_Fᵀv + w_F) the edge
coefficients (C the rows of [G G₀]⁺ that belong to G).  The equalities touch only the dofs D
of the bodies those contacts act on; with Z_D a basis of the null space of E = P H_{F,D}ᵀ and
E v₀ = −P w_F, v = v₀ + Z ξ (Z the identity off D).  The reduced problem, in ξ, is an
ordinary rolling-friction problem: M' = ZᵀMZ, f' = Zᵀ(f − Mv₀), the other contacts with
H' = ZᵀH and w' = w + Hᵀv₀, and one frictionless contact (μ = μr = 0) per edge, with normal
column Zᵀ H_{F,D} cⱼ and w_N = cⱼᵀ(w_F + H_Fᵀ v₀).  It has an interior, so Algorithm 1
converges on it as on any problem.

Z is exact (the null space over Q of the face system [H_{F,D}ᵀ | −G | −G₀], whose edge parts
are the edge functionals exactly); the reduced problem holds float64 roundings of its data, and
its double-double phase gets ZᵀH and the edge functionals exactly to double-double
(:meth:`FaceReduction.refine`), because a contact beside the face that is active at the
solution sits ~μ inside its cone, far less than a float64 rounding.  The reduced problem is a
device for finding points, never the subject of a proof: :func:`FaceReduction.lift` maps its
points back (v = v₀ + Zξ; r on F from the edge multipliers ρ and the equalities' multipliers λ,
r_F = Σ cⱼ ρⱼ + Pᵀλ, λ by least squares with exact residuals), and the proof
(:func:`.bound.prove`) moves the lifted point onto the exact face and adds a multiple of y to r
before it evaluates the theorem on the file's own data.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from fractions import Fraction

from ..model.problem import SPACEDIM, Problem
from . import Point
from . import rational as Q
from .dyadic import Dyadic
from .face import SelfStress

@dataclass
class _Block:
    """The reduction of one self-stress: its contacts' columns, the dofs D, Z_D, v₀_D, P, C."""

    cols: np.ndarray
    dofs: np.ndarray
    Z: np.ndarray       # (|D|, k_D)
    v0: np.ndarray      # (|D|,)
    P: np.ndarray       # (p, 5|F|)
    C: np.ndarray       # (e, 5|F|) edge-coefficient rows
    HtD: np.ndarray     # H_{F,D}ᵀ (5|F|, |D|)
    edges: list         # per row of C: (contact index in F, the edge as 5 exact Fractions)
    Zx: list            # Z exactly: |D| rows of k_D Fractions (the face's motions of these bodies)
    Sx: list            # the edge coefficients exactly: e rows of k_D Fractions (s = Sx ξ + s0)
    v0x: list           # v₀ on D exactly (|D| Fractions)
    s0x: list           # the edge coefficients at v₀ (e Fractions)
    mu: np.ndarray
    mu_r: np.ndarray


def _block(problem: Problem, stress: SelfStress) -> _Block | None:
    contacts = stress.contacts
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    Hc = sp.csc_matrix(problem.H)[:, cols]
    dofs = np.unique(Hc.indices)
    HtD = Hc[dofs].T.toarray()
    nF = cols.size
    edges, free, exact_edges = [], [], []
    for i in range(contacts.size):
        for g in stress.edges[i]:
            vec = np.zeros(nF)
            vec[SPACEDIM * i:SPACEDIM * i + SPACEDIM] = [float(x) for x in g]
            edges.append(vec)
            exact_edges.append((i, g))
        for g in stress.free[i]:
            vec = np.zeros(nF)
            vec[SPACEDIM * i:SPACEDIM * i + SPACEDIM] = [float(x) for x in g]
            free.append(vec)
    G_all = np.array(edges + free, dtype=np.float64).reshape(-1, nF).T  # (5|F|, e + f)
    if G_all.shape[1]:
        U, sv, _ = np.linalg.svd(G_all, full_matrices=True)
        rank = int(np.sum(sv > 1e-12 * sv[0]))
        P = U[:, rank:].T
        C = np.linalg.pinv(G_all)[:len(edges)]
    else:
        P = np.eye(nF)
        C = np.zeros((0, nF))
    # The motions the face allows, exactly: the null space over Q of [H_{F,D}ᵀ | −G_edges | −G_free]
    # (δ on D, edge and free coefficients); its δ parts are Z, its edge parts the edge functionals.
    gens = [g for i in range(contacts.size) for g in ([(i, x) for x in stress.edges[i]]
                                                       + [(i, x) for x in stress.free[i]])]
    A = Q.as_fractions(HtD)
    for r_i, row in enumerate(A):
        i, comp = divmod(r_i, SPACEDIM)
        row += [-g[comp] if gi == i else Fraction(0) for gi, g in gens]
    nD, ne = dofs.size, len(edges)
    basis = Q.null_space(A, nD + len(gens))
    basis = [b for b in basis if any(b[:nD])]
    if not basis:
        return None  # the face allows these bodies no motion at all: nothing to reduce to
    basis = [[x / max(abs(t) for t in b[:nD]) for x in b] for b in basis]  # columns of Z at most 1
    Zx = [[b[d] for b in basis] for d in range(nD)]
    Sx = [[b[nD + j] for b in basis] for j in range(ne)]
    wF = [Fraction(float(x)) for x in problem.w[cols]]
    if any(wF):
        x0 = Q.particular_solution(A, [-x for x in wF])
        if x0 is None:
            return None
    else:
        x0 = [Fraction(0)] * (nD + len(gens))
    v0x, s0x = x0[:nD], x0[nD:nD + ne]
    Z = np.array([[float(x) for x in row] for row in Zx])
    v0 = Q.to_float(v0x)
    return _Block(cols, dofs, Z, v0, P, C, HtD, exact_edges, Zx, Sx, v0x, s0x,
                  problem.mu[contacts], problem.mu_r[contacts])


@dataclass
class FaceReduction:
    """The reduced problem (:attr:`problem`) and the data to map its points back."""

    original: Problem
    problem: Problem
    stresses: list
    blocks: list
    Z: sp.csc_matrix          # (m, m') v = v₀ + Z ξ
    v0: np.ndarray            # (m,)
    kept_contacts: np.ndarray  # the original contacts that stay, in order (the first of the reduced ones)
    edge_owner: list           # per reduced edge contact: (block index, edge index)

    def refine(self, data) -> None:
        """Give the extended phase of :attr:`problem` (``data``, its
        :class:`~rfverify.extended.data.ExtendedData`) the entries of H̃ on the face's dofs as the
        exact products Zᵀ H of the original data (Z exact, rational) rounded to double-double,
        and the edge contacts' exact coefficients, instead of the float64 roundings the reduced
        problem holds: a contact beside the face that is active at the solution sits ~1e-29
        inside its cone at a converged iterate, far less than those roundings (~1e-16), and its
        lifted velocity (:meth:`lift`, with the same exact Z) must be in the cone exactly.  Also
        ``data.contact_names``: each contact's index in the original, −1 − e for the face's edge
        contact e (for the run's step reports)."""
        from fractions import Fraction

        # its contacts named as the problem's own where they are (the step reports of its run)
        data.contact_names = np.concatenate([self.kept_contacts, -1 - np.arange(len(self.edge_owner))])
        Ht = data.Ht
        rows, cols, _, _ = Ht.coo()
        n_kept_dofs = self.Z.shape[0] - sum(b.dofs.size for b in self.blocks)
        flat = data.lp.keep[rows]
        rc, comp = np.divmod(flat, SPACEDIM)
        which = np.flatnonzero(cols >= n_kept_dofs)
        if not which.size:
            return
        H = sp.csc_matrix(self.original.H)
        col_of = {}  # reduced dof -> (block, column of its Z)
        start = n_kept_dofs
        for b in self.blocks:
            for t in range(b.Z.shape[1]):
                col_of[start + t] = (b, t)
            start += b.Z.shape[1]
        hi, lo = Ht.hi.copy(), Ht.lo.copy()
        nk = self.kept_contacts.size
        for e in which:
            b, t = col_of[int(cols[e])]
            if rc[e] >= nk:  # a frictionless edge contact: its coefficient s_j exactly
                bi, j = self.edge_owner[int(rc[e]) - nk]
                exact = self.blocks[bi].Sx[j][t] if comp[e] == 0 else Fraction(0)
            else:
                column = H[:, SPACEDIM * int(self.kept_contacts[rc[e]]) + int(comp[e])]
                exact = Fraction(0)
                for d, z in zip(b.dofs, b.Zx):
                    h = column[int(d), 0]
                    if h and z[t]:
                        exact += z[t] * Fraction(float(h))
            exact *= Fraction(float(data.lp.scale[rows[e]]))
            hi[e] = float(exact)
            lo[e] = float(exact - Fraction(hi[e]))
        from ..extended.data import DDMatrix

        data.Ht = DDMatrix(Ht.shape, Ht.indptr, Ht.indices, hi, lo)
        data.HtT = data.Ht.transpose()

    def lift(self, point: Point) -> Point:
        """A point of the reduced problem as a point of the original one (double-double)."""
        orig = self.original
        m, n = orig.n_dofs, orig.n_contacts
        xi_h, xi_l = point.v_hi, point.v_lo
        Z = self.Z
        # v = v₀ + Z ξ: a copy off D, and on D the exact rational Z ξ rounded to double-double
        vh = self.v0 + Z @ xi_h
        vl = np.zeros(m)
        first = int(np.sum(~np.isin(np.arange(m), np.concatenate([b.dofs for b in self.blocks]))))
        off_D = np.ones(m, dtype=bool)
        for b in self.blocks:
            off_D[b.dofs] = False
        vl[off_D] = Z[off_D] @ xi_l
        for b in self.blocks:
            xi = [Fraction(float(xi_h[first + t])) + Fraction(float(xi_l[first + t])) for t in range(b.Z.shape[1])]
            for d, row, v0d in zip(b.dofs, b.Zx, b.v0x):
                x = v0d + sum((z * c for z, c in zip(row, xi) if z), Fraction(0))
                vh[d] = float(x)
                vl[d] = float(x - Fraction(vh[d]))
            first += b.Z.shape[1]
        rh = np.zeros(SPACEDIM * n)
        rl = np.zeros(SPACEDIM * n)
        kept_cols = (SPACEDIM * self.kept_contacts[:, None] + np.arange(SPACEDIM)).ravel()
        nk = kept_cols.size
        rh[kept_cols], rl[kept_cols] = point.r_hi[:nk], point.r_lo[:nk]
        # r on F: Σ cⱼρⱼ + Pᵀλ, λ fitting the force the reduced solution leaves on D
        vd = Dyadic.from_dd(vh, vl)
        rd_kept = Dyadic.from_dd(rh, rl)
        exact_res = _force_residual(orig, vd, rd_kept)  # M v − f − H r (r zero on F), exact
        rho = point.r_hi[nk::SPACEDIM] + point.r_lo[nk::SPACEDIM]
        k0 = 0
        for b in self.blocks:
            ne = b.C.shape[0]
            base = b.C.T @ rho[k0:k0 + ne] if ne else np.zeros(b.cols.size)
            k0 += ne
            # R_D = H_{F,D}(Σcρ) + H_{F,D}Pᵀλ: λ by least squares, refined on exact residuals
            A = b.HtD.T @ b.P.T  # (|D|, p)
            parts_h = base.copy()
            parts_l = np.zeros_like(base)
            target = exact_res[b.dofs]
            resid = _residual_on(target, b.HtD, parts_h, parts_l)
            for _ in range(3):
                lam = np.linalg.lstsq(A, resid.nearest(), rcond=None)[0]
                step = b.P.T @ lam
                parts_h, parts_l = _dd_add(parts_h, parts_l, step)
                resid = _residual_on(target, b.HtD, parts_h, parts_l)
            for j, (i, g) in enumerate(b.edges):
                sl = slice(SPACEDIM * i, SPACEDIM * i + SPACEDIM)
                parts_h[sl], parts_l[sl] = _edge_positive(parts_h[sl], parts_l[sl], g, rho[k0 - ne + j])
            rh[b.cols], rl[b.cols] = parts_h, parts_l
            for i, c in enumerate(b.cols):
                comp = i % SPACEDIM
                contact = i // SPACEDIM
                if (comp in (1, 2) and b.mu[contact] == 0) or (comp in (3, 4) and b.mu_r[contact] == 0):
                    rh[c] = rl[c] = 0.0  # K forces these to 0 exactly
        return Point(vh, vl, rh, rl)


EDGE_FLOOR = 2.0 ** -90
"""Least gᵀr kept on an edge, relative to ‖r_i‖: a lifted r_F must have gᵀr_i > 0 on each edge g
for r + τy ∈ K to hold for some τ (:func:`.face.shift_into_K`); the edge multiplier ρ is
tiny where the contact slides (ρ → 0), so rounding could make it negative."""


def _edge_positive(hi: np.ndarray, lo: np.ndarray, g, rho: float):
    """r_i (double-double, 5 entries) changed along the edge g, where needed, so that gᵀr_i lies
    in [floor, 2t] exactly, t = max(ρ, floor), floor = EDGE_FLOOR·‖r_i‖∞: positive (so r + τy ∈
    K for some τ), and not much larger than the edge multiplier ρ says (gᵀr_i·s is this contact's
    part of the duality gap once u_i = g s).  Where it is changed, the change is of the order of
    the rounding of r_i, or of ρ where ρ is that small."""
    from fractions import Fraction

    gf = np.array([float(x) for x in g])
    lower = Fraction(EDGE_FLOOR * float(np.max(np.abs(hi))))
    target = max(Fraction(float(rho)), lower)
    for _ in range(6):
        have = sum((gk * (Fraction(float(a)) + Fraction(float(b))) for gk, a, b in zip(g, hi, lo) if gk), Fraction(0))
        if lower <= have <= 2 * target:
            break
        alpha = float(Fraction(3, 2) * target - have) / float(gf @ gf)
        hi, lo = _dd_add(hi, lo, alpha * gf)
    return hi, lo


def _force_residual(problem: Problem, v: Dyadic, r: Dyadic) -> Dyadic:
    from .dyadic import DyadicCSR

    M = DyadicCSR.from_scipy(problem.M_eq)
    H = DyadicCSR.from_scipy(problem.H)
    return M.matvec(v) - H.matvec(r) - Dyadic.from_float(problem.f)


def _residual_on(target: Dyadic, HtD: np.ndarray, hi: np.ndarray, lo: np.ndarray) -> Dyadic:
    """target − H_{F,D}(hi + lo), exact."""
    from .dyadic import DyadicCSR

    A = DyadicCSR.from_scipy(sp.csr_matrix(HtD.T))
    return target - A.matvec(Dyadic.from_dd(hi, lo))


def _dd_add(hi: np.ndarray, lo: np.ndarray, x: np.ndarray):
    s = hi + x
    bb = s - hi
    err = (hi - (s - bb)) + (x - bb)
    lo = lo + err
    h2 = s + lo
    return h2, lo - (h2 - s)


def reduce_to_face(problem: Problem, stresses: list) -> FaceReduction | None:
    """The reduced problem of ``stresses`` (verified, feasible, on disjoint bodies), or None when
    the face leaves their bodies no motion, every contact is stuck on it (no contact problem is
    left), or the problem is local."""
    if problem.local is not None or not stresses:
        return None
    blocks = []
    for s in stresses:
        b = _block(problem, s)
        if b is None:
            return None
        blocks.append(b)
    m, n = problem.n_dofs, problem.n_contacts
    in_D = np.zeros(m, dtype=bool)
    for b in blocks:
        if np.any(in_D[b.dofs]):
            return None  # two stresses on shared bodies: not reduced (not met so far)
        in_D[b.dofs] = True
    kept_dofs = np.flatnonzero(~in_D)
    # Z: identity on the kept dofs (first), then each block's Z_D
    rows, cols, vals = [kept_dofs], [np.arange(kept_dofs.size)], [np.ones(kept_dofs.size)]
    col0 = kept_dofs.size
    v0 = np.zeros(m)
    for b in blocks:
        r_idx, c_idx = np.nonzero(np.ones_like(b.Z, dtype=bool))
        rows.append(b.dofs[r_idx])
        cols.append(col0 + c_idx)
        vals.append(b.Z[r_idx, c_idx])
        col0 += b.Z.shape[1]
        v0[b.dofs] = b.v0
    Z = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m, col0))
    Z.eliminate_zeros()
    F = np.zeros(n, dtype=bool)
    for s in stresses:
        F[s.contacts] = True
    kept_contacts = np.flatnonzero(~F)
    kept_cols = (SPACEDIM * kept_contacts[:, None] + np.arange(SPACEDIM)).ravel()
    H = sp.csc_matrix(problem.H)
    M = sp.csc_matrix(problem.M)
    M_red = (Z.T @ M @ Z).tocsc()
    f_red = Z.T @ (problem.f - M @ v0)
    H_kept = (Z.T @ H[:, kept_cols]).tocsc()
    w_kept = problem.w[kept_cols] + H[:, kept_cols].T @ v0
    edge_cols, edge_w, owner = [], [], []
    first = kept_dofs.size
    for bi, b in enumerate(blocks):
        for j in range(b.C.shape[0]):  # s_j = Sx_j ξ + s0_j: a frictionless contact on the block's ξ
            col = np.zeros(Z.shape[1])
            col[first:first + b.Z.shape[1]] = [float(x) for x in b.Sx[j]]
            edge_cols.append(col)
            edge_w.append(float(b.s0x[j]))
            owner.append((bi, j))
        first += b.Z.shape[1]
    ne = len(edge_cols)
    if kept_contacts.size + ne == 0:
        return None  # every contact stuck on the face: no contact problem is left to pose (not reduced)
    blocks_H = [H_kept]
    if ne:
        E = np.zeros((Z.shape[1], SPACEDIM * ne))
        for j, col in enumerate(edge_cols):
            E[:, SPACEDIM * j] = col
        blocks_H.append(sp.csc_matrix(E))
    H_red = sp.hstack(blocks_H, format="csc")
    w_red = np.concatenate([w_kept] + [np.array([wj, 0, 0, 0, 0]) for wj in edge_w])
    mu = np.concatenate([problem.mu[kept_contacts], np.zeros(ne)])
    mu_r = np.concatenate([problem.mu_r[kept_contacts], np.zeros(ne)])
    reduced = Problem.from_arrays(M_red, H_red, f_red, w_red, mu, mu_r, title=f"{problem.title} (on the face)",
                                  max_asymmetry=np.inf, source=getattr(problem, "source", ""))
    reduced = reduced.stored_equations(problem.equations == "stored")
    return FaceReduction(problem, reduced, list(stresses), blocks, Z, v0, kept_contacts, owner)
