"""Quick random rolling-friction problems with rigid-body structure (a stand-in until the
scene generator exists).

Each body has 6 dofs (velocity, angular velocity): M = diag(m I3, I_body) with a random SPD
inertia tensor.  Each contact joins two distinct bodies (or a body and the fixed ground) at a
random point with a random unit normal; its H columns give the relative velocity
(N, T1, T2) = frameᵀ (v_a + ω_a × ρ_a − v_b − ω_b × ρ_b) and the relative angular velocity in
the tangent plane (R1, R2) = (T1, T2)ᵀ (ω_a − ω_b) — the FCLIB convention u = Hᵀ v + w.
f = M v_prev + h·(gravity + random forces), w = small separating normal velocities (w ∈ K*,
so v = 0 is feasible and every problem has a solution).  Fully
vectorised over contacts and bodies.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..model.problem import Problem


def random_problem(n_bodies: int, n_contacts: int, *, seed: int = 0, mu=0.5, mu_r=0.05,
                   mu_zero_fraction: float = 0.0, mu_r_zero_fraction: float = 0.0,
                   ground_fraction: float = 0.3, mass_ratio: float = 10.0,
                   free_bodies: int = 0, title: str = "") -> Problem:
    """A random problem with ``n_bodies`` contact bodies plus ``free_bodies`` bodies that no
    contact touches; m = 6·(n_bodies + free_bodies), n = ``n_contacts``.

    ``mu``/``mu_r`` are the base coefficients (each contact gets a random multiple in
    [0.5, 1.5]); the given fractions of contacts get exactly 0.  Masses are log-uniform over
    ``[1, mass_ratio]``.  Deterministic for a given seed.
    """
    if n_bodies < 1 or n_contacts < 1:
        raise ValueError("need at least one body and one contact")
    rng = np.random.default_rng(seed)
    nb = n_bodies + free_bodies
    m = 6 * nb
    mass = np.exp(rng.uniform(0, np.log(mass_ratio), nb))
    A = rng.normal(size=(nb, 3, 3))
    inertia = 0.1 * mass[:, None, None] * (np.einsum("bij,bkj->bik", A, A) / 3 + np.eye(3))
    rows = (6 * np.arange(nb)[:, None] + np.arange(3)[None, :]).ravel()
    Mvals = [np.repeat(mass, 3)]
    Mrows, Mcols = [rows], [rows]
    ii, jj = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
    Mrows.append((6 * np.arange(nb)[:, None, None] + 3 + ii).ravel())
    Mcols.append((6 * np.arange(nb)[:, None, None] + 3 + jj).ravel())
    Mvals.append(inertia.ravel())
    M = sp.csc_matrix((np.concatenate(Mvals), (np.concatenate(Mrows), np.concatenate(Mcols))), shape=(m, m))

    # Contacts: body a always a contact body; b another one or the ground (-1).
    a = rng.integers(0, n_bodies, n_contacts)
    if n_contacts <= n_bodies:
        a[:] = rng.permutation(n_bodies)[:n_contacts]  # spread contacts over bodies
    b = rng.integers(0, n_bodies, n_contacts)
    same = b == a
    b[same] = (b[same] + 1) % n_bodies if n_bodies > 1 else -1
    b[rng.random(n_contacts) < ground_fraction] = -1
    if n_bodies == 1:
        b[:] = -1
    normal = rng.normal(size=(n_contacts, 3))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    t1 = np.cross(normal, rng.normal(size=(n_contacts, 3)))
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    frame = np.stack((normal, t1, t2), axis=1)  # (n, 3, 3): rows N, T1, T2
    rho_a = 0.5 * rng.normal(size=(n_contacts, 3))
    rho_b = 0.5 * rng.normal(size=(n_contacts, 3))

    def blocks(body, rho, sign):
        # u_{N,T} = frame (v + ω × ρ) = frame v − frame [ρ]× ω ; u_R = (T1,T2) ω
        cross = np.zeros((n_contacts, 3, 3))
        cross[:, 0, 1], cross[:, 0, 2] = -rho[:, 2], rho[:, 1]
        cross[:, 1, 0], cross[:, 1, 2] = rho[:, 2], -rho[:, 0]
        cross[:, 2, 0], cross[:, 2, 1] = -rho[:, 1], rho[:, 0]
        G = np.zeros((n_contacts, 5, 6))
        G[:, :3, :3] = frame
        G[:, :3, 3:] = -np.einsum("nij,njk->nik", frame, cross)
        G[:, 3:, 3:] = frame[:, 1:, :]
        keep = body >= 0
        c = np.flatnonzero(keep)
        r_idx = (5 * c[:, None, None] + np.arange(5)[None, :, None]) + 0 * np.arange(6)[None, None, :]
        c_idx = (6 * body[c][:, None, None] + np.arange(6)[None, None, :]) + 0 * np.arange(5)[None, :, None]
        return r_idx.ravel(), c_idx.ravel(), sign * G[c].ravel()

    ra, ca, va = blocks(a, rho_a, 1.0)
    rb, cb, vb = blocks(b, rho_b, -1.0)
    HT = sp.csc_matrix((np.concatenate((va, vb)), (np.concatenate((ra, rb)), np.concatenate((ca, cb)))),
                       shape=(5 * n_contacts, m))
    H = HT.T.tocsc()

    h = 1e-3
    gravity = np.zeros(m)
    gravity[2::6] = -9.81 * mass
    v_prev = 0.1 * rng.normal(size=m)
    f = M @ v_prev + h * (gravity + rng.normal(size=m) * mass.repeat(6))
    w = np.zeros(5 * n_contacts)
    # Separating normal offsets (w ∈ K*): v = 0 is then feasible, so every problem has a solution.
    w[0::5] = rng.uniform(0.0, 0.05, n_contacts)

    mu_c = mu * rng.uniform(0.5, 1.5, n_contacts)
    mur_c = mu_r * rng.uniform(0.5, 1.5, n_contacts)
    mu_c[rng.random(n_contacts) < mu_zero_fraction] = 0.0
    mur_c[rng.random(n_contacts) < mu_r_zero_fraction] = 0.0
    return Problem.from_arrays(
        M, H, f, w, mu_c, mur_c,
        title=title or f"random-nb-{nb}-nc-{n_contacts}-seed-{seed}",
        description=f"rfverify.scenes.random_problems.random_problem(n_bodies={n_bodies}, "
                    f"n_contacts={n_contacts}, seed={seed}, free_bodies={free_bodies})",
    )


def random_local_problem(n_contacts: int, *, seed: int = 0) -> Problem:
    """The global lifting (M = I, H = G with W ≈ GᵀG) of a local problem as Siconos writes them:
    W = Hᵀ M⁻¹ H and q = Hᵀ M⁻¹ f + w of :func:`random_problem` with ``n_contacts`` contacts on
    n_contacts // 2 bodies — more contact rows than dofs, so W is dense and singular.  The
    result is a *global* problem (``problem.local`` is None): certificates of it are about this
    lifted problem, which is what it is; a local *file* with such a W is proven on its own W
    (DESIGN §6.1b), and its rounding usually makes it indefinite, so it is not certified.
    Used by ``benchmarks/bench_digits.py`` and the tests of ``method="auto"``."""
    from ..io.local_lift import LocalProblem, lift_local

    base = random_problem(n_contacts // 2, n_contacts, seed=seed)
    Minv_H = np.linalg.solve(base.M_sym.toarray(), base.H.toarray())
    W = base.H.toarray().T @ Minv_H
    q = base.H.T @ np.linalg.solve(base.M_sym.toarray(), base.f) + base.w
    problem, _report = lift_local(LocalProblem(W=(W + W.T) / 2, q=q, mu=base.mu, mu_r=base.mu_r))
    return problem
