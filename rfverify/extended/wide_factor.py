"""The Newton solve of the multiple-precision tail (:mod:`.wide`): per-contact factors
F_c⁻¹ of G_c = J_c Q_{p⁻²} J_cᵀ and the dof-space form :class:`WideDofSpace`, which
assembles S = M + H̃ᵀG⁻¹H̃ = M + BᵀB (B = F⁻¹H̃) in ``bits``-bit mpfr at a
:class:`rfverify.jordan.mpfr.Scaling` and solves M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t with
the factor of one of :mod:`.wide_cholesky`'s engines."""

from __future__ import annotations

from collections.abc import Callable

import gmpy2
import numpy as np
import scipy.sparse as sp

from ..jordan.mpfr import Scaling, quad_matrix
from .data import ExtendedData, contact_dof_pattern, contact_local_H
from .ldl import fill_reducing_order
from .wide_cholesky import OrderedPattern, SparseWideCholesky, WideCholesky
from .wide_data import WideData, from_dd, zeros

_sqrt = np.frompyfunc(gmpy2.sqrt, 1, 1)


def contact_factor_inverse(data: ExtendedData, sc: Scaling) -> np.ndarray:
    """F_c⁻¹ per contact, (n, 5, 5) mpfr, for F_c F_cᵀ = G_c = J_c Q_{p⁻²} J_cᵀ: the formulas
    of :func:`.blocks.contact_factor_inverse` (Q_p for one cone, p² for a normal ray, (R⁻¹)ᵀ
    of a Householder QR of (J_c Q_{p⁻¹})ᵀ for a full contact), vectorised over contacts.
    Raises ArithmeticError if a factor is singular."""
    n = data.n
    F = np.empty((n, 5, 5), dtype=object)
    F[:] = gmpy2.mpfr(0)
    kinds = data.kinds
    ray = np.flatnonzero(kinds == 3)
    if ray.size:
        F[ray, 0, 0] = sc.q1[data.normal_cone[ray] - data.n3] ** 2
    for kind, cones in ((1, data.fric_cone), (2, data.roll_cone)):
        sel = np.flatnonzero(kinds == kind)
        if sel.size:
            F[sel, :3, :3] = quad_matrix(sc, 1, cones[sel])
    full = np.flatnonzero(kinds == 0)
    if full.size:
        nf = full.size
        At = np.empty((nf, 6, 5), dtype=object)
        At[:] = gmpy2.mpfr(0)
        At[:, :3, :3] = quad_matrix(sc, -1, data.fric_cone[full])
        At[:, 3:, [0, 3, 4]] = quad_matrix(sc, -1, data.roll_cone[full])
        R = At
        for j in range(5):
            norm = _sqrt(np.sum(R[:, j:, j] * R[:, j:, j], axis=1))
            if not (norm > 0).astype(bool).all():
                raise ArithmeticError("a contact's factor is singular")
            alpha = np.where((R[:, j, j] > 0).astype(bool), -norm, norm)
            vcol = R[:, j:, j].copy()
            vcol[:, 0] = vcol[:, 0] - alpha
            beta = 2 / np.sum(vcol * vcol, axis=1)
            for c in range(j + 1, 5):
                proj = np.sum(vcol * R[:, j:, c], axis=1) * beta
                R[:, j:, c] = R[:, j:, c] - proj[:, None] * vcol
            R[:, j, j] = alpha
        Rinv_T = np.empty((nf, 5, 5), dtype=object)
        Rinv_T[:] = gmpy2.mpfr(0)
        for c in range(5):  # column c of R⁻¹, stored as row c of (R⁻¹)ᵀ
            for r in range(c, -1, -1):
                acc = np.full(nf, gmpy2.mpfr(1 if r == c else 0), dtype=object)
                for q in range(r + 1, c + 1):
                    acc = acc - R[:, r, q] * Rinv_T[:, c, q]
                Rinv_T[:, c, r] = acc / R[:, r, r]
        F[full] = Rinv_T
    return F


