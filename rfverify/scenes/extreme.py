"""The stiff and extreme scene families, each stressing one property of the contact problem:
a mass ratio (MassRatio), rolling resistance from 0 to 1 m (RollingExtremes), no friction
(Frictionless), every contact sticking (AllSticking), badly scaled units (Millimetre),
redundant contacts (Lattice), every contact open (AllOpen), and size — 1e4 to 1e5 contacts
built without any solve (GranularBed).  The piles among them are :class:`.published.SpheresPile`
variants.
"""

from __future__ import annotations

import math

import numpy as np

from .deposition import fcc_positions, open_cluster
from .geometry import Bodies, Statics, quat_to_matrix, random_quaternions
from .scene import G, Scene, World, coefficient_table, min_rule_table, stage_count
from .stepper import SceneError
from .published import SpheresPile


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
        return coefficient_table(p["mu"], self.n_materials), min_rule_table(self.MU_R_LEVELS)


class Frictionless(SpheresPile):
    name = "Frictionless"
    summary = ("pile with mu = 0 at every contact; mu_r = 0 for material 0 and mu_r for "
               "material 1 (the ground is material 1)")
    defaults = {k: v for k, v in SpheresPile.defaults.items() if k != "mu"}
    default_size = 60
    n_materials = 2

    def tables(self, p):
        return coefficient_table(0.0, self.n_materials), min_rule_table((0.0, p["mu_r"]))


