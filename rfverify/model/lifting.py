"""Lifting of the rolling-friction cone to a product of Lorentz cones (DESIGN §2), with the
per-contact cone reduction of the presolve (DESIGN §4).

Per contact i with P_i = diag(1, μ, μ, μr, μr): H̃ = P Hᵀ, w̃ = P w, r̃ = P⁻¹ r, ũ = P u, so
H̃ᵀ r̃ = H r and ũᵀ r̃ = uᵀ r.  Then ũ ∈ K*  ⟺  ũ = J z with z = (t, ū; t', ǔ) ∈ L3 × L3,
and r̃ ∈ K ⟺ Jᵀ r̃ = (r0, r̄; r0, ř) ∈ L3 × L3.

Contacts with a zero coefficient keep only the components that are not forced to zero —
dividing by μ or μr would otherwise be needed:

==========  ==========================  ==================  ========================
kind        coefficients                kept components     lifted cones
==========  ==========================  ==================  ========================
``full``    μ > 0, μr > 0               N, T1, T2, R1, R2   L3 (N,T) × L3 (N,R); u0 = t + t'
``coulomb`` μ > 0, μr = 0               N, T1, T2           L3
``rolling`` μ = 0, μr > 0               N, R1, R2           L3
``normal``  μ = μr = 0                  N                   L1 (r_N ≥ 0 ⊥ u_N ≥ 0)
==========  ==========================  ==================  ========================

A dropped component has r = 0 (K forces it) and an unconstrained u (K* does not involve it);
u is recomputed as Hᵀ v + w in the original layout.

Layout of the cone variables: all L3 cones first (array ``(n3, 3)`` when reshaped), then all
L1 cones (``(n1, 1)``), so each family is one contiguous block that the Jordan algebra
processes in one vectorised call; :class:`rfverify.solver.cones.ProductCone` splits, joins and
operates on such vectors.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .problem import SPACEDIM, Problem

KIND_FULL, KIND_COULOMB, KIND_ROLLING, KIND_NORMAL = 0, 1, 2, 3
KIND_NAMES = ("full", "coulomb", "rolling", "normal")
CONE_PARTS = ("friction", "rolling", "normal")
"""The part of a contact each cone of the lifted problem holds (``LiftedProblem.cone_part``)."""

CONE_SIDES = {"z": "velocity", "s": "reaction"}
"""A cone's two members: z (H̃v + w̃ = Jz, the lifted velocity u) and s = Jᵀr̃ (the reaction)."""


def cone_words(held: dict) -> str:
    """"contact 453's rolling cone (velocity)" for a :meth:`LiftedProblem.held_by` dict; a
    contact None with "face_edge" e (a problem on a self-stress's face) is "the face's edge
    contact e's"."""
    who = (f"contact {held['contact']}'s" if held.get("contact") is not None
           else f"the face's edge contact {held['face_edge']}'s")
    return f"{who} {held['part']} cone ({held['side']})"


_KEPT = {  # kept local components per kind
    KIND_FULL: (0, 1, 2, 3, 4),
    KIND_COULOMB: (0, 1, 2),
    KIND_ROLLING: (0, 3, 4),
    KIND_NORMAL: (0,),
}


@dataclass(frozen=True)
class LiftedProblem:
    """The lifted Lorentz-cone form of a :class:`Problem`.

    Attributes
    ----------
    problem : Problem
        The original problem.
    kinds : ndarray of int, (n,)
        Cone kind of each contact (``KIND_FULL`` … ``KIND_NORMAL``).
    keep : ndarray of int, (nk,)
        Indices into the flat 5n contact vector of the kept components.
    scale : ndarray, (nk,)
        Diagonal of P on the kept components (1 for N, μ for T, μr for R); all > 0.
    H_t : scipy.sparse.csr_matrix, (nk, m)
        H̃ = P Hᵀ restricted to the kept components.
    w_t : ndarray, (nk,)
        w̃ = P w on the kept components.
    J : scipy.sparse.csr_matrix, (nk, nz)
        Sums the two cone heads of a full contact into u0 and copies the rest; 0/1 entries.
    n3, n1 : int
        Number of L3 and L1 cones; nz = 3·n3 + n1.
    cone_contact : ndarray of int, (n3 + n1,)
        Contact of each cone (L3 cones first).
    cone_part : ndarray of int, (n3 + n1,)
        0 = friction (N,T) cone, 1 = rolling (N,R) cone, 2 = normal-only L1 cone.
    """

    problem: Problem
    kinds: np.ndarray
    keep: np.ndarray
    scale: np.ndarray
    H_t: sp.csr_matrix
    w_t: np.ndarray
    J: sp.csr_matrix
    n3: int
    n1: int
    cone_contact: np.ndarray
    cone_part: np.ndarray

    @property
    def nz(self) -> int:
        return 3 * self.n3 + self.n1

    @property
    def nk(self) -> int:
        return int(self.keep.size)

    @property
    def n_cones(self) -> int:
        return self.n3 + self.n1

    def held_by(self, cone: int, side: str) -> dict:
        """Cone ``cone`` (an index of ``cone_contact``) on side ``side`` — "z" (the lifted
        velocity) or "s" (Jᵀr̃, the reaction) — in the problem's terms: {"contact": its
        contact, "part": friction / rolling / normal (:data:`CONE_PARTS`), "side": velocity /
        reaction (:data:`CONE_SIDES`)}."""
        return {"contact": int(self.cone_contact[cone]), "part": CONE_PARTS[int(self.cone_part[cone])],
                "side": CONE_SIDES[side]}

    def reduction_counts(self) -> dict:
        """How many contacts of each kind (the cone-reduction part of the presolve report)."""
        return {name: int(np.sum(self.kinds == k)) for k, name in enumerate(KIND_NAMES)}

    def r_from_lifted(self, r_t: np.ndarray) -> np.ndarray:
        """r = P r̃ in the original 5n layout (dropped components are 0)."""
        r = np.zeros(SPACEDIM * self.problem.n_contacts, dtype=np.result_type(r_t, np.float64))
        r[self.keep] = self.scale * r_t
        return r

    def lifted_from_r(self, r: np.ndarray) -> np.ndarray:
        """r̃ = P⁻¹ r on the kept components (only divides by the kept, positive scales)."""
        return np.asarray(r)[self.keep] / self.scale

    def u_from_v(self, v: np.ndarray) -> np.ndarray:
        """u = Hᵀ v + w in the original layout (every component, dropped ones included)."""
        return self.problem.H.T @ v + self.problem.w


