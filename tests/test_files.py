"""The real problem files (the copies bundled in rfverify/data/, byte-identical to the project's
originals in ../shared/data): every one loads, the two Chute versions agree, lifted local
problems reproduce W, broken files are refused precisely."""

from __future__ import annotations

import filecmp
import hashlib
import shutil

import h5py
import numpy as np
import pytest

import rfverify
from rfverify import InvalidProblemError, ProblemFileError
from rfverify.model.check import check_solution
from rfverify.io import bundled_problems, parse_siconos_dat

SHA256 = {  # the originals' checksums: the bundled copies are these files, byte for byte
    "Chute-ndof-768-nc-4-3.hdf5": "9992f758a22b72c1413780628fa270a09003ae0750417d51b0b22df6d7226687",
    "GRFC3D_Chute-ndof-768-nc-4-3.dat": "1331a6c3af7fd06ddb00dae580ac9e90b2f7ce5066036cbc51b7ca06c31d3bbe",
    "RFC3D_cube_1.dat": "14f08075db2b69c592e1923236ab1eb5938bfefe8aefe3c4f24fae5d60852ead",
    "RFC3D_sphere_1.dat": "67f2bad3ed59cab5caa8e6d87d1098290917691a8fbffbf717a5dcf6c8d7e46f",
    "rfc3d_sphere_from_grfc3d.dat": "1f83f1409043fb91c23501178aeb9dd8ea73a9ee22ff90ac0bc9ccee22e03d56",
}

SHARED_FILES = {
    "Chute-ndof-768-nc-4-3.hdf5": (768, 4),
    "GRFC3D_Chute-ndof-768-nc-4-3.dat": (768, 4),
    "RFC3D_sphere_1.dat": (None, 1),
    "RFC3D_cube_1.dat": (None, 2),
    "rfc3d_sphere_from_grfc3d.dat": (None, 2),
}


@pytest.mark.parametrize("name", sorted(SHARED_FILES))
def test_every_real_file_loads(real_data, name):
    problem = rfverify.load(real_data / name)
    m, n = SHARED_FILES[name]
    assert problem.n_contacts == n
    if m is not None:
        assert problem.n_dofs == m
    assert problem.H.shape == (problem.n_dofs, 5 * n)
    assert problem.blocks.proven and problem.blocks.lam_lower.min() > 0


def test_bundled_files_are_the_original_files(real_data):
    """Every bundled problem is one of the originals, unchanged (checksums pinned here); where
    the originals are beside the repository (../shared/data), they are compared directly too."""
    from conftest import SHARED_DATA

    bundled = {p.name: p for p in bundled_problems().values()}
    assert set(bundled) == set(SHA256) == set(SHARED_FILES)
    for name, path in bundled.items():
        assert path.parent == real_data
        assert hashlib.sha256(path.read_bytes()).hexdigest() == SHA256[name], name
        if SHARED_DATA.is_dir():
            assert filecmp.cmp(path, SHARED_DATA / name, shallow=False), name


def test_chute_hdf5_facts(real_data):
    p = rfverify.load(real_data / "Chute-ndof-768-nc-4-3.hdf5")
    assert (p.n_dofs, p.n_contacts) == (768, 4)
    assert p.storage == {"M": "triplet", "H": "triplet"}
    assert p.symmetry.scaled > 1e-3  # the real file is measurably unsymmetric
    assert p.symmetry.frobenius > 0
    np.testing.assert_array_equal(p.mu, [1, 1, 1, 1])
    np.testing.assert_array_equal(p.mu_r, [0.1] * 4)
    # Its stored solution is a placeholder: v = r = 0, which the check must expose.
    chk = check_solution(p, p.solution)
    assert set(chk.zero) == {"v", "r"}
    assert chk.dynamics == pytest.approx(1.0)
    assert not chk.ok(1e-3)


