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
* :func:`relax_fire` — gravity settling of capsules and spheres in a container by energy
  minimisation (penalty overlap energy + potential energy) with FIRE (Bitzek et al., PRL 97,
  170201, 2006); used where deposition by rolling is not exact (capsules).
* :func:`fcc_positions` — close-packed face-centred cubic stacking (square layers).
* :func:`open_cluster` — a connected cluster of spheres with all gaps in a prescribed band.

All take a ``numpy.random.Generator``; none uses global random state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import Bodies, Statics, candidate_pairs, detect_contacts, quat_exp, quat_mul

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


# ---------------------------------------------------------------------- FIRE relaxation
@dataclass
class Relaxation:
    """Result of :func:`relax_fire`: iterations, final scaled residual force, largest overlap
    (as a fraction of the smallest radius), and whether ``ftol`` was reached."""

    iterations: int
    residual: float
    max_overlap: float
    converged: bool


def penalty_forces(bodies: Bodies, statics: Statics, gravity, stiffness: float, pairs=None):
    """Generalised forces (nb, 6) of gravity plus a linear penalty k·overlap along the contact
    normal at each overlapping contact (force on A, its opposite on B, torques about the
    centres); and the contacts."""
    c = detect_contacts(bodies, statics, 0.0, pairs=pairs)
    nb = bodies.count
    F = np.zeros((nb, 6))
    F[:, :3] = bodies.mass[:, None] * np.asarray(gravity)[None, :]
    over = c.gap < 0
    if over.any():
        a, b = c.a[over], c.b[over]
        f = (-stiffness * c.gap[over])[:, None] * c.normal[over]
        ta = np.cross(c.point[over] - bodies.pos[a], f)
        G = np.concatenate((f, ta), axis=1)
        for comp in range(6):
            F[:, comp] += np.bincount(a, weights=G[:, comp], minlength=nb)
        hb = b >= 0
        if hb.any():
            tb = np.cross(c.point[over][hb] - bodies.pos[b[hb]], -f[hb])
            Gb = np.concatenate((-f[hb], tb), axis=1)
            for comp in range(6):
                F[:, comp] += np.bincount(b[hb], weights=Gb[:, comp], minlength=nb)
    return F, c


def compress_column(bodies: Bodies, statics: Statics, up=(0.0, 0.0, 1.0), iters: int = 30) -> float:
    """Lower a loose arrangement towards the floor without creating overlaps: each body's
    height above its lowest admissible height, h_i = z_i − R_i (R = bounding radius), is
    multiplied by the smallest λ ∈ [0, 1] (bisection) for which no two bodies overlap.  Keeps
    the random arrangement but removes most of the empty space a fall would have to cross.
    Modifies ``bodies.pos``; returns λ."""
    up = np.asarray(up, float)
    z = bodies.pos @ up
    Rb = bodies.bounding_radius
    base = bodies.pos - np.outer(z - Rb, up)
    lo, hi = 0.0, 1.0
    for _ in range(iters):
        lam = 0.5 * (lo + hi)
        bodies.pos = base + np.outer((z - Rb) * lam, up)
        c = detect_contacts(bodies, statics, 0.0)
        if c.count and c.gap.min() < 0:
            lo = lam
        else:
            hi = lam
    bodies.pos = base + np.outer((z - Rb) * hi, up)
    return hi


