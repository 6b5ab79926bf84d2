"""Facial reduction for the proof: self-stresses found, verified exactly, and points moved onto
the face they force (DESIGN §6.8).

A **self-stress** is a y ∈ K, y ≠ 0, with H y = 0 and wᵀy = 0: contact forces that balance
on their own (a sphere wedged in a μ = 1 corner, two spheres jammed between a wall and the
bottom).  For every velocity v with u(v) = Hᵀv + w ∈ K*, yᵀu(v) = (Hy)ᵀv + wᵀy = 0, and each
term y_iᵀu_i ≥ 0, so every one vanishes: on the contacts y touches, u_i lies in the face
K*_i ∩ y_i^⊥ — u_i = 0 where y_i ∈ int K_i, u_i on one edge of the friction (or rolling) cone
where y_i is on that cone's boundary.  The feasible set has no interior, a computed point is
almost never exactly in K*, and the theorem of DESIGN §6.1 (which needs u(v) ∈ K* exactly)
cannot start from it.  With wᵀy < 0 the data admit no feasible velocity at all.

What this module does, for the contacts where a point's u(v) ∉ K*:

1. :func:`find_self_stress` solves a small conic problem (Clarabel) on the neighbourhood of
   those contacts — max Σ y_N over y ∈ K, H y = 0, wᵀy ≤ 0, y_N ≤ 1 — and makes the answer
   exact: each contact on a cone's boundary gets an exactly unit rational direction near the
   float one, and y is taken in the exact null space of H and those boundary equations
   (:mod:`.rational`).  H y = 0, y ∈ K and the sign of wᵀy are then checked in exact
   arithmetic; nothing is claimed otherwise.
2. :func:`restore` moves a point onto the face exactly: v' = v + δ with δ on the bodies those
   contacts touch, solving H_Fᵀδ − G s = −u_F(v) exactly (G: the edges of the face, s ≥ 0),
   so that u_F(v') = G s ∈ K*_F exactly.  The proof then evaluates the theorem at v', a
   rational point (:class:`.dyadic.Quotient`); its residual g carries M δ.  Whether the whole
   u(v') is in K* is decided by the proof's own exact test, as for any point.

The self-stress only guides the move; the proof's validity rests on the exact cone test of v'
alone, so a wrong guess can cost digits, never a false claim.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction

import numpy as np
import scipy.sparse as sp

from ..model.problem import SPACEDIM
from . import rational as Q
from .dyadic import Dyadic, Quotient

NEIGHBOUR_RINGS = 3
"""Contacts within this many shared bodies of the failing ones are searched for a self-stress."""
MAX_NEIGHBOURS = 3000
"""A larger neighbourhood is not searched (the conic solve would cost more than the proof)."""
SUPPORT_TOL = 1e-6
"""y_N below this (against y_N ≤ 1) counts as 0 in the float self-stress."""
BOUNDARY_TOL = 1e-4
"""A float y_i with ‖y_T‖ ≥ (1 − this)·μ y_N is taken to be on the friction cone's boundary."""
SNAP_DENOMINATORS = (1, 2 ** 4, 2 ** 10, 2 ** 20, 2 ** 30)
"""Largest denominators tried for tan(θ/2) of a boundary direction (θ its angle)."""
MAX_GROUP_CONTACTS = 16
"""A self-stress on more contacts than this (one connected group) is not made exact: exact
elimination over Q costs O(k³) operations on growing fractions (a hyperstatic lattice's group of
~200 contacts took minutes), and the stresses met in piles — a sphere or a chain of two wedged in
a corner — have 2–4 contacts."""
KINDS = {"stuck": "u = 0 (no relative motion)", "friction": "u on one edge of the friction cone",
         "rolling": "u on one edge of the rolling cone", "friction+rolling": "u on a face of both cones",
         "face": "u on a face of its cone (its part off the face held at 0 by the proof's move)"}


