"""The scenes: configurations of bodies and obstacles, one per stage of a run.

A scene builds, once per seed, a *base configuration* by a fast geometric method (deposition,
collapse, lattice; see :mod:`.deposition`), and from it one :class:`World` per stage of the
trace: stage φ ∈ [0, 1] (φ = K/(count−1) for the K-th of ``count`` problems) holds the part of
the run reached at that time — the first spheres of a pile, the bodies already landed in a
chute, the landed part of a soup — with the velocities of bodies in motion.  The
generator (:func:`rfverify.scenes.generate`) then takes a few Moreau–Jean steps from each world
and dumps the last one's problem.

Units are SI (m, kg, s) except where a scene says otherwise (Millimetre).  μr is a length
(the rolling-resistance moment is bounded by μr·r_N), μ is dimensionless.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .deposition import (collapse_downwards, deposit_spheres, fcc_positions, open_cluster,
                         place_bodies_random, place_random)
from .geometry import Bodies, Statics, random_quaternions
from .stepper import SceneError

G = 9.81
"""Standard gravity used by every scene (m/s²)."""


@dataclass
class World:
    """Everything a Moreau–Jean run needs, plus notes for the problem description.

    bodies, statics        the state at the start of the stage
    gravity : (3,)         acceleration (length/time²)
    h : float              time step
    margin : float         contact detection margin (length)
    mu_table, mu_r_table   (materials × materials) coefficient tables
    notes : dict           stage facts (JSON-able) for the description
    """

    bodies: Bodies
    statics: Statics
    gravity: np.ndarray
    h: float
    margin: float
    mu_table: np.ndarray
    mu_r_table: np.ndarray
    notes: dict = field(default_factory=dict)


def _stage_count(lo: float, hi: float, phi: float) -> int:
    return int(round(lo + phi * (hi - lo)))


def _table(value, n=1):
    return np.full((n, n), float(value))


def _min_rule_table(levels) -> np.ndarray:
    """Coefficient of a material pair = levels[min(i, j)] (so every level occurs)."""
    k = len(levels)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    return np.asarray(levels, dtype=float)[np.minimum(i, j)]


class Scene:
    """A named scene: defaults, base configuration, stages.  Subclasses set the class
    attributes and implement :meth:`prepare` and :meth:`stage`."""

    name: str = ""
    summary: str = ""
    configuration: str = ""
    defaults: dict = {}
    default_size: int = 1
    min_size: int = 1
    size_unit: str = "bodies"
    units: str = "SI (m, kg, s)"

    def convert(self, arrays: dict) -> dict:
        """Transform the arrays of a dumped problem (identity; Millimetre changes units)."""
        return arrays

    def prepare(self, p: dict, size: int, rng: np.random.Generator):
        """Build the base configuration (expensive part, done once per seed)."""
        raise NotImplementedError

    def stage(self, base, p: dict, size: int, phi: float, rng: np.random.Generator) -> World:
        """The world at stage φ ∈ [0, 1] (1 = the full-size, last stage)."""
        raise NotImplementedError


# ---------------------------------------------------------------------- piles of spheres
class SpheresPile(Scene):
    name = "SpheresPile"
    summary = ("spheres of one diameter dropped one by one on a ground box (FCLIB SpheresPile: "
               "250 spheres, d = 0.02 m, rho = 1300 kg/m3, h = 1e-3 s, mu = 0.3, mu_r = 1e-3, "
               "e = 0)")
    configuration = ("Visscher-Bolsterli sequential deposition (drop at a random point of a disk, "
                     "fall, roll without friction to a stable rest on 3 supports or the ground); "
                     "stage = the first spheres of the deposit, the last one arriving from "
                     "above at its first-touch point, the most recent ones still agitated")
    defaults = dict(diameter=0.02, density=1300.0, h=1e-3, mu=0.3, mu_r=1e-3, margin=1e-3,
                    drop_radius=0.05, box_half_width=0.16, box_depth=0.05, fall_height=0.04,
                    agitation=0.05, recent_fraction=0.1, first_stage_bodies=4, tilt=0.0)
    default_size = 250
    min_size = 2
    size_unit = "spheres"
    # Scene variants change these.
    falling = True
    n_materials = 1

    def prepare(self, p, size, rng):
        d = p["diameter"]
        a = p["box_half_width"]
        R_drop = p["drop_radius"]
        if R_drop + d / 2 > a:
            raise SceneError(f"{self.name}: drop_radius + d/2 = {R_drop + d / 2:g} exceeds "
                             f"box_half_width = {a:g}")

        def drop_xy(g, R):
            rr = R_drop * math.sqrt(g.uniform())
            th = g.uniform(0.0, 2 * math.pi)
            return rr * math.cos(th), rr * math.sin(th)

        dep = deposit_spheres(np.full(size, d / 2), rng, drop_xy, [[0.0, 0.0, 1.0]], [0.0],
                              footprint=(-a, a, -a, a))
        if dep.centers.shape[0] < size:
            raise SceneError(f"{self.name}: only {dep.centers.shape[0]} of {size} spheres could "
                             f"be deposited on the box (make box_half_width larger)")
        materials = self.materials(rng, size)
        return {"deposit": dep, "materials": materials}

    def materials(self, rng, size):
        if self.n_materials == 1:
            return np.zeros(size, dtype=np.int64)
        return rng.integers(0, self.n_materials, size)

    def densities(self, p, nb, base):
        return np.full(nb, p["density"])

    def tables(self, p):
        return _table(p["mu"]), _table(p["mu_r"])

    def ground_material(self):
        return 0

    def stage(self, base, p, size, phi, rng):
        dep = base["deposit"]
        nb = max(1, min(size, _stage_count(min(p["first_stage_bodies"], size), size, phi)))
        d = p["diameter"]
        r = d / 2
        pos = dep.centers[:nb].copy()
        bodies = Bodies.make(np.full(nb, r), 0.0, self.densities(p, nb, base), pos,
                             material=base["materials"][:nb])
        notes = {"bodies": nb, "deposited_discarded": dep.discarded}
        h = p["h"]
        if self.falling and nb >= 2:
            # The newest sphere arrives from fall_height above its first contact, released so
            # that it strikes during the first step (gap = half the distance it covers).
            v_fall = math.sqrt(2 * G * p["fall_height"])
            last = nb - 1
            bodies.pos[last] = dep.first_touch[last] + np.array([0.0, 0.0, 0.5 * v_fall * h])
            bodies.vel[last] = np.array([0.0, 0.0, -v_fall]) + 0.1 * v_fall * np.append(rng.normal(size=2), 0.0)
            bodies.omega[last] = 0.1 * v_fall / r * rng.normal(size=3)
            k_recent = int(round(p["recent_fraction"] * nb))
            recent = np.arange(max(0, last - k_recent), last)
            if recent.size and p["agitation"] > 0:
                s = p["agitation"]
                bodies.vel[recent] = s * rng.normal(size=(recent.size, 3))
                bodies.omega[recent] = s / r * rng.normal(size=(recent.size, 3))
            notes.update(falling_sphere=int(last), impact_speed=v_fall,
                         agitated_spheres=int(recent.size))
        a = p["box_half_width"]
        statics = Statics.make(boxes=[((-a, -a, -p["box_depth"]), (a, a, 0.0), self.ground_material())])
        tilt = math.radians(p["tilt"])
        gravity = G * np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
        mu_t, mur_t = self.tables(p)
        return World(bodies=bodies, statics=statics, gravity=gravity, h=h, margin=p["margin"],
                     mu_table=mu_t, mu_r_table=mur_t, notes=notes)


class MassRatio(SpheresPile):
    name = "MassRatio"
    summary = ("pile of equal-size spheres whose densities span mass_ratio (log-uniform; the "
               "first sphere light, the second exactly mass_ratio times heavier), heavy spheres "
               "resting on light ones")
    defaults = dict(SpheresPile.defaults, mass_ratio=1e6)
    default_size = 60

    def prepare(self, p, size, rng):
        base = super().prepare(p, size, rng)
        u = rng.uniform(0.0, 1.0, size)
        u[0], u[1:2] = 0.0, 1.0  # every stage (≥ 2 spheres) has the full ratio exactly
        base["log_ratio"] = u
        return base

    def stage(self, base, p, size, phi, rng):
        w = super().stage(base, p, size, phi, rng)
        w.notes["mass_ratio"] = float(w.bodies.mass.max() / w.bodies.mass.min())
        return w

    def densities(self, p, nb, base):
        return p["density"] * p["mass_ratio"] ** base["log_ratio"][:nb]


class RollingExtremes(SpheresPile):
    name = "RollingExtremes"
    summary = ("pile with three materials whose rolling resistance mu_r is 0, 1e-5 or 1 m "
               "(a pair takes the level of its lower material; the ground is material 2)")
    defaults = {k: v for k, v in SpheresPile.defaults.items() if k != "mu_r"}
    default_size = 60
    n_materials = 3
    MU_R_LEVELS = (0.0, 1e-5, 1.0)

    def tables(self, p):
        return _table(p["mu"], 3), _min_rule_table(self.MU_R_LEVELS)

    def ground_material(self):
        return 2


class Frictionless(SpheresPile):
    name = "Frictionless"
    summary = ("pile with mu = 0 at every contact; mu_r = 0 for material 0 and mu_r for "
               "material 1 (the ground is material 1)")
    defaults = {k: v for k, v in SpheresPile.defaults.items() if k != "mu"}
    default_size = 60
    n_materials = 2

    def tables(self, p):
        return _table(0.0, 2), _min_rule_table((0.0, p["mu_r"]))

    def ground_material(self):
        return 1


class AllSticking(SpheresPile):
    name = "AllSticking"
    summary = ("pile at rest on a ground tilted by 'tilt' degrees, with friction and rolling "
               "resistance large enough that every contact sticks (v = 0 is the solution); only "
               "touching contacts (margin 1e-6 m: the deposit's gaps are at round-off level, and "
               "the margin must exceed the drift h*v of an interior-point solution at 1e-10, "
               "measured ~4e-9 m per step)")
    defaults = dict(SpheresPile.defaults, mu=1.0, mu_r=1.0, tilt=10.0, margin=1e-6,
                    agitation=0.0)
    default_size = 60
    falling = False


class Millimetre(SpheresPile):
    name = "Millimetre"
    summary = ("SpheresPile written in badly scaled units: millimetres, grams, seconds (masses "
               "~5 g, inertias ~2e2 g mm2, lever arms ~10 mm, mu_r in mm); the run is the "
               "SpheresPile run with the same seed, each dumped problem converted exactly")
    default_size = 60
    units = "mm, g, s (simulated in SI, problem converted)"
    LENGTH, MASS = 1e3, 1e3  # one metre / one kilogram in the problem's units

    def convert(self, arrays):
        return rescale_arrays(arrays, self.LENGTH, self.MASS)


def rescale_arrays(arrays: dict, length: float, mass: float) -> dict:
    """The one-step problem ``arrays`` (M, H, f, w, mu, mu_r of a rigid-body problem with 6
    dofs per body) in other units: lengths × ``length``, masses × ``mass``, time unchanged.

    With E = diag(1,1,1, L,L,L) per body and C = diag(L,L,L, 1,1) per contact, velocities
    become v' = D v (D = diag(L,L,L,1,1,1)), u' = C u, impulses r' = mass·L·diag(1,1,1,L,L) r,
    and the problem data M' = mass·E M E, H' = D⁻¹ H C, f' = mass·L·E f, w' = C w,
    μ' = μ, μr' = L μr (a length): the same physical problem exactly.
    """
    import scipy.sparse as sp

    L = float(length)
    m = arrays["M"].shape[0]
    n = arrays["mu"].size
    e = np.tile([1.0, 1.0, 1.0, L, L, L], m // 6)
    dinv = np.tile([1.0 / L, 1.0 / L, 1.0 / L, 1.0, 1.0, 1.0], m // 6)
    c = np.tile([L, L, L, 1.0, 1.0], n)
    E = sp.diags(e)
    out = dict(arrays)
    out["M"] = (mass * (E @ arrays["M"] @ E)).tocsc()
    out["H"] = (sp.diags(dinv) @ arrays["H"] @ sp.diags(c)).tocsc()
    out["f"] = mass * L * e * arrays["f"]
    out["w"] = c * arrays["w"]
    out["mu"] = np.array(arrays["mu"], dtype=float)
    out["mu_r"] = L * np.asarray(arrays["mu_r"], dtype=float)
    return out


# ---------------------------------------------------------------------- lattice
class Lattice(SpheresPile):
    name = "Lattice"
    summary = ("equal spheres in close-packed face-centred cubic stacking in a box whose walls "
               "touch the square layers: every sphere has up to 12 touching neighbours, contacts "
               "are redundant (hyperstatic), r is not unique")
    configuration = ("FCC lattice (square layers nx x ny alternating with (nx-1) x (ny-1) in the "
                     "hollows, spacing d/sqrt(2)), filled layer by layer; stage = the first "
                     "lattice sites (one full bottom layer at the first stage); at rest")
    defaults = dict(diameter=0.02, density=1300.0, h=1e-3, mu=0.3, mu_r=1e-3, margin=2e-3, width=0)
    default_size = 60
    min_size = 1

    def _width(self, p, size):
        w = int(p["width"])
        return w if w >= 2 else max(2, int(round(math.sqrt(size / 4.0))))

    def prepare(self, p, size, rng):
        nx = self._width(p, size)
        return {"pos": fcc_positions(size, p["diameter"], nx, nx), "nx": nx}

    def stage(self, base, p, size, phi, rng):
        nx = base["nx"]
        nb = max(1, min(size, _stage_count(min(nx * nx, size), size, phi)))
        d = p["diameter"]
        bodies = Bodies.make(np.full(nb, d / 2), 0.0, p["density"], base["pos"][:nb])
        L = nx * d
        statics = Statics.make(planes=[((0, 0, 1), 0.0, 0), ((1, 0, 0), 0.0, 0), ((-1, 0, 0), -L, 0),
                                       ((0, 1, 0), 0.0, 0), ((0, -1, 0), -L, 0)])
        return World(bodies=bodies, statics=statics, gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                     margin=p["margin"], mu_table=_table(p["mu"]), mu_r_table=_table(p["mu_r"]),
                     notes={"bodies": nb, "layer_width": nx})


# ---------------------------------------------------------------------- large beds, no stepping
class GranularBed(Scene):
    name = "GranularBed"
    summary = ("a large bed of equal spheres at rest on the ground (simple cubic or FCC lattice, "
               "radii shrunk at random so that every lattice contact has a small gap, random "
               "agitation), written as the problem of its first Moreau-Jean step WITHOUT any solve: "
               "1e4-1e5 contacts in seconds (simple cubic: 3 nx ny nz - nx nz - ny nz contacts)")
    configuration = ("lattice sites (packing 0: simple cubic, spacing d; 1: FCC, square nx x ny "
                     "layers alternating with (nx-1) x (ny-1) in their hollows) filled layer by "
                     "layer, row by row, rotated about the vertical by a random angle; radius of "
                     "sphere i = d/2 (1 - gap_jitter U_i), U_i uniform in [0, 1), so lattice "
                     "neighbours have gaps in [0, gap_jitter d] (all within the margin) and no "
                     "other pair is within it; velocities N(0, agitation^2) per component, spins "
                     "N(0, (agitation/r)^2); stage = the first lattice sites (one full bottom layer "
                     "at the first stage); the dumped problem is the first step's, so 'steps' is "
                     "not used")
    defaults = dict(diameter=0.02, density=1300.0, h=1e-3, mu=0.3, mu_r=1e-3, margin=1e-3,
                    packing=0.0, width=0.0, gap_jitter=1e-3, agitation=0.01, tilt=0.0)
    default_size = 3375
    min_size = 1
    size_unit = "spheres"
    step_free = True
    """Built by :func:`rfverify.scenes.generate` without solving: the dumped problem is the
    one-step problem of :meth:`stage`'s world (:meth:`.stepper.MoreauJean.one_step_arrays`)."""

    def _check(self, p):
        d = p["diameter"]
        if p["packing"] not in (0.0, 1.0):
            raise SceneError(f"{self.name}: parameter packing = {p['packing']!r} must be 0 (simple "
                             "cubic) or 1 (FCC)")
        if not 0 <= p["gap_jitter"] < 0.1:
            raise SceneError(f"{self.name}: parameter gap_jitter = {p['gap_jitter']!r} must be in "
                             "[0, 0.1) (a fraction of the diameter)")
        # Lattice neighbours must all be contacts, second neighbours (at sqrt(2) d) none.
        if not p["gap_jitter"] * d <= p["margin"] < (math.sqrt(2.0) - 1.0) * d:
            raise SceneError(f"{self.name}: margin = {p['margin']:g} must be at least gap_jitter * "
                             f"diameter = {p['gap_jitter'] * d:g} and below (sqrt(2) - 1) * diameter = "
                             f"{(math.sqrt(2.0) - 1.0) * d:g}")
        for k in ("diameter", "density"):
            if not p[k] > 0:
                raise SceneError(f"{self.name}: parameter {k} = {p[k]!r} must be > 0")
        if not p["agitation"] >= 0:
            raise SceneError(f"{self.name}: parameter agitation = {p['agitation']!r} must be >= 0")

    def layer_width(self, p, size) -> int:
        """Spheres along x and y of the bottom layer: ``width``, or a roughly cubic bed."""
        w = int(p["width"])
        if w >= 1:
            return w
        per_width = 1.0 if p["packing"] == 0 else math.sqrt(2.0)  # sites per d of height, relative
        return max(1, int(round((size / per_width) ** (1.0 / 3.0))))

    def sites(self, p, size) -> np.ndarray:
        """Lattice sites (size, 3) before the rotation, filled layer by layer, row by row."""
        d, nx = p["diameter"], self.layer_width(p, size)
        if p["packing"] == 1:
            return fcc_positions(size, d, nx, nx)
        k = np.arange(size)
        return d * np.stack((k % nx + 0.5, (k // nx) % nx + 0.5, k // (nx * nx) + 0.5), axis=1)

    def prepare(self, p, size, rng):
        self._check(p)
        angle = rng.uniform(0.0, 2 * math.pi)
        c, s = math.cos(angle), math.sin(angle)
        pos = self.sites(p, size) @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
        radii = 0.5 * p["diameter"] * (1.0 - p["gap_jitter"] * rng.uniform(0.0, 1.0, size))
        return {"pos": pos, "radii": radii, "angle": angle, "nx": self.layer_width(p, size),
                "vel": rng.normal(size=(size, 3)), "omega": rng.normal(size=(size, 3))}

    def stage(self, base, p, size, phi, rng):
        nx = base["nx"]
        nb = max(1, min(size, _stage_count(min(nx * nx, size), size, phi)))
        r = base["radii"][:nb]
        bodies = Bodies.make(r, 0.0, p["density"], base["pos"][:nb])
        bodies.vel = p["agitation"] * base["vel"][:nb]
        bodies.omega = p["agitation"] / r[:, None] * base["omega"][:nb]
        tilt = math.radians(p["tilt"])
        gravity = G * np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
        return World(bodies=bodies, statics=Statics.make(planes=[((0, 0, 1), 0.0, 0)]), gravity=gravity,
                     h=p["h"], margin=p["margin"], mu_table=_table(p["mu"]), mu_r_table=_table(p["mu_r"]),
                     notes={"bodies": nb, "layer_width": nx, "packing": "fcc" if p["packing"] == 1 else "cubic",
                            "rotation_deg": math.degrees(base["angle"])})


# ---------------------------------------------------------------------- all open
class AllOpen(Scene):
    name = "AllOpen"
    summary = ("a loose cluster of spheres (mixed radii) in free fall, expanding: every "
               "contact is a speculative one with a positive gap and separating velocity, so "
               "r = 0 at every contact")
    configuration = ("connected cluster: each sphere placed at a gap in [gap_lo, gap_hi] x "
                     "margin from an earlier one, no closer to any other; velocities = uniform "
                     "expansion + noise, random spins; stage = the first spheres of the cluster")
    defaults = dict(radius_min=0.008, radius_max=0.012, density=1300.0, h=1e-3, mu=0.3,
                    mu_r=1e-3, margin=2e-3, gap_lo=0.25, gap_hi=0.85, expansion=1.0,
                    spin=5.0, speed_noise=0.01)
    default_size = 60
    min_size = 2
    size_unit = "spheres"

    def prepare(self, p, size, rng):
        if not 0 < p["gap_lo"] < p["gap_hi"] < 1:
            raise SceneError("AllOpen: need 0 < gap_lo < gap_hi < 1 (fractions of the margin)")
        radii = rng.uniform(p["radius_min"], p["radius_max"], size)
        m = p["margin"]
        return {"radii": radii, "pos": open_cluster(radii, rng, p["gap_lo"] * m, p["gap_hi"] * m)}

    def stage(self, base, p, size, phi, rng):
        nb = max(2, min(size, _stage_count(2, size, phi)))
        pos = base["pos"][:nb]
        b = Bodies.make(base["radii"][:nb], 0.0, p["density"], pos)
        b.vel = p["expansion"] * (pos - pos.mean(axis=0)) + p["speed_noise"] * rng.normal(size=(nb, 3))
        b.omega = p["spin"] * rng.normal(size=(nb, 3))
        return World(bodies=b, statics=Statics(), gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                     margin=p["margin"], mu_table=_table(p["mu"]), mu_r_table=_table(p["mu_r"]),
                     notes={"bodies": nb})


# ---------------------------------------------------------------------- chute
class Chute(Scene):
    name = "Chute"
    summary = ("spheres of mixed radii flowing down an inclined channel with side walls "
               "(FCLIB Chute: h = 1e-4 s, mu = 1, mu_r = 0.1); the number of bodies grows "
               "along the run as the chute fills")
    configuration = ("bed: Visscher-Bolsterli deposition onto the chute floor in the chute frame "
                     "(gravity normal to the floor), then gravity tilted by 'incline'; flow "
                     "velocity U (0.5 + 0.5 z/H) down the chute with random partial rolling and "
                     "noise; stream: bodies still in flight placed at random above the bed; "
                     "stage = more bodies present and a larger landed fraction")
    defaults = dict(radius_min=0.03, radius_max=0.06, density=1000.0, incline=25.0, width=0.6,
                    h=1e-4, mu=1.0, mu_r=0.1, margin=3e-3, flow_speed=1.0, bed_fraction=0.5,
                    first_stage_fraction=128 / 1088, first_bed_fraction=0.02, layers=1.5,
                    stream_packing=0.05)
    default_size = 1088
    min_size = 4
    size_unit = "spheres"

    def prepare(self, p, size, rng):
        W = p["width"]
        if 2 * p["radius_max"] >= W:
            raise SceneError("Chute: width must exceed the largest diameter")
        n_bed = max(2, int(round(size * p["bed_fraction"])))
        radii = rng.uniform(p["radius_min"], p["radius_max"], n_bed)
        stream_radii = rng.uniform(p["radius_min"], p["radius_max"], size)
        # Floor area for 'layers' layers of the full bed at ~65 % areal coverage per layer.
        length = max(4 * p["radius_max"], np.pi * np.sum(radii ** 2) / (0.65 * p["layers"] * W))

        def drop_xy(g, R):
            return g.uniform(0.0, length), g.uniform(-W / 2 + R, W / 2 - R)

        planes_n = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]
        planes_o = [0.0, -W / 2, -W / 2]
        dep = deposit_spheres(radii, rng, drop_xy, planes_n, planes_o)
        if dep.centers.shape[0] < n_bed:
            raise SceneError(f"Chute: only {dep.centers.shape[0]} of {n_bed} bed spheres deposited")
        return {"deposit": dep, "stream_radii": stream_radii, "length": length}

    def stage(self, base, p, size, phi, rng):
        dep, L, W = base["deposit"], base["length"], p["width"]
        nb = max(2, min(size, _stage_count(p["first_stage_fraction"] * size, size, phi)))
        frac = p["first_bed_fraction"] + phi * (p["bed_fraction"] - p["first_bed_fraction"])
        n_bed = int(min(dep.centers.shape[0], max(2, round(nb * frac)), nb))
        n_str = nb - n_bed
        U = p["flow_speed"]
        bed = Bodies.make(dep.radii[:n_bed], 0.0, p["density"], dep.centers[:n_bed])
        z = bed.pos[:, 2] - bed.radius
        H = max(float(z.max()), 1e-12)
        vx = U * (0.5 + 0.5 * z / H)
        bed.vel = np.stack((vx, np.zeros(n_bed), np.zeros(n_bed)), axis=1) \
            + U * np.array([0.05, 0.05, 0.02]) * rng.normal(size=(n_bed, 3))
        roll = rng.uniform(0.0, 1.0, n_bed)  # fraction of rolling without slip on the floor
        bed.omega = np.stack((np.zeros(n_bed), roll * vx / bed.radius, np.zeros(n_bed)), axis=1) \
            + 0.1 * U / bed.radius[:, None] * rng.normal(size=(n_bed, 3))
        parts = [bed]
        if n_str:
            rs = base["stream_radii"][:n_str]
            top = float(np.max(bed.pos[:, 2] + bed.radius))
            Hs = max(4 * p["radius_max"],
                     np.sum(4.0 / 3.0 * np.pi * rs ** 3) / (p["stream_packing"] * L * W))
            cs = place_random(rs, (0.0, -W / 2, 0.0), (L, W / 2, top + Hs), rng,
                              existing=bed.pos, existing_radii=bed.radius)
            st = Bodies.make(rs, 0.0, p["density"], cs)
            st.vel = U * (np.array([1.0, 0.0, -0.3]) + 0.1 * rng.normal(size=(n_str, 3)))
            st.omega = 0.3 * U / rs[:, None] * rng.normal(size=(n_str, 3))
            parts.append(st)
        bodies = Bodies.concatenate(parts)
        statics = Statics.make(planes=[((0, 0, 1), 0.0, 0), ((0, 1, 0), -W / 2, 0), ((0, -1, 0), -W / 2, 0)])
        a = math.radians(p["incline"])
        gravity = G * np.array([math.sin(a), 0.0, -math.cos(a)])
        return World(bodies=bodies, statics=statics, gravity=gravity, h=p["h"], margin=p["margin"],
                     mu_table=_table(p["mu"]), mu_r_table=_table(p["mu_r"]),
                     notes={"bodies": nb, "landed": n_bed, "in_flight": n_str,
                            "chute_length": L, "deposited_discarded": dep.discarded})


# ---------------------------------------------------------------------- primitive soup
class PrimitiveSoup(Scene):
    name = "PrimitiveSoup"
    summary = ("about 1000 bodies of mixed shapes and sizes (spheres of 3 radii, capsules of 2 "
               "radii and random lengths) poured into a square container (FCLIB PrimitiveSoup: "
               "m = 6000, h = 5e-4 s, mu = 0.7); all bodies present, the landed fraction grows")
    configuration = ("Visscher-Bolsterli deposition of the bodies' bounding spheres into the "
                     "container, each body placed in its sphere with a random orientation, then "
                     "every body lowered straight down, bottom-up, until it touches a body or the "
                     "floor (exact); stage = the lowest fraction of that packing at rest, the "
                     "other bodies raining from above at random positions")
    defaults = dict(capsule_fraction=0.5, density=1000.0, h=5e-4, mu=0.7, mu_r=1e-3,
                    margin=2e-3, first_bed_fraction=0.01, rain_speed=1.0, rain_packing=0.05)
    default_size = 1000
    min_size = 2
    SPHERE_RADII = (0.01, 0.015, 0.02)
    CAPSULE_RADII = (0.008, 0.012)

    def prepare(self, p, size, rng):
        cap = rng.random(size) < p["capsule_fraction"]
        r = np.where(cap, rng.choice(self.CAPSULE_RADII, size), rng.choice(self.SPHERE_RADII, size))
        hl = np.where(cap, rng.uniform(0.5, 1.5, size) * r, 0.0)
        vol = np.sum(4.0 / 3.0 * np.pi * r ** 3 + 2 * np.pi * r ** 2 * hl)
        S = max((vol / 0.55) ** (1.0 / 3.0), 2.5 * float(np.max(r + hl)))
        Rb = r + hl
        planes = [((0, 0, 1), 0.0, 0), ((1, 0, 0), 0.0, 0), ((-1, 0, 0), -S, 0),
                  ((0, 1, 0), 0.0, 0), ((0, -1, 0), -S, 0)]
        statics = Statics.make(planes=planes)
        dep = deposit_spheres(Rb, rng, lambda g, R: tuple(g.uniform(R, S - R, 2)),
                              statics.plane_normal, statics.plane_offset)
        if dep.centers.shape[0] < size:
            raise SceneError(f"PrimitiveSoup: only {dep.centers.shape[0]} of {size} bodies deposited")
        src = dep.source
        bodies = Bodies.make(r[src], hl[src], p["density"], dep.centers,
                             random_quaternions(rng, size))
        collapse = collapse_downwards(bodies)
        return {"bodies": bodies, "statics": statics, "side": S, "collapse": collapse}

    def stage(self, base, p, size, phi, rng):
        settled, S = base["bodies"], base["side"]
        frac = p["first_bed_fraction"] + phi * (1.0 - p["first_bed_fraction"])
        n_bed = int(min(size, max(1, round(size * frac))))
        top = settled.pos[:, 2] + settled.bounding_radius
        order = np.argsort(top, kind="stable")
        bed = settled.subset(np.sort(order[:n_bed]))
        parts = [bed]
        n_rain = size - n_bed
        if n_rain:
            rain = settled.subset(np.sort(order[n_bed:]))
            bed_top = float(np.max(bed.pos[:, 2] + bed.bounding_radius))
            vol = np.sum(4.0 / 3.0 * np.pi * rain.radius ** 3 + 2 * np.pi * rain.radius ** 2 * rain.half_length)
            Hr = vol / (p["rain_packing"] * S * S) + 2 * float(rain.bounding_radius.max())
            rain.pos = place_bodies_random(rain, (0.0, 0.0, bed_top - 2 * float(rain.bounding_radius.max())),
                                           (S, S, bed_top + Hr), rng, existing=bed)
            v = p["rain_speed"]
            rain.vel = v * (np.array([0.0, 0.0, -1.0]) + 0.2 * rng.normal(size=(n_rain, 3)))
            rain.omega = 0.5 * v / rain.bounding_radius[:, None] * rng.normal(size=(n_rain, 3))
            parts.append(rain)
        bodies = Bodies.concatenate(parts)
        col = base["collapse"]
        return World(bodies=bodies, statics=base["statics"], gravity=np.array([0.0, 0.0, -G]),
                     h=p["h"], margin=p["margin"], mu_table=_table(p["mu"]),
                     mu_r_table=_table(p["mu_r"]),
                     notes={"bodies": size, "settled": n_bed, "raining": n_rain,
                            "capsules": int(np.sum(bodies.half_length > 0)), "container_side": S,
                            "collapse": {"mean_drop": col.mean_drop, "max_drop": col.max_drop,
                                         "resting_on_bodies": col.on_bodies,
                                         "resting_on_floor": col.on_floor}})


# ---------------------------------------------------------------------- elastic block (FE)
class ElasticBlock(Scene):
    name = "ElasticBlock"
    summary = ("finite-element scene: a linear-elastic steel block (linear tetrahedra, 3 dofs "
               "per node, consistent mass) resting with zero gap on a rigid support, one "
               "contact per bottom node, w = 0, mu_r = 0; M = M_mass + h^2 K is sparse, "
               "non-diagonal, SPD; every contact sticks (u = 0, v = the clamped solve)")
    configuration = ("block of size x round(size*width_ratio) x round(size*height_ratio) cubic "
                     "cells of edge 'cell', Kuhn subdivision into 6 tetrahedra per cell, nodes "
                     "jittered by up to jitter*cell (bottom nodes stay on z = 0); tangent frames "
                     "rotated about the normal at random; starts at rest, stress-free, when "
                     "gravity is switched on; Moreau-Jean steps with the clamped solution "
                     "(checked strictly inside every friction cone); stage K dumps step "
                     "(K+1)*steps of the run")
    defaults = dict(cell=0.25, density=7850.0, young=2.1e11, poisson=0.3, h=1e-3, mu=1.0,
                    jitter=0.1, width_ratio=0.5, height_ratio=0.25)
    default_size = 8
    min_size = 1
    size_unit = "cells along the length"
    finite_element = True
    """Generated by :func:`rfverify.scenes.generate` through :class:`.fem.ElasticMoreauJean`,
    not the rigid-body :class:`World` / :class:`MoreauJean` path."""

    def cells(self, p, size) -> tuple[int, int, int]:
        """(nx, ny, nz) cells of the block at ``size`` cells along the length."""
        def rnd(x):
            return max(1, int(math.floor(x + 0.5)))
        return int(size), rnd(size * p["width_ratio"]), rnd(size * p["height_ratio"])

    def prepare(self, p, size, rng):
        from .fem import block_mesh, lame, mass_matrix, stiffness_matrix, support_contact_matrix

        for k in ("cell", "density", "young", "width_ratio", "height_ratio"):
            if not p[k] > 0:
                raise SceneError(f"{self.name}: parameter {k} = {p[k]!r} must be > 0")
        if not p["mu"] >= 0:
            raise SceneError(f"{self.name}: parameter mu = {p['mu']!r} must be >= 0")
        if not 0 <= p["jitter"] <= 0.25:
            raise SceneError(f"{self.name}: parameter jitter = {p['jitter']!r} must be in "
                             "[0, 0.25] (a fraction of the cell edge)")
        lame(p["young"], p["poisson"])  # checks the material
        nx, ny, nz = self.cells(p, size)
        mesh = block_mesh(nx, ny, nz, p["cell"], p["jitter"], rng)
        angles = rng.uniform(0.0, 2 * math.pi, mesh.bottom.size)
        H, frames = support_contact_matrix(mesh, angles)
        return {"mesh": mesh, "M_mass": mass_matrix(mesh, p["density"]),
                "K": stiffness_matrix(mesh, p["young"], p["poisson"]), "H": H, "frames": frames}

    def stepper(self, base, p):
        """A fresh :class:`.fem.ElasticMoreauJean` run from rest (q = 0, v = 0)."""
        from .fem import ElasticMoreauJean

        return ElasticMoreauJean(base["mesh"], base["M_mass"], base["K"], base["H"],
                                 base["frames"], gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                                 mu=p["mu"])


# ---------------------------------------------------------------------- registry
SCENES: dict[str, Scene] = {s.name: s for s in (
    SpheresPile(), Chute(), PrimitiveSoup(), MassRatio(), RollingExtremes(), Frictionless(),
    Lattice(), AllOpen(), AllSticking(), Millimetre(), GranularBed())}
"""All rigid-body scenes by name (the FCLIB-like ones first, then the stiff and extreme
families, then the large GranularBed): 6 dofs per body, block-diagonal M, stepped by
:class:`.stepper.MoreauJean` (GranularBed, ``step_free``: only its first step's problem is built,
with no solve)."""

FE_SCENES: dict[str, Scene] = {s.name: s for s in (ElasticBlock(),)}
"""Finite-element scenes by name: 3 dofs per node, non-diagonal M (assembled iteration
matrix), stepped by :class:`.fem.ElasticMoreauJean`.  Kept apart from :data:`SCENES`, whose
users (and tests) rely on rigid-body structure."""

ALL_SCENES: dict[str, Scene] = {**SCENES, **FE_SCENES}
"""Every scene :func:`rfverify.scenes.generate` can make (rigid-body, then finite-element)."""

ALIASES = {"spherepile": "SpheresPile", "spherespile": "SpheresPile", "soup": "PrimitiveSoup",
           "millimeter": "Millimetre"}


def resolve_scene(name: str) -> Scene:
    """The scene called ``name`` (case-insensitive; a few aliases); SceneError otherwise."""
    if isinstance(name, Scene):
        return name
    key = str(name).strip()
    table = {k.lower(): v for k, v in ALL_SCENES.items()}
    low = ALIASES.get(key.lower(), key).lower()
    if low not in table:
        raise SceneError(f"unknown scene {name!r}; scenes: {', '.join(ALL_SCENES)}")
    return table[low]