def test_chute_dat_and_hdf5_agree_to_print_precision(real_data):
    h5 = rfverify.load(real_data / "Chute-ndof-768-nc-4-3.hdf5")
    dat = rfverify.load(real_data / "GRFC3D_Chute-ndof-768-nc-4-3.dat")
    assert dat.provenance["significant_digits"] == 6
    # Vectors are printed with %.24e: exact.  Matrices by CSparse's %g: 6 significant digits,
    # so each entry is within half a unit of the 6th digit, ≤ 5e-6 relative.
    for name in ("f", "w", "mu", "mu_r"):
        np.testing.assert_array_equal(getattr(dat, name), getattr(h5, name))
    for name in ("M", "H"):
        a = getattr(h5, name).toarray()
        b = getattr(dat, name).toarray()
        np.testing.assert_array_equal(a == 0, b == 0)
        nz = a != 0
        assert np.max(np.abs(a[nz] - b[nz]) / np.abs(a[nz])) <= 5e-6
    assert dat.symmetry.scaled == pytest.approx(h5.symmetry.scaled, rel=1e-3)


@pytest.mark.parametrize("name", ["RFC3D_sphere_1.dat", "RFC3D_cube_1.dat",
                                  "rfc3d_sphere_from_grfc3d.dat"])
def test_lifted_local_problem_reproduces_W_and_q(real_data, name):
    kind, local, digits = parse_siconos_dat(real_data / name)
    assert kind == "local"
    p = rfverify.load(real_data / name)
    lift = p.provenance["lift"]
    H = p.H.toarray()
    W = 0.5 * (local.W + local.W.T)
    norm = np.linalg.norm(W, 2)
    # HᵀH equals W up to the dropped eigenvalues (each ≤ rank_tol·‖W‖) and rounding.
    err = np.linalg.norm(H.T @ H - W, 2)
    assert err <= max(lift["rank_tol"], 1e-13) * norm * 1.01
    np.testing.assert_array_equal(p.M.toarray(), np.eye(p.n_dofs))
    np.testing.assert_array_equal(p.f, 0.0)
    np.testing.assert_array_equal(p.w, local.q)
    np.testing.assert_array_equal(p.mu, local.mu)
    np.testing.assert_array_equal(p.mu_r, local.mu_r)
    assert lift["rank"] + lift["dropped"] == W.shape[0]


def test_dense_dat_is_column_major(tmp_path):
    # A deliberately unsymmetric 5×5 W: column-major reading puts entry k at (k % 5, k // 5).
    W = np.diag(np.full(5, 100.0))
    W_cm = W.copy()
    W_cm[1, 0] = 1e-3  # appears as the 2nd printed number (column 0, row 1)
    flat = W_cm.ravel(order="F")
    text = "5\n1\n0\n5\n5\n5\t5\n" + "\n".join(" ".join(f"{x:.17e}" for x in flat[5 * k:5 * k + 5])
                                             for k in range(5))
    text += "\n" + " ".join(["1.0"] * 5) + "\n0.5\n0.1\n"
    path = tmp_path / "cm.dat"
    path.write_text(text)
    kind, local, _ = parse_siconos_dat(path)
    assert local.W[1, 0] == 1e-3 and local.W[0, 1] == 0.0


# ---------------------------------------------------------------------- broken files
def test_missing_file(tmp_path):
    with pytest.raises(ProblemFileError, match="no such file"):
        rfverify.load(tmp_path / "nope.hdf5")


