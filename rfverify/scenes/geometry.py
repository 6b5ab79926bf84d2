"""Rigid bodies, static obstacles and contact detection for the scene generator.

Bodies
------
Every moving body is a *capsule*: the set of points within ``radius`` of a segment of
half-length ``half_length`` along the body's z axis; ``half_length = 0`` is a sphere.  This one
shape family keeps every contact exact (closest points of two segments, of a segment end and a
plane, of a sphere and a box) while giving spheres of several radii and elongated bodies.

Each body has 6 dofs, in this order: velocity of the centre of mass (3) and angular velocity
(3), both in the WORLD frame.  Its mass-matrix block is ``diag(m·I3, R I_body Rᵀ)`` with R the
body-to-world rotation (unit quaternion ``(w, x, y, z)``) and ``I_body`` the principal moments.

Static obstacles (no dofs): half-spaces ``{x : n·x ≥ offset}`` (ground, walls, inclined floors)
and axis-aligned boxes (the SpheresPile ground box; spheres only).

Contacts (FCLIB conventions, DESIGN §1)
---------------------------------------
A contact joins body A (``a``) and body B (``b``, or ``-1`` for a static obstacle).  Its normal
N points from B to A; ``gap`` is the signed distance of the two surfaces along N (negative =
penetration).  Both lever arms go to ONE point, the midpoint of the two surface points, so that
a rigid motion of the whole assembly gives exactly zero relative velocity even for speculative
contacts with a positive gap (with one point per body, Ω × (p_A − p_B) = gap·Ω × N would leak
into the tangential velocity).  The frame (N, T1, T2) is right-handed; the rolling directions
are T1 and T2.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

KIND_BODY, KIND_PLANE, KIND_BOX = 0, 1, 2


# ---------------------------------------------------------------------- rotations
def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (k, 3, 3) of unit quaternions ``q`` (k, 4) ordered (w, x, y, z)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=float), -1, 0)
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def quat_mul(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Hamilton product p ⊗ q of quaternion arrays (..., 4)."""
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack((pw * qw - px * qx - py * qy - pz * qz,
                     pw * qx + px * qw + py * qz - pz * qy,
                     pw * qy - px * qz + py * qw + pz * qx,
                     pw * qz + px * qy - py * qx + pz * qw), axis=-1)


def quat_exp(rotvec: np.ndarray) -> np.ndarray:
    """Unit quaternions of rotation vectors (k, 3) (axis·angle, radians): the exponential map."""
    angle = np.linalg.norm(rotvec, axis=-1)
    half = 0.5 * angle
    # sin(θ/2)/θ → 1/2 as θ → 0; the series keeps full accuracy for tiny rotations.
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(angle > 1e-8, np.sin(half) / np.where(angle > 0, angle, 1.0),
                     0.5 - angle * angle / 48.0)
    return np.concatenate((np.cos(half)[..., None], s[..., None] * rotvec), axis=-1)


