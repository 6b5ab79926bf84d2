"""rfverify.scenes: contact kinematics, H structure, the Moreau–Jean stepper, determinism, the
FCLIB round trip of generated files, the extreme families' parameters, and `rfverify generate`.

Sizes are small (≤ 20 bodies) so the whole file stays well under a minute on two cores.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import rfverify
from rfverify.cli import build_parser, main
from rfverify.scenes import (SCENES, Bodies, MoreauJean, Statics, contact_matrix, contact_state_mix,
                             detect_contacts, generate, h_structure, mass_matrix, relative_velocity,
                             save_collection)
from rfverify.scenes.assembly import generalized_velocity
from rfverify.scenes.deposition import _descent, deposit_spheres, fcc_positions
from rfverify.scenes.geometry import random_quaternions, segment_closest_points
from rfverify.scenes.extreme import rescale_arrays

SAMPLE_DIR = Path(__file__).parent / "data" / "scenes"
SMALL = 12


@pytest.fixture(scope="module")
def small_problems():
    """One small problem of every scene (generated once for the module)."""
    return {name: generate(name, count=1, seed=3, size=SMALL if name != "Lattice" else 20)[0]
            for name in SCENES}


# ---------------------------------------------------------------------- kinematics
def _random_assembly(seed: int, n_bodies: int, capsule_fraction: float):
    """Bodies of mixed shapes close enough to each other and to a floor that contacts exist."""
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.01, 0.02, n_bodies)
    hl = np.where(rng.random(n_bodies) < capsule_fraction, rng.uniform(0.5, 1.5, n_bodies) * r, 0.0)
    pos = rng.uniform(-0.04, 0.04, (n_bodies, 3)) + np.array([0.0, 0.0, 0.03])
    b = Bodies.make(r, hl, 1000.0, pos, random_quaternions(rng, n_bodies))
    statics = Statics.make(planes=[((0.0, 0.1, 1.0), 0.0, 0)])
    return b, statics, rng


@given(seed=st.integers(0, 2 ** 32 - 1), n_bodies=st.integers(2, 7),
       capsule_fraction=st.sampled_from([0.0, 0.5, 1.0]))
def test_rigid_motion_gives_zero_relative_velocity(seed, n_bodies, capsule_fraction):
    # A rigid motion of the whole assembly, v_i = V + Ω × x_i, ω_i = Ω, moves no contact point
    # relative to another body: Hᵀv = 0 on every body–body contact (also speculative ones with
    # a positive gap, because both lever arms go to one common point).
    b, statics, rng = _random_assembly(seed, n_bodies, capsule_fraction)
    c = detect_contacts(b, statics, margin=0.1)
    V, Omega = rng.normal(size=3), rng.normal(size=3) * 10
    b.vel = V + np.cross(Omega, b.pos)
    b.omega = np.tile(Omega, (b.count, 1))
    H = contact_matrix(b, c)
    u = (H.T @ generalized_velocity(b)).reshape(-1, 5)
    scale = np.linalg.norm(V) + np.linalg.norm(Omega) * 0.1
    between = c.b >= 0
    assert np.abs(u[between]).max(initial=0.0) <= 1e-13 * scale
    # ... and the static contacts do see the motion (the test is not vacuous).
    if (~between).any() and (c.gap[~between] < 0.05).any():
        assert np.abs(u[~between]).max() > 1e-6 * scale


@given(seed=st.integers(0, 2 ** 32 - 1), n_bodies=st.integers(2, 6))
def test_H_matches_the_kinematic_formula(seed, n_bodies):
    # Hᵀv assembled by sparse blocks equals the relative velocity computed directly from
    # (N, T1, T2)ᵀ(v_A + ω_A × ρ_A − v_B − ω_B × ρ_B) and (T1, T2)ᵀ(ω_A − ω_B).
    b, statics, rng = _random_assembly(seed, n_bodies, 0.5)
    c = detect_contacts(b, statics, margin=0.1)
    b.vel = rng.normal(size=(b.count, 3))
    b.omega = rng.normal(size=(b.count, 3)) * 30
    u = (contact_matrix(b, c).T @ generalized_velocity(b)).reshape(-1, 5)
    assert np.allclose(u, relative_velocity(b, c), rtol=0, atol=1e-12)
    N, T1, T2 = c.frames()
    F = np.stack((N, T1, T2), axis=1)
    assert np.allclose(np.einsum("nij,nkj->nik", F, F), np.eye(3), atol=1e-14)
    assert np.allclose(np.einsum("ij,ij->i", np.cross(N, T1), T2), 1.0)  # right-handed


def test_rotating_sphere_on_the_ground():
    r = 0.01
    b = Bodies.make([r], 0.0, 1300.0, [[0.0, 0.0, r]])
    ground = Statics.make(planes=[((0, 0, 1), 0.0, 0)])
    c = detect_contacts(b, ground, margin=1e-3)
    assert c.count == 1 and c.kind[0] == 1 and abs(c.gap[0]) < 1e-15
    N, T1, T2 = c.frames()
    assert np.allclose(N[0], [0, 0, 1])
    # Pure rotation about y: the contact point slips with ω × ρ = (−r ω_y, 0, 0) and the
    # sphere rolls with angular velocity (T1, T2)·ω relative to the ground.
    wy = 7.0
    b.omega[0] = [0.0, wy, 0.0]
    u = contact_matrix(b, c).T @ generalized_velocity(b)
    slip = np.array([-r * wy, 0.0, 0.0])
    assert u[0] == pytest.approx(0.0, abs=1e-15)
    assert np.allclose(u[1:3], [T1[0] @ slip, T2[0] @ slip], atol=1e-15)
    assert np.allclose(u[3:5], [T1[0] @ b.omega[0], T2[0] @ b.omega[0]], atol=1e-15)
    assert np.linalg.norm(u[3:5]) == pytest.approx(wy)
    # Rolling without slipping: v = (r ω_y, 0, 0) cancels the slip, the rolling stays.
    b.vel[0] = [r * wy, 0.0, 0.0]
    u = contact_matrix(b, c).T @ generalized_velocity(b)
    assert np.allclose(u[:3], 0.0, atol=1e-15)
    assert np.linalg.norm(u[3:5]) == pytest.approx(wy)
    # Spin about the normal is neither slip nor rolling (no torsional friction in FCLIB).
    b.vel[0] = 0.0
    b.omega[0] = [0.0, 0.0, 5.0]
    assert np.allclose(contact_matrix(b, c).T @ generalized_velocity(b), 0.0, atol=1e-15)


def test_capsule_contacts_are_exact():
    # Two crossed horizontal capsules, one above the other: closest points at the crossing.
    q_x = np.array([np.cos(np.pi / 4), 0.0, np.sin(np.pi / 4), 0.0])  # body z → world x
    q_y = np.array([np.cos(np.pi / 4), -np.sin(np.pi / 4), 0.0, 0.0])  # body z → world y
    b = Bodies.make([0.01, 0.02], [0.05, 0.03], 1000.0, [[0, 0, 0.031], [0.0, 0.0, 0.0]],
                    np.stack((q_x, q_y)))
    assert np.allclose(b.axis(), [[1, 0, 0], [0, 1, 0]], atol=1e-15)
    # Lying flat on a plane z = −0.02: both ends of capsule 1 touch it, capsule 0 does not.
    c = detect_contacts(b, Statics.make(planes=[((0, 0, 1), -0.02, 0)]), margin=2e-3)
    assert c.count == 3
    bb = c.kind == 0
    assert np.allclose(c.normal[bb], [[0, 0, 1]]) and c.gap[bb][0] == pytest.approx(0.001)
    assert np.allclose(c.point[bb], [[0, 0, 0.0205]])
    assert np.sum(c.a[~bb] == 1) == 2 and np.allclose(c.gap[~bb], 0.0, atol=1e-15)
    # Segment closest points: parallel overlapping segments give the middle of the overlap.
    s, t = segment_closest_points(np.array([[0.0, 0, 0]]), np.array([[1.0, 0, 0]]),
                                  np.array([[0.5, 1, 0]]), np.array([[2.0, 1, 0]]))
    assert s[0] == pytest.approx(0.75) and t[0] == pytest.approx(0.25 / 1.5)


def test_mass_matrix_world_inertia():
    rng = np.random.default_rng(0)
    b = Bodies.make([0.01, 0.01], [0.0, 0.02], 1000.0, [[0, 0, 0], [1, 0, 0]], random_quaternions(rng, 2))
    M = mass_matrix(b).toarray()
    R = b.rotation()[1]
    assert np.allclose(M[9:12, 9:12], R @ np.diag(b.inertia[1]) @ R.T, rtol=1e-14)
    assert np.array_equal(M, M.T)
    assert np.allclose(M[:3, :3], b.mass[0] * np.eye(3))
    # Sphere: I = 2/5 m r²; capsule moments from its cylinder and hemispheres.
    assert b.inertia[0, 0] == pytest.approx(0.4 * b.mass[0] * 0.01 ** 2)
    assert b.mass[1] == pytest.approx(1000 * (np.pi * 0.01 ** 2 * 0.04 + 4 / 3 * np.pi * 0.01 ** 3))


# ---------------------------------------------------------------------- deposition, stepper
def test_deposited_spheres_are_stable_and_disjoint():
    rng = np.random.default_rng(5)
    radii = rng.uniform(0.008, 0.012, 40)
    dep = deposit_spheres(radii, rng, lambda g, R: tuple(g.uniform(-0.02, 0.02, 2)),
                          [[0.0, 0.0, 1.0]], [0.0])
    C, R = dep.centers, dep.radii
    assert C.shape == (40, 3) and dep.discarded == 0
    gaps = np.linalg.norm(C[:, None] - C[None], axis=2) - (R[:, None] + R[None])
    np.fill_diagonal(gaps, np.inf)
    assert gaps.min() > -1e-12 and (C[:, 2] - R).min() > -1e-12
    # Every sphere, against the spheres deposited before it and the floor, is in
    # frictionless equilibrium: gravity lies in the cone of its contact normals.
    stacked = 0
    for i in range(40):
        touching = np.flatnonzero(gaps[i, :i] < 1e-9)
        normals = [(C[i] - C[j]) / np.linalg.norm(C[i] - C[j]) for j in touching]
        if C[i, 2] - R[i] < 1e-9:
            normals.append(np.array([0.0, 0.0, 1.0]))
        else:
            stacked += 1
            assert len(normals) >= 3
        d, _ = _descent(np.array(normals).reshape(-1, 3))
        assert np.linalg.norm(d) < 1e-8
    assert stacked >= 10  # a pile, not a single layer


def test_stepper_sphere_lands_without_bounce():
    # e = 0 and a speculative contact: a sphere 1.5 mm above the ground falling at 2 m/s
    # closes the gap exactly within the first step (u_N = 0 ⇔ v_z = −gap/h), loses the rest of
    # its normal momentum in the second, and then stays on the ground, sliding (it is fast
    # enough that friction cannot stop the slip: needs 2/7·3 m/s of impulse per mass, gets μ·2.0).
    r, h, mu = 0.01, 1e-3, 0.3
    b = Bodies.make([r], 0.0, 1300.0, [[0.0, 0.0, r + 0.0015]])
    b.vel[0] = [3.0, 0.0, -2.0]
    mj = MoreauJean(b, Statics.make(planes=[((0, 0, 1), 0.0, 0)]), h=h,
                    gravity=[0, 0, -9.81], margin=0.003, mu_table=[[mu]], mu_r_table=[[0.0]])
    records = mj.run(4)
    assert [rec.n_contacts for rec in records] == [1, 1, 1, 1]
    assert all(rec.success for rec in records)
    m = b.mass[0]
    rN = np.array([rec.r[0] for rec in records])
    # The De Saxcé fixed point stops when the shift moves by < 1e-3·margin/h: that bounds
    # the error of the normal velocity, hence of r_N/m.
    tol = 1e-3 * 0.003 / h
    assert rN[0] / m == pytest.approx(2.0 + h * 9.81 - 1.5, abs=tol)
    assert rN[0] / m + rN[1] / m == pytest.approx(2.0 + 2 * h * 9.81, abs=2 * tol)
    assert np.allclose(rN[2:] / m, h * 9.81, atol=tol)
    assert records[0].desaxce_solves >= 2  # the impact changes the slip: fixed point iterated
    for rec in records:  # sliding: friction saturated, opposing the slip
        assert np.linalg.norm(rec.r[1:3]) == pytest.approx(mu * rec.r[0], rel=1e-6)
    # The De Saxcé fixed point keeps the sliding sphere on the ground (no lift-off, no sink).
    z = mj.bodies.pos[0, 2] - r
    assert abs(z) < 4 * h * tol and abs(mj.bodies.vel[0, 2]) < tol
    assert mj.bodies.vel[0, 0] == pytest.approx(3.0 - mu * rN.sum() / m, rel=1e-6)
    assert mj.bodies.omega[0, 1] > 0  # friction spins it up in the rolling direction


def test_stepper_records_failed_solves(monkeypatch):
    # A solve that does not reach its tolerance advances with the best iterate, and says so.
    b = Bodies.make([0.01], 0.0, 1300.0, [[0.0, 0.0, 0.01]])
    mj = MoreauJean(b, Statics.make(planes=[((0, 0, 1), 0.0, 0)]), h=1e-3, gravity=[0, 0, -9.81],
                    margin=0.002, mu_table=[[0.3]], mu_r_table=[[1e-3]], max_iter=2)
    rec = mj.step()
    assert not rec.success and rec.status in ("MaxIterations", "InsufficientProgress")
    assert rec.message and np.all(np.isfinite(mj.bodies.vel))


# ---------------------------------------------------------------------- generated problems
def test_H_structure_of_generated_problems(small_problems):
    for name, p in small_problems.items():
        s = h_structure(p)
        assert s["max_bodies_per_contact"] <= 2, name
        assert s["max_rows_per_contact"] <= 12, name
        assert p.H.shape == (p.n_dofs, 5 * p.n_contacts) and p.n_dofs % 6 == 0
        # Rolling columns never touch translational rows.
        coo = p.H.tocoo()
        assert not np.any((coo.col % 5 >= 3) & (coo.row % 6 < 3)), name
        # M is block diagonal per body, exactly symmetric.
        Mc = p.M.tocoo()
        assert np.all(Mc.row // 6 == Mc.col // 6) and (p.M != p.M.T).nnz == 0, name


def test_small_instances_solve_with_jqinv(small_problems):
    # Every scene, including the families built to stress the solver: Lattice (redundant
    # contacts, the reaction set is not a point) and Millimetre (badly scaled units).
    for name, p in small_problems.items():
        r = rfverify.solve(p, method="jqinv", tol=1e-10)
        assert r.success, (name, r.status, r.message)


def test_state_mix_of_piles_and_the_open_and_sticking_families(small_problems):
    def mix(name):
        p = small_problems[name]
        r = rfverify.solve(p, method="jqinv", tol=1e-10)
        return contact_state_mix(p, r.v, r.u, r.r), r

    m_open, _ = mix("AllOpen")
    assert m_open.counts["open"] == m_open.labels.size > 0
    m_stick, r = mix("AllSticking")
    assert m_stick.counts["sticking"] == m_stick.labels.size > 0
    assert m_stick.counts["rolling"] == 0
    assert np.abs(r.v).max() < 1e-3 * 9.81 * 1e-3  # at rest to solver accuracy (v_free = h g)
    pile = generate("SpheresPile", count=1, seed=3, size=20)[0]
    r = rfverify.solve(pile, tol=1e-10)
    counts = contact_state_mix(pile, r.v, r.u, r.r).counts
    for state in ("open", "sticking", "sliding", "rolling"):
        assert counts[state] > 0, counts
    chute = small_problems["Chute"]
    r = rfverify.solve(chute, tol=1e-10)
    assert contact_state_mix(chute, r.v, r.u, r.r).counts["sliding"] > 0


def test_state_mix_classifies_a_sliding_sphere():
    # One sphere sliding fast on the ground with no spin: sliding and, since it does not
    # spin, rolling relative to the ground only if friction makes it spin (it does).
    r = 0.01
    b = Bodies.make([r], 0.0, 1300.0, [[0.0, 0.0, r]])
    b.vel[0] = [1.0, 0.0, 0.0]
    mj = MoreauJean(b, Statics.make(planes=[((0, 0, 1), 0.0, 0)]), h=1e-3, gravity=[0, 0, -9.81],
                    margin=1e-3, mu_table=[[0.3]], mu_r_table=[[0.0]])
    M, H, f, w, mu, mur, _ = mj.one_step_arrays()
    p = rfverify.Problem.from_arrays(M, H, f, w, mu, mur)
    sol = rfverify.solve(p, tol=1e-12)
    mix = contact_state_mix(p, sol.v, sol.u, sol.r)
    assert mix.labels[0] == "slide+roll"
    # Rolling without slipping at μr = 0: sticking, rolling.
    b.omega[0] = [0.0, 1.0 / r, 0.0]
    mj = MoreauJean(b, mj.statics, h=1e-3, gravity=[0, 0, -9.81], margin=1e-3,
                    mu_table=[[0.3]], mu_r_table=[[0.0]])
    M, H, f, w, mu, mur, _ = mj.one_step_arrays()
    p = rfverify.Problem.from_arrays(M, H, f, w, mu, mur)
    sol = rfverify.solve(p, tol=1e-12)
    assert contact_state_mix(p, sol.v, sol.u, sol.r).labels[0] == "stick+roll"


def test_determinism():
    a = generate("PrimitiveSoup", count=2, seed=11, size=10)
    b = generate("PrimitiveSoup", count=2, seed=11, size=10)
    c = generate("PrimitiveSoup", count=2, seed=12, size=10)
    for pa, pb in zip(a, b):
        assert _same(pa, pb)
    assert not all(_same(pa, pc) for pa, pc in zip(a, c))
    assert a[0].n_contacts <= a[1].n_contacts  # the soup settles along the trace


def _same(p, q) -> bool:
    return (p.M.shape == q.M.shape and p.H.shape == q.H.shape
            and (p.M != q.M).nnz == 0 and (p.H != q.H).nnz == 0
            and all(np.array_equal(getattr(p, k), getattr(q, k)) for k in ("f", "w", "mu", "mu_r")))


def test_fclib_round_trip(tmp_path):
    probs = generate("SpheresPile", count=3, seed=2, size=8)
    paths = save_collection(probs, tmp_path / "out")
    assert [p.name for p in paths] == [f"SpheresPile-ndof-{q.n_dofs}-nc-{q.n_contacts}-{k}.hdf5"
                                       for k, q in enumerate(probs)]
    assert probs[0].n_dofs < probs[-1].n_dofs  # the pile grows along the trace
    for path, p in zip(paths, probs):
        q = rfverify.load(path)
        assert _same(p, q)
        assert q.title == "SpheresPile" and "seed 2" in q.description
        assert "generator version" in q.description and "Moreau-Jean" in q.description
        with h5py.File(path, "r") as fh:
            g = fh["fclib_global_rolling"]
            assert g["spacedim"][()][0] == 5
            assert g["info/title"][()] == b"SpheresPile"
            params = g["info/description"][()].decode().split("parameters: ")[1].splitlines()[0]
            assert json.loads(params)["density"] == 1300.0
            assert np.array_equal(g["vectors/mu"][:], p.mu)


def test_committed_sample_is_reproduced():
    # The sample in tests/data/scenes was written by the command in its README; regenerating
    # must give the same problems (to round-off: other BLAS/CPUs may differ in the last bits).
    files = sorted(SAMPLE_DIR.glob("*.hdf5"))
    assert len(files) >= 3
    by_scene = {}
    for f in files:
        by_scene.setdefault(f.name.split("-")[0], []).append(f)
    for scene, fs in by_scene.items():
        stored = [rfverify.load(f) for f in fs]
        pv = json.loads(stored[0].description.split("parameters: ")[1].splitlines()[0])
        meta = stored[0].description.splitlines()[3]
        seed = int(meta.split("seed ")[1].split(";")[0])
        count = int(meta.split(" of ")[1].split(" ")[0])
        size = int(meta.split("size ")[1].split(" ")[0])
        fresh = generate(scene, count=count, seed=seed, size=size)
        for old in stored:
            k = int(old.description.split("problem K = ")[1].split(" ")[0])
            new = fresh[k]
            assert (new.n_dofs, new.n_contacts) == (old.n_dofs, old.n_contacts)
            # Steps that stopped short of the tolerance (Lattice) carry the solver's best
            # iterate into f: round-off differences between machines can grow there.
            rtol = 1e-6 if "best iterate" in old.description else 1e-9
            for name in ("f", "w", "mu", "mu_r"):
                assert np.allclose(getattr(new, name), getattr(old, name), rtol=rtol,
                                   atol=rtol * 1e-3 * np.abs(getattr(old, name)).max()), (scene, name)
            assert abs(new.H - old.H).max() <= 1e-9 * abs(old.H).max()
            assert abs(new.M - old.M).max() <= 1e-12 * abs(old.M).max()
        assert pv == SCENES[scene].defaults


# ---------------------------------------------------------------------- extreme families
def test_mass_ratio_family(small_problems):
    p = small_problems["MassRatio"]
    mass = p.M.diagonal().reshape(-1, 6)[:, 0]
    assert mass.max() / mass.min() == pytest.approx(1e6, rel=1e-12)
    p2 = generate("MassRatio", count=1, seed=3, size=SMALL, mass_ratio=1e3)[0]
    mass2 = p2.M.diagonal().reshape(-1, 6)[:, 0]
    assert mass2.max() / mass2.min() == pytest.approx(1e3, rel=1e-12)


def test_rolling_extremes_family():
    p = generate("RollingExtremes", count=1, seed=3, size=20)[0]
    assert set(np.unique(p.mu_r)) == {0.0, 1e-5, 1.0}
    assert np.all(p.mu == 0.3)


def test_frictionless_family(small_problems):
    p = small_problems["Frictionless"]
    assert np.all(p.mu == 0.0)
    assert set(np.unique(p.mu_r)) == {0.0, 1e-3}


def test_lattice_family_is_hyperstatic(small_problems):
    p = small_problems["Lattice"]  # 20 spheres: 2 x 2 square layers and 1-sphere hollow layers
    # Count the touching pairs of the FCC sites directly (distance = d), plus floor and walls.
    d = 0.02
    X = fcc_positions(20, d, 2, 2)
    D = np.linalg.norm(X[:, None] - X[None], axis=2)
    pairs = int(np.sum(np.triu(np.abs(D - d) < 1e-12, 1)))
    floor = int(np.sum(np.abs(X[:, 2] - d / 2) < 1e-12))
    walls = int(np.sum(np.isclose(X[:, :2], d / 2)) + np.sum(np.isclose(X[:, :2], 2 * d - d / 2)))
    assert p.n_contacts == pairs + floor + walls
    # Redundant contacts: the normal columns of H are linearly dependent.
    HN = p.H[:, 0::5].toarray()
    assert np.linalg.matrix_rank(HN) < p.n_contacts
    # All touching: gaps (w_N·h) below 1e-9·d — the steps' inexact solves open a few by ~1e-12 m.
    assert np.all(p.w[0::5] * 1e-3 < 1e-9 * d)


def test_all_open_family_has_positive_gaps(small_problems):
    p = small_problems["AllOpen"]
    assert np.all(p.w[0::5] > 0)


def test_millimetre_family_is_spherespile_in_other_units(small_problems):
    mm = small_problems["Millimetre"]
    si = generate("SpheresPile", count=1, seed=3, size=SMALL)[0]
    conv = rescale_arrays({k: getattr(si, k) for k in ("M", "H", "f", "w", "mu", "mu_r")}, 1e3, 1e3)
    assert abs(mm.M - conv["M"]).max() <= 1e-14 * abs(conv["M"]).max()
    assert abs(mm.H - conv["H"]).max() <= 1e-14 * abs(conv["H"]).max()
    for k in ("f", "w", "mu", "mu_r"):
        assert np.allclose(getattr(mm, k), conv[k], rtol=1e-14, atol=0), k
    diag = mm.M.diagonal().reshape(-1, 6)
    r_mm, rho = 10.0, 1300e3 / 1e9  # radius in mm, density in g/mm³
    m = rho * 4 / 3 * np.pi * r_mm ** 3
    assert np.allclose(diag[:, :3], m) and np.allclose(diag[:, 3:], 0.4 * m * r_mm ** 2)
    assert np.allclose(mm.mu_r, 1.0)  # 1e-3 m = 1 mm
    # The same physics: the SI solution, converted, solves the millimetre problem.
    s_si = rfverify.solve(si, tol=1e-11)
    s_mm = rfverify.solve(mm, method="clarabel", tol=1e-10)
    v_si = s_si.v.reshape(-1, 6) * np.array([1e3, 1e3, 1e3, 1, 1, 1])
    # Interior-point velocities are accurate to ~sqrt(tol) on these problems (docs/DECISIONS.md):
    # 4 digits; a unit error would be off by orders of magnitude.
    assert np.allclose(s_mm.v.reshape(-1, 6), v_si, atol=1e-4 * np.abs(v_si).max())


def test_unknown_parameters_and_sizes_are_refused():
    with pytest.raises(rfverify.RfverifyError, match="unknown parameter"):
        generate("SpheresPile", size=4, mass_ratio=3)
    with pytest.raises(rfverify.RfverifyError, match="unknown scene"):
        generate("Spheres", size=4)
    with pytest.raises(rfverify.RfverifyError, match="below the minimum"):
        generate("AllOpen", size=1)


# ---------------------------------------------------------------------- CLI
def test_cli_generate_writes_loadable_files(capsys, tmp_path):
    out = tmp_path / "coll"
    code = main(["generate", "allopen", "--count", "2", "--seed", "4", "--size", "6",
                 "--out", str(out), "--quiet", "--json"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    summary = json.loads(captured.out)
    assert summary["scene"] == "AllOpen" and len(summary["files"]) == 2
    for f in summary["files"]:
        assert Path(f["path"]).exists() and Path(f["path"]).parent == out
        code = main(["info", f["path"], "--json"])
        info = json.loads(capsys.readouterr().out)
        assert code == 0 and info["title"] == "AllOpen" and info["n"] == f["n"]


@pytest.mark.parametrize("argv, expect", [
    (["generate", "NoSuchScene", "--out", "x"], "unknown scene"),
    (["generate", "Chute", "--count", "0", "--out", "x"], "must be ≥ 1"),
    (["generate", "Chute", "--param", "speed", "--out", "x"], "KEY=VALUE"),
    (["generate", "Chute", "--param", "nope=1", "--out", "x"], "unknown parameter"),
    (["generate", "Chute"], "--out"),
])
def test_cli_generate_errors_are_one_line(capsys, argv, expect):
    try:
        code = main(argv)
    except SystemExit as ex:
        code = ex.code
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and expect in err


def test_cli_generate_help_and_list(capsys):
    gen = build_parser()._subparsers._group_actions[0].choices["generate"]
    text = gen.format_help()
    for name in SCENES:
        assert name in text
    for action in gen._actions:
        if action.dest != "help":
            assert action.help, action.dest
    assert main(["generate", "--list"]) == 0
    listing = capsys.readouterr().out
    assert all(name in listing for name in SCENES) and "mass_ratio=1e+06" in listing


def test_a_count_beyond_what_a_run_can_hold_is_refused_before_any_work(capsys):
    """--count 1000000000 allocated its seeds before anything else (1.2 GB in 15 s, no output)."""
    from rfverify.cli import main
    from rfverify.scenes import MAX_COUNT, generate
    from rfverify.scenes.stepper import SceneError

    with pytest.raises(SceneError, match="at most"):
        generate("SpheresPile", count=MAX_COUNT + 1, size=5)
    assert main(["generate", "SpheresPile", "--size", "5", "--count", "1000000000", "--out", "unused"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fix:" in err[0]


def test_every_scene_parameter_domain_names_a_parameter_and_holds_its_default():
    from rfverify.scenes import PARAMETER_DOMAINS, SCENE_DOMAINS, resolve_scene
    from rfverify.scenes.library import ALL_SCENES

    names = set()
    for name in ALL_SCENES:
        sc = resolve_scene(name)
        names |= set(sc.defaults)
        for key, value in sc.defaults.items():
            domain = SCENE_DOMAINS.get(sc.name, {}).get(key, PARAMETER_DOMAINS.get(key))
            assert domain is None or domain[1](value), (name, key, value)
    assert set(PARAMETER_DOMAINS) <= names  # no domain for a name no scene has (a typo)


@pytest.mark.parametrize("scene, param", [("SpheresPile", "recent_fraction=2"), ("SpheresPile", "tilt=95"),
                                          ("SpheresPile", "first_stage_bodies=2.5"), ("Lattice", "width=-1"),
                                          ("Chute", "width=0"), ("MassRatio", "mass_ratio=0.5"),
                                          ("AllOpen", "gap_lo=0.9"), ("SpheresPile", "first_stage_bodies=100"),
                                          ("GranularBed", "packing=2"), ("GranularBed", "orientation=2"),
                                          ("GranularBed", "gap_jitter=0.5"), ("GranularBed", "margin=1"),
                                          ("ElasticBlock", "jitter=0.5"), ("ElasticBlock", "poisson=0.6"),
                                          ("SpheresPile", "colour=1"), ("SpheresPile", "mu=abc")])
def test_a_parameter_outside_its_domain_is_refused_with_the_fix(capsys, scene, param):
    """An audit found these accepted: clamped, truncated, recorded as given, or the pile upside down."""
    from rfverify.cli import main

    assert main(["generate", scene, "--size", "5", "--param", param, "--out", "unused"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and param.split("=")[0] in err[0] and "fix:" in err[0], err
    with pytest.raises(SystemExit) as stop:  # (an argparse type: argparse exits)
        main(["generate", "NoSuchScene", "--out", "unused"])
    assert stop.value.code == 2 and "fix:" in capsys.readouterr().err
