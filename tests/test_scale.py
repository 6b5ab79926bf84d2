"""Issue 27 at scale: the ``schur`` method (CHOLMOD with the optional extra ``cholmod``, QDLDL
without it) as a method name, ``auto``'s choice of it with either engine; and the GranularBed
scene, the large structured problems built without any solve (small sizes here)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import rfverify
from rfverify.cli import main
from rfverify.scenes import SCENES, SceneError, generate
from rfverify.solver import auto_sequence
from rfverify.solver.result import (ALGORITHM1_METHODS, AUTO_SCHUR_MIN_CONTACTS, AUTO_SCHUR_MIN_FILL,
                                    AUTO_SEQUENCE, AUTO_SEQUENCE_LARGE, METHODS, method_unavailable)

# ---------------------------------------------------------------- schur, the method
def test_schur_is_declared_once_and_left_out_of_the_bench_defaults():
    from rfverify.bench.runner import DEFAULT_METHODS
    from rfverify.cli.app import build_parser

    assert "schur" in ALGORITHM1_METHODS and "schur" in METHODS
    assert "schur" not in DEFAULT_METHODS  # form (16)'s iterates by another engine
    sol = build_parser()._subparsers._group_actions[0].choices["solve"]
    method = next(a for a in sol._actions if a.dest == "method")
    assert "schur" in method.choices and "CHOLMOD" in method.help and "cvxopt" in method.help
    assert str(AUTO_SCHUR_MIN_CONTACTS) in method.help and f"{AUTO_SCHUR_MIN_FILL:g}" in method.help
    assert "schur" in rfverify.solve.__doc__


def _never():
    raise AssertionError("the fill is computed only when the problem is large enough for schur")


def test_auto_sequence_starts_with_schur_only_when_large_and_filling():
    n, fill = AUTO_SCHUR_MIN_CONTACTS, AUTO_SCHUR_MIN_FILL
    assert auto_sequence(n - 1, _never) == AUTO_SEQUENCE and AUTO_SEQUENCE[0] == "jqinv"
    assert auto_sequence(n, fill) == AUTO_SEQUENCE_LARGE and AUTO_SEQUENCE_LARGE[0] == "schur"
    assert auto_sequence(n, lambda: fill) == AUTO_SEQUENCE_LARGE
    assert auto_sequence(10 ** 6, 0.99 * fill) == AUTO_SEQUENCE  # a thin chute flow: jqinv wins
    assert auto_sequence(10 ** 6, None) == AUTO_SEQUENCE


def test_schur_runs_with_either_engine(schur_engine):
    assert method_unavailable("schur") is None and method_unavailable("jqinv") is None
    from rfverify.engines.factor import schur_engine_name

    assert schur_engine_name() == schur_engine


def test_body_fill_counts_the_factor_of_the_body_graph(schur_engine):
    from rfverify.solver import body_fill

    # Two spheres side by side on the ground: 3 contacts, body graph = one edge, L has column
    # counts 2 and 1: (4 + 1)/3.  One sphere alone: 1 per contact.
    assert body_fill(generate("GranularBed", seed=1, size=2, width=2)[0]) == pytest.approx(5 / 3)
    assert body_fill(generate("GranularBed", seed=1, size=1)[0]) == 1.0
    # A cubic bed fills in (3-D lattice); one layer of the same contact count much less.
    cube = body_fill(generate("GranularBed", seed=1, size=216)[0])
    layer = body_fill(generate("GranularBed", seed=1, size=400, width=20)[0])
    assert cube >= AUTO_SCHUR_MIN_FILL > layer


def test_auto_runs_what_auto_sequence_says(monkeypatch, schur_engine, capsys):
    import rfverify.solver as solver_pkg

    monkeypatch.setattr(solver_pkg, "AUTO_SCHUR_MIN_CONTACTS", 1)  # the chute counts as large
    monkeypatch.setattr(solver_pkg, "AUTO_SCHUR_MIN_FILL", 0.0)
    p = rfverify.load("bundled:chute")
    res = rfverify.solve(p, tol=1e-8, verbose=True)
    assert res.success and res.extras["attempts"][0]["method"] == "schur" == res.method
    assert f"form schur (factored by {schur_engine})" in capsys.readouterr().out


def test_schur_through_the_cli_and_the_api(capsys, schur_engine):
    assert main(["solve", "bundled:chute", "--method", "schur", "--tol", "1e-9", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["method"] == "schur" and out["status"] == "Solved" and out["criterion"] <= 1e-9
    p = rfverify.load("bundled:chute")
    api = rfverify.solve(p, method="schur", tol=1e-9)
    ref = rfverify.solve(p, method="reduced_factored", tol=1e-9)
    assert api.method == "schur" and api.success and api.nit == ref.nit == out["iterations"]
    np.testing.assert_allclose(api.v, ref.v, rtol=0, atol=1e-9 * np.abs(ref.v).max())


# ---------------------------------------------------------------- GranularBed
def _lattice_contacts(k: np.ndarray, nx: int) -> int:
    """Contacts of simple cubic sites with flat indices k (filled in order, nx x nx layers),
    counted on the integer lattice: pairs one step apart along an axis, plus the bottom layer."""
    ijk = np.stack((k % nx, (k // nx) % nx, k // (nx * nx)), axis=1)
    occupied = {tuple(t) for t in ijk.tolist()}
    pairs = sum((i + 1, j, l) in occupied for i, j, l in occupied) + \
        sum((i, j + 1, l) in occupied for i, j, l in occupied) + \
        sum((i, j, l + 1) in occupied for i, j, l in occupied)
    return pairs + int(np.sum(ijk[:, 2] == 0))


@pytest.mark.parametrize("size, width", [(27, 0), (32, 4), (20, 3), (1, 0)])
def test_granular_bed_has_every_lattice_contact_and_no_other(size, width):
    p = generate("GranularBed", seed=2, size=size, width=width)[0]
    nx = width or round(size ** (1 / 3))
    assert p.n_contacts == _lattice_contacts(np.arange(size), nx)
    if size == nx * nx * (size // (nx * nx)):  # full layers: the closed form of the summary
        nz = size // (nx * nx)
        assert p.n_contacts == 3 * nx * nx * nz - 2 * nx * nz
    assert p.n_dofs == 6 * size and p.provenance["solves"] == [] and p.provenance["steps"] == 0


def test_granular_bed_fcc_counts_neighbours_at_one_diameter():
    size, d = 30, 0.02
    p = generate("GranularBed", seed=4, size=size, packing=1, width=3)[0]
    from rfverify.scenes.deposition import fcc_positions

    x = fcc_positions(size, d, 3, 3)
    dist = np.linalg.norm(x[:, None] - x[None], axis=2)
    pairs = int(np.sum(np.triu(np.abs(dist - d) < 1e-9 * d, 1)))
    assert p.n_contacts == pairs + int(np.sum(np.abs(x[:, 2] - d / 2) < 1e-12))


def test_granular_bed_is_a_well_posed_problem():
    p = generate("GranularBed", seed=7, size=45, width=3, agitation=0.02)[0]
    M = p.M.toarray()
    assert np.array_equal(M, M.T) and np.linalg.eigvalsh(M).min() > 0
    # Each contact's (N, T1, T2) is an orthonormal right-handed frame: body A's translational rows.
    H = p.H.toarray()
    Hc = p.H.tocsc()
    a = [Hc.indices[Hc.indptr[5 * c]:Hc.indptr[5 * c + 1]].min() // 6 for c in range(p.n_contacts)]  # A: lower index
    for c in range(p.n_contacts):
        E = H[6 * a[c]:6 * a[c] + 3, 5 * c:5 * c + 3]
        assert np.allclose(E.T @ E, np.eye(3), atol=1e-14) and np.linalg.det(E) > 0
        assert np.allclose(H[6 * a[c] + 3:6 * a[c] + 6, 5 * c + 3:5 * c + 5], E[:, 1:], atol=1e-14)
    # Strictly feasible (Slater): a dilation about a point far below the bed separates every
    # contact faster than friction and rolling resistance allow, so the solution exists.
    world_x = _centres(p)
    v = np.zeros(p.n_dofs)
    v.reshape(-1, 6)[:, :3] = world_x - np.array([world_x[:, 0].mean(), world_x[:, 1].mean(), -10.0])
    U = (p.H.T @ v + p.w).reshape(-1, 5)
    assert np.all(U[:, 0] > p.mu * np.linalg.norm(U[:, 1:3], axis=1) + p.mu_r * np.linalg.norm(U[:, 3:], axis=1))
    assert np.all(p.w[0::5] >= 0) and np.all(p.w[0::5] <= 1e-3 * 0.02 / 1e-3 * (1 + 1e-9))  # gap_jitter·d/h


def _centres(p):
    """Sphere centres rebuilt from the generator (same seed and parameters as the problem)."""
    from rfverify.scenes.library import SCENES as REG

    sc = REG["GranularBed"]
    prm = dict(sc.defaults, **{k: float(v) for k, v in p.provenance["parameters"].items()})
    rng = np.random.default_rng(np.random.SeedSequence(p.provenance["seed"]).spawn(2)[0])
    return sc.prepare(prm, p.provenance["size"], rng)["pos"]


def test_granular_bed_is_reproducible_by_seed():
    a, b = (generate("GranularBed", seed=11, size=40, count=2) for _ in range(2))
    c = generate("GranularBed", seed=12, size=40)[0]
    for x, y in zip(a, b):
        for name in ("f", "w", "mu", "mu_r"):
            assert np.array_equal(getattr(x, name), getattr(y, name))
        assert (x.H != y.H).nnz == 0 and (x.M != y.M).nnz == 0
    assert a[0].n_contacts < a[1].n_contacts  # stage 0 is the bottom layer
    assert not np.array_equal(a[1].f, c.f)


def test_granular_bed_solves_at_small_size():
    p = generate("GranularBed", seed=3, size=64)[0]
    res = rfverify.solve(p, method="jqinv", tol=1e-9)
    assert res.success, res.message
    from rfverify.scenes import contact_state_mix

    counts = contact_state_mix(p, res.v, res.u, res.r).counts
    assert counts["open"] > 0 and counts["sticking"] + counts["sliding"] + counts["rolling"] > 0, counts
    s = rfverify.solve(p, method="schur", tol=1e-9)  # CHOLMOD or QDLDL, whichever is here
    assert s.success and abs(s.nit - res.nit) <= 1


def test_granular_bed_refuses_bad_parameters(capsys, tmp_path):
    assert "GranularBed" in SCENES
    with pytest.raises(SceneError, match="packing"):
        generate("GranularBed", size=8, packing=2)
    with pytest.raises(SceneError, match="margin"):
        generate("GranularBed", size=8, margin=1e-6)  # below gap_jitter·d: lattice contacts lost
    with pytest.raises(SceneError, match="margin"):
        generate("GranularBed", size=8, margin=0.01)  # second neighbours would be contacts
    assert main(["generate", "GranularBed", "--size", "8", "--param", "packing=3", "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert main(["generate", "GranularBed", "--size", "27", "--out", str(tmp_path / "o"), "--json", "--quiet"]) == 0
    out = json.loads(capsys.readouterr().out)
    q = rfverify.load(out["files"][0]["path"])
    assert q.title == "GranularBed" and q.n_contacts == 63 and "no step was solved" in q.description


# ---------------------------------------------------------------- the turned bed (issue 47)
def test_a_turned_bed_is_the_same_bed_turned_with_generic_contact_frames():
    """orientation=1 turns the whole bed (lattice, ground, gravity, velocities) by one rotation Q:
    the same physics, so the solution is the axis-aligned bed's turned — translational and
    angular velocities alike — while the contact frames become generic (more nonzeros of H)."""
    flat = generate("GranularBed", seed=5, size=27, agitation=0.02)[0]
    turned = generate("GranularBed", seed=5, size=27, agitation=0.02, orientation=1)[0]
    assert flat.n_contacts == turned.n_contacts and flat.n_dofs == turned.n_dofs
    assert turned.H.nnz > 1.7 * flat.H.nnz  # generic normals and tangents
    normals = np.abs(_translational_normals(turned))
    assert np.all(np.sort(normals, axis=1)[:, 0] > 1e-6)  # no normal lies in a coordinate plane
    up = np.array(turned.provenance["notes"]["turned_vertical"])
    a = rfverify.solve(flat, method="jqinv", tol=1e-11)
    b = rfverify.solve(turned, method="jqinv", tol=1e-11)
    assert a.success and b.success
    # Q from the ground contacts' normals: the flat bed's are e_z, the turned bed's Q e_z = up.
    assert np.allclose(_translational_normals(turned)[-9:], up, atol=1e-14)
    Q = _rotation_between(flat, turned)
    va, vb = a.v.reshape(-1, 2, 3), b.v.reshape(-1, 2, 3)
    scale = np.abs(a.v).max()
    assert np.abs(va @ Q.T - vb).max() < 1e-7 * scale
    # cones are isotropic: normal velocities and the norms of the tangential parts agree
    ua, ub = a.u.reshape(-1, 5), b.u.reshape(-1, 5)
    assert np.abs(ua[:, 0] - ub[:, 0]).max() < 1e-7 * scale
    assert np.abs(np.linalg.norm(ua[:, 1:3], axis=1) - np.linalg.norm(ub[:, 1:3], axis=1)).max() < 1e-7 * scale
    with pytest.raises(SceneError, match="orientation"):
        generate("GranularBed", size=8, orientation=2)


def _translational_normals(p):
    """Each contact's normal: body A's translational rows of its first column of H."""
    Hc = p.H.tocsc()
    out = np.zeros((p.n_contacts, 3))
    for c in range(p.n_contacts):
        rows = Hc.indices[Hc.indptr[5 * c]:Hc.indptr[5 * c + 1]]
        vals = Hc.data[Hc.indptr[5 * c]:Hc.indptr[5 * c + 1]]
        a = rows.min() // 6
        for r, x in zip(rows, vals):
            if 6 * a <= r < 6 * a + 3:
                out[c, r - 6 * a] = x
    return out


def _rotation_between(flat, turned):
    """The rotation taking the flat bed's contact normals to the turned bed's (least squares,
    Kabsch), checked to map every normal."""
    A, B = _translational_normals(flat), _translational_normals(turned)
    U, _, Vt = np.linalg.svd(B.T @ A)
    Q = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt
    assert np.allclose(A @ Q.T, B, atol=1e-12)
    return Q
