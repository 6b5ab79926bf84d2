"""Mass matrix M and contact matrix H of a rigid-body assembly (FCLIB conventions).

Dofs: body i owns rows 6i..6i+5 = (v_x, v_y, v_z, ω_x, ω_y, ω_z), world frame.

For contact c (columns 5c..5c+4 ordered N, T1, T2, R1, R2) between A and B with common point
x_c, lever arms ρ_A = x_c − x_A, ρ_B = x_c − x_B:

    (u_N, u_T1, u_T2) = Fᵀ (v_A + ω_A × ρ_A − v_B − ω_B × ρ_B),   F = [N T1 T2]
    (u_R1, u_R2)      = (T1, T2)ᵀ (ω_A − ω_B)

and u = Hᵀ v + w.  Since e·(ω × ρ) = ω·(ρ × e), the column of component e ∈ {N, T1, T2} holds
e in A's translational rows and ρ_A × e in its rotational rows (negated for B); the rolling
columns hold T1, T2 in the rotational rows only.  A static B (b = −1) has no dofs: its rows
are simply absent.  So each contact's 5 columns touch at most 12 rows.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .geometry import Bodies, Contacts


def mass_matrix(bodies: Bodies) -> sp.csc_matrix:
    """Block-diagonal M (6nb × 6nb): diag(m·I3, R I_body Rᵀ) per body, exactly symmetric."""
    nb = bodies.count
    base = 6 * np.arange(nb)
    Iw = bodies.world_inertia()
    rows_t = (base[:, None] + np.arange(3)).ravel()
    ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    rows_r = (base[:, None, None] + 3 + ii).ravel()
    cols_r = (base[:, None, None] + 3 + jj).ravel()
    rows = np.concatenate((rows_t, rows_r))
    cols = np.concatenate((rows_t, cols_r))
    vals = np.concatenate((np.repeat(bodies.mass, 3), Iw.ravel()))
    keep = vals != 0  # off-diagonal inertia of spheres is exactly zero: not stored
    M = sp.csc_matrix((vals[keep], (rows[keep], cols[keep])), shape=(6 * nb, 6 * nb))
    M.sort_indices()
    return M


def contact_blocks(bodies: Bodies, contacts: Contacts):
    """Per-contact 6×5 blocks (n, 6, 5) of H for body A and for body B (zeros where b = −1)."""
    N, T1, T2 = contacts.frames()
    E = np.stack((N, T1, T2), axis=2)  # (n, 3, 3): columns are N, T1, T2
    n = contacts.count

    def block(rho, sign):
        G = np.zeros((n, 6, 5))
        G[:, :3, :3] = E
        G[:, 3:, :3] = np.cross(rho[:, :, None], E, axisa=1, axisb=1, axisc=1)
        G[:, 3:, 3] = T1
        G[:, 3:, 4] = T2
        return sign * G

    GA = block(contacts.point - bodies.pos[contacts.a], 1.0)
    has_b = contacts.b >= 0
    rho_b = np.zeros((n, 3))
    rho_b[has_b] = contacts.point[has_b] - bodies.pos[contacts.b[has_b]]
    GB = block(rho_b, -1.0)
    GB[~has_b] = 0.0
    return GA, GB


# Rows of a 6×5 block that can be structurally nonzero: all but translational × rolling.
_PATTERN = np.ones((6, 5), dtype=bool)
_PATTERN[:3, 3:] = False


def contact_matrix(bodies: Bodies, contacts: Contacts) -> sp.csc_matrix:
    """H (6nb × 5n), vectorised over contacts (see the module docstring)."""
    nb, n = bodies.count, contacts.count
    GA, GB = contact_blocks(bodies, contacts)
    r6 = np.arange(6)[:, None]
    c5 = np.arange(5)[None, :]
    rows, cols, vals = [], [], []
    for body, G, mask in ((contacts.a, GA, np.ones(n, bool)), (contacts.b, GB, contacts.b >= 0)):
        idx = np.flatnonzero(mask)
        R = 6 * body[idx, None, None] + r6[None]
        C = 5 * idx[:, None, None] + c5[None]
        pat = np.broadcast_to(_PATTERN, (idx.size, 6, 5))
        rows.append(np.broadcast_to(R, pat.shape)[pat])
        cols.append(np.broadcast_to(C, pat.shape)[pat])
        vals.append(G[idx][pat])
    H = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(6 * nb, 5 * n))
    H.eliminate_zeros()  # exact zeros of axis-aligned frames are not stored
    H.sort_indices()
    return H


def relative_velocity(bodies: Bodies, contacts: Contacts) -> np.ndarray:
    """Contact-wise (n, 5) relative velocity computed directly from the kinematic formula
    (not from H): an independent check of :func:`contact_matrix`."""
    N, T1, T2 = contacts.frames()
    a, b = contacts.a, contacts.b
    rho_a = contacts.point - bodies.pos[a]
    va = bodies.vel[a] + np.cross(bodies.omega[a], rho_a)
    wa = bodies.omega[a]
    vb = np.zeros_like(va)
    wb = np.zeros_like(wa)
    hb = b >= 0
    rho_b = contacts.point[hb] - bodies.pos[b[hb]]
    vb[hb] = bodies.vel[b[hb]] + np.cross(bodies.omega[b[hb]], rho_b)
    wb[hb] = bodies.omega[b[hb]]
    dv, dw = va - vb, wa - wb
    return np.stack((np.einsum("ij,ij->i", N, dv), np.einsum("ij,ij->i", T1, dv),
                     np.einsum("ij,ij->i", T2, dv), np.einsum("ij,ij->i", T1, dw),
                     np.einsum("ij,ij->i", T2, dw)), axis=1)


def generalized_velocity(bodies: Bodies) -> np.ndarray:
    """v (6nb,) = (v_0, ω_0, v_1, ω_1, ...)."""
    return np.concatenate((bodies.vel, bodies.omega), axis=1).ravel()
