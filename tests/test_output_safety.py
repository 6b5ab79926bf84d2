"""Issue 17, output safety: --out never replaces an input (except /solution written into the
input .hdf5, which keeps everything else), never replaces a non-regular file or a symbolic
link, and is checked before the expensive work."""

from __future__ import annotations

import os
import stat

import h5py
import numpy as np
import pytest

import rfverify
from rfverify.cli import main
from rfverify.errors import OutputPathError
from rfverify.io import write_fclib
from rfverify.scenes.random_problems import random_problem

from privileges import as_ordinary_user, world_traversable_dir

ROOT = "fclib_global_rolling"


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def refused(capsys, *argv, expect=()):
    code, out, err = run(capsys, *argv)
    assert code == 2, (code, err)
    assert err.count("\n") == 1 and "fix:" in err and "internal error" not in err, err
    for text in expect:
        assert text in err, (text, err)
    return err


@pytest.fixture
def no_solve(monkeypatch):
    """Fail the test if a solve (the expensive work) starts."""
    import rfverify.solver

    def boom(*a, **k):
        raise AssertionError("the solve ran before the output path was checked")

    monkeypatch.setattr(rfverify.solver, "solve", boom)


@pytest.fixture
def problem_file(tmp_path):
    path = tmp_path / "in.hdf5"
    write_fclib(random_problem(2, 3, seed=7), path)
    return path


def dat_text():
    W = np.diag([1.0, 1.01, 1.01, 1.0, 1.0]).ravel(order="F")
    body = "\n".join(" ".join(f"{x:.17e}" for x in W[5 * k:5 * k + 5]) for k in range(5))
    return "5\n1\n0\n5\n5\n5\t5\n" + body + "\n-8.9 0.19 0.0 0.0 -1.0\n0.6\n0.5\n"


# ---------------------------------------------------------------------- inputs are not outputs
def test_solve_dat_onto_itself_is_refused(capsys, tmp_path, no_solve):
    path = tmp_path / "in.dat"
    path.write_text(dat_text())
    before = path.read_bytes()
    refused(capsys, "solve", path, "--out", path, expect=[str(path), "--out", "input"])
    assert path.read_bytes() == before


def test_solve_onto_input_through_symlink_or_hard_link_is_refused(capsys, tmp_path, no_solve):
    path = tmp_path / "in.dat"
    path.write_text(dat_text())
    (tmp_path / "soft.h5").symlink_to(path)
    os.link(path, tmp_path / "hard.h5")
    before = path.read_bytes()
    refused(capsys, "solve", path, "--out", tmp_path / "soft.h5", expect=["input"])
    refused(capsys, "solve", path, "--out", tmp_path / "hard.h5", expect=["input"])
    assert path.read_bytes() == before


def test_solve_onto_bundled_file_is_refused(capsys, no_solve):
    target = rfverify.io.bundled_problems()["sphere"]
    before = target.read_bytes()
    refused(capsys, "solve", "bundled:sphere", "--out", target, expect=["bundled"])
    assert target.read_bytes() == before


def test_no_command_writes_over_a_bundled_problem(capsys, tmp_path, no_solve):
    """Audit (2026-12-08): a bundled file was refused only as the command's own input; solving
    another problem --out onto it, or rfverify.save(p, p.source), replaced it, and
    bundled:chute then named another problem."""
    target = rfverify.io.bundled_problems()["chute"]
    before = target.read_bytes()
    refused(capsys, "solve", "bundled:sphere", "--out", target, expect=["bundled:chute"])
    refused(capsys, "solve", "bundled:sphere", "--out", "bundled:chute", expect=["bundled"])
    p = rfverify.load("bundled:chute")
    with pytest.raises(OutputPathError, match="bundled"):
        rfverify.save(p, p.source)
    assert target.read_bytes() == before
    assert not (tmp_path / "bundled:chute").exists()


def test_certify_out_onto_an_input_is_refused(capsys, tmp_path, problem_file, monkeypatch):
    import rfverify.verify.certification

    monkeypatch.setattr(rfverify.verify.certification, "certify",
                        lambda *a, **k: pytest.fail("certify ran before the output check"))
    sol = tmp_path / "sol.h5"
    code, _, err = run(capsys, "solve", problem_file, "--tol", "1e-8", "--out", sol)
    assert code == 0, err
    for victim in (problem_file, sol):
        before = victim.read_bytes()
        refused(capsys, "certify", problem_file, "--solution", sol, "--out", victim,
                expect=["input", "--out"])
        assert victim.read_bytes() == before


