"""The scenes of the FCLIB rolling-friction collections, made the way FCLIB made them
(DESIGN §8): SpheresPile (spheres of one diameter dropped one by one on a ground box), Chute
(spheres of mixed radii flowing down an inclined channel) and PrimitiveSoup (spheres and
capsules of mixed sizes poured into a container).  SpheresPile is also the base of the stiff
and extreme families (:mod:`.extreme`).
"""

from __future__ import annotations

import math

import numpy as np

from .deposition import collapse_downwards, deposit_spheres, place_bodies_random, place_random
from .geometry import Bodies, Statics, random_quaternions
from .scene import G, Scene, World, coefficient_table, stage_count
from .stepper import SceneError


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
                             f"box_half_width = {a:g}; fix: a larger --param box_half_width or a smaller "
                             "--param drop_radius")

        def drop_xy(g, R):
            rr = R_drop * math.sqrt(g.uniform())
            th = g.uniform(0.0, 2 * math.pi)
            return rr * math.cos(th), rr * math.sin(th)

        dep = deposit_spheres(np.full(size, d / 2), rng, drop_xy, [[0.0, 0.0, 1.0]], [0.0],
                              footprint=(-a, a, -a, a))
        if dep.centers.shape[0] < size:
            raise SceneError(f"{self.name}: only {dep.centers.shape[0]} of {size} spheres could "
                             f"be deposited on the box; fix: a larger --param box_half_width")
        materials = self.materials(rng, size)
        return {"deposit": dep, "materials": materials}

    def materials(self, rng, size):
        if self.n_materials == 1:
            return np.zeros(size, dtype=np.int64)
        return rng.integers(0, self.n_materials, size)

    def densities(self, p, nb, base):
        return np.full(nb, p["density"])

    def tables(self, p):
        return coefficient_table(p["mu"]), coefficient_table(p["mu_r"])

    def ground_material(self):
        """The ground is made of the last material (the only one of a one-material pile)."""
        return self.n_materials - 1

    def stage(self, base, p, size, phi, rng):
        dep = base["deposit"]
        nb = max(1, min(size, stage_count(min(p["first_stage_bodies"], size), size, phi)))
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
            raise SceneError("Chute: width must exceed the largest diameter; fix: a larger --param width or a "
                             "smaller --param radius_max")
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
            raise SceneError(f"Chute: only {dep.centers.shape[0]} of {n_bed} bed spheres deposited; fix: a smaller "
                             "--param bed_fraction or a larger --param width")
        return {"deposit": dep, "stream_radii": stream_radii, "length": length}

    def stage(self, base, p, size, phi, rng):
        dep, L, W = base["deposit"], base["length"], p["width"]
        nb = max(2, min(size, stage_count(p["first_stage_fraction"] * size, size, phi)))
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
                     mu_table=coefficient_table(p["mu"]), mu_r_table=coefficient_table(p["mu_r"]),
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
            raise SceneError(f"PrimitiveSoup: only {dep.centers.shape[0]} of {size} bodies deposited; fix: a "
                             "smaller --size or another --seed")
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
                     h=p["h"], margin=p["margin"], mu_table=coefficient_table(p["mu"]),
                     mu_r_table=coefficient_table(p["mu_r"]),
                     notes={"bodies": size, "settled": n_bed, "raining": n_rain,
                            "capsules": int(np.sum(bodies.half_length > 0)), "container_side": S,
                            "collapse": {"mean_drop": col.mean_drop, "max_drop": col.max_drop,
                                         "resting_on_bodies": col.on_bodies,
                                         "resting_on_floor": col.on_floor}})
