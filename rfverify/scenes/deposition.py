"""Fast construction of granular configurations (instead of a full dynamic simulation).

* :func:`deposit_spheres` — sequential geometric deposition (Visscher & Bolsterli, Nature 239,
  1972): each sphere is dropped at a random (x, y), falls until it touches something, then
  rolls without friction along the steepest feasible descent path — over one support, then
  along the circle of two supports — until gravity is balanced by its contacts (the upward
  vertical lies in the cone of its contact normals: three supports, or the floor).  Every
  sphere ends exactly touching its supports (gaps at round-off level), so the pile is
  mechanically stable sphere by sphere.  Gravity is −e_z in the deposition frame.
* :func:`place_random` — random sequential addition of non-overlapping bodies in a box region
  (loose "in flight" bodies).
* :func:`place_bodies_random` — the same with exact capsule geometry.
* :func:`collapse_downwards` — lower every body straight down until it touches something
  (exact for capsules): turns a loose arrangement (capsules in the cages of their deposited
  bounding spheres) into one where every body rests on at least one contact.
* :func:`fcc_positions` — close-packed face-centred cubic stacking (square layers).
* :func:`open_cluster` — a connected cluster of spheres with all gaps in a prescribed band.

Those that draw random numbers take a ``numpy.random.Generator``; none uses global random state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Bodies

_UP = np.array([0.0, 0.0, 1.0])
_DOWN = -_UP


# ---------------------------------------------------------------------- deposition
@dataclass
class Deposit:
    """Result of :func:`deposit_spheres`.

    centers : (k, 3)     rest positions, in deposition order
    radii : (k,)
    first_touch : (k, 3) position of each sphere when it first touched something (end of its
                         free fall; the rolling starts there) — a collision-free position for
                         a sphere "just arriving" on the pile of its predecessors
    source : (k,)        index of each kept sphere in the input radii
    discarded : int      drops rejected (fell off the footprint or failed to settle)
    moves : int          total rolling moves
    """

    centers: np.ndarray
    radii: np.ndarray
    first_touch: np.ndarray
    source: np.ndarray
    discarded: int
    moves: int


def _descent(normals: np.ndarray):
    """Steepest feasible descent direction for a sphere touching obstacles with unit contact
    normals ``normals`` (t, 3) (pointing into the sphere): the projection d of −e_z onto the
    cone {d : n_j·d ≥ 0}.  Returns (d, active indices).  d = 0 means gravity is balanced by
    non-negative normal forces (frictionless equilibrium).

    The projection is the unique KKT point; it is found by trying active sets of size 0, 1, 2
    (vectorised) — in 3-D a non-zero projection has at most two active constraints.
    """
    g = _DOWN
    t = normals.shape[0]
    eps = 1e-12
    if t == 0 or np.all(normals[:, 2] <= eps):
        return g.copy(), ()
    # One active constraint j: d = g − (g·n_j) n_j, multiplier λ_j = n_z ≥ 0.
    nz = normals[:, 2]
    D1 = g[None, :] - (-nz)[:, None] * normals  # g·n = −n_z
    feas1 = (normals @ D1.T >= -eps).all(axis=0) & (nz >= -eps)
    ok = np.flatnonzero(feas1)
    if ok.size:
        j = int(ok[0])
        return D1[j], (j,)
    # Two active constraints (j, k): d along m = n_j × n_k; g − d = −(λ_j n_j + λ_k n_k).
    if t >= 2:
        jj, kk = np.triu_indices(t, 1)
        m = np.cross(normals[jj], normals[kk])
        mn = np.linalg.norm(m, axis=1)
        good = mn > 1e-12
        mhat = m / np.where(good, mn, 1.0)[:, None]
        D2 = (mhat @ g)[:, None] * mhat
        r = g[None, :] - D2  # = −(λ_j n_j + λ_k n_k)
        G11 = np.ones(jj.size)
        G12 = np.einsum("ij,ij->i", normals[jj], normals[kk])
        b1 = -np.einsum("ij,ij->i", r, normals[jj])
        b2 = -np.einsum("ij,ij->i", r, normals[kk])
        det = G11 * G11 - G12 * G12
        with np.errstate(divide="ignore", invalid="ignore"):
            lj = (b1 - G12 * b2) / det
            lk = (b2 - G12 * b1) / det
        feas2 = good & (lj >= -eps) & (lk >= -eps) & ((normals @ D2.T) >= -eps).all(axis=0)
        ok = np.flatnonzero(feas2)
        if ok.size:
            p = int(ok[0])
            return D2[p], (int(jj[p]), int(kk[p]))
    return np.zeros(3), tuple(range(t))


def _arc_entry(P, A, B, theta_end):
    """Smallest θ in (0, θ_end] where P + A cos θ + B sin θ becomes negative (entering an
    obstacle along an arc), +inf when it does not; vectorised."""
    S = np.hypot(A, B)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(S > 0, -P / S, np.inf)
    hit = kappa > -1.0
    beta = np.arccos(np.clip(kappa, -1.0, 1.0))
    theta = np.mod(np.arctan2(B, A) + beta, 2 * np.pi)
    theta = np.where(hit & (theta > 1e-14) & (theta <= theta_end), theta, np.inf)
    return theta


def deposit_spheres(radii, rng: np.random.Generator, drop_xy, plane_normal, plane_offset, *,
                    footprint=None, floor: int = 0, max_moves: int = 400,
                    max_attempts: int = 50, arc_step: float = 0.2) -> Deposit:
    """Deposit spheres of the given radii one by one (see the module docstring).

    Parameters
    ----------
    radii : (k,)
    drop_xy : callable(rng, radius) -> (x, y)
        where a sphere is released (above everything deposited so far).
    plane_normal, plane_offset : (p, 3), (p,)
        half-spaces {x : n·x ≥ offset} (floor, walls); the floor must have n_z > 0 so that
        every fall ends.
    footprint : (xmin, xmax, ymin, ymax) or None
        a sphere that comes to rest on plane ``floor`` with its centre outside this rectangle
        has fallen off the ground box: it is discarded and another drop is made.
    arc_step : float
        longest rolling move (radians) before the active supports are re-examined; the path
        is exact, this only bounds how far a support that has stopped carrying load is kept.
    """
    radii = np.asarray(radii, dtype=float)
    pn = np.asarray(plane_normal, dtype=float).reshape(-1, 3)
    po = np.asarray(plane_offset, dtype=float).reshape(-1)
    k = radii.size
    centers = np.empty((k, 3))
    first = np.empty((k, 3))
    source = np.empty(k, dtype=np.int64)
    kept = 0
    discarded = 0
    total_moves = 0
    for i in range(k):
        R = radii[i]
        for _attempt in range(max_attempts):
            x, y = drop_xy(rng, R)
            C, Rs = centers[:kept], radii[source[:kept]]
            top = float(np.max(C[:, 2] + Rs)) if kept else 0.0  # release above everything
            c = np.array([x, y, max(top, 0.0) + 2.0 * R])
            c, touch, moves, ok = _settle(c, R, C, Rs, pn, po, max_moves, arc_step)
            total_moves += moves
            if ok and footprint is not None:
                on_floor = pn[floor] @ c - po[floor] - R <= 1e-9 * R
                xmin, xmax, ymin, ymax = footprint
                if on_floor and not (xmin <= c[0] <= xmax and ymin <= c[1] <= ymax):
                    ok = False
            if ok:
                centers[kept] = c
                first[kept] = touch
                source[kept] = i
                kept += 1
                break
            discarded += 1
    return Deposit(centers=centers[:kept].copy(), radii=radii[source[:kept]].copy(),
                   first_touch=first[:kept].copy(), source=source[:kept].copy(),
                   discarded=discarded, moves=total_moves)


def _settle(c, R, C_all, Rs_all, pn, po, max_moves, arc_step):
    """Move one sphere (centre c, radius R) among fixed spheres (C_all, Rs_all) and half-spaces
    (pn, po) until it is stable.  Returns (centre, first-touch centre, moves, success)."""
    first = None
    tol = 1e-10 * R
    # Only spheres that the path can reach matter: those within ``reach`` horizontally of
    # where the selection was made; reselected when the sphere has rolled half that far.
    reach = 4.0 * (R + (float(Rs_all.max()) if Rs_all.size else R))
    sel_xy = None
    for move in range(max_moves):
        if sel_xy is None or np.hypot(*(c[:2] - sel_xy)) > 0.5 * reach:
            sel_xy = c[:2].copy()
            dxy = C_all[:, :2] - sel_xy
            pick = np.einsum("ij,ij->i", dxy, dxy) < (reach + R + Rs_all) ** 2
            C, D = C_all[pick], Rs_all[pick] + R
        diff = c[None, :] - C
        dist = np.sqrt(np.einsum("ij,ij->i", diff, diff))
        gs = dist - D
        gp = pn @ c - po - R
        if (gs.size and gs.min() < -1e-7 * R) or gp.min() < -1e-7 * R:
            return c, c if first is None else first, move, False
        touch_s = gs <= tol
        touch_p = gp <= tol
        ts = np.flatnonzero(touch_s)
        tp = np.flatnonzero(touch_p)
        if first is None and (ts.size or tp.size):
            first = c.copy()
        normals = np.concatenate((diff[ts] / dist[ts, None], pn[tp]))
        d, active = _descent(normals)
        dn = np.sqrt(d @ d)
        if dn <= 1e-9:
            return c, c if first is None else first, move, True
        d = d / dn
        act_s = [ts[a] for a in active if a < ts.size]
        act_p = [tp[a - ts.size] for a in active if a >= ts.size]
        Co, Do = C[~touch_s], D[~touch_s]
        pno, poo = pn[~touch_p], po[~touch_p]
        if not act_s:
            # Straight line: free fall, or sliding along one or two walls.
            q = c[None, :] - Co
            dq = q @ d
            disc = dq ** 2 - (np.einsum("ij,ij->i", q, q) - Do ** 2)
            s_sph = np.where(disc >= 0, -dq - np.sqrt(np.maximum(disc, 0)), np.inf)
            s_sph = np.where(s_sph > 1e-14 * R, s_sph, np.inf)
            nd = pno @ d
            with np.errstate(divide="ignore", invalid="ignore"):
                s_pl = np.where(nd < 0, (poo + R - pno @ c) / nd, np.inf)
            s = min(s_sph.min(initial=np.inf), s_pl.min(initial=np.inf))
            if not np.isfinite(s):
                return c, c if first is None else first, move, False  # falls forever
            c = c + s * d
            continue
        # Arc: about one sphere, or the circle of two supports.
        if len(active) == 1:
            o = C[act_s[0]]
            rho = D[act_s[0]]
            u = (c - o) / np.sqrt((c - o) @ (c - o))
            v = d - (d @ u) * u
            v /= np.sqrt(v @ v)
            theta_end = np.arctan2(u[2], -v[2])  # the support's equator: it stops carrying load
        else:
            j = act_s[0]
            if len(act_s) == 2:
                k2 = act_s[1]
                L = np.sqrt((C[k2] - C[j]) @ (C[k2] - C[j]))
                e = (C[k2] - C[j]) / L
                a = (D[j] ** 2 - D[k2] ** 2 + L ** 2) / (2 * L)
                o = C[j] + a * e
            else:
                p = act_p[0]
                h = pn[p] @ C[j] - po[p] - R
                o = C[j] - h * pn[p]
            rho = np.sqrt((c - o) @ (c - o))
            u = (c - o) / rho
            v = d - (d @ u) * u
            v /= np.sqrt(v @ v)
            theta_end = np.mod(np.arctan2(-v[2], -u[2]), 2 * np.pi)  # lowest point of the circle
        theta_end = min(theta_end, arc_step)
        q = o[None, :] - Co
        P = np.einsum("ij,ij->i", q, q) + rho ** 2 - Do ** 2
        th_s = _arc_entry(P, 2 * rho * (q @ u), 2 * rho * (q @ v), theta_end)
        Pp = pno @ o - poo - R
        th_p = _arc_entry(Pp, rho * (pno @ u), rho * (pno @ v), theta_end)
        theta = min(th_s.min(initial=np.inf), th_p.min(initial=np.inf), theta_end)
        c = o + rho * (np.cos(theta) * u + np.sin(theta) * v)
    return c, c if first is None else first, max_moves, False


# ---------------------------------------------------------------------- random placement
def place_random(bounding_radii, lo, hi, rng: np.random.Generator, *, existing=None,
                 existing_radii=None, min_gap: float = 0.0, max_tries: int = 2000) -> np.ndarray:
    """Centres (k, 3) of k bodies with the given bounding radii placed one by one uniformly at
    random in the box [lo + R, hi − R] without their bounding spheres coming closer than
    ``min_gap`` to each other or to ``existing`` spheres (centres, radii).  Raises
    RuntimeError when a body finds no room after ``max_tries`` draws (region too small)."""
    Rb = np.asarray(bounding_radii, dtype=float)
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    ex_c = np.zeros((0, 3)) if existing is None else np.asarray(existing, float).reshape(-1, 3)
    ex_r = np.zeros(0) if existing_radii is None else np.asarray(existing_radii, float)
    C = np.concatenate((ex_c, np.empty((Rb.size, 3))))
    Rall = np.concatenate((ex_r, Rb))
    n0 = ex_c.shape[0]
    for i, R in enumerate(Rb):
        m = n0 + i
        for _ in range(max_tries):
            x = rng.uniform(lo + R, hi - R)
            if m == 0 or np.all(np.linalg.norm(C[:m] - x, axis=1) >= Rall[:m] + R + min_gap):
                C[m] = x
                break
        else:
            raise RuntimeError(f"no room for body {i} of {Rb.size} in the region {lo}..{hi}")
    return C[n0:].copy()


def place_bodies_random(bodies: Bodies, lo, hi, rng: np.random.Generator, *, existing=None,
                        min_gap: float = 0.0, max_tries: int = 2000) -> np.ndarray:
    """Like :func:`place_random` but with the exact capsule geometry of ``bodies`` (their
    radius, half-length and orientation are kept; only the centres are drawn): a body is
    accepted when its surface gap to every placed body and to ``existing`` (Bodies) is ≥
    ``min_gap``.  Elongated bodies pack far more densely this way than by bounding spheres.
    Returns the centres (nb, 3)."""
    from .geometry import segment_closest_points

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    placed = existing.count if existing is not None else 0
    allb = bodies.copy() if existing is None else Bodies.concatenate([existing, bodies])
    axis = allb.axis() * allb.half_length[:, None]
    Rb = allb.bounding_radius
    for i in range(bodies.count):
        m = placed + i
        R = Rb[m]
        for _ in range(max_tries):
            x = rng.uniform(lo + R, hi - R)
            near = np.flatnonzero(np.linalg.norm(allb.pos[:m] - x, axis=1) < Rb[:m] + R + min_gap)
            if near.size:
                s, t = segment_closest_points(np.broadcast_to(x - axis[m], (near.size, 3)),
                                              np.broadcast_to(x + axis[m], (near.size, 3)),
                                              allb.pos[near] - axis[near], allb.pos[near] + axis[near])
                p1 = x - axis[m] + 2 * s[:, None] * axis[m]
                p2 = allb.pos[near] - axis[near] + 2 * t[:, None] * axis[near]
                gap = np.linalg.norm(p1 - p2, axis=1) - allb.radius[m] - allb.radius[near]
                if gap.min() < min_gap:
                    continue
            allb.pos[m] = x
            break
        else:
            raise RuntimeError(f"no room for body {i} of {bodies.count} in the region {lo}..{hi}")
    return allb.pos[placed:].copy()


# ---------------------------------------------------------------------- collapse
@dataclass
class Collapse:
    """Result of :func:`collapse_downwards`: how far bodies were lowered (length) and how many
    ended resting on another body or on the floor."""

    mean_drop: float
    max_drop: float
    on_bodies: int
    on_floor: int


def collapse_downwards(bodies: Bodies, floor_offset: float = 0.0, max_iter: int = 500) -> Collapse:
    """Lower every body straight down (−z) until it touches another body or the floor
    z = ``floor_offset``, bottom-up (by lowest point), the others held where they are.

    Exact for capsules and spheres, by conservative advancement: the gap between two bodies
    changes at most as fast as one of them is translated (it is 1-Lipschitz in the drop s), so
    stepping s by the smallest current gap never passes the first contact, and converges to it
    (to 1e-10 of the smallest radius).  Only bodies whose bounding spheres the sweep can meet
    are examined.  The result never overlaps.  Vertical walls do not stop a vertical drop.
    Modifies ``bodies.pos``.
    """
    from .geometry import segment_closest_points

    nb = bodies.count
    axis = bodies.axis() * bodies.half_length[:, None]
    r = bodies.radius
    Rb = bodies.bounding_radius
    lowest = bodies.pos[:, 2] - np.abs(axis[:, 2]) - r
    tol = 1e-10 * float(r.min())
    drops = np.zeros(nb)
    on_body = np.zeros(nb, dtype=bool)
    for i in np.argsort(lowest, kind="stable"):
        c = bodies.pos
        s_floor = max(0.0, c[i, 2] - abs(axis[i, 2]) - r[i] - floor_offset)
        D = Rb[i] + Rb
        dxy2 = np.sum((c[:, :2] - c[i, :2]) ** 2, axis=1)
        cand = np.flatnonzero((dxy2 < D ** 2) & (np.arange(nb) != i)
                              & (c[:, 2] - Rb < c[i, 2] + Rb[i]))
        Pj, Qj = c[cand] - axis[cand], c[cand] + axis[cand]
        k = cand.size
        s = 0.0
        gap_min = s_floor
        for _ in range(max_iter):
            gap_min = s_floor - s
            if k:
                Pi = np.broadcast_to(c[i] - axis[i] - [0.0, 0.0, s], (k, 3))
                Qi = np.broadcast_to(c[i] + axis[i] - [0.0, 0.0, s], (k, 3))
                a, b = segment_closest_points(Pi, Qi, Pj, Qj)
                d = (Pi + a[:, None] * (Qi - Pi)) - (Pj + b[:, None] * (Qj - Pj))
                gaps = np.sqrt(np.einsum("ij,ij->i", d, d)) - r[i] - r[cand]
                gap_min = min(gap_min, float(gaps.min()))
            if gap_min <= tol:
                break
            s += gap_min
        bodies.pos[i, 2] -= s
        drops[i] = s
        on_body[i] = s < s_floor - tol
    return Collapse(mean_drop=float(drops.mean()), max_drop=float(drops.max()),
                    on_bodies=int(on_body.sum()), on_floor=int((~on_body).sum()))


# ---------------------------------------------------------------------- lattices, clusters
def fcc_positions(count: int, d: float, nx: int, ny: int) -> np.ndarray:
    """Centres (count, 3) of equal spheres (diameter d) in face-centred cubic stacking on the
    floor z = 0 inside the box [0, nx·d] × [0, ny·d]: square layers of nx × ny spheres
    (touching each other and the walls) alternating with (nx−1) × (ny−1) layers in their
    hollows, layer spacing d/√2.  Every sphere touches its 4 in-layer neighbours and 4 in each
    adjacent layer (12 in the bulk).  Filled layer by layer, row by row."""
    out = []
    layer = 0
    while sum(len(o) for o in out) < count:
        z = d / 2 + layer * d / np.sqrt(2.0)
        if layer % 2 == 0:
            xs = d / 2 + d * np.arange(nx)
            ys = d / 2 + d * np.arange(ny)
        else:
            xs = d + d * np.arange(nx - 1)
            ys = d + d * np.arange(ny - 1)
        X, Y = np.meshgrid(xs, ys, indexing="ij")
        out.append(np.stack((X.ravel(), Y.ravel(), np.full(X.size, z)), axis=1))
        layer += 1
    return np.concatenate(out)[:count]


def open_cluster(radii, rng: np.random.Generator, gap_lo: float, gap_hi: float,
                 max_tries: int = 2000) -> np.ndarray:
    """Centres (k, 3) of a connected cluster of spheres: each new sphere is put at a gap drawn
    uniformly in [gap_lo, gap_hi] from a random earlier sphere, in a random direction, and kept
    only if its gap to every other sphere is ≥ gap_lo.  So no two spheres touch and every
    sphere has a neighbour within gap_hi."""
    radii = np.asarray(radii, dtype=float)
    C = np.zeros((radii.size, 3))
    for i in range(1, radii.size):
        for _ in range(max_tries):
            j = int(rng.integers(0, i))
            u = rng.normal(size=3)
            u /= np.linalg.norm(u)
            x = C[j] + (radii[i] + radii[j] + rng.uniform(gap_lo, gap_hi)) * u
            if np.all(np.linalg.norm(C[:i] - x, axis=1) - radii[:i] - radii[i] >= gap_lo * (1 - 1e-12)):
                C[i] = x
                break
        else:
            raise RuntimeError(f"open_cluster: no room for sphere {i}")
    return C