def snapshot(path) -> dict:
    """Every object of an HDF5 file: kind, dtype, shape, data bytes and attributes."""
    out = {}

    def attrs(obj):
        return {k: np.asarray(v).tobytes() + str(np.asarray(v).dtype).encode() for k, v in obj.attrs.items()}

    with h5py.File(path, "r") as fh:
        out["/"] = ("group", attrs(fh))

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset):
                out["/" + name] = ("dataset", str(obj.dtype), obj.shape, np.asarray(obj[()]).tobytes(),
                                   attrs(obj))
            else:
                out["/" + name] = ("group", attrs(obj))

        fh.visititems(visit)
    return out


def test_solve_into_its_own_hdf5_keeps_everything_else(capsys, problem_file):
    old = {k: np.full(n, 7.0) for k, n in (("v", 12), ("u", 15), ("r", 15))}
    with h5py.File(problem_file, "r+") as fh:
        user = fh.create_group("user")
        user.create_dataset("notes", data=np.arange(5, dtype=np.int16))
        user["notes"].attrs["unit"] = "s"
        fh[ROOT].attrs["origin"] = "hand-made"
        fh[ROOT]["info"].create_dataset("author", data=np.bytes_(b"someone"))
        fh[ROOT]["info"].attrs["version"] = 3
        sol = fh.create_group("solution")
        sol.attrs["solver"] = "old"
        for k, v in old.items():
            sol.create_dataset(k, data=v)
        sol.create_dataset("l", data=np.ones(2))
    problem_file.chmod(0o640)
    before = snapshot(problem_file)
    code, out, err = run(capsys, "solve", problem_file, "--tol", "1e-8", "--out", problem_file)
    assert code == 0, err
    after = snapshot(problem_file)
    replaced = {"/solution/v", "/solution/u", "/solution/r"}
    assert set(after) == set(before)
    for name in set(before) - replaced - {"/solution"}:
        assert after[name] == before[name], name
    # /solution keeps its own attributes and gains the documented ones (layout, the problem it
    # solves and its equations, what was symmetrised, both asymmetry measures); nothing else changes.
    added = {"layout", "problem", "equations", "symmetrised", "symmetrised_matrix", "asymmetry_entrywise",
             "asymmetry_normwise"}
    kind, attrs_after = after["/solution"]
    assert kind == before["/solution"][0]
    assert {k: v for k, v in attrs_after.items() if k not in added} == before["/solution"][1]
    assert set(attrs_after) == set(before["/solution"][1]) | added
    assert stat.S_IMODE(problem_file.stat().st_mode) == 0o640
    res = rfverify.solve(rfverify.load(problem_file), tol=1e-8)
    with h5py.File(problem_file, "r") as fh:
        for k in ("v", "u", "r"):
            np.testing.assert_array_equal(fh["solution"][k][()], getattr(res, k))
    assert sorted(p.name for p in problem_file.parent.iterdir()) == ["in.hdf5"]  # no temporaries
    check = rfverify.check_solution(rfverify.load(problem_file), rfverify.load(problem_file).solution)
    assert check.ok(1e-6)


def test_solve_into_a_copy_writes_a_new_file(capsys, tmp_path, problem_file):
    out = tmp_path / "out.h5"
    out.write_bytes(b"old content")
    code, _, err = run(capsys, "solve", problem_file, "--tol", "1e-8", "--out", out)
    assert code == 0, err
    assert rfverify.load(out).solution is not None