@dataclass(frozen=True)
class SelfStress:
    """An exactly verified y ∈ K with H y = 0 and wᵀy ≤ 0 (y ≠ 0).

    ``contacts`` (k,) the contacts y touches (sorted); ``y`` their 5k components, exact,
    contact-major in the order (N, T1, T2, R1, R2); ``kinds`` per contact, a key of
    :data:`KINDS`; ``edges`` per contact, the face's generators (5 Fractions each) that
    u_i may use with a coefficient ≥ 0, ``free`` those it may use with any sign (the
    tangential part of a μ = 0 contact, the rolling part of a μr = 0 one); ``w_dot_y`` the
    exact wᵀy (< 0: no feasible velocity exists at all)."""

    contacts: np.ndarray
    y: tuple
    kinds: tuple
    edges: tuple
    free: tuple
    w_dot_y: Fraction

    @property
    def infeasible(self) -> bool:
        return self.w_dot_y < 0

    def contact_list(self) -> str:
        c = [int(i) for i in self.contacts]
        return ", ".join(map(str, c[:-1])) + f" and {c[-1]}" if len(c) > 1 else str(c[0])

    def describe(self) -> str:
        """One sentence: which contacts, and what the stress forces there."""
        groups: dict[str, list[int]] = {}
        for c, k in zip(self.contacts, self.kinds):
            groups.setdefault(k, []).append(int(c))
        forced = "; ".join(f"{KINDS[k]} at {', '.join(map(str, cs))}" for k, cs in groups.items())
        who = (f"contacts {self.contact_list()} carry" if self.contacts.size > 1
               else f"contact {self.contact_list()} carries")
        if self.infeasible:
            return (f"{who} forces y ∈ K with Hy = 0 and wᵀy < 0 (verified in "
                    "exact arithmetic): no velocity satisfies Hᵀv + w ∈ K*, so the problem has no solution")
        return (f"{who} a self-stress (y ∈ K, y ≠ 0, Hy = 0, wᵀy = 0, verified in "
                f"exact arithmetic): the data allow no strictly feasible velocity, and every admissible one has "
                f"{forced}")

    def as_dict(self) -> dict:
        return {"contacts": [int(c) for c in self.contacts], "kinds": list(self.kinds),
                "y": [str(x) for x in self.y], "w_dot_y": str(self.w_dot_y), "infeasible": self.infeasible}


@dataclass
class FaceRepair:
    """A point moved exactly onto the face that ``stresses`` force.  ``point_v`` is the moved
    v' (exact, rational); ``moved`` ≥ ‖v' − v‖∞; ``shifts`` maps the index of a stress to the
    τ ≥ 0 (exact) with r + τ·y ∈ K on its contacts, where r alone is not in K there (the proof
    is then about r + τ·y, which has the same Hr and, since yᵀu(v) = 0 for every v, the same
    rᵀu)."""

    stresses: list
    point_v: Quotient
    moved: float
    shifts: dict = field(default_factory=dict)

    def describe(self) -> str:
        parts = [s.describe() for s in self.stresses]
        text = "; ".join(parts) + ". The proof's point was moved exactly onto that face"
        text += f" (v changed by at most {self.moved:.1e})" if self.moved > 0 else " (it was on it)"
        if self.shifts:
            text += " and its r taken plus a multiple of the self-stress, which lies in K"
        return text + ", and the theorem applied there (DESIGN §6.8)"

    def as_dict(self) -> dict:
        return {"self_stresses": [s.as_dict() for s in self.stresses], "moved": self.moved,
                "r_shifts": {str(k): str(v) for k, v in self.shifts.items()}}


@dataclass
class FaceSearch:
    """Per-problem cache of the self-stresses found (one conic solve per set of failing
    contacts).  ``found`` lists the verified ones; ``tried`` the failing sets already searched."""

    found: list = field(default_factory=list)
    tried: dict = field(default_factory=dict)