def relax_fire(bodies: Bodies, statics: Statics, gravity, *, stiffness: float,
               max_iter: int = 3000, ftol: float = 1e-2, soft_factor: float = 0.1,
               fall_height: float | None = None, skin: float | None = None,
               callback=None) -> Relaxation:
    """Settle ``bodies`` (modified in place: pos, quat; vel = omega = 0 on return) under
    ``gravity`` in the container ``statics`` by minimising potential + penalty energy.

    Two phases; the path is not physical, only the minimum is:

    1. *Sedimentation* with penalty stiffness ``soft_factor``·stiffness (larger stable steps)
       for about twice the free-fall time from ``fall_height``: damped dynamics whose velocity
       test is done per body (a body moving against its net force is stopped), so bodies still
       falling keep their speed while those landing are damped — a global FIRE reset would
       stop the whole column whenever one body lands.
    2. *FIRE* (Bitzek et al., PRL 97, 170201, 2006) at full ``stiffness`` until every body's
       net force is below ``ftol``·m|g| and its net torque below ``ftol``·m|g|·R, or
       ``max_iter`` iterations in all.

    Fictitious isotropic inertia m·R² (R = bounding radius) makes the rotational contact
    stiffness at most the translational one, so one step size serves both.  Speeds are capped so that a Verlet list with ``skin`` stays valid for
    several steps.  Overlaps left are of order (load)/stiffness.
    """
    g = np.asarray(gravity, dtype=float)
    gnorm = float(np.linalg.norm(g))
    m = bodies.mass
    Rb = bodies.bounding_radius
    I_f = m * Rb ** 2
    skin = 0.5 * float(bodies.radius.min()) if skin is None else skin
    if fall_height is None:
        fall_height = float(np.ptp(bodies.pos @ (-g / gnorm))) + 1e-12
    k_soft = soft_factor * stiffness
    dt_soft = 0.25 * np.sqrt(m.min() / k_soft)
    n_soft = int(min(max_iter // 2, 2 * np.sqrt(2 * fall_height / gnorm) / dt_soft + 50))
    vel = np.zeros((bodies.count, 3))
    omg = np.zeros((bodies.count, 3))
    state = {"pairs": None, "ends": None}

    def forces(k):
        P, Q = bodies.endpoints()
        if state["pairs"] is None or max(np.abs(P - state["ends"][0]).max(),
                                         np.abs(Q - state["ends"][1]).max()) > 0.5 * skin:
            state["pairs"] = candidate_pairs(bodies, skin)
            state["ends"] = (P, Q)
        F, _ = penalty_forces(bodies, statics, g, k, state["pairs"])
        resid = max(np.max(np.linalg.norm(F[:, :3], axis=1) / (m * gnorm)),
                    np.max(np.linalg.norm(F[:, 3:], axis=1) / (m * gnorm * Rb)))
        return F, resid

    def move(dt):
        # Cap the displacement per step at skin/8 (Verlet list valid ≥ 4 steps).
        vmax = skin / (8 * dt)
        sp = np.linalg.norm(vel, axis=1)
        fast = sp > vmax
        vel[fast] *= (vmax / sp[fast])[:, None]
        wmax = vmax / Rb
        sw = np.linalg.norm(omg, axis=1)
        fast = sw > wmax
        omg[fast] *= (wmax[fast] / sw[fast])[:, None]
        bodies.pos = bodies.pos + dt * vel
        q = quat_mul(quat_exp(dt * omg), bodies.quat)
        bodies.quat = q / np.linalg.norm(q, axis=1, keepdims=True)

    def mix(alpha, F, per_body):
        for x, f in ((vel, F[:, :3]), (omg, F[:, 3:])):
            if per_body:
                fn = np.linalg.norm(f, axis=1)
                xn = np.linalg.norm(x, axis=1)
                ok = fn > 0
                x[ok] = (1 - alpha) * x[ok] + alpha * (xn[ok] / fn[ok])[:, None] * f[ok]
            else:
                fn = np.linalg.norm(f)
                if fn > 0:
                    xn = np.linalg.norm(x)
                    x *= 1 - alpha
                    x += alpha * xn * f / fn

    it = 0
    resid = np.inf
    for it in range(1, n_soft + 1):  # phase 1: sedimentation
        F, resid = forces(k_soft)
        power = np.einsum("ij,ij->i", F[:, :3], vel) + np.einsum("ij,ij->i", F[:, 3:], omg)
        stop = power < 0
        vel[stop] = 0.0
        omg[stop] = 0.0
        vel += dt_soft * F[:, :3] / m[:, None]
        omg += dt_soft * F[:, 3:] / I_f[:, None]
        mix(0.1, F, per_body=True)
        move(dt_soft)
        if callback is not None and it % 100 == 0:
            callback(it, resid)
    # phase 2: FIRE at full stiffness
    dt_max = 0.25 * np.sqrt(m.min() / stiffness)
    dt = 0.2 * dt_max
    alpha0, alpha, f_alpha, f_inc, f_dec, n_delay = 0.1, 0.1, 0.99, 1.1, 0.5, 5
    n_pos = 0
    vel[:] = 0.0
    omg[:] = 0.0
    while it < max_iter:
        it += 1
        F, resid = forces(stiffness)
        if resid <= ftol:
            break
        power = np.sum(F[:, :3] * vel) + np.sum(F[:, 3:] * omg)
        if power > 0:
            n_pos += 1
            if n_pos > n_delay:
                dt = min(dt * f_inc, dt_max)
                alpha *= f_alpha
        else:
            n_pos = 0
            dt *= f_dec
            alpha = alpha0
            vel[:] = 0.0
            omg[:] = 0.0
        vel += dt * F[:, :3] / m[:, None]
        omg += dt * F[:, 3:] / I_f[:, None]
        mix(alpha, F, per_body=False)
        move(dt)
        if callback is not None and it % 100 == 0:
            callback(it, resid)
    c = detect_contacts(bodies, statics, 0.0)
    overlap = float(max(0.0, -c.gap.min())) if c.count else 0.0
    bodies.vel = np.zeros((bodies.count, 3))
    bodies.omega = np.zeros((bodies.count, 3))
    return Relaxation(iterations=it, residual=float(resid),
                      max_overlap=overlap / float(bodies.radius.min()), converged=bool(resid <= ftol))


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
