"""Problems with a known exact solution, built in small dyadic numbers so that every product
and sum forming f and w is exact in float64: M v* = H r* + f and u* = Hᵀv* + w hold exactly,
with r* ∈ K, u* ∈ K* and u*ᵀr* = 0 contact by contact.

The stored M may be unsymmetric (a small skew part A, M = M_s + A): then (v*, u*, r*) solves
the *stored* equations, and the symmetrised problem (M_s) has another solution.

Contact kinds: "open" (r* = 0, u* inside K*), "stick" (u* = 0, r* inside K), "slide_t"
(sliding: r on the friction boundary, u_T opposite r_T), "slide_r" (rolling: the same on the
rolling cone), "slide_both" (both boundaries, u_N = μ‖u_T‖ + μr‖u_R‖).
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import scipy.sparse as sp

import rfverify

KINDS = ("open", "stick", "slide_t", "slide_r", "slide_both")


def exact_problem(seed: int, n_contacts: int = 4, *, asymmetry: int = 0, kinds=None, bodies: int | None = None,
                  mu=0.5, mu_r=0.25, max_asymmetry: float = rfverify.model.problem.DEFAULT_MAX_ASYMMETRY,
                  free_bodies: int = 0, contact_skew: bool = True):
    """(problem, v*, u*, r*) with exact data.  ``asymmetry``: largest |A_ij| of the skew part
    (integers; the diagonal of M is about 2^12, so 15 gives an entrywise asymmetry of ~7e-3;
    above about 20 pass a larger ``max_asymmetry``).  ``free_bodies``: that many more bodies
    that no contact touches (their skew part too), after the others; ``contact_skew=False``
    puts the skew part on those free bodies only (as in the Siconos Chute, whose contact
    bodies' velocities hardly differ between the stored and symmetrised equations).
    ``kinds``: the contact kinds in order (default: random, every kind at least once when
    n_contacts ≥ 5).  mu, mu_r: dyadic floats (exact squares)."""
    rng = np.random.default_rng(seed)
    nb_contact = bodies or max(2, n_contacts)
    nb = nb_contact + free_bodies
    m = 6 * nb
    # M_s: block diagonal per body, integer, strongly diagonally dominant (SPD).
    Ms = np.zeros((m, m))
    for b in range(nb):
        s = slice(6 * b, 6 * b + 6)
        B = rng.integers(-40, 41, size=(6, 6)).astype(float)
        B = B + B.T
        B += np.diag(rng.integers(3000, 5000, size=6).astype(float))
        Ms[s, s] = B
    A = np.zeros((m, m))
    if asymmetry:
        for b in range(0 if contact_skew else nb_contact, nb):
            s = slice(6 * b, 6 * b + 6)
            X = rng.integers(-asymmetry, asymmetry + 1, size=(6, 6)).astype(float)
            A[s, s] = np.triu(X, 1) - np.triu(X, 1).T
    M = Ms + A
    if kinds is None:
        kinds = list(KINDS[:min(n_contacts, len(KINDS))]) + list(rng.choice(KINDS, size=max(0, n_contacts - len(KINDS))))
        rng.shuffle(kinds)
    kinds = list(kinds)
    n = len(kinds)
    # H: each contact touches one or two bodies with small integer entries.
    H = np.zeros((m, 5 * n))
    for c in range(n):
        a = c % nb_contact
        H[6 * a:6 * a + 6, 5 * c:5 * c + 5] = rng.integers(-8, 9, size=(6, 5))
        if nb_contact > 1 and rng.random() < 0.5:
            b = (a + 1 + rng.integers(0, nb_contact - 1)) % nb_contact
            H[6 * b:6 * b + 6, 5 * c:5 * c + 5] = rng.integers(-8, 9, size=(6, 5))
        H[6 * a + (c % 6), 5 * c] += 16.0  # keep H's columns independent
    mu_v = np.full(n, float(mu))
    mur_v = np.full(n, float(mu_r))
    r = np.zeros(5 * n)
    u = np.zeros(5 * n)
    for c, kind in enumerate(kinds):
        rN = float(rng.integers(4, 33))
        sT = rng.choice([-1.0, 1.0], size=2) * rng.integers(0, 2, size=2)
        dT = np.array([1.0, 0.0]) if rng.random() < 0.5 else np.array([0.0, 1.0])
        dR = np.array([0.0, 1.0]) if rng.random() < 0.5 else np.array([1.0, 0.0])
        dT = dT * rng.choice([-1.0, 1.0])
        dR = dR * rng.choice([-1.0, 1.0])
        blk_r = np.zeros(5)
        blk_u = np.zeros(5)
        if kind == "open":
            blk_u[1:] = rng.integers(-4, 5, size=4)
            blk_u[0] = mu * np.hypot(*blk_u[1:3]) + mu_r * np.hypot(*blk_u[3:5]) + float(rng.integers(1, 9))
            blk_u[0] = float(np.ceil(blk_u[0]))
        elif kind == "stick":
            blk_r[0] = rN
            blk_r[1:3] = sT * rN * mu / 4
            blk_r[3:5] = rng.choice([-1.0, 1.0], size=2) * rN * mu_r / 4
        else:
            s = float(rng.integers(1, 9))
            t = float(rng.integers(1, 9))
            blk_r[0] = rN
            if kind in ("slide_t", "slide_both"):
                blk_r[1:3] = -mu * rN * dT
                blk_u[1:3] = s * dT
                blk_u[0] += mu * s
            else:
                blk_r[1:3] = sT * rN * mu / 4
            if kind in ("slide_r", "slide_both"):
                blk_r[3:5] = -mu_r * rN * dR
                blk_u[3:5] = t * dR
                blk_u[0] += mu_r * t
            else:
                blk_r[3:5] = rng.choice([-1.0, 1.0], size=2) * rN * mu_r / 4
        r[5 * c:5 * c + 5] = blk_r
        u[5 * c:5 * c + 5] = blk_u
    v = rng.integers(-64, 65, size=m).astype(float)
    f = M @ v - H @ r
    w = u - H.T @ v
    # Everything above is small dyadic arithmetic: check exactness rather than trust it.
    _check_exact(M, H, v, r, f, w, u)
    problem = rfverify.Problem.from_arrays(sp.csc_matrix(M), sp.csc_matrix(H), f, w, mu_v, mur_v,
                                           title=f"exact seed {seed}", max_asymmetry=max_asymmetry)
    return problem, v, u, r


def _check_exact(M, H, v, r, f, w, u):
    F = Fraction
    m, k = H.shape
    for i in range(m):
        lhs = sum(F(M[i, j]) * F(v[j]) for j in np.flatnonzero(M[i])) - sum(F(H[i, j]) * F(r[j]) for j in np.flatnonzero(H[i]))
        assert lhs == F(f[i]), "f is not exact"
    for j in range(k):
        val = sum(F(H[i, j]) * F(v[i]) for i in np.flatnonzero(H[:, j])) + F(w[j])
        assert val == F(u[j]), "w is not exact"


def symmetrised_solution(problem, dps: int = 60, tol: float = 1e-45):
    """The solution of the symmetrised problem by the independent reference (mpf lists)."""
    import reference

    ref = reference.solve(problem, dps=dps, tol=tol)
    assert ref.success, ref.message
    return ref


def solve_rational(A, b) -> list:
    """x with A x = b, by Gaussian elimination with row pivoting in exact rationals (A a
    nonsingular list of rows of Fractions, b a list of Fractions)."""
    n = len(b)
    T = [list(row) + [bb] for row, bb in zip(A, b)]
    for k in range(n):
        p = next(i for i in range(k, n) if T[i][k] != 0)
        T[k], T[p] = T[p], T[k]
        for i in range(k + 1, n):
            if T[i][k]:
                c = T[i][k] / T[k][k]
                T[i] = [a - c * b for a, b in zip(T[i], T[k])]
    x = [Fraction(0)] * n
    for k in reversed(range(n)):
        x[k] = (T[k][n] - sum(T[k][j] * x[j] for j in range(k + 1, n))) / T[k][k]
    return x