# ---------------------------------------------------------------------- non-regular targets
def test_fifo_target_is_refused_and_kept(capsys, tmp_path, no_solve):
    fifo = tmp_path / "pipe.h5"
    os.mkfifo(fifo)
    refused(capsys, "solve", "bundled:sphere", "--out", fifo, expect=["FIFO"])
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)
    with pytest.raises(OutputPathError, match="FIFO"):
        rfverify.save(rfverify.load("bundled:sphere"), fifo)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_directory_target_is_refused(capsys, tmp_path, no_solve, monkeypatch):
    import rfverify.verify.certification

    monkeypatch.setattr(rfverify.verify.certification, "certify",
                        lambda *a, **k: pytest.fail("certify ran before the output check"))
    refused(capsys, "solve", "bundled:sphere", "--out", tmp_path, expect=["directory"])
    refused(capsys, "certify", "bundled:sphere", "--out", tmp_path, expect=["directory"])


def test_symlink_to_fifo_is_refused(capsys, tmp_path, no_solve):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    link = tmp_path / "link.h5"
    link.symlink_to(fifo)
    refused(capsys, "solve", "bundled:sphere", "--out", link, expect=["FIFO"])
    assert link.is_symlink() and stat.S_ISFIFO(os.lstat(fifo).st_mode)


def test_symlink_is_written_through_never_replaced(capsys, tmp_path):
    target = tmp_path / "real.h5"
    target.write_bytes(b"old")
    link = tmp_path / "link.h5"
    link.symlink_to(target)
    code, _, err = run(capsys, "solve", "bundled:sphere", "--tol", "1e-8", "--out", link)
    assert code == 0, err
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert rfverify.load(target).solution is not None
    dangling = tmp_path / "dangling.h5"
    dangling.symlink_to(tmp_path / "new.h5")
    code, _, err = run(capsys, "solve", "bundled:sphere", "--tol", "1e-8", "--out", dangling)
    assert code == 0, err
    assert dangling.is_symlink() and (tmp_path / "new.h5").is_file()


# ---------------------------------------------------------------------- checked before the work
def test_missing_directory_is_refused_before_solving(capsys, tmp_path, no_solve):
    refused(capsys, "solve", "bundled:sphere", "--out", tmp_path / "no" / "x.h5",
            expect=["does not exist", "mkdir"])


def test_read_only_directory_is_refused_before_solving(capsys, no_solve):
    """Mode bits, enforced: as an ordinary user (root drops to nobody, tests/privileges.py)."""
    with world_traversable_dir() as folder:
        ro = folder / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        with as_ordinary_user():
            assert not os.access(ro, os.W_OK, effective_ids=os.access in os.supports_effective_ids)
            refused(capsys, "solve", "bundled:sphere", "--out", ro / "x.h5", expect=["not writable"])


def test_unwritable_directory_is_refused_before_solving_even_as_root(capsys, tmp_path, no_solve,
                                                                     monkeypatch):
    """The writability probe is a real file creation; here it fails as it would on a
    read-only mount (root cannot be denied by permissions)."""
    import tempfile

    real = tempfile.mkstemp

    def denied(*args, dir=None, **kwargs):
        if str(dir) == str(tmp_path):
            raise PermissionError(13, "Permission denied")
        return real(*args, dir=dir, **kwargs)

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    refused(capsys, "solve", "bundled:sphere", "--out", tmp_path / "x.h5", expect=["not writable"])


def test_generate_out_naming_a_file_is_refused_before_any_work(capsys, tmp_path, monkeypatch):
    import rfverify.scenes

    monkeypatch.setattr(rfverify.scenes, "generate",
                        lambda *a, **k: pytest.fail("generated before checking --out"))
    path = tmp_path / "afile"
    path.write_text("keep me")
    refused(capsys, "generate", "spherespile", "--size", "3", "--out", path,
            expect=["not a directory"])
    assert path.read_text() == "keep me"


def test_bench_out_naming_a_file_is_refused(capsys, tmp_path):
    path = tmp_path / "afile"
    path.write_text("keep me")
    refused(capsys, "bench", "bundled:sphere", "--out", path, expect=["not a directory"])
    assert path.read_text() == "keep me"


def test_failed_write_leaves_the_old_file(tmp_path):
    path = tmp_path / "out.h5"
    path.write_bytes(b"precious")
    p = rfverify.load("bundled:sphere")
    bad = rfverify.Problem.from_arrays(p.M, p.H, p.f, p.w, p.mu, p.mu_r, title="bad \ud800")
    with pytest.raises(UnicodeEncodeError):
        rfverify.save(bad, path)
    assert path.read_bytes() == b"precious"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out.h5"]