def test_truncated_hdf5(real_data, tmp_path):
    src = (real_data / "Chute-ndof-768-nc-4-3.hdf5").read_bytes()
    path = tmp_path / "trunc.hdf5"
    path.write_bytes(src[: len(src) // 2])
    with pytest.raises(ProblemFileError) as err:
        rfverify.load(path)
    assert "trunc.hdf5" in str(err.value)


def test_not_hdf5(tmp_path):
    path = tmp_path / "fake.hdf5"
    path.write_text("hello, I am not HDF5\n")
    with pytest.raises(ProblemFileError, match="not an HDF5 file"):
        rfverify.load(path)


@pytest.mark.parametrize("victim", ["fclib_global_rolling", "fclib_global_rolling/M",
                                    "fclib_global_rolling/H/p", "fclib_global_rolling/vectors/mu_r",
                                    "fclib_global_rolling/vectors", "fclib_global_rolling/spacedim"])
def test_missing_group_is_named(real_data, tmp_path, victim):
    path = tmp_path / "cut.hdf5"
    shutil.copy(real_data / "Chute-ndof-768-nc-4-3.hdf5", path)
    path.chmod(0o644)
    with h5py.File(path, "r+") as fh:
        del fh[victim]
    with pytest.raises(ProblemFileError) as err:
        rfverify.load(path)
    assert victim.split("/")[-1] in str(err.value)
    assert err.value.location is not None and victim.split("/")[-1] in err.value.location


def test_nan_in_hdf5_data_names_field(real_data, tmp_path):
    path = tmp_path / "nan.hdf5"
    shutil.copy(real_data / "Chute-ndof-768-nc-4-3.hdf5", path)
    path.chmod(0o644)
    with h5py.File(path, "r+") as fh:
        fh["fclib_global_rolling/vectors/f"][7] = np.nan
    with pytest.raises(InvalidProblemError) as err:
        rfverify.load(path)
    assert err.value.field == "f" and err.value.index == 7


def test_wrong_size_in_hdf5_names_field(real_data, tmp_path):
    path = tmp_path / "size.hdf5"
    shutil.copy(real_data / "Chute-ndof-768-nc-4-3.hdf5", path)
    path.chmod(0o644)
    with h5py.File(path, "r+") as fh:
        w = fh["fclib_global_rolling/vectors/w"][()]
        del fh["fclib_global_rolling/vectors/w"]
        fh["fclib_global_rolling/vectors/w"] = w[:-1]
    with pytest.raises(InvalidProblemError) as err:
        rfverify.load(path)
    assert err.value.field == "w"


def test_other_fclib_kind_is_refused(tmp_path):
    path = tmp_path / "fc3d.hdf5"
    with h5py.File(path, "w") as fh:
        fh.create_group("fclib_local")
    with pytest.raises(ProblemFileError, match="fclib_local"):
        rfverify.load(path)


@pytest.mark.parametrize("mutate, expect", [
    (lambda t: t.replace("5\n1\n0", "3\n1\n0", 1), r"W is 5×5, expected 3×3 \(3nc × 3nc\)"),  # d = 3: FC3D
    (lambda t: "\n".join(t.splitlines()[:-1]), "short"),
    (lambda t: t + "\n1.0\n", "unexpected numbers"),
    (lambda t: t.replace("5\t5", "5\t4", 1), "dense header"),
    (lambda t: t.replace("1.000000000000000000000000e+00", "1.0x", 1), "not a number"),
    (lambda t: t.replace("5\n1\n0", "5\n1\n1", 1), "expected the number of blocks of first matrix"),
])
def test_broken_dat_files(real_data, tmp_path, mutate, expect):
    text = (real_data / "RFC3D_sphere_1.dat").read_text()
    path = tmp_path / "broken.dat"
    path.write_text(mutate(text))
    with pytest.raises(ProblemFileError, match=expect) as err:
        rfverify.load(path)
    assert err.value.location is not None


def test_broken_csparse_listing(real_data, tmp_path):
    lines = (real_data / "rfc3d_sphere_from_grfc3d.dat").read_text().splitlines()
    del lines[12]  # an entry of column 0 disappears
    path = tmp_path / "broken.dat"
    path.write_text("\n".join(lines))
    with pytest.raises(ProblemFileError, match="line"):
        rfverify.load(path)


def test_binary_garbage_dat(tmp_path):
    path = tmp_path / "garbage.dat"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(ProblemFileError):
        rfverify.load(path)


def test_unknown_bundled_name():
    with pytest.raises(ProblemFileError, match="bundled problems"):
        rfverify.load("bundled:nonexistent")
