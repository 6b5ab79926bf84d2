"""Rigid-body scenes whose Moreau–Jean one-step problems form FCLIB-like collections.

The FCLIB rolling-friction collections (Chute, SpheresPile, PrimitiveSoup) cannot be
downloaded here, so rfverify makes its own the way FCLIB was made: a velocity-level time
stepping of rigid bodies whose one-step problems are dumped along the run (DESIGN §8).  A full
simulation would be far too slow on two cores, so each scene builds its configurations by a
fast geometric method (:mod:`.deposition`) and takes only a few Moreau–Jean steps
(:mod:`.stepper`) from each of them.

Python API::

    from rfverify.scenes import SCENES, generate, save_collection, contact_state_mix
    problems = generate("SpheresPile", count=3, seed=1, size=20)   # list[Problem]
    paths = save_collection(problems, "out/")                      # FCLIB HDF5 files

CLI: ``rfverify generate SCENE --count N --seed S --out DIR [--size K]``.

One finite-element scene (:data:`FE_SCENES`: ElasticBlock, :mod:`.fem`) sits beside the
rigid-body ones: a linear-elastic block on a rigid support, 3 dofs per node, M an assembled
iteration matrix, every contact sticking with w = 0 and a solution known exactly (stored in
the file's ``/solution``).  :data:`ALL_SCENES` holds both kinds.

Conventions (FCLIB, DESIGN §1): 6 dofs per body (velocity and angular velocity in the world
frame), M = diag(m·I3, R I_body Rᵀ) per body, u = Hᵀ v + w with u_i = (N, T1, T2, R1, R2),
N from body B to body A, (u_N, u_T) = Fᵀ(v_A + ω_A×ρ_A − v_B − ω_B×ρ_B),
u_R = (T1, T2)ᵀ(ω_A − ω_B); static obstacles have no dofs; w_N = max(gap, 0)/h.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from .analysis import StateMix, contact_state_mix, contacts_per_body, free_velocity, h_structure
from .assembly import contact_matrix, mass_matrix, relative_velocity
from .geometry import Bodies, Contacts, Statics, detect_contacts
from .library import ALIASES, ALL_SCENES, FE_SCENES, SCENES, resolve_scene
from .scene import Scene, World
from .stepper import STEP_SOLVER_SETTINGS, MoreauJean, SceneError, StepRecord
from ..model.problem import Problem

GENERATOR_VERSION = "2"
"""Bumped whenever the same (scene, seed, options) would give different arrays."""

DEFAULT_STEPS = 3
"""Moreau–Jean steps taken from each stage configuration; the last one is dumped."""

__all__ = ["SCENES", "FE_SCENES", "ALL_SCENES", "Scene", "World", "generate", "save_collection",
           "fclib_name",
           "contact_state_mix", "StateMix", "h_structure", "contacts_per_body", "free_velocity",
           "MoreauJean", "StepRecord", "SceneError", "Bodies", "Statics", "Contacts",
           "detect_contacts", "mass_matrix", "contact_matrix", "relative_velocity",
           "resolve_scene", "scene_parameters", "GENERATOR_VERSION", "DEFAULT_STEPS"]


PARAMETER_DOMAINS = {
    **{k: ("> 0", lambda x: x > 0) for k in (
        "diameter", "density", "h", "margin", "radius_min", "radius_max", "drop_radius", "box_half_width",
        "box_depth", "fall_height", "flow_speed", "rain_speed", "layers", "cell", "young", "expansion",
        "width_ratio", "height_ratio")},
    **{k: ("≥ 0", lambda x: x >= 0) for k in ("mu", "mu_r", "agitation", "speed_noise", "spin", "gap_jitter")},
    **{k: ("in [0, 1]", lambda x: 0 <= x <= 1) for k in (
        "recent_fraction", "capsule_fraction", "bed_fraction", "first_stage_fraction", "first_bed_fraction",
        "jitter")},
    # (a stream's length goes as 1/packing: 0 overflowed)
    **{k: ("in [0.001, 1]", lambda x: 1e-3 <= x <= 1) for k in ("stream_packing", "rain_packing")},
    "tilt": ("in [0, 90) degrees", lambda x: 0 <= x < 90),
    "incline": ("in (0, 90) degrees", lambda x: 0 < x < 90),
    "mass_ratio": ("≥ 1", lambda x: x >= 1),
    "first_stage_bodies": ("a whole number ≥ 1", lambda x: x >= 1 and float(x).is_integer()),
    "width": ("a whole number ≥ 0 (0: the scene's own choice)", lambda x: x >= 0 and float(x).is_integer()),
}
"""What each scene parameter may be (where a value outside would be silently clamped, truncated or
turn the scene upside down); the scenes check the rest (packing, orientation, gap_lo < gap_hi,
the elastic constants) themselves.  :data:`SCENE_DOMAINS` overrides a name one scene uses
otherwise."""

SCENE_DOMAINS = {"Chute": {"width": ("> 0 (the channel's width, m)", lambda x: x > 0)}}

MAX_COUNT = 10_000
"""Most problems one :func:`generate` call makes (they are kept in memory until written)."""


def scene_parameters(scene, size=None, **params) -> tuple[Scene, dict, int]:
    """(scene, parameters, size) after applying overrides to the scene's defaults.

    Raises SceneError for an unknown scene, an unknown parameter name, a non-finite value or
    a size below the scene's minimum.
    """
    sc = resolve_scene(scene)
    unknown = sorted(set(params) - set(sc.defaults))
    if unknown:
        raise SceneError(f"{sc.name}: unknown parameter(s) {', '.join(unknown)}; parameters: "
                         f"{', '.join(sorted(sc.defaults))}; fix: use one of those names (rfverify generate --list "
                         "gives each scene's parameters and defaults)")
    p = dict(sc.defaults)
    for k, val in params.items():
        try:
            val = float(val)
        except (TypeError, ValueError):
            raise SceneError(f"{sc.name}: parameter {k} = {val!r} is not a number; fix: give --param {k}=NUMBER "
                             f"(default {sc.defaults[k]:g})") from None
        if not math.isfinite(val):
            raise SceneError(f"{sc.name}: parameter {k} = {val!r} must be finite; fix: give a finite number "
                             f"(default {sc.defaults[k]:g})")
        domain = SCENE_DOMAINS.get(sc.name, {}).get(k, PARAMETER_DOMAINS.get(k))
        if domain is not None and not domain[1](val):
            raise SceneError(f"{sc.name}: parameter {k} = {val:g} must be {domain[0]}; fix: give --param "
                             f"{k}=VALUE with VALUE {domain[0]} (default {sc.defaults[k]:g})")
        p[k] = val
    if "radius_min" in p and "radius_max" in p and p["radius_min"] > p["radius_max"]:
        raise SceneError(f"{sc.name}: radius_min = {p['radius_min']:g} is above radius_max = {p['radius_max']:g}; "
                         "fix: give --param radius_min=A --param radius_max=B with A ≤ B")
    for k in ("h", "margin"):
        if k in p and not p[k] > 0:
            raise SceneError(f"{sc.name}: parameter {k} = {p[k]!r} must be > 0; fix: give --param {k}=VALUE > 0")
    size = sc.default_size if size is None else int(size)
    if size < sc.min_size:
        raise SceneError(f"{sc.name}: size {size} is below the minimum of {sc.min_size} {sc.size_unit}; fix: give "
                         f"--size {sc.min_size} or more")
    if params.get("first_stage_bodies") is not None and p["first_stage_bodies"] > size:  # (clamped, recorded as given)
        raise SceneError(f"{sc.name}: parameter first_stage_bodies = {p['first_stage_bodies']:g} is more than the "
                         f"size, {size} {sc.size_unit}; fix: give --param first_stage_bodies={min(size, 4)} or a "
                         "larger --size")
    return sc, p, size


def generate(scene, count: int = 1, seed: int = 0, size: int | None = None, *,
             steps: int = DEFAULT_STEPS, method: str = "jqinv", tol: float = 1e-10,
             max_iter: int = 100, progress=None, **params) -> list:
    """Generate ``count`` one-step problems of ``scene`` (a name from :data:`SCENES`).

    Parameters
    ----------
    scene : str
        Scene name (case-insensitive), e.g. ``"SpheresPile"``.
    count : int
        Problems in the trace.  Problem K (0-based) comes from stage φ = K/(count−1) of the
        run (φ = 1 when count = 1): for growing scenes the bodies present grow from the
        scene's first-stage size to ``size``.
    seed : int
        Seeds a ``numpy.random.SeedSequence``: one child for the base configuration, one per
        stage.  The same (scene, count, seed, size, steps, params) gives identical arrays.
    size : int, optional
        Bodies at the last stage (default: the scene's published size, e.g. 250 spheres).
    steps : int
        Moreau–Jean steps per stage; the problem of the last one is returned (if it has no
        contact the run goes on, up to 10·steps more steps).
    method, tol, max_iter
        Solver of the stepping (:func:`rfverify.solve`).  A step whose solve does not reach
        ``tol`` advances with the solver's best iterate; this is recorded in the problem's
        description and ``provenance["solves"]``.  Finite-element scenes (ElasticBlock) do
        not use them: their steps are solved exactly by a clamped direct solve
        (:class:`.fem.ElasticMoreauJean`), stage K dumps step (K+1)·steps of one run, and the
        problems carry that solution as ``/solution``.
    progress : callable(fraction, text), optional
        Called as the work advances (for a progress bar).
    **params
        Overrides of the scene's numeric parameters (``SCENES[name].defaults``).

    Returns
    -------
    list of Problem
        title = scene name; description = human-readable scene, parameters, seed, stage and
        step, generator version; ``provenance`` holds the same as a dict plus the sizes.
    """
    sc, p, size = scene_parameters(scene, size, **params)
    try:
        return _generate(sc, p, size, count, seed, steps, method, tol, max_iter, progress)
    except SceneError:
        raise
    except (ArithmeticError, ValueError, np.linalg.LinAlgError, RuntimeError) as exc:
        if not params:  # the scene's own defaults: a bug, not the user's choice
            raise
        given = ", ".join(f"{k}={v}" for k, v in params.items())
        raise SceneError(f"{sc.name}: the parameters given ({given}) build no scene: {type(exc).__name__}: {exc}; "
                         "fix: choose values nearer the defaults (rfverify generate --list)") from exc


def _generate(sc, p, size, count, seed, steps, method, tol, max_iter, progress) -> list:
    if int(count) < 1:
        raise SceneError(f"count = {count!r} must be ≥ 1; fix: give --count 1 or more")
    if int(count) > MAX_COUNT:  # (a billion allocated its seeds before the first problem, 1.2 GB in 15 s)
        raise SceneError(f"count = {count!r}: at most {MAX_COUNT} problems a run (each is simulated and kept "
                         f"until written); fix: run generate several times with different --seed values")
    if int(steps) < 1:
        raise SceneError(f"steps = {steps!r} must be ≥ 1; fix: give --steps 1 or more")
    count, steps = int(count), int(steps)
    children = np.random.SeedSequence(int(seed)).spawn(count + 1)
    say = progress or (lambda frac, text: None)
    if getattr(sc, "finite_element", False):
        return _generate_finite_element(sc, p, size, count, int(seed), steps, children, say)
    if getattr(sc, "step_free", False):
        return _generate_step_free(sc, p, size, count, int(seed), children, say)
    say(0.0, f"{sc.name}: base configuration")
    t_base, worlds = _stage_worlds(sc, p, size, count, children)
    out = []
    for K, phi, t1, world in worlds:
        stepper = _stepper(world, method=method, tol=tol, max_iter=max_iter)
        records = []
        dumped = None
        limit = steps + 10 * steps
        while dumped is None and len(records) < limit:
            k = len(records)
            rec = stepper.step(keep_problem=k >= steps - 1)
            records.append(rec)
            if rec.problem is not None:
                dumped = rec
            say((K + len(records) / (steps + 1)) / count,
                f"{sc.name} {K + 1}/{count}: step {len(records)}, {rec.n_contacts} contacts")
        if dumped is None:
            raise SceneError(f"{sc.name} stage {K} (phi = {phi:.3f}): no contact in "
                             f"{len(records)} steps; nothing to dump; fix: a larger --size, more --steps or "
                             "another --seed")
        t_stage = time.perf_counter() - t1
        solves = [{"step": r.step, "contacts": r.n_contacts, "status": r.status,
                   "iterations": r.nit, "solves": r.desaxce_solves, "time": round(r.solve_time, 4),
                   **({"message": r.message} if not r.success else {})} for r in records]
        prov = _provenance(
            sc, int(seed), count, K, phi, size,
            steps=steps, dumped_step=dumped.step, time=dumped.time,
            parameters=p, units=sc.units, notes=world.notes,
            solver={"method": method, "tol": tol, "max_iter": max_iter, **STEP_SOLVER_SETTINGS},
            solves=solves, failed_solves=sum(not r.success for r in records),
            timing={"base_configuration": round(t_base, 3),
                    "stage_without_solves": round(t_stage - sum(r.solve_time for r in records), 3),
                    "solves": round(sum(r.solve_time for r in records), 3)},
        )
        raw = dumped.problem
        arrays = sc.convert({k: getattr(raw, k) for k in ("M", "H", "f", "w", "mu", "mu_r")})
        problem = Problem.from_arrays(**arrays, title=sc.name, provenance=prov)
        problem = replace(problem, description=_description(sc, prov, problem))
        out.append(problem)
    say(1.0, f"{sc.name}: done")
    return out


def _stage_worlds(sc: Scene, p: dict, size: int, count: int, children):
    """The base configuration, built once from the first child seed, and its build time; then,
    lazily, per stage K: (K, φ = K/(count−1) (1 when count = 1), the time the stage began, its
    world, built from child seed K + 1)."""
    t0 = time.perf_counter()
    base = sc.prepare(p, size, np.random.default_rng(children[0]))
    t_base = time.perf_counter() - t0

    def worlds():
        for K in range(count):
            phi = K / (count - 1) if count > 1 else 1.0
            t1 = time.perf_counter()
            yield K, phi, t1, sc.stage(base, p, size, phi, np.random.default_rng(children[K + 1]))

    return t_base, worlds()


def _stepper(world: World, **solver) -> MoreauJean:
    """A Moreau–Jean run from ``world`` (``solver``: method, tol, max_iter of its step solves)."""
    return MoreauJean(world.bodies, world.statics, h=world.h, gravity=world.gravity, margin=world.margin,
                      mu_table=world.mu_table, mu_r_table=world.mu_r_table, **solver)


def _provenance(sc: Scene, seed: int, count: int, K: int, phi: float, size: int, **rest) -> dict:
    """A generated problem's ``provenance``: generator, versions, scene, seed and stage, then ``rest``."""
    from .._version import __version__

    return {"generator": "rfverify.scenes", "generator_version": GENERATOR_VERSION,
            "rfverify_version": __version__, "scene": sc.name, "seed": seed,
            "count": count, "trace_index": K, "stage": phi, "size": size, **rest}


def _header_lines(sc: Scene, p: dict) -> list[str]:
    """The first lines of every generated problem's description: generator, scene, seed, stage."""
    return [
        f"rfverify.scenes {sc.name} (generator version {p['generator_version']}, "
        f"rfverify {p['rfverify_version']})",
        f"scene: {sc.summary}",
        f"configuration: {sc.configuration}",
        f"seed {p['seed']}; problem K = {p['trace_index']} of {p['count']} in the trace "
        f"(stage {p['stage']:.4f}); size {p['size']} {sc.size_unit} at the last stage",
    ]


def _description(sc: Scene, prov: dict, problem) -> str:
    p = prov
    nb = problem.n_dofs // 6
    solves = ", ".join(f"{s['status']} ({s['iterations']} it)" for s in p["solves"])
    lines = [
        *_header_lines(sc, p),
        f"bodies {nb} (m = {problem.n_dofs} dofs), contacts {problem.n_contacts}",
        f"time stepping: Moreau-Jean, theta = 1, h = {p['parameters']['h']:g}, e = 0, "
        f"w_N = max(gap, 0)/h (speculative contacts within margin {p['parameters']['margin']:g}); "
        f"dumped step {p['dumped_step'] + 1} of the stage, t = {p['time']:.6g}",
        f"step solves ({p['solver']['method']}, tol {p['solver']['tol']:g}): {solves}"
        + (f"; {p['failed_solves']} step(s) advanced with the best iterate" if p["failed_solves"] else ""),
        f"units: {p['units']}",
        "parameters: " + json.dumps(p["parameters"], sort_keys=True),
        "stage: " + json.dumps(p["notes"], sort_keys=True, default=float),
    ]
    return "\n".join(lines)


def _generate_step_free(sc: Scene, p: dict, size: int, count: int, seed: int, children, say) -> list:
    """:func:`generate` for a scene built without stepping (GranularBed): problem K is the
    one-step Moreau-Jean problem of stage K's world (contacts, M, H, f = M v + h F, w_N =
    max(gap, 0)/h, all vectorised), written as it is: no solve, so no step can fail and the
    arrays do not depend on the solver."""
    say(0.0, f"{sc.name}: lattice")
    t_base, worlds = _stage_worlds(sc, p, size, count, children)
    out = []
    for K, phi, t1, world in worlds:
        M, H, f, w, mu, mu_r, contacts = _stepper(world).one_step_arrays()
        if contacts.count == 0:
            raise SceneError(f"{sc.name} stage {K} (phi = {phi:.3f}): no contact; nothing to dump; fix: a larger "
                             "--size or another --seed")
        gaps = contacts.gap
        notes = dict(world.notes, contacts=contacts.count, open_gap_max=float(gaps.max()),
                     touching=int(np.sum(gaps <= 0)))
        prov = _provenance(
            sc, seed, count, K, phi, size,
            steps=0, dumped_step=0, time=0.0, parameters=p, units=sc.units, notes=notes,
            solver={"method": "none (the first step's problem, built without solving)"},
            solves=[], failed_solves=0,
            timing={"base_configuration": round(t_base, 3), "stage": round(time.perf_counter() - t1, 3)},
        )
        problem = Problem.from_arrays(M, H, f, w, mu, mu_r, title=sc.name, provenance=prov)
        out.append(replace(problem, description=_step_free_description(sc, prov, problem)))
        say((K + 1) / count, f"{sc.name} {K + 1}/{count}: {contacts.count} contacts")
    say(1.0, f"{sc.name}: done")
    return out


def _step_free_description(sc: Scene, prov: dict, problem) -> str:
    p = prov
    lines = [
        *_header_lines(sc, p),
        f"bodies {problem.n_dofs // 6} (m = {problem.n_dofs} dofs), contacts {problem.n_contacts}",
        f"time stepping: the first Moreau-Jean step (theta = 1, h = {p['parameters']['h']:g}, e = 0, "
        f"w_N = max(gap, 0)/h, speculative contacts within margin {p['parameters']['margin']:g}) from "
        "the configuration below; no step was solved",
        f"units: {p['units']}",
        "parameters: " + json.dumps(p["parameters"], sort_keys=True),
        "stage: " + json.dumps(p["notes"], sort_keys=True, default=float),
    ]
    return "\n".join(lines)


def _generate_finite_element(sc: Scene, p: dict, size: int, count: int, seed: int, steps: int,
                             children, say) -> list:
    """:func:`generate` for a finite-element scene (ElasticBlock): one run of
    :class:`.fem.ElasticMoreauJean` from rest; problem K is the problem of step (K+1)·steps
    (1-based) of that run, written with its known solution (the clamped solve, every contact
    checked strictly inside its cone) as ``/solution``.  No interior-point solve is made."""
    from ..model.problem import StoredSolution
    from .fem import entry_range

    say(0.0, f"{sc.name}: mesh and matrices")
    t0 = time.perf_counter()
    base = sc.prepare(p, size, np.random.default_rng(children[0]))
    mj = sc.stepper(base, p)
    t_base = time.perf_counter() - t0
    mesh, H = base["mesh"], base["H"]
    n = mesh.bottom.size
    w = np.zeros(5 * n)
    mu = np.full(n, float(p["mu"]))
    mu_r = np.zeros(n)
    lo, hi = entry_range(mj.M)
    out = []
    records = []
    for K in range(count):
        phi = K / (count - 1) if count > 1 else 1.0
        t1 = time.perf_counter()
        while len(records) < (K + 1) * steps:
            records.append(mj.step())
            say(len(records) / (count * steps), f"{sc.name}: step {len(records)}")
        rec = records[-1]
        notes = {"cells": list(mesh.shape), "nodes": mesh.n_nodes,
                 "tetrahedra": int(mesh.tets.shape[0]), "contacts": n,
                 "max_tangential_ratio": rec.max_ratio, "min_normal_impulse": rec.min_rN,
                 "max_speed": float(np.abs(rec.v).max()), "M_entry_min": lo, "M_entry_max": hi,
                 "M_nnz": int(mj.M.nnz)}
        solves = [{"step": r.step, "contacts": n, "status": "Clamped", "iterations": 0,
                   "solves": 1, "max_tangential_ratio": round(r.max_ratio, 6)}
                  for r in records[K * steps:]]
        prov = _provenance(
            sc, seed, count, K, phi, size,
            steps=steps, dumped_step=rec.step, time=rec.time, parameters=p, units=sc.units, notes=notes,
            solver={"method": "clamped direct solve (sparse LU of M on the free dofs)"},
            solves=solves, failed_solves=0,
            timing={"base_configuration": round(t_base, 3), "stage": round(time.perf_counter() - t1, 3)},
        )
        u = H.T @ rec.v + w  # exactly 0: the bottom nodes' velocity is exactly 0
        problem = Problem.from_arrays(mj.M, H, rec.f, w, mu, mu_r, title=sc.name, provenance=prov,
                                      solution=StoredSolution(v=rec.v, u=u, r=rec.r))
        out.append(replace(problem, description=_fe_description(sc, prov, problem)))
    say(1.0, f"{sc.name}: done")
    return out


def _fe_description(sc: Scene, prov: dict, problem) -> str:
    p, nt = prov, prov["notes"]
    par = p["parameters"]
    lines = [
        *_header_lines(sc, p),
        f"mesh: {' x '.join(map(str, nt['cells']))} cells of edge {par['cell']:g} m, "
        f"{nt['nodes']} nodes (m = {problem.n_dofs} dofs, 3 per node), {nt['tetrahedra']} linear "
        f"tetrahedra; contacts {problem.n_contacts} (one per bottom node, support normal +z)",
        f"time stepping: Moreau-Jean, theta = 1, h = {par['h']:g}, no damping, from rest in the "
        f"stress-free configuration; M = M_mass + h^2 K (consistent mass, linear-tetrahedron "
        f"stiffness), f = M_mass v_k + h (F_gravity - K q_k), w = 0 (zero gap), mu_r = 0 and "
        f"empty R1, R2 columns of H (nodes have no rotation); dumped step {p['dumped_step'] + 1} "
        f"of the run, t = {p['time']:.6g}",
        f"M: nnz {nt['M_nnz']}, |M_ij| from {nt['M_entry_min']:.3g} to {nt['M_entry_max']:.3g}",
        f"solution (stored in /solution): every contact sticks, u = 0; v solves the clamped "
        f"system (bottom nodes fixed), max |v| = {nt['max_speed']:.3g}; r from the bottom rows, "
        f"max |r_T|/r_N = {nt['max_tangential_ratio']:.4g} < mu = {par['mu']:g}, "
        f"min r_N = {nt['min_normal_impulse']:.3g}",
        f"units: {p['units']}",
        "parameters: " + json.dumps(par, sort_keys=True),
        "stage: " + json.dumps(nt, sort_keys=True, default=float),
    ]
    return "\n".join(lines)


def fclib_name(problem, index: int) -> str:
    """FCLIB-style file name ``SCENE-ndof-M-nc-N-K.hdf5``."""
    return f"{problem.title}-ndof-{problem.n_dofs}-nc-{problem.n_contacts}-{int(index)}.hdf5"


def save_collection(problems, out_dir, *, start_index: int = 0) -> list:
    """Write problems as FCLIB HDF5 files named by :func:`fclib_name` (K = start_index + i)
    into ``out_dir`` (created if missing).  Returns the paths."""
    from ..io import save

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, prob in enumerate(problems):
        K = prob.provenance.get("trace_index", start_index + i) if prob.provenance else start_index + i
        paths.append(save(prob, out / fclib_name(prob, K)))
    return paths