# ---------------------------------------------------------------------------------- finding
def neighbourhood(H: sp.csc_matrix, HT: sp.csc_matrix, seeds: np.ndarray, rings: int = NEIGHBOUR_RINGS) -> np.ndarray:
    """Contacts reachable from ``seeds`` through at most ``rings`` shared degrees of freedom."""
    contacts = np.unique(np.asarray(seeds, dtype=np.int64))
    for _ in range(rings):
        cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
        rows = np.unique(H[:, cols].indices)
        more = np.union1d(contacts, HT[:, rows].indices // SPACEDIM)  # (a seed touching no body stays)
        if more.size == contacts.size:
            break
        contacts = more
        if contacts.size > MAX_NEIGHBOURS:
            break
    return contacts


def float_self_stress(problem, contacts: np.ndarray) -> np.ndarray | None:
    """Clarabel's y (5·len(contacts),) maximising Σ y_N over y ∈ K, H y = 0, wᵀy ≤ 0,
    y_N ≤ 1 on ``contacts``, or None (no self-stress there, or Clarabel failed)."""
    import clarabel

    k = contacts.size
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    Hc = sp.csc_matrix(problem.H)[:, cols]
    rows = np.unique(Hc.indices)
    Hs = sp.csr_matrix(Hc[rows])
    n = SPACEDIM * k
    idx_n = SPACEDIM * np.arange(k)
    mu, mur = problem.mu[contacts], problem.mu_r[contacts]
    r_i = np.repeat(np.arange(6 * k), 1).reshape(k, 6)
    soc_rows = r_i.ravel()
    soc_cols = (idx_n[:, None] + np.array([0, 1, 2, 0, 3, 4])).ravel()
    soc_vals = np.column_stack([-mu, -np.ones(k), -np.ones(k), -mur, -np.ones(k), -np.ones(k)]).ravel()
    A = sp.vstack([Hs, sp.csr_matrix(problem.w[cols].reshape(1, -1)),
                   sp.csr_matrix((np.ones(k), (np.arange(k), idx_n)), shape=(k, n)),
                   sp.csr_matrix((soc_vals, (soc_rows, soc_cols)), shape=(6 * k, n))], format="csc")
    b = np.concatenate([np.zeros(rows.size + 1), np.ones(k), np.zeros(6 * k)])
    cones = [clarabel.ZeroConeT(rows.size), clarabel.NonnegativeConeT(1 + k)] + [clarabel.SecondOrderConeT(3)] * (2 * k)
    q = np.zeros(n)
    q[idx_n] = -1.0
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    try:
        sol = clarabel.DefaultSolver(sp.csc_matrix((n, n)), q, A, b, cones, settings).solve()
    except Exception:  # a conic solver's failure only means no self-stress is found
        return None
    y = np.asarray(sol.x, dtype=np.float64)
    if str(sol.status) not in ("Solved", "AlmostSolved") or not np.all(np.isfinite(y)):
        return None
    if float(np.max(y[idx_n], initial=0.0)) < SUPPORT_TOL:
        return None
    return y


def _unit_direction(a: float, b: float, max_den: int) -> tuple[Fraction, Fraction] | None:
    """An exactly unit rational vector near (a, b)/‖(a, b)‖: ((1 − t²), 2t)/(1 + t²) with t
    a rational approximation of tan(θ/2) (of the opposite vector where a < 0, so t stays small)."""
    norm = math.hypot(a, b)
    if not norm > 0:
        return None
    sign = 1 if a >= 0 else -1
    t = Fraction(sign * b / (norm + abs(a))).limit_denominator(max_den)
    d = 1 + t * t
    return sign * (1 - t * t) / d, sign * 2 * t / d


def _components(H: sp.csc_matrix, contacts: np.ndarray) -> list[np.ndarray]:
    """``contacts`` grouped by shared degrees of freedom (connected components)."""
    from scipy.sparse.csgraph import connected_components

    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    incidence = abs(H[:, cols]).tocsc()
    per_contact = sp.csr_matrix((np.ones(cols.size), (np.repeat(np.arange(contacts.size), SPACEDIM),
                                                      np.arange(cols.size))), shape=(contacts.size, cols.size))
    touch = (per_contact @ incidence.T).astype(bool).astype(np.int8)
    graph = touch @ touch.T
    ncomp, labels = connected_components(graph, directed=False)
    return [contacts[labels == c].astype(np.int64) for c in range(ncomp)]


def _exact_stress(problem, H: sp.csc_matrix, contacts: np.ndarray, y_float: np.ndarray,
                  max_den: int | None) -> SelfStress | None:
    """The float self-stress ``y_float`` on ``contacts`` (one connected group) made exact, or None.
    ``max_den`` None: every part taken strictly inside its cone (no boundary direction snapped),
    for a y_float within :data:`BOUNDARY_TOL` of a boundary it does not lie on."""
    k = contacts.size
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    Hc = H[:, cols]
    rows = np.unique(Hc.indices)
    eqs = Q.as_fractions(Hc[rows].toarray())
    n = SPACEDIM * k
    kinds, bounds = [], []
    mu_f = [Fraction(float(x)) for x in problem.mu[contacts]]
    mur_f = [Fraction(float(x)) for x in problem.mu_r[contacts]]
    if np.any(y_float[::SPACEDIM] <= 0):
        return None  # a self-stress pushes (y_N > 0) on every contact it touches
    for i in range(k):
        yN, yT, yR = y_float[SPACEDIM * i], y_float[SPACEDIM * i + 1:SPACEDIM * i + 3], y_float[SPACEDIM * i + 3:SPACEDIM * i + 5]
        on = {}
        for part, (coef, ys, off) in {"friction": (mu_f[i], yT, 1), "rolling": (mur_f[i], yR, 3)}.items():
            if coef == 0:  # K forces these components to 0
                for j in (0, 1):
                    row = [Fraction(0)] * n
                    row[SPACEDIM * i + off + j] = Fraction(1)
                    eqs.append(row)
                continue
            if max_den is not None and math.hypot(*ys) >= (1 - BOUNDARY_TOL) * float(coef) * yN:
                d = _unit_direction(float(ys[0]), float(ys[1]), max_den)
                if d is None:
                    return None
                on[part] = (off, d)
                for j in (0, 1):  # y_part = coef · y_N · d exactly
                    row = [Fraction(0)] * n
                    row[SPACEDIM * i + off + j] = Fraction(1)
                    row[SPACEDIM * i] = -coef * d[j]
                    eqs.append(row)
        kinds.append("+".join(on) if on else "stuck")
        bounds.append(on)
    basis = Q.null_space(eqs, n)
    if not basis:
        return None
    B = np.array([Q.to_float(b) for b in basis]).T
    coef, *_ = np.linalg.lstsq(B, y_float, rcond=None)
    if not np.all(np.isfinite(coef)):
        return None
    c = [Fraction(float(x)) for x in coef]
    y = [sum((cj * bj[t] for cj, bj in zip(c, basis) if cj), Fraction(0)) for t in range(n)]
    # exact checks: H y = 0 on every row, y ∈ K with y_N > 0 on every contact of the group
    if any(Q.matvec(Q.as_fractions(Hc[rows].toarray()), y)):
        return None
    edges, free = [], []
    for i in range(k):
        yN = y[SPACEDIM * i]
        if yN <= 0:
            return None
        yT2 = y[SPACEDIM * i + 1] ** 2 + y[SPACEDIM * i + 2] ** 2
        yR2 = y[SPACEDIM * i + 3] ** 2 + y[SPACEDIM * i + 4] ** 2
        if yT2 > mu_f[i] ** 2 * yN ** 2 or yR2 > mur_f[i] ** 2 * yN ** 2:
            return None
        e, fr = [], []
        for part, coef, off in (("friction", mu_f[i], 1), ("rolling", mur_f[i], 3)):
            if coef == 0:  # u's components here are free in K*
                for j in (0, 1):
                    g = [Fraction(0)] * SPACEDIM
                    g[off + j] = Fraction(1)
                    fr.append(tuple(g))
            elif part in bounds[i]:  # the edge of K*_i orthogonal to y_i: (coef, −d) on these components
                _, d = bounds[i][part]
                g = [Fraction(0)] * SPACEDIM
                g[0], g[off], g[off + 1] = coef, -d[0], -d[1]
                e.append(tuple(g))
        edges.append(tuple(e))
        free.append(tuple(fr))
        # "u = 0" is claimed only where it follows: y_i strictly inside every cone part it has
        # (exactly), and no component of u left free by a zero coefficient.
        strict_T = mu_f[i] > 0 and yT2 < mu_f[i] ** 2 * yN ** 2
        strict_R = mur_f[i] > 0 and yR2 < mur_f[i] ** 2 * yN ** 2
        exact_kind = {"stuck": strict_T and strict_R, "friction": strict_R, "rolling": strict_T}
        if fr or not exact_kind.get(kinds[i], True):
            kinds[i] = "face"
    w_dot_y = sum((Fraction(float(wk)) * yk for wk, yk in zip(problem.w[cols], y) if yk), Fraction(0))
    if w_dot_y > 0:
        return None
    return SelfStress(contacts.copy(), tuple(y), tuple(kinds), tuple(edges), tuple(free), w_dot_y)


def find_self_stress(problem, seeds, cache: FaceSearch | None = None) -> list:
    """Exactly verified self-stresses (:class:`SelfStress`) near the contacts ``seeds``; [] when
    none is found.  ``cache`` (per problem) avoids repeating the search for the same seeds."""
    seeds = np.unique(np.asarray(seeds, dtype=np.int64))
    key = tuple(seeds.tolist())
    if cache is not None:
        covered = [s for s in cache.found if np.all(np.isin(seeds, s.contacts))]
        if covered and set(seeds.tolist()) <= set(np.concatenate([s.contacts for s in covered]).tolist()):
            return covered
        if key in cache.tried:
            return cache.tried[key]
    H = sp.csc_matrix(problem.H)
    out: list = []
    hood = neighbourhood(H, sp.csc_matrix(problem.H.T), seeds)
    search, H, shift = _in_search_units(problem, H, hood)
    y = float_self_stress(search, hood) if hood.size <= MAX_NEIGHBOURS else None
    if y is not None:
        yN = y[SPACEDIM * np.arange(hood.size)]
        support = hood[yN > SUPPORT_TOL * float(np.max(yN))]
        pos = {int(c): i for i, c in enumerate(hood)}
        for group in _components(H, support):
            if group.size > MAX_GROUP_CONTACTS:
                continue  # not made exact (see MAX_GROUP_CONTACTS): no claim is made about it
            yg = np.concatenate([y[SPACEDIM * pos[int(c)]:SPACEDIM * pos[int(c)] + SPACEDIM] for c in group])
            # (None last: a stress strictly inside K near its boundary, e.g. |y_T| = 2 y_N at μ = 2 + 2⁻³⁰)
            for max_den in SNAP_DENOMINATORS + (None,):
                stress = _exact_stress(search, H, group, yg, max_den)
                if stress is not None:
                    out.append(stress if shift is None else _in_problem_units(stress, shift))
                    break
    if cache is not None:
        cache.tried[key] = out
        cache.found += [s for s in out if not any(np.array_equal(s.contacts, t.contacts) for t in cache.found)]
    return out


SEARCH_UNIT_SPREAD = 6
"""Contacts near the seeds whose reactions' units (the largest entry of their normal column of
H, as a power of two) span more than 2^6 are searched in units brought together: the float
search's bound y_N ≤ 1, its support threshold and its least-squares fit are relative, and a
self-stress between contacts in units 2^12 apart was not found (a Chute of 1355 contacts whose
per-contact units were spread over 2^±12).  The exact stress is mapped back exactly."""


def _in_search_units(problem, H: sp.csc_matrix, hood: np.ndarray):
    """(problem, H, None) where the units of ``hood``'s contacts agree within
    :data:`SEARCH_UNIT_SPREAD`, else (a view with H's columns and w's rows of each contact
    multiplied by 2^s_c, that H, s) with s_c bringing every contact's normal column to [1/2, 1)."""
    from types import SimpleNamespace

    from ..model.scaling import columns_in_contact_units, normal_exponents

    e, loaded = normal_exponents(H, problem.mu.size)
    if hood.size == 0 or int(np.ptp(e[hood])) <= SEARCH_UNIT_SPREAD:
        return problem, H, None
    shift = np.where(loaded, -e, 0)
    Hs = H.copy()
    Hs.data = columns_in_contact_units(H, shift)
    view = SimpleNamespace(H=Hs, w=np.ldexp(np.asarray(problem.w, dtype=np.float64), np.repeat(shift, SPACEDIM)),
                           mu=problem.mu, mu_r=problem.mu_r)
    return view, Hs, shift


def _in_problem_units(stress: SelfStress, shift: np.ndarray) -> SelfStress:
    """A self-stress found in the search's units (contact c's columns of H multiplied by
    2^shift_c) in the problem's own: y_c multiplied by 2^shift_c, exactly.  Each y_c is scaled
    by a positive number, so it stays in K with the same kinds, face generators and wᵀy."""
    y = []
    for i, c in enumerate(stress.contacts):
        factor = Fraction(2) ** int(shift[int(c)])
        y.extend(x * factor for x in stress.y[SPACEDIM * i:SPACEDIM * i + SPACEDIM])
    return SelfStress(stress.contacts.copy(), tuple(y), stress.kinds, stress.edges, stress.free, stress.w_dot_y)


# ---------------------------------------------------------------------------------- r along y
def _in_K(r5, mu: Fraction, mur: Fraction) -> bool:
    rN = r5[0]
    return (rN >= 0 and r5[1] ** 2 + r5[2] ** 2 <= mu * mu * rN * rN
            and r5[3] ** 2 + r5[4] ** 2 <= mur * mur * rN * rN)


MAX_SHIFT_DOUBLINGS = 400


def shift_into_K(problem, stress: SelfStress, point_r: Dyadic) -> Fraction | None:
    """The first of τ = 0, τ₀, 2τ₀, 4τ₀, … with r + τ·y ∈ K exactly on the contacts of
    ``stress`` (τ₀ = max|r| / min y_N there), or None.  For each contact the τ that work form an
    interval [τ_i, ∞) or nothing (y_i ∈ K), so doubling finds a common one when there is one."""
    k = stress.contacts.size
    cols = (SPACEDIM * stress.contacts[:, None] + np.arange(SPACEDIM)).ravel()
    r = point_r[cols].fractions()
    y = stress.y
    mu = [Fraction(float(x)) for x in problem.mu[stress.contacts]]
    mur = [Fraction(float(x)) for x in problem.mu_r[stress.contacts]]

    def fits(tau: Fraction) -> bool:
        return all(_in_K([r[5 * i + c] + tau * y[5 * i + c] for c in range(SPACEDIM)], mu[i], mur[i])
                   for i in range(k))

    if fits(Fraction(0)):
        return Fraction(0)
    big = max(abs(x) for x in r)
    small = min(y[5 * i] for i in range(k))
    if small <= 0:
        return None
    tau = max(big / small, Fraction(1, 2 ** 60))
    for _ in range(MAX_SHIFT_DOUBLINGS):
        if fits(tau):
            return tau
        tau *= 2
    return None


# ---------------------------------------------------------------------------------- the move
def _move(problem, stress: SelfStress, u_of, weights: np.ndarray):
    """(dofs, δ) exact with u_F(v + δ) on the face of ``stress`` and its edge coefficients ≥ 0,
    or None.  ``u_of(cols)`` gives u_F(v) exactly (Fractions)."""
    contacts = stress.contacts
    cols = (SPACEDIM * contacts[:, None] + np.arange(SPACEDIM)).ravel()
    Hc = sp.csc_matrix(problem.H)[:, cols]
    dofs = np.unique(Hc.indices)
    HtD = Q.as_fractions(Hc[dofs].T.toarray())  # (5k, |D|)
    rhs = [-x for x in u_of(cols)]
    gens = []  # (row block, vector, nonneg)
    for i in range(contacts.size):
        gens += [(i, g, True) for g in stress.edges[i]] + [(i, g, False) for g in stress.free[i]]
    active = list(range(len(gens)))
    for _ in range(len(gens) + 1):
        A = [row[:] for row in HtD]
        for r_i, row in enumerate(A):
            i, comp = divmod(r_i, SPACEDIM)
            row += [-gens[j][1][comp] if gens[j][0] == i else Fraction(0) for j in active]
        # float least squares (δ weighted by √M_jj, edge coefficients nearly free) then an exact correction
        Af = np.array([[float(x) for x in row] for row in A])
        scale = np.concatenate([1.0 / weights[dofs], np.full(len(active), 1e3)])
        with np.errstate(all="ignore"):
            x0, *_ = np.linalg.lstsq(Af * scale, np.array([float(x) for x in rhs]), rcond=None)
        x0 = x0 * scale
        if not np.all(np.isfinite(x0)):
            x0 = np.zeros(len(A[0]))
        x = [Fraction(float(t)) for t in x0]
        resid = [b - ax for b, ax in zip(rhs, Q.matvec(A, x))]
        corr = Q.particular_solution(A, resid)
        if corr is None:
            return None
        x = [a + b for a, b in zip(x, corr)]
        # Along the face's own directions the move is free (A has a null space there): take the
        # exact solution of least weighted size, x + N t with N an exact null basis of A.
        N = Q.null_space(A, len(A[0]))
        if N:
            nd = dofs.size  # the size of δ counts (weighted by √M_jj), the edge coefficients are free
            Nf = np.array([Q.to_float(col[:nd]) for col in N]).T * weights[dofs][:, None]
            xf = Q.to_float(x[:nd]) * weights[dofs]
            t = np.linalg.lstsq(Nf, -xf, rcond=None)[0]
            if np.all(np.isfinite(t)):
                tq = [Fraction(float(ti)) for ti in t]
                x = [xi + sum((tj * col[i] for tj, col in zip(tq, N) if tj), Fraction(0)) for i, xi in enumerate(x)]
        coeffs = x[dofs.size:]
        negative = [j for j, c in zip(active, coeffs) if gens[j][2] and c < 0]
        if not negative:
            return dofs, x[:dofs.size]
        active = [j for j in active if j not in negative]  # on the wrong side of an edge: use 0 there
    return None


def restore(problem, exact, point_v: Dyadic, stresses: list) -> FaceRepair | None:
    """``point_v`` moved exactly onto the face of every stress in ``stresses`` (see the module
    docstring), or None when the move is impossible (an inconsistent face, or an infeasible one)."""
    if not stresses or any(s.infeasible for s in stresses):
        return None
    weights = np.sqrt(np.maximum(np.abs(problem.M_sym.diagonal()), np.finfo(float).tiny))
    HT = sp.csr_matrix(problem.H.T)
    changed: dict[int, Fraction] = {}  # v' − v on the dofs moved so far (exact)

    def u_of(cols):
        out = []
        for c in cols:
            lo, hi = HT.indptr[c], HT.indptr[c + 1]
            out.append(sum((Fraction(float(a)) * (point_v.fraction(int(j)) + changed.get(int(j), 0))
                            for a, j in zip(HT.data[lo:hi], HT.indices[lo:hi])), Fraction(float(problem.w[c]))))
        return out

    for stress in stresses:
        step = _move(problem, stress, u_of, weights)
        if step is None:
            return None
        dofs, delta = step
        for j, d in zip(dofs, delta):
            changed[int(j)] = changed.get(int(j), Fraction(0)) + d
    # v' = (den·v + den·δ) / den, den the lcm of δ's odd denominators
    idx = np.array(sorted(changed), dtype=np.int64)
    step_q = Quotient.from_fractions([changed[int(j)] for j in idx]) if idx.size else Quotient(Dyadic.zeros(0), 1)
    num = point_v.times_int(step_q.den)
    if idx.size:
        add = Dyadic.zeros(len(point_v))
        ints = add.ints.copy()
        ints[idx] = step_q.num.ints
        num = num + Dyadic(ints, step_q.num.exp)
    moved = float(np.max(step_q.abs_upper(), initial=0.0))
    return FaceRepair(list(stresses), Quotient(num, step_q.den), moved)


RETURNED_CONE_TOL = 1e-11
"""Relative cone violation accepted in the float64 r returned on self-stressed contacts: 1e-11,
below the 1e-10 of the paper's criterion, while τ stays small enough (~1e5 on the generated
Chutes) that the rounding of τ·y costs Hr about one digit of sixteen (measured: 1e-13 needed
τ ~ 8e5 and left Hr 10.0 digits)."""


def returned_reactions(problem, stresses: list, r: np.ndarray) -> np.ndarray:
    """The float64 r to return where self-stresses make r* non-unique and possibly unattained:
    r + τ·y on each stress's contacts, with the first τ = 0, τ₀, 2τ₀, … at which the rounded
    result is in K to a relative ``RETURNED_CONE_TOL`` (exact membership may need τ ~ 1e26
    where a contact slides: the reactions then grow without bound as the accuracy does, as an
    interior-point iterate's do).  Hr changes only by the rounding of τ·y (H y = 0 exactly);
    rᵀu does not change where u is on the face (yᵀu(v) = 0 for every v)."""
    out = np.array(r, dtype=np.float64, copy=True)
    for s in stresses:
        cols = (SPACEDIM * s.contacts[:, None] + np.arange(SPACEDIM)).ravel()
        y = np.array([float(x) for x in s.y])
        base = out[cols].copy()
        mu, mur = problem.mu[s.contacts], problem.mu_r[s.contacts]

        def fits(cand):
            c = cand.reshape(-1, SPACEDIM)
            scale = np.maximum(np.abs(c).max(axis=1), np.finfo(float).tiny)
            tol = RETURNED_CONE_TOL * scale
            return bool(np.all(c[:, 0] >= -tol) and np.all(np.hypot(c[:, 1], c[:, 2]) - mu * c[:, 0] <= tol)
                        and np.all(np.hypot(c[:, 3], c[:, 4]) - mur * c[:, 0] <= tol))

        if fits(base):
            continue
        tau = float(np.max(np.abs(base))) / float(np.min(y[::SPACEDIM]))
        for _ in range(200):
            cand = base + tau * y
            if fits(cand):
                out[cols] = cand
                break
            tau *= 2
    return out
