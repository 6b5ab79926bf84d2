"""Checks and statistics of generated problems: contact states of a solution, H structure,
coordination."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..model.problem import Problem


@dataclass
class StateMix:
    """Contact states of a solution (see :func:`contact_state_mix`).

    counts : dict   open, sticking, sliding, rolling (closed contacts with ‖u_R‖ > 0, counted
                    independently of sticking/sliding), closed, and ambiguous (contacts whose
                    complementary pair is not resolved to a factor ``ratio``)
    labels : (n,) str array   "open", "stick", "slide", "stick+roll" or "slide+roll"
    """

    counts: dict
    labels: np.ndarray

    def fractions(self) -> dict:
        n = max(1, self.labels.size)
        return {k: v / n for k, v in self.counts.items()}

    def __str__(self) -> str:
        c = self.counts
        return (f"open {c['open']}, sticking {c['sticking']}, sliding {c['sliding']}, "
                f"rolling {c['rolling']} (of {self.labels.size})")


def free_velocity(problem: Problem) -> np.ndarray:
    """v_free = M⁻¹ f, the velocity without contact forces (m,)."""
    return splu(problem.M_sym.tocsc()).solve(np.asarray(problem.f, dtype=float))


def contact_state_mix(problem: Problem, v, u, r, ratio: float = 100.0) -> StateMix:
    """Classify each contact of a solution (v, u, r) of ``problem``.

    * open      r_N ≈ 0 and u_N > 0
    * otherwise closed, and then
      sticking  ‖u_T‖ ≈ 0,   sliding ‖u_T‖ > 0 with ‖r_T‖ = μ r_N,
      rolling   ‖u_R‖ > 0 with ‖r_R‖ = μr r_N (counted independently of sticking/sliding).

    "≈ 0" is decided *relative to the complementary quantity*, in scaled units: a contact is
    open when (u_N − μ‖u_T‖ − μr‖u_R‖)/s_v > r_N/s_r (the convex relaxation lets a loaded
    sliding contact separate at exactly u_N = μ‖u_T‖ + μr‖u_R‖, DESIGN §1), sliding when ‖u_T‖/s_v > (μ r_N − ‖r_T‖)/s_r, rolling when
    ‖u_R‖/s_ω > (μr r_N − ‖r_R‖)/(s_r ℓ).  An interior-point solution at tolerance τ has
    (gap of the pair) ≈ τ/(other member), so fixed thresholds misclassify (open contacts of a
    1e-10 solution carry r_N ~ 1e-8·max r_N); comparing the pair does not.  A pair whose two
    members are within ``ratio`` of each other is counted as ``ambiguous`` (not strictly
    complementary at the solution's accuracy).

    Scales: s_v = max(‖u_NT‖∞, ‖w_NT‖∞, ‖(Hᵀ v_free + w)_NT‖∞) with v_free = M⁻¹ f (at rest u ≈ 0,
    so ‖u‖ alone would make round-off look like slip); ℓ = the largest lever arm in H;
    s_ω = max(‖u_R‖∞, ‖(Hᵀ v_free)_R‖∞, s_v/ℓ); s_r = max(max r_N, 1e-3‖f‖∞) (the floor
    keeps the scale meaningful when every r ≈ 0).  Frictionless directions (μ = 0 or μr = 0)
    slide or roll as soon as their velocity exceeds 1e-9 of its scale.
    """
    v, u, r = (np.asarray(x, dtype=float) for x in (v, u, r))
    n = problem.n_contacts
    U = u.reshape(n, 5)
    Rr = r.reshape(n, 5)
    ufree = (problem.H.T @ free_velocity(problem) + problem.w).reshape(n, 5)
    W = np.asarray(problem.w).reshape(n, 5)
    H = sp.csc_matrix(problem.H)
    # Largest lever arm: the rotational entries of the (N, T) columns of a rigid-body H.
    rot_rows = (H.tocoo().row % 6) >= 3
    nt_cols = (H.tocoo().col % 5) < 3
    lever = float(np.abs(H.tocoo().data[rot_rows & nt_cols]).max(initial=0.0)) or 1.0
    s_v = max(np.abs(U[:, :3]).max(), np.abs(W[:, :3]).max(), np.abs(ufree[:, :3]).max(), 1e-300)
    s_w = max(np.abs(U[:, 3:]).max(), np.abs(ufree[:, 3:]).max(), s_v / lever)
    rN = Rr[:, 0]
    s_r = max(float(rN.max()), 1e-3 * float(np.abs(problem.f).max()), 1e-300)
    uT = np.linalg.norm(U[:, 1:3], axis=1) / s_v
    uR = np.linalg.norm(U[:, 3:], axis=1) / s_w
    slack_T = np.maximum(problem.mu * rN - np.linalg.norm(Rr[:, 1:3], axis=1), 0.0) / s_r
    slack_R = np.maximum(problem.mu_r * rN - np.linalg.norm(Rr[:, 3:], axis=1), 0.0) / (s_r * lever)
    rNs = np.maximum(rN, 0.0) / s_r
    floor = 1e-9
    # The relaxation lets a sliding or rolling contact separate at u_N = μ‖u_T‖ + μr‖u_R‖
    # while it carries load; what is complementary to r_N is the excess over that.
    uN_excess = (U[:, 0] - problem.mu * np.linalg.norm(U[:, 1:3], axis=1)
                 - problem.mu_r * np.linalg.norm(U[:, 3:], axis=1)) / s_v
    is_open = uN_excess > rNs
    closed = ~is_open
    slide = closed & (uT > np.maximum(slack_T, floor))
    roll = closed & (uR > np.maximum(slack_R, floor))

    def amb(a, b):
        hi, lo = np.maximum(a, b), np.minimum(a, b)
        return (hi > floor) & (hi < ratio * lo)

    ambiguous = amb(uN_excess, rNs) | (closed & (amb(uT, slack_T) | amb(uR, slack_R)))
    labels = np.where(is_open, "open", np.where(slide, "slide", "stick")).astype(object)
    labels[roll] = labels[roll] + "+roll"
    counts = {"open": int(is_open.sum()), "sticking": int((closed & ~slide).sum()),
              "sliding": int(slide.sum()), "rolling": int(roll.sum()), "closed": int(closed.sum()),
              "ambiguous": int(ambiguous.sum())}
    return StateMix(counts=counts, labels=labels.astype(str))


def h_structure(problem: Problem) -> dict:
    """Structure of H per contact: the largest number of distinct bodies (blocks of 6 rows)
    and of distinct nonzero rows touched by one contact's 5 columns, and whether every
    contact's rows lie in at most two 6-row blocks."""
    H = sp.csc_matrix(problem.H)
    n = problem.n_contacts
    coo = H.tocoo()
    contact = coo.col // 5
    # Distinct (contact, row) and (contact, body) pairs.
    rows = np.unique(contact.astype(np.int64) * H.shape[0] + coo.row)
    bodies = np.unique(contact.astype(np.int64) * H.shape[0] + coo.row // 6)
    rows_per = np.bincount(rows // H.shape[0], minlength=n)
    bodies_per = np.bincount(bodies // H.shape[0], minlength=n)
    return {"max_bodies_per_contact": int(bodies_per.max(initial=0)),
            "max_rows_per_contact": int(rows_per.max(initial=0)),
            "contacts_with_two_bodies": int(np.sum(bodies_per == 2)),
            "contacts_with_one_body": int(np.sum(bodies_per == 1))}


def contacts_per_body(problem: Problem, closed_only_r=None) -> dict:
    """Mean number of contacts each body takes part in (a body–body contact counts for both),
    over the bodies that have at least one contact, and n / (number of bodies).  With a
    reaction vector ``closed_only_r`` only contacts with r_N > 0 count (the load-bearing
    network of a settled pile)."""
    H = sp.csc_matrix(problem.H)
    n = problem.n_contacts
    nb = problem.n_dofs // 6
    coo = H.tocoo()
    pairs = np.unique((coo.col // 5).astype(np.int64) * nb + coo.row // 6)
    c, b = pairs // nb, pairs % nb
    if closed_only_r is not None:
        rN = np.asarray(closed_only_r).reshape(n, 5)[:, 0]
        keep = rN[c] > 1e-9 * max(rN.max(), 1e-300)
        c, b = c[keep], b[keep]
    per_body = np.bincount(b, minlength=nb)
    touched = per_body > 0
    return {"bodies": nb, "bodies_in_contact": int(touched.sum()),
            "mean_contacts_per_body": float(per_body[touched].mean()) if touched.any() else 0.0,
            "contacts_over_bodies": float(np.unique(c).size / nb)}