def dof_space_pattern(data: ExtendedData, CD=None) -> sp.csc_matrix:
    """The sparsity pattern of M + H̃ᵀG⁻¹H̃ (m × m): M's, and a dof pair wherever one contact
    touches both (``CD``: the contact–dof pattern, if the caller has it)."""
    CD = contact_dof_pattern(data) if CD is None else CD
    return (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()


def dof_space_ordering(data: ExtendedData, CD=None):
    """(minimum-degree order of M + H̃ᵀG⁻¹H̃'s pattern, the number of multiply-subtract pairs
    its Cholesky factor costs in that order: :attr:`.wide_cholesky.OrderedPattern.ops`)."""
    pattern = dof_space_pattern(data, CD)
    perm = fill_reducing_order(pattern)
    return perm, OrderedPattern(pattern, perm).ops


class WideDofSpace:
    """The dof-space Newton matrix S = M + H̃ᵀG⁻¹H̃ = M + BᵀB (B = F⁻¹H̃, per contact) in
    ``bits``-bit mpfr, the tail's Newton back end: ``update`` assembles S at a scaling and
    has ``engine`` factor it in a minimum-degree order (``perm``, from
    :func:`dof_space_ordering`, if the caller has it); ``solve`` eliminates dr̃ with
    G⁻¹ = F⁻ᵀF⁻¹ and solves with that factor.  ``engine`` builds a
    :class:`.wide_cholesky.WideCholesky` from the ordered pattern:
    :class:`.wide_cholesky.SparseWideCholesky` (the tail's) or
    :class:`.wide_cholesky.DenseWideCholesky` (its reference).

    Why not the double-double back ends: S and the contact-space S' = I + F⁻¹W̃F⁻ᵀ both have
    condition numbers near 1/μ along redundant sticking contacts (W̃ singular), and near
    μ = 1e-40 their float64 and double-double factors lose definiteness (measured on a
    274-contact Lattice, DECISIONS).  A factor in ``bits``-bit arithmetic does not."""

    def __init__(self, data: ExtendedData, W: WideData,
                 engine: Callable[[OrderedPattern], WideCholesky] = SparseWideCholesky,
                 perm: np.ndarray | None = None):
        self.data = data
        self.W = W
        CD = contact_dof_pattern(data)
        pattern = dof_space_pattern(data, CD)
        order = fill_reducing_order(pattern) if perm is None else perm
        ordered = OrderedPattern(pattern, order)
        self.engine = engine(ordered)
        self.name = f"{self.engine.kind} dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"
        loc_dofs, Hh, Hl = contact_local_H(data, CD)
        self.Hc = from_dd(Hh, Hl) if Hh.size else np.empty(Hh.shape, dtype=object)  # (n, 5, d)
        d = loc_dofs.shape[1]
        valid = loc_dofs >= 0
        both = valid[:, :, None] & valid[:, None, :]
        rows = np.broadcast_to(loc_dofs[:, :, None], (data.n, d, d))
        cols = np.broadcast_to(loc_dofs[:, None, :], (data.n, d, d))
        slots = np.full((data.n, d, d), -1, dtype=np.int64)
        slots[both] = ordered.slots(rows[both], cols[both])
        self.block_take = slots >= 0  # the entries of each B_cᵀB_c in the stored triangle
        self.block_pos = slots[self.block_take]
        mr, mc, mh, ml = data.M.coo()
        m_slots = ordered.slots(mr, mc)
        stored = m_slots >= 0
        self.M_values = zeros(ordered.indices.size)
        np.add.at(self.M_values, m_slots[stored], from_dd(mh[stored], ml[stored]))
        self.Finv = None

    def update(self, sc: Scaling) -> bool:
        """Form and factor S at the scaling ``sc``; False if a pivot is not positive."""
        self.Finv = contact_factor_inverse(self.data, sc)  # (n, 5, 5); zero past a contact's kept rows
        B = np.matmul(self.Finv, self.Hc)  # (n, 5, d)
        blocks = np.matmul(np.transpose(B, (0, 2, 1)), B)  # (n, d, d) = B_cᵀB_c
        S = self.M_values.copy()
        np.add.at(S, self.block_pos, blocks[self.block_take])
        return self.engine.factor(S)

    def _G_inv(self, x):
        """G⁻¹x = F⁻ᵀ(F⁻¹x), contact by contact (x over the kept rows)."""
        data = self.data
        X = zeros(data.n * 5).reshape(data.n, 5)
        rows_local = np.arange(data.nk) - np.repeat(data.row_start, data.row_count)
        cont = np.repeat(np.arange(data.n), data.row_count)
        X[cont, rows_local] = x
        Y = np.matmul(self.Finv, X[:, :, None])
        Z = np.matmul(np.transpose(self.Finv, (0, 2, 1)), Y)[:, :, 0]
        return Z[cont, rows_local]

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (mpfr; dv (m,), dr̃ (nk,))."""
        W = self.W
        dv = self.engine.solve(a + W.HtT @ self._G_inv(t))
        dr = self._G_inv(t - W.Ht @ dv)
        return dv, dr