def lift(problem: Problem, *, reduce_cones: bool = True) -> LiftedProblem:
    """Build the lifted form of ``problem``.

    With ``reduce_cones=False`` every contact is treated as ``full``; that requires μ > 0 and
    μr > 0 everywhere (raises ``ValueError`` naming the first contact otherwise), because the
    lifting divides by them.
    """
    mu, mu_r = problem.mu, problem.mu_r
    n = problem.n_contacts
    kinds = np.full(n, KIND_FULL, dtype=np.int64)
    if reduce_cones:
        kinds[(mu > 0) & (mu_r == 0)] = KIND_COULOMB
        kinds[(mu == 0) & (mu_r > 0)] = KIND_ROLLING
        kinds[(mu == 0) & (mu_r == 0)] = KIND_NORMAL
    else:
        bad = np.flatnonzero((mu == 0) | (mu_r == 0))
        if bad.size:
            raise ValueError(f"contact {bad[0]} has mu = {mu[bad[0]]}, mu_r = {mu_r[bad[0]]}: the "
                             "unreduced lifting divides by both; enable the cone reduction")

    # Kept components, contact by contact in order, built without a Python loop over contacts.
    mask = np.zeros((n, SPACEDIM), dtype=bool)
    for kind, comps in _KEPT.items():
        rows = kinds == kind
        mask[np.ix_(rows, comps)] = True
    keep = np.flatnonzero(mask.ravel())
    comp = keep % SPACEDIM
    contact_of_kept = keep // SPACEDIM
    scale = np.where(comp == 0, 1.0, np.where(comp <= 2, mu[contact_of_kept], mu_r[contact_of_kept]))

    H_t = (sp.diags(scale) @ problem.H.T.tocsr()[keep, :]).tocsr()
    w_t = scale * problem.w[keep]

    # Cones: L3 cones for the (N,T) part of full/coulomb contacts and the (N,R) part of
    # full/rolling contacts; L1 for normal contacts.
    has_fric = (kinds == KIND_FULL) | (kinds == KIND_COULOMB)
    has_roll = (kinds == KIND_FULL) | (kinds == KIND_ROLLING)
    n_l3_per_contact = has_fric.astype(np.int64) + has_roll
    n3 = int(n_l3_per_contact.sum())
    normal = np.flatnonzero(kinds == KIND_NORMAL)
    n1 = int(normal.size)
    l3_first = np.concatenate(([0], np.cumsum(n_l3_per_contact)[:-1]))  # first L3 cone of contact
    fric_cone = np.where(has_fric, l3_first, -1)
    roll_cone = np.where(has_roll, l3_first + has_fric, -1)

    # Position of each kept component within the kept vector: kept_pos[contact, comp].
    kept_pos = np.full((n, SPACEDIM), -1, dtype=np.int64)
    kept_pos.ravel()[keep] = np.arange(keep.size)

    rows, cols = [], []
    fc = np.flatnonzero(has_fric)  # friction cone (N, T1, T2) of these contacts
    for j, comp_j in enumerate((0, 1, 2)):
        rows.append(kept_pos[fc, comp_j])
        cols.append(3 * fric_cone[fc] + j)
    rc = np.flatnonzero(has_roll)  # rolling cone (N, R1, R2)
    for j, comp_j in enumerate((0, 3, 4)):
        rows.append(kept_pos[rc, comp_j])
        cols.append(3 * roll_cone[rc] + j)
    rows.append(kept_pos[normal, 0])
    cols.append(3 * n3 + np.arange(n1))
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    J = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(keep.size, 3 * n3 + n1))

    cone_contact = np.empty(n3 + n1, dtype=np.int64)
    cone_part = np.empty(n3 + n1, dtype=np.int64)
    cone_contact[fric_cone[fc]] = fc
    cone_part[fric_cone[fc]] = 0
    cone_contact[roll_cone[rc]] = rc
    cone_part[roll_cone[rc]] = 1
    cone_contact[n3:] = normal
    cone_part[n3:] = 2
    return LiftedProblem(problem=problem, kinds=kinds, keep=keep, scale=scale, H_t=H_t, w_t=w_t,
                         J=J, n3=n3, n1=n1, cone_contact=cone_contact, cone_part=cone_part)