class AllSticking(SpheresPile):
    name = "AllSticking"
    summary = ("pile at rest on a ground tilted by 'tilt' degrees, with friction and rolling "
               "resistance large enough that every contact sticks (v* ≈ 0, not exactly: a touching contact's "
               "round-off gap makes w_N = gap/h > 0, and v* of that size, about 1e-12 m/s); only "
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
        nb = max(1, min(size, stage_count(min(nx * nx, size), size, phi)))
        d = p["diameter"]
        bodies = Bodies.make(np.full(nb, d / 2), 0.0, p["density"], base["pos"][:nb])
        L = nx * d
        statics = Statics.make(planes=[((0, 0, 1), 0.0, 0), ((1, 0, 0), 0.0, 0), ((-1, 0, 0), -L, 0),
                                       ((0, 1, 0), 0.0, 0), ((0, -1, 0), -L, 0)])
        return World(bodies=bodies, statics=statics, gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                     margin=p["margin"], mu_table=coefficient_table(p["mu"]), mu_r_table=coefficient_table(p["mu_r"]),
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
                     "at the first stage); orientation 1: the whole bed (lattice, ground plane and "
                     "gravity) turned by a uniformly random 3-D rotation, so that contact normals "
                     "and tangent frames are generic (H has 3-6 nonzeros per column instead of "
                     "1-2; the physics is that of orientation 0); the dumped problem is the first "
                     "step's, so 'steps' is not used")
    defaults = dict(diameter=0.02, density=1300.0, h=1e-3, mu=0.3, mu_r=1e-3, margin=1e-3,
                    packing=0.0, width=0.0, gap_jitter=1e-3, agitation=0.01, tilt=0.0,
                    orientation=0.0)
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
                             "cubic) or 1 (FCC); fix: give --param packing=0 or 1")
        if not 0 <= p["gap_jitter"] < 0.1:
            raise SceneError(f"{self.name}: parameter gap_jitter = {p['gap_jitter']!r} must be in "
                             "[0, 0.1) (a fraction of the diameter); fix: give e.g. --param gap_jitter=0.001 "
                             "(the default), or 0 for touching contacts")
        # Lattice neighbours must all be contacts, second neighbours (at sqrt(2) d) none.
        if not p["gap_jitter"] * d <= p["margin"] < (math.sqrt(2.0) - 1.0) * d:
            raise SceneError(f"{self.name}: margin = {p['margin']:g} must be at least gap_jitter * "
                             f"diameter = {p['gap_jitter'] * d:g} and below (sqrt(2) - 1) * diameter = "
                             f"{(math.sqrt(2.0) - 1.0) * d:g}; fix: a --param margin=VALUE between them")
        for k in ("diameter", "density"):
            if not p[k] > 0:
                raise SceneError(f"{self.name}: parameter {k} = {p[k]!r} must be > 0; fix: give --param {k}=VALUE > 0")
        if not p["agitation"] >= 0:
            raise SceneError(f"{self.name}: parameter agitation = {p['agitation']!r} must be >= 0; fix: give "
                             "--param agitation=VALUE >= 0")
        if p["orientation"] not in (0.0, 1.0):
            raise SceneError(f"{self.name}: parameter orientation = {p['orientation']!r} must be 0 "
                             "(lattice axes: vertical and horizontal contact normals) or 1 (the bed "
                             "turned by a random 3-D rotation: generic contact frames); fix: give --param "
                             "orientation=0 or 1")

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
        base = {"pos": pos, "radii": radii, "angle": angle, "nx": self.layer_width(p, size),
                "vel": rng.normal(size=(size, 3)), "omega": rng.normal(size=(size, 3)),
                "turn": np.eye(3)}
        if p["orientation"] == 1:  # drawn last: orientation 0 keeps its arrays bit for bit
            base["turn"] = quat_to_matrix(random_quaternions(rng, 1))[0]
        return base

    def stage(self, base, p, size, phi, rng):
        nx = base["nx"]
        nb = max(1, min(size, stage_count(min(nx * nx, size), size, phi)))
        r = base["radii"][:nb]
        bodies = Bodies.make(r, 0.0, p["density"], base["pos"][:nb])
        bodies.vel = p["agitation"] * base["vel"][:nb]
        bodies.omega = p["agitation"] / r[:, None] * base["omega"][:nb]
        tilt = math.radians(p["tilt"])
        gravity = G * np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
        Q = base["turn"]  # rows of positions turn as x -> Q x
        if p["orientation"] == 1:
            bodies.pos, bodies.vel, bodies.omega = bodies.pos @ Q.T, bodies.vel @ Q.T, bodies.omega @ Q.T
            gravity = Q @ gravity
        return World(bodies=bodies, statics=Statics.make(planes=[(tuple(Q[:, 2]), 0.0, 0)]), gravity=gravity,
                     h=p["h"], margin=p["margin"], mu_table=coefficient_table(p["mu"]),
                     mu_r_table=coefficient_table(p["mu_r"]),
                     notes={"bodies": nb, "layer_width": nx, "packing": "fcc" if p["packing"] == 1 else "cubic",
                            "rotation_deg": math.degrees(base["angle"]),
                            **({"turned_vertical": [float(x) for x in Q[:, 2]]} if p["orientation"] == 1 else {})})


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
            raise SceneError("AllOpen: need 0 < gap_lo < gap_hi < 1 (fractions of the margin); fix: give e.g. "
                             "--param gap_lo=0.25 --param gap_hi=0.85 (the defaults)")
        radii = rng.uniform(p["radius_min"], p["radius_max"], size)
        m = p["margin"]
        return {"radii": radii, "pos": open_cluster(radii, rng, p["gap_lo"] * m, p["gap_hi"] * m)}

    def stage(self, base, p, size, phi, rng):
        nb = max(2, min(size, stage_count(2, size, phi)))
        pos = base["pos"][:nb]
        b = Bodies.make(base["radii"][:nb], 0.0, p["density"], pos)
        b.vel = p["expansion"] * (pos - pos.mean(axis=0)) + p["speed_noise"] * rng.normal(size=(nb, 3))
        b.omega = p["spin"] * rng.normal(size=(nb, 3))
        return World(bodies=b, statics=Statics(), gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                     margin=p["margin"], mu_table=coefficient_table(p["mu"]), mu_r_table=coefficient_table(p["mu_r"]),
                     notes={"bodies": nb})
