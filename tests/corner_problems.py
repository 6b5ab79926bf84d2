"""Problems with a planted self-stress (issue 45): a sphere in a μ = 1 corner of the floor and a
side wall with zero gap, whose two friction cones touch along one ray — the feasible set of
velocities has no interior.  Built by hand (rigid spheres, 6 dofs each, contact frames
(N, T1, T2) with lever arms), so the geometry is exact and the self-stress is known:
forces (N, T) = (c, ∓c) at 45° on both contacts, which balance on their own.

A second sphere rests on the floor away from the walls with a tangent frame turned by a random
angle (generic floats), and a third, optionally, sits in the opposite corner."""

from __future__ import annotations

import numpy as np

import rfverify


def _columns(n, t1, t2, arm):
    """H's 6×5 block of one contact on one body: translation rows n, t1, t2; rotation rows
    arm × n, arm × t1, arm × t2; rolling rows t1, t2 (relative angular velocity)."""
    n, t1, t2, arm = (np.asarray(x, dtype=float) for x in (n, t1, t2, arm))
    B = np.zeros((6, 5))
    for k, d in enumerate((n, t1, t2)):
        B[:3, k] = d
        B[3:, k] = np.cross(arm, d)
    B[3:, 3], B[3:, 4] = t1, t2
    return B


def _turned(n, t1, t2, angle):
    """The tangent frame (t1, t2) turned by ``angle`` about the normal n (floats: generic)."""
    c, s = np.cos(angle), np.sin(angle)
    return n, c * t1 + s * t2, -s * t1 + c * t2


def corner_problem(seed: int = 0, second_corner: bool = False, mu_r: float = 0.1,
                   turn: float = 0.0) -> rfverify.Problem:
    """Spheres on a floor z = 0 between walls y = ±W/2 (μ = 1 everywhere): sphere 0 in the
    corner of the floor and the wall y = −W/2 with zero gap (self-stress on contacts 0 and 1),
    sphere 1 on the floor alone, and with ``second_corner`` sphere 2 in the corner at y = +W/2
    (a second self-stress, on contacts 3 and 4).  Free velocities random (``seed``), some moving
    out of their corner so that v* ≠ 0; w = 0 (zero gaps)."""
    rng = np.random.default_rng(seed)
    n_bodies = 3 if second_corner else 2
    R = np.array([0.05, 0.04, 0.03])[:n_bodies] * rng.uniform(0.8, 1.2, n_bodies)
    mass = 1000.0 * 4.0 / 3.0 * np.pi * R ** 3
    inertia = 0.4 * mass * R ** 2
    m = 6 * n_bodies
    M = np.diag(np.concatenate([[mass[b]] * 3 + [inertia[b]] * 3 for b in range(n_bodies)]))
    blocks = []  # (body, 6×5 block)
    z, y, x = np.eye(3)[2], np.eye(3)[1], np.eye(3)[0]
    # sphere 0: floor (N = z, T = x, y) and wall y = −W/2 (N = +y, T = x, z)
    # (``turn`` ≠ 0: their tangent frames turned about the normals, generic floats; the cones
    # then touch only up to rounding, and no exact self-stress need exist)
    blocks.append((0, _columns(*_turned(z, x, y, turn), -R[0] * z)))
    blocks.append((0, _columns(*_turned(y, x, z, turn), -R[0] * y)))
    # sphere 1: floor only, tangent frame turned by a random angle about z
    th = rng.uniform(0, 2 * np.pi)
    t1 = np.array([np.cos(th), np.sin(th), 0.0])
    blocks.append((1, _columns(z, t1, np.cross(z, t1), -R[1] * z)))
    if second_corner:  # sphere 2: floor and the wall y = +W/2 (N = −y)
        blocks.append((2, _columns(z, x, y, -R[2] * z)))
        blocks.append((2, _columns(-y, x, z, R[2] * y)))
    n = len(blocks)
    H = np.zeros((m, 5 * n))
    for i, (b, B) in enumerate(blocks):
        H[6 * b:6 * b + 6, 5 * i:5 * i + 5] = B
    h, g = 1e-3, 9.81
    v_free = rng.normal(size=m) * 0.1
    v_free[[1, 2]] = np.abs(v_free[[1, 2]]) + 0.05  # sphere 0 leaves its corner diagonally: v* ≠ 0
    f = M @ v_free + h * np.concatenate([[0, 0, -g * mass[b], 0, 0, 0] for b in range(n_bodies)])
    return rfverify.Problem.from_arrays(M, H, f, np.zeros(5 * n), np.ones(n), np.full(n, mu_r),
                                        title=f"corner spheres, seed {seed}")
