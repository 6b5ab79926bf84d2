"""Presolve of Algorithm 1: what is decided before the first iteration.

The rolling cones are lifted (DESIGN §2); bodies no contact touches decouple and get
v = M⁻¹f on their dofs; the body–contact graph splits into independent components, each
solved as its own problem (at most ``Settings.max_components`` of them).  The result is the
list of groups the driver runs and the presolve record a :class:`SolveResult` keeps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..model.lifting import LiftedProblem, lift
from ..model.problem import Problem
from .result import Settings


@dataclass
class Presolved:
    """``lifted``: the lifted problem; ``v`` (m,) longdouble with the contact-free dofs solved
    (zeros elsewhere); ``groups``: one (dofs, lifted rows, z indices, cone indices,
    n_contacts) per system the driver solves; ``info``: the presolve record (cone kinds, free
    dofs, components)."""

    lifted: LiftedProblem
    v: np.ndarray
    groups: list
    info: dict


def presolve(problem: Problem, settings: Settings) -> Presolved:
    """Lift, solve the contact-free bodies and split into independent components as
    ``settings`` ask (``drop_free_bodies``, ``split_components``, ``max_components``)."""
    lp = lift(problem, reduce_cones=settings.reduce_cones)
    m = problem.n_dofs
    info = {"cone_kinds": lp.reduction_counts()}
    # Bodies no contact touches decouple: v = M⁻¹ f on their dofs (whole blocks of M).
    v = np.zeros(m, dtype=np.longdouble)
    free = problem.contact_free_dofs if (settings.drop_free_bodies or settings.split_components) \
        else np.empty(0, dtype=np.int64)
    if free.size:
        M = problem.M_eq  # the posed equations' M: (M + Mᵀ)/2, or M as stored
        v[free] = splu(M[free][:, free].tocsc()).solve(problem.f[free])
    info["free_dofs"] = int(free.size)
    groups = independent_components(problem, lp, free) if settings.split_components else None
    if groups is not None and len(groups) > settings.max_components:
        info["components"] = f"{len(groups)} (> max_components = {settings.max_components}: solved together)"
        groups = None
    if groups is None:
        active = np.setdiff1d(np.arange(m), free)
        groups = [(active, np.arange(lp.nk), np.arange(lp.nz), np.arange(lp.n_cones), problem.n_contacts)]
    else:
        info["components"] = len(groups)
    return Presolved(lp, v, groups, info)


def independent_components(problem: Problem, lp, free) -> list:
    """Independent connected components of the body–contact graph (contact-free blocks
    excluded).  Returns a list of (dofs, kept rows, z indices, cone indices, n_contacts)."""
    from scipy.sparse.csgraph import connected_components

    n = problem.n_contacts
    blocks = problem.blocks
    HT = problem.H.T.tocoo()
    contact = HT.row // 5
    block = blocks.labels[HT.col]
    nb = blocks.count
    adj = sp.coo_matrix((np.ones(contact.size), (contact, n + block)), shape=(n + nb, n + nb))
    _, lab = connected_components(adj, directed=False)
    contact_comp = lab[:n]
    comps, contact_comp = np.unique(contact_comp, return_inverse=True)
    dof_lab = lab[n + blocks.labels]
    dof_comp = np.searchsorted(comps, dof_lab)
    active = np.ones(problem.n_dofs, dtype=bool)
    active[free] = False
    row_comp = contact_comp[lp.keep // 5]
    cone_comp = contact_comp[lp.cone_contact]
    cone_ids = np.arange(lp.n_cones)
    out = []
    dofs_all = np.flatnonzero(active)
    by_dof = _group(dof_comp[dofs_all], dofs_all, comps.size)
    by_row = _group(row_comp, np.arange(lp.nk), comps.size)
    by_cone = _group(cone_comp, cone_ids, comps.size)
    by_contact = np.bincount(contact_comp, minlength=comps.size)
    for c in range(comps.size):
        cids = by_cone[c]
        l3 = cids[cids < lp.n3]
        l1 = cids[cids >= lp.n3]
        zidx = np.concatenate(((3 * l3[:, None] + np.arange(3)).ravel(), 3 * lp.n3 + (l1 - lp.n3)))
        out.append((by_dof[c], by_row[c], zidx, cids, int(by_contact[c])))
    return out


def _group(keys, values, count):
    order = np.argsort(keys, kind="stable")
    bounds = np.searchsorted(keys[order], np.arange(count + 1))
    return [values[order[bounds[i]:bounds[i + 1]]] for i in range(count)]