def random_quaternions(rng: np.random.Generator, k: int) -> np.ndarray:
    """k unit quaternions uniformly distributed on SO(3) (normalised Gaussian 4-vectors)."""
    q = rng.normal(size=(k, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1  # one representative of ±q, so equal rotations compare equal
    return q


def tangent_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit tangents (T1, T2), each (n, 3), completing unit normals (n, 3) to a right-handed
    orthonormal frame (N, T1, T2).

    T1 = normalise(N × e) with e the coordinate axis least aligned with N (never parallel to
    it), T2 = N × T1.  Deterministic, so the same geometry always gives the same H.
    """
    normal = np.asarray(normal, dtype=float)
    axis = np.argmin(np.abs(normal), axis=1)
    e = np.zeros_like(normal)
    e[np.arange(len(normal)), axis] = 1.0
    t1 = np.cross(normal, e)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    return t1, t2


# ---------------------------------------------------------------------- bodies
def capsule_mass_properties(radius, half_length, density):
    """Mass (k,) and principal moments of inertia (k, 3) about the centre of mass, axis = body z,
    of capsules (cylinder of length 2·half_length capped by two hemispheres) of uniform
    ``density``.  SI or any consistent units: mass = density·length³, inertia = mass·length².
    """
    r = np.asarray(radius, dtype=float)
    hl = np.asarray(half_length, dtype=float)
    rho = np.broadcast_to(np.asarray(density, dtype=float), r.shape)
    H = 2 * hl
    m_cyl = rho * np.pi * r ** 2 * H
    m_hemi = rho * (2.0 / 3.0) * np.pi * r ** 3  # one hemisphere
    mass = m_cyl + 2 * m_hemi
    i_axis = m_cyl * r ** 2 / 2 + 2 * m_hemi * (2.0 / 5.0) * r ** 2
    # Hemisphere about the capsule centre: 2/5 m r² about its flat face's centre, moved by the
    # parallel-axis theorem through its own centre of mass (3r/8 from the face).
    i_perp = (m_cyl * (H ** 2 / 12 + r ** 2 / 4)
              + 2 * m_hemi * (2.0 / 5.0 * r ** 2 + H ** 2 / 4 + 3.0 * H * r / 8))
    # A sphere (half_length 0) is isotropic exactly: the two formulas round differently, and
    # whether they agree then depended on the last bit of m_hemi (r³ comes from libm's or numpy's
    # SIMD pow, which differ between machines), so a sphere's M was diagonal on one and not on another.
    i_perp = np.where(hl == 0, i_axis, i_perp)
    inertia = np.stack((i_perp, i_perp, i_axis), axis=-1)
    return mass, inertia


@dataclass
class Bodies:
    """State and properties of ``nb`` moving rigid bodies (capsules; spheres when
    ``half_length = 0``).  All arrays are float64 (``material`` int), first axis = body.

    radius, half_length : (nb,)      length
    mass : (nb,)                     mass
    inertia : (nb, 3)                principal moments about the body axes (axis = body z)
    pos : (nb, 3)                    centre of mass, world frame
    quat : (nb, 4)                   body-to-world rotation, unit quaternion (w, x, y, z)
    vel : (nb, 3)                    velocity of the centre of mass, world frame
    omega : (nb, 3)                  angular velocity, WORLD frame
    material : (nb,) int             row/column of the scene's friction tables
    """

    radius: np.ndarray
    half_length: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    pos: np.ndarray
    quat: np.ndarray
    vel: np.ndarray
    omega: np.ndarray
    material: np.ndarray

    @classmethod
    def make(cls, radius, half_length, density, pos, quat=None, material=None) -> "Bodies":
        """Bodies of uniform ``density`` (scalar or per body) at rest at ``pos``; identity
        orientation unless ``quat`` is given; material 0 unless given."""
        radius = np.array(radius, dtype=float)
        half_length = np.broadcast_to(np.asarray(half_length, dtype=float), radius.shape).copy()
        mass, inertia = capsule_mass_properties(radius, half_length, density)
        nb = radius.size
        if quat is None:
            quat = np.tile([1.0, 0.0, 0.0, 0.0], (nb, 1))
        if material is None:
            material = np.zeros(nb, dtype=np.int64)
        return cls(radius=radius, half_length=half_length, mass=mass, inertia=inertia,
                   pos=np.array(pos, dtype=float).reshape(nb, 3),
                   quat=np.array(quat, dtype=float).reshape(nb, 4),
                   vel=np.zeros((nb, 3)), omega=np.zeros((nb, 3)),
                   material=np.array(material, dtype=np.int64).reshape(nb))

    @property
    def count(self) -> int:
        return int(self.radius.size)

    @property
    def bounding_radius(self) -> np.ndarray:
        """Radius of the smallest sphere about the centre containing the body."""
        return self.radius + self.half_length

    def copy(self) -> "Bodies":
        return replace(self, **{k: np.array(getattr(self, k)) for k in self.__dataclass_fields__})

    def subset(self, index) -> "Bodies":
        """A new Bodies with the bodies ``index`` (array of indices or boolean mask), in order."""
        return replace(self, **{k: np.array(getattr(self, k)[index]) for k in self.__dataclass_fields__})

    @staticmethod
    def concatenate(parts) -> "Bodies":
        parts = list(parts)
        return Bodies(**{k: np.concatenate([getattr(p, k) for p in parts])
                         for k in Bodies.__dataclass_fields__})

    def rotation(self) -> np.ndarray:
        """Body-to-world rotation matrices (nb, 3, 3)."""
        return quat_to_matrix(self.quat)

    def axis(self) -> np.ndarray:
        """World direction of each body's z axis (the capsule axis), (nb, 3)."""
        return self.rotation()[:, :, 2]

    def endpoints(self) -> tuple[np.ndarray, np.ndarray]:
        """Ends (P, Q), each (nb, 3), of the core segments (P = Q = centre for spheres)."""
        d = self.axis() * self.half_length[:, None]
        return self.pos - d, self.pos + d

    def world_inertia(self) -> np.ndarray:
        """World inertia tensors R diag(I_body) Rᵀ, (nb, 3, 3), exactly symmetric.

        Spheres (equal moments) get exactly ``I·I3``, independent of the orientation's rounding.
        """
        R = self.rotation()
        I = np.einsum("bij,bj,bkj->bik", R, self.inertia, R)
        I = 0.5 * (I + np.swapaxes(I, 1, 2))
        iso = np.all(self.inertia == self.inertia[:, :1], axis=1)
        if iso.any():
            I[iso] = self.inertia[iso, 0, None, None] * np.eye(3)
        return I

    def kinetic_energy(self) -> float:
        Iw = self.world_inertia()
        return float(0.5 * np.sum(self.mass * np.sum(self.vel ** 2, axis=1))
                     + 0.5 * np.einsum("bi,bij,bj->", self.omega, Iw, self.omega))


@dataclass
class Statics:
    """Static obstacles, which have no dofs.

    plane_normal : (p, 3) unit normals, pointing into the free side
    plane_offset : (p,)   the half-space is {x : n·x ≥ offset}
    plane_material : (p,) int
    box_lo, box_hi : (q, 3) corners of axis-aligned boxes (only spheres may touch boxes)
    box_material : (q,) int
    """

    plane_normal: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    plane_offset: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plane_material: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    box_lo: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    box_hi: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    box_material: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    @classmethod
    def make(cls, planes=(), boxes=()) -> "Statics":
        """``planes``: iterable of (normal, offset, material); ``boxes``: of (lo, hi, material)."""
        planes, boxes = list(planes), list(boxes)
        pn = np.array([np.asarray(n, float) / np.linalg.norm(n) for n, _, _ in planes]).reshape(-1, 3)
        return cls(plane_normal=pn,
                   plane_offset=np.array([o for _, o, _ in planes], dtype=float),
                   plane_material=np.array([m for _, _, m in planes], dtype=np.int64),
                   box_lo=np.array([lo for lo, _, _ in boxes], dtype=float).reshape(-1, 3),
                   box_hi=np.array([hi for _, hi, _ in boxes], dtype=float).reshape(-1, 3),
                   box_material=np.array([m for _, _, m in boxes], dtype=np.int64))

    def scaled(self, length: float) -> "Statics":
        """The same obstacles with lengths multiplied by ``length`` (a change of units)."""
        return replace(self, plane_offset=self.plane_offset * length,
                       box_lo=self.box_lo * length, box_hi=self.box_hi * length)


# ---------------------------------------------------------------------- contacts
@dataclass
class Contacts:
    """Contacts found by :func:`detect_contacts` (n of them, one row each).

    a : (n,) int           body A
    b : (n,) int           body B, or -1 for a static obstacle
    kind : (n,) int        KIND_BODY, KIND_PLANE or KIND_BOX
    static : (n,) int      index of the plane/box (-1 for body–body)
    normal : (n, 3)        unit normal from B to A
    point : (n, 3)         common application point (midpoint of the surface points)
    gap : (n,)             signed surface distance along N (< 0: penetration)
    material_b : (n,) int  material of B (body or obstacle)
    """

    a: np.ndarray
    b: np.ndarray
    kind: np.ndarray
    static: np.ndarray
    normal: np.ndarray
    point: np.ndarray
    gap: np.ndarray
    material_b: np.ndarray

    @property
    def count(self) -> int:
        return int(self.a.size)

    def frames(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(N, T1, T2), each (n, 3)."""
        t1, t2 = tangent_frame(self.normal)
        return self.normal, t1, t2


def _clip01(x):
    # np.clip costs ~5 µs of dispatch per call on small arrays; this is called in tight loops.
    return np.minimum(np.maximum(x, 0.0), 1.0)


def segment_closest_points(p1, q1, p2, q2):
    """Parameters (s, t) in [0, 1] of the closest points p1 + s(q1 − p1), p2 + t(q2 − p2) of
    pairs of segments (arrays (k, 3)); degenerate segments (points) allowed.

    Ericson, *Real-Time Collision Detection* §5.1.9, vectorised.  For (nearly) parallel
    overlapping segments the closest points are not unique; the middle of the overlap is
    returned so that the contact point does not jump to an end.
    """
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    tiny = 1e-300
    pt1, pt2 = a <= tiny, e <= tiny
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = a * e - b * b
        parallel = denom <= 1e-12 * a * e
        s = np.where(parallel, 0.0, _clip01((b * f - c * e) / np.where(denom > 0, denom, 1.0)))
        # Parallel: middle of the projection of segment 2 onto segment 1.
        s_par = 0.5 * (_clip01(-c / np.where(pt1, 1.0, a)) + _clip01((b - c) / np.where(pt1, 1.0, a)))
        s = np.where(parallel, s_par, s)
        t = (b * s + f) / np.where(pt2, 1.0, e)
        low, high = t < 0, t > 1
        t = _clip01(t)
        s = np.where(low, _clip01(-c / np.where(pt1, 1.0, a)),
                     np.where(high, _clip01((b - c) / np.where(pt1, 1.0, a)), s))
    # Degenerate cases: a point against a segment, or two points.
    s = np.where(pt1, 0.0, s)
    t = np.where(pt1 & ~pt2, _clip01(f / np.where(pt2, 1.0, e)), t)
    s = np.where(~pt1 & pt2, _clip01(-c / np.where(pt1, 1.0, a)), s)
    t = np.where(pt2, 0.0, t)
    return s, t


def _empty_contacts() -> Contacts:
    z = np.zeros(0, dtype=np.int64)
    return Contacts(a=z, b=z, kind=z, static=z, normal=np.zeros((0, 3)), point=np.zeros((0, 3)),
                    gap=np.zeros(0), material_b=z)


def candidate_pairs(bodies: Bodies, reach: float) -> np.ndarray:
    """Broad phase: pairs (i, j), i < j, (k, 2) sorted, whose bounding spheres are closer than
    ``reach`` (a k-d tree over the centres; then an exact bounding-sphere filter)."""
    nb = bodies.count
    if nb < 2:
        return np.zeros((0, 2), dtype=np.int64)
    R = bodies.bounding_radius
    tree = cKDTree(bodies.pos)
    pairs = tree.query_pairs(2 * float(R.max()) + reach, output_type="ndarray").astype(np.int64)
    if pairs.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.sort(pairs, axis=1)
    dist = np.linalg.norm(bodies.pos[pairs[:, 0]] - bodies.pos[pairs[:, 1]], axis=1)
    pairs = pairs[dist <= R[pairs[:, 0]] + R[pairs[:, 1]] + reach]
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def body_body_geometry(bodies: Bodies, pairs: np.ndarray, ends=None):
    """Normal (from the second body of each pair to the first), gap, common point, (k, ·)."""
    P, Q = bodies.endpoints() if ends is None else ends
    i, j = pairs[:, 0], pairs[:, 1]
    s, t = segment_closest_points(P[i], Q[i], P[j], Q[j])
    ci = P[i] + s[:, None] * (Q[i] - P[i])
    cj = P[j] + t[:, None] * (Q[j] - P[j])
    diff = ci - cj
    dist = np.linalg.norm(diff, axis=1)
    # Coincident core points (a deep overlap that valid scenes never have): any unit normal.
    normal = np.where(dist[:, None] > 0, diff / np.where(dist > 0, dist, 1.0)[:, None], [0.0, 0.0, 1.0])
    ri, rj = bodies.radius[i], bodies.radius[j]
    gap = dist - ri - rj
    point = 0.5 * ((ci - ri[:, None] * normal) + (cj + rj[:, None] * normal))
    return normal, gap, point


def detect_contacts(bodies: Bodies, statics: Statics, margin: float, pairs=None) -> Contacts:
    """All contacts with gap ≤ ``margin`` (speculative contacts included), in a deterministic
    order: body–body pairs (a < b, lexicographic; A = the lower index), then body–plane
    (by body, plane, segment end), then sphere–box.

    Body–body: one contact per pair, at the closest points of the core segments.  Body–plane:
    one contact per segment end within the margin (a capsule lying flat gets two, a sphere
    one).  Sphere–box: closest point of the box; a centre inside the box uses the face of
    least penetration.  Capsules against boxes are refused (ValueError): their contact is not a
    single closest point in general.

    ``pairs`` (k, 2) replaces the broad phase by a given candidate list (a Verlet list that
    the caller keeps valid), e.g. in the relaxation loops of :mod:`.deposition`.
    """
    parts = []
    nb = bodies.count
    if nb == 0:
        return _empty_contacts()
    P, Q = bodies.endpoints()
    if pairs is None:
        pairs = candidate_pairs(bodies, margin)
    if pairs.size:
        normal, gap, point = body_body_geometry(bodies, pairs, (P, Q))
        keep = gap <= margin
        k = int(keep.sum())
        parts.append(Contacts(a=pairs[keep, 0], b=pairs[keep, 1], kind=np.full(k, KIND_BODY),
                              static=np.full(k, -1), normal=normal[keep], point=point[keep],
                              gap=gap[keep], material_b=bodies.material[pairs[keep, 1]]))
    if statics.plane_normal.shape[0]:
        ends = np.stack((P, Q), axis=1)  # (nb, 2, 3)
        height = np.einsum("bej,pj->bpe", ends, statics.plane_normal) - statics.plane_offset[None, :, None]
        gap = height - bodies.radius[:, None, None]
        is_cap = (bodies.half_length > 0)[:, None, None]
        # A sphere's two "ends" coincide: count it once.
        use = (gap <= margin) & (is_cap | (np.arange(2)[None, None, :] == 0))
        bi, pi, ei = np.nonzero(use)
        nrm = statics.plane_normal[pi]
        g = gap[bi, pi, ei]
        point = ends[bi, ei] - (bodies.radius[bi] + 0.5 * g)[:, None] * nrm
        parts.append(Contacts(a=bi, b=np.full(bi.size, -1), kind=np.full(bi.size, KIND_PLANE),
                              static=pi, normal=nrm, point=point, gap=g,
                              material_b=statics.plane_material[pi]))
    if statics.box_lo.shape[0]:
        c = bodies.pos
        lo, hi = statics.box_lo, statics.box_hi
        closest = np.clip(c[:, None, :], lo[None], hi[None])  # (nb, q, 3)
        diff = c[:, None, :] - closest
        dist = np.linalg.norm(diff, axis=2)
        inside = dist == 0
        # Inside: push out through the nearest face.
        depth = np.concatenate((c[:, None, :] - lo[None], hi[None] - c[:, None, :]), axis=2)  # (nb,q,6)
        face = np.argmin(depth, axis=2)
        face_normal = np.zeros(face.shape + (3,))
        ax = face % 3
        sign = np.where(face < 3, -1.0, 1.0)
        np.put_along_axis(face_normal, ax[..., None], sign[..., None], axis=2)
        with np.errstate(invalid="ignore", divide="ignore"):
            normal = np.where(inside[..., None], face_normal, diff / np.where(inside, 1.0, dist)[..., None])
        signed = np.where(inside, -np.take_along_axis(depth, face[..., None], axis=2)[..., 0], dist)
        gap = signed - bodies.radius[:, None]
        bi, qi = np.nonzero(gap <= margin)
        if bi.size and np.any(bodies.half_length[bi] > 0):
            raise ValueError("capsule–box contacts are not supported (use half-spaces for "
                             "capsule containers)")
        nrm = normal[bi, qi]
        g = gap[bi, qi]
        point = c[bi] - (bodies.radius[bi] + 0.5 * g)[:, None] * nrm
        parts.append(Contacts(a=bi, b=np.full(bi.size, -1), kind=np.full(bi.size, KIND_BOX),
                              static=qi, normal=nrm, point=point, gap=g,
                              material_b=statics.box_material[qi]))
    if not parts:
        return _empty_contacts()
    return Contacts(**{k: np.concatenate([getattr(p, k) for p in parts])
                       for k in Contacts.__dataclass_fields__})


def min_gap(bodies: Bodies, statics: Statics) -> float:
    """Smallest signed gap over all pairs and obstacles (inf without any)."""
    reach = float(bodies.bounding_radius.max()) if bodies.count else 0.0
    c = detect_contacts(bodies, statics, margin=reach)
    return float(c.gap.min()) if c.count else np.inf
