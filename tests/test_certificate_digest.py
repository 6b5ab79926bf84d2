"""Issue 48 item 2: a stored certificate is bound to the problem's data as well as to the solution.

A file holding problem q beside the /solution and /certificate of problem p (same sizes) used
to be reported as "about this /solution (digest matches)"; the digest now covers M, H, f, w, μ,
μr as read (W, q for a local problem), in a defined byte order, and such a certificate is "about
another problem".  Certificates written before (solution digest only) are read, and said to have
a digest of the old kind that covers only the solution.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.cli import main
from rfverify.io.certificate import PROBLEM_DIGEST, problem_digest


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    """The bundled Chute solved and proven to 10 digits, written with its certificate."""
    path = tmp_path_factory.mktemp("digest") / "chute.hdf5"
    assert main(["solve", "bundled:chute", "--digits", "10", "--out", str(path), "--quiet"]) == 0
    return path


def other_problem(tmp_path):
    """The Chute with one entry of w changed: same sizes, other data."""
    p = rfverify.load("bundled:chute")
    w = p.w.copy()
    w[0] += 1.0
    q = rfverify.Problem.from_arrays(p.M, p.H, p.f, w, p.mu, p.mu_r, title=p.title)
    path = tmp_path / "other.hdf5"
    rfverify.save(q, path)
    return path


def transplant(source, target):
    """Copy /solution and /certificate of ``source`` into ``target`` (a tool other than rfverify)."""
    with h5py.File(source, "r") as src, h5py.File(target, "a") as dst:
        for name in ("solution", "certificate"):
            if name in dst:
                del dst[name]
            src.copy(src[name], dst, name)


def test_a_transplanted_certificate_is_about_another_problem(solved, tmp_path, capsys):
    target = other_problem(tmp_path)
    transplant(solved, target)
    code = main(["certify", str(target), "--digits", "10", "--quiet"])
    out = capsys.readouterr().out
    assert code == 1  # the fresh verdict: the solution of p does not solve q
    note = next(line for line in out.splitlines() if line.startswith("stored certificate"))
    assert "about ANOTHER problem" in note and "match" not in note.replace("does not hold", ""), note
    assert main(["certify", str(target), "--digits", "10", "--quiet", "--json"]) == 1
    stored = json.loads(capsys.readouterr().out)["stored_certificate"]
    assert stored["matches_problem"] is False and stored["matches_solution"] is True
    assert stored["digest_kind"] == "problem and solution"


def test_with_solution_from_another_file_the_problem_given_is_the_one_judged(solved, tmp_path, capsys):
    """certify P --solution S: the certificate in S is compared with P's data."""
    target = other_problem(tmp_path)
    transplant(solved, target)
    assert main(["certify", str(solved), "--solution", str(solved), "--quiet"]) == 0
    assert "about this problem and this /solution (both digests match)" in capsys.readouterr().out


def test_an_old_certificate_is_read_and_said_to_cover_the_solution_only(solved, tmp_path, capsys):
    old = tmp_path / "old.hdf5"
    old.write_bytes(solved.read_bytes())
    with h5py.File(old, "a") as fh:  # as rfverify wrote it before the problem digest
        for key in ("problem_sha256", "problem_digest"):
            del fh["certificate"].attrs[key]
    assert main(["certify", str(old), "--digits", "10", "--quiet"]) == 0
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("stored certificate"))
    assert "of the old kind" in note and "covers only the /solution" in note, note
    assert "digests match" not in note and "about this problem" not in note
    assert main(["certify", str(old), "--digits", "10", "--quiet", "--json"]) == 0
    stored = json.loads(capsys.readouterr().out)["stored_certificate"]
    assert stored["digest_kind"] == "solution only" and stored["matches_problem"] is None
    # ... and beside another problem, it is not called a match either
    target = other_problem(tmp_path)
    transplant(old, target)
    assert main(["certify", str(target), "--digits", "10", "--quiet"]) == 1
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("stored certificate"))
    assert "of the old kind" in note and "cannot be told" in note


