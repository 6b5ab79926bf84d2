"""Siconos's 3-D Coulomb ``.dat`` files (FC3D local, GFC3D global: d = 3) and its sparse-block
matrix storage (type 1): read as the FCLIB 3-D readers read the same problem, refused in one line
when malformed, and a real file of Siconos's own test data solved and proven for the physical
problem (issue 51).

The files are written here by a writer independent of the library's, following Siconos's
``frictionContact_printInFile``, ``globalFrictionContact_printInFile`` and ``SBM_write_in_file``
(numerics sources of commit 6070f0f6).
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.cli import main
from test_coulomb import physical_violations
from test_fclib3d import GLOBAL_SCENES, LOCAL_SCENE, local_from, scene_3d, slots, write_global, write_local

TWO_RODS = Path(__file__).resolve().parent / "data" / "siconos" / "GFC3D_TwoRods1.dat"


# ---------------------------------------------------------------------- independent writer
def sbm_lines(A, row_ends, col_ends, fmt="%32.24e"):
    """``SBM_write_in_file`` of the dense A cut at the cumulative sizes: its nonzero blocks."""
    A = np.asarray(A, dtype=float)
    r0, c0 = np.r_[0, row_ends[:-1]], np.r_[0, col_ends[:-1]]
    pointers, columns, blocks = [0], [], []
    for i in range(len(row_ends)):
        for j in range(len(col_ends)):
            B = A[r0[i]:row_ends[i], c0[j]:col_ends[j]]
            if B.any():
                columns.append(j)
                blocks.append(B)
        pointers.append(len(columns))
    out = [str(len(blocks)), str(len(row_ends)), str(len(col_ends)),
           "".join(f"{e}\t" for e in row_ends), "".join(f"{e}\t" for e in col_ends),
           str(len(pointers)), str(len(columns)),
           "".join(f"{p}\t" for p in pointers), "".join(f"{c}\t" for c in columns)]
    for k, B in enumerate(blocks):
        out.append(str(k))
        out.extend(fmt % x for x in B.ravel(order="F"))
    return out


def matrix_lines(A, row_ends, col_ends, fmt="%32.24e"):
    m, n = np.shape(A)
    return ["1", str(m), str(n)] + sbm_lines(A, row_ends, col_ends, fmt)


def vector_line(x):
    return " ".join(f"{v:32.24e}" for v in x)


def write_gfc3d(path, M, H3, f, w3, mu, *, body=6, trailer=(), fmt="%32.24e"):
    m, n3 = H3.shape
    ends_m = list(range(body, m + 1, body))
    lines = ["3", str(n3 // 3)] + matrix_lines(M, ends_m, ends_m, fmt) + \
        matrix_lines(H3, ends_m, list(range(3, n3 + 1, 3)), fmt) + [vector_line(f), vector_line(w3), vector_line(mu)]
    Path(path).write_text("\n".join(lines + list(trailer)) + "\n")
    return path


def write_fc3d(path, W, q, mu):
    n3 = W.shape[0]
    ends = list(range(3, n3 + 1, 3))
    lines = ["3", str(n3 // 3)] + matrix_lines(W, ends, ends) + [vector_line(q), vector_line(mu)]
    Path(path).write_text("\n".join(lines) + "\n")
    return path


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


# ---------------------------------------------------------------------- the same problem as FCLIB's
@pytest.mark.parametrize("name", GLOBAL_SCENES)
def test_gfc3d_dat_is_the_fclib_global_problem(tmp_path, name):
    M, H3, f, w3, mu = scene_3d(name)
    dat = rfverify.load(write_gfc3d(tmp_path / "p.dat", M, H3, f, w3, mu))
    h5 = rfverify.load(write_global(tmp_path / "p.hdf5", M, H3, f, w3, mu))
    for field in ("M", "H"):
        assert (getattr(dat, field) != getattr(h5, field)).nnz == 0, field
    for field in ("f", "w", "mu", "mu_r"):
        np.testing.assert_array_equal(getattr(dat, field), getattr(h5, field))
    assert dat.statement == h5.statement and "3-D problem" in dat.statement
    assert dat.provenance["significant_digits"] is None  # %32.24e: every float64 exactly
    a, b = rfverify.solve(dat), rfverify.solve(h5)
    np.testing.assert_array_equal(a.v, b.v)
    np.testing.assert_array_equal(a.r, b.r)


def test_fc3d_dat_is_the_fclib_local_problem(tmp_path):
    W, q = local_from(*[scene_3d(LOCAL_SCENE)[k] for k in (0, 1, 2, 3)])
    mu = scene_3d(LOCAL_SCENE)[4]
    dat = rfverify.load(write_fc3d(tmp_path / "p.dat", W, q, mu))
    h5 = rfverify.load(write_local(tmp_path / "p.hdf5", W, q, mu))
    assert (dat.local.W != h5.local.W).nnz == 0
    np.testing.assert_array_equal(dat.local.q, h5.local.q)
    np.testing.assert_array_equal(dat.mu, h5.mu)
    assert dat.provenance["lifted"]["rank"] == h5.provenance["lifted"]["rank"]
    out = rfverify.solve_to_digits(dat, digits=10)
    assert out.success
    np.testing.assert_allclose(out.u[slots(mu.size)], (W @ out.r[slots(mu.size)] + q), rtol=0,
                               atol=1e-9 * np.abs(q).max())


def test_printed_precision_is_read_from_the_blocks(tmp_path):
    M, H3, f, w3, mu = scene_3d(GLOBAL_SCENES[0])
    p = rfverify.load(write_gfc3d(tmp_path / "p.dat", M, H3, f, w3, mu, fmt="%32e"))
    assert p.provenance["significant_digits"] == 7


# ---------------------------------------------------------------------- refusals
def _gfc3d_text(tmp_path):
    M, H3, f, w3, mu = scene_3d(GLOBAL_SCENES[0])
    return write_gfc3d(tmp_path / "p.dat", M, H3, f, w3, mu).read_text().splitlines()


@pytest.mark.parametrize("case", ["block_number", "pointers", "sizes", "two_extra", "dimension"])
def test_malformed_3d_dat_is_refused_in_one_line(tmp_path, capsys, case):
    lines = _gfc3d_text(tmp_path)
    first_block = lines.index("0", 14)  # the number of M's first block (lines 5-13: M's block structure)
    if case == "block_number":
        lines[first_block] = "7"
        words = "expected the number of block 0 of first matrix, found '7'"
    elif case == "pointers":
        lines[12] = lines[12].replace("0", "1", 1)  # the block-row pointers must start at 0
        words = "inconsistent block pointers"
    elif case == "sizes":
        lines[8] = "6\t5\t" + lines[8].split("\t", 2)[2]  # cumulative block-row sizes
        words = "are not increasing"
    elif case == "two_extra":
        lines += ["1", "2"]
        words = "2 unexpected numbers after mu"
    else:
        lines[0] = "4"
        words = "dimension d = 4: neither a rolling-friction problem (d = 5) nor a 3-D Coulomb"
    path = tmp_path / "bad.dat"
    path.write_text("\n".join(lines) + "\n")
    code, out, err = run(capsys, "info", path)
    assert code == 2 and out == ""
    assert len(err.strip().splitlines()) == 1 and words in err, err
    assert "Traceback" not in err


def test_a_lone_trailing_integer_is_ignored_and_said(tmp_path, capsys):
    M, H3, f, w3, mu = scene_3d(GLOBAL_SCENES[0])
    path = write_gfc3d(tmp_path / "p.dat", M, H3, f, w3, mu, trailer=["1"])
    code, out, err = run(capsys, "info", path)
    assert code == 0, err
    assert "a lone integer (1) after mu, which Siconos's reader does not read, was ignored" in out
    assert "3-D Coulomb friction (Siconos GFC3D .dat, d = 3, 3 per contact)" in out


# ---------------------------------------------------------------------- a real file of Siconos
def test_two_rods_is_the_bundled_copy():
    assert hashlib.sha256(TWO_RODS.read_bytes()).hexdigest() == \
        "04051ac92a50f58ca2049d8e37865c119ef739c9118bc079d763d6fbf169c623"


def test_two_rods_physical_problem_is_proven_and_rechecked(tmp_path, capsys):
    """Siconos's GFC3D_TwoRods1.dat (sparse-block M and H, 7 printed digits): the issue-51
    command exits 0 with a backward error ≤ 1e-10, and the written answer meets the physical
    conditions at 1e-10 in a 40-digit recheck that does not use rfverify's measures."""
    sol = tmp_path / "rods.h5"
    code, out, err = run(capsys, "solve", TWO_RODS, "--problem", "coulomb", "--digits", "10", "--out", sol,
                         "--json", "--quiet")
    assert code == 0, err
    out = json.loads(out)
    assert out["status"] == "Certified" and out["backward_error"] <= 1e-10
    problem = rfverify.load(TWO_RODS)
    import h5py

    with h5py.File(sol, "r") as fh:
        v, r3 = fh["solution/v"][()], fh["solution/r"][()]
    assert r3.size == 3 * problem.n_contacts  # written back 3 per contact, as the file is
    r = np.zeros(5 * problem.n_contacts)
    r[slots(problem.n_contacts)] = r3
    bad = physical_violations(problem, v, r)
    assert all(x <= 1e-10 for x in bad.values()), bad
    relaxed = rfverify.solve(problem)  # the recheck can fail: the relaxation's answer does
    assert physical_violations(problem, relaxed.v, relaxed.r)["complementarity"] > 1e-6