@pytest.mark.parametrize("name", ["bundled:chute", "bundled:chute-dat"])
def test_the_problem_digest_survives_writing_and_reading(name, tmp_path):
    p = rfverify.load(name)
    digest = problem_digest(p)
    for storage in ("triplet", "csc", "csr"):
        path = tmp_path / f"copy-{storage}.hdf5"
        rfverify.save(p, path, storage=storage)
        assert problem_digest(rfverify.load(path)) == digest, storage


def test_the_problem_digest_sees_every_field_and_only_the_data():
    p = rfverify.load("bundled:chute")
    base = problem_digest(p)
    assert len(base) == 64 and PROBLEM_DIGEST.endswith("v1")

    def digest(**change):
        kw = {"M": p.M, "H": p.H, "f": p.f, "w": p.w, "mu": p.mu, "mu_r": p.mu_r, **change}
        return problem_digest(rfverify.Problem.from_arrays(**kw, title="another title"))

    assert digest() == base  # the title is not data
    M = sp.csc_matrix(p.M, copy=True)
    M.data[0] = np.nextafter(M.data[0], np.inf)
    H = sp.csc_matrix(p.H, copy=True)
    H.data[-1] *= 2
    changed = {"M": M, "H": H}
    for name in ("f", "w", "mu", "mu_r"):
        x = getattr(p, name).copy()
        x[-1] = x[-1] + 0.5 if name != "mu_r" else x[-1] * 0.5
        changed[name] = x
    for name, value in changed.items():
        assert digest(**{name: value}) != base, name
    f = p.f.copy()
    zero = np.flatnonzero(f == 0)
    if zero.size:
        f[zero[0]] = -0.0  # the same number
        assert digest(f=f) == base
    # explicit zeros and storage do not matter: the matrix as a mathematical object does
    Mz = sp.coo_matrix(p.M)
    Mz = sp.coo_matrix((np.append(Mz.data, 0.0), (np.append(Mz.row, 0), np.append(Mz.col, p.n_dofs - 1))),
                       shape=p.M.shape)
    assert digest(M=Mz.tocsr()) == base


@pytest.mark.parametrize("kind", ["global", "local"])
def test_3d_files_keep_their_digest_and_their_certificate_matches(kind, tmp_path, capsys):
    """A 3-D FCLIB file (read embedded in the rolling layout): written back in its own layout,
    and proven in place, its certificate matches the problem read again."""
    from test_fclib3d import GLOBAL_SCENES, LOCAL_SCENE, local_from, scene_3d, write_global, write_local

    if kind == "global":
        M, H3, f, w3, mu = scene_3d(GLOBAL_SCENES[0])
        path = write_global(tmp_path / "g3.hdf5", M, H3, f, w3, mu)
    else:
        M, H3, f, w3, mu = scene_3d(LOCAL_SCENE)
        W, q = local_from(M, H3, f, w3)
        path = write_local(tmp_path / "l3.hdf5", W, q, mu)
    p = rfverify.load(path)
    copy = tmp_path / "copy.hdf5"
    rfverify.save(p, copy)
    assert problem_digest(rfverify.load(copy)) == problem_digest(p)
    code = main(["solve", str(path), "--digits", "6", "--out", str(path), "--quiet"])
    capsys.readouterr()
    assert code in (0, 1)
    main(["certify", str(path), "--digits", "6", "--quiet"])
    assert "about this problem and this /solution (both digests match)" in capsys.readouterr().out


def test_a_local_dat_problem_written_as_its_lifting(tmp_path, capsys):
    """solve X.dat --digits --out S.h5 writes the global lifting of the .dat's local problem beside a
    certificate about the local problem: certify X.dat --solution S.h5 matches, and S.h5 alone (the
    lifting, other data) is said to be another problem, with the way to check the claim."""
    sol = tmp_path / "s.h5"
    assert main(["solve", "bundled:sphere", "--digits", "6", "--out", str(sol), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["certify", "bundled:sphere", "--solution", str(sol), "--digits", "6", "--quiet"]) == 0
    assert "about this problem and this /solution (both digests match)" in capsys.readouterr().out
    main(["certify", str(sol), "--digits", "6", "--quiet"])
    note = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("stored certificate"))
    assert "about ANOTHER problem" in note and "--solution" in note, note
