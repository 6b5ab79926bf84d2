"""Issue 17, bad input: every case is exit 2 with one line on stderr naming the file, the field
and a fix — never exit 3 ("internal error"), never silently read as something else.

Every bad file is built here (h5py / text), from a small valid problem."""

from __future__ import annotations

import os
import tracemalloc

import h5py
import numpy as np
import pytest

import rfverify
from rfverify.cli import main
from rfverify.errors import InvalidArgumentError, RfverifyError
from rfverify.io import write_fclib
from rfverify.scenes.random_problems import random_problem

from privileges import as_ordinary_user, world_traversable_dir


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def one_line_error(capsys, *argv, names=(), forbid=()):
    """Exit 2, nothing on stdout, one stderr line with the file, the fields in ``names`` and a fix."""
    code, out, err = run(capsys, *argv)
    assert code == 2, (code, err)
    assert out == ""
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"rfverify {argv[0]}: error: "), err
    assert "internal error" not in err and "Traceback" not in err
    assert "fix:" in err, err
    for text in names:
        assert str(text) in err, (text, err)
    for text in forbid:
        assert text not in err, (text, err)
    return err


@pytest.fixture
def good(tmp_path):
    """A small valid FCLIB file (triplet storage, as real files have)."""
    path = tmp_path / "good.hdf5"
    write_fclib(random_problem(2, 3, seed=5), path, storage="triplet")
    return path


def mutate(path, fn):
    with h5py.File(path, "r+") as fh:
        fn(fh)
    return path


def replace(fh, name, data=None, **kw):
    del fh[name]
    if data is not None:
        fh.create_dataset(name, data=data, **kw)


ROOT = "fclib_global_rolling"


# ---------------------------------------------------------------------- HDF5 files
def test_good_file_is_accepted(capsys, good):
    code, out, err = run(capsys, "info", good)
    assert code == 0 and err == ""


def test_huge_m_is_refused_before_allocating(capsys, good):
    for key in ("m", "n"):
        mutate(good, lambda fh: replace(fh, f"{ROOT}/M/{key}", np.array([2**31 - 1], np.int32)))
    tracemalloc.start()
    try:
        err = one_line_error(capsys, "info", good, names=[good, "M", "2147483647"])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6, f"{peak / 1e6:.0f} MB allocated before refusing"
    assert "vectors/f" in err


def test_huge_declared_vector_is_refused_before_allocating(capsys, good):
    # An HDF5 dataset may be declared far larger than what is stored (fill values).
    mutate(good, lambda fh: (replace(fh, f"{ROOT}/vectors/f"),
                             fh.create_dataset(f"{ROOT}/vectors/f", shape=(2**30,), dtype="f8")))
    tracemalloc.start()
    try:
        one_line_error(capsys, "info", good, names=[good, "vectors/f"])
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 50e6


@pytest.mark.parametrize("case, names", [
    ("empty m", ["/M/m", "empty"]),
    ("spacedim string", ["spacedim", "strings"]),
    ("root a dataset", [f"/{ROOT}", "is a dataset, expected a group"]),
    ("M dense", [f"/{ROOT}/M", "dense"]),
    ("f a group", ["vectors/f", "is a group, expected a dataset"]),
    ("x compound", ["M/x", "compound"]),
    ("x complex", ["M/x", "complex"]),
    ("p fractional", ["M/p", "floating-point"]),
    ("p integral floats", ["M/p", "floating-point"]),
    ("nz float", ["M/nz", "floating-point"]),
    ("i strings", ["M/i", "strings"]),
    ("x strings", ["M/x", "strings"]),
    ("x longdouble inexact", ["M/x", "cannot represent exactly"]),
    ("mu 2-D", ["vectors/mu", "shape"]),
    ("dangling soft link", ["vectors/w", "SoftLink"]),
    ("missing external file", ["vectors/w", "ExternalLink"]),
    ("solution a dataset", ["/solution", "expected a group"]),
    # Odd info/* metadata (not UTF-8, a number, ...) is read with a warning, not refused:
    # tests/test_info_metadata.py.
    ("guesses count float", ["number_of_guesses", "floating-point"]),
    ("negative n", ["/H/n", "outside"]),
    ("index out of range", ["M/i", "out of range"]),
])
def test_malformed_hdf5_is_one_line_exit_2(capsys, good, case, names):
    def apply(fh):
        g = fh[ROOT]
        if case == "empty m":
            replace(fh, f"{ROOT}/M/m", np.array([], np.int32))
        elif case == "spacedim string":
            replace(fh, f"{ROOT}/spacedim", np.bytes_(b"5"))
        elif case == "root a dataset":
            del fh[ROOT]
            fh[ROOT] = np.arange(3.0)
        elif case == "M dense":
            del g["M"]
            g["M"] = np.eye(12)
        elif case == "f a group":
            del g["vectors/f"]
            g["vectors"].create_group("f")
        elif case == "x compound":
            x = g["M/x"][()]
            rec = np.zeros(x.size, dtype=[("re", "f8"), ("im", "f8")])
            rec["re"] = x
            replace(fh, f"{ROOT}/M/x", rec)
        elif case == "x complex":
            replace(fh, f"{ROOT}/M/x", g["M/x"][()] + 0j)
        elif case == "p fractional":
            replace(fh, f"{ROOT}/M/p", g["M/p"][()] + 0.5)
        elif case == "p integral floats":
            replace(fh, f"{ROOT}/M/p", g["M/p"][()].astype(np.float64))
        elif case == "nz float":
            replace(fh, f"{ROOT}/M/nz", g["M/nz"][()].astype(np.float64))
        elif case == "i strings":
            replace(fh, f"{ROOT}/M/i", np.array([str(k).encode() for k in g["M/i"][()]]))
        elif case == "x strings":
            replace(fh, f"{ROOT}/M/x", np.array([repr(k).encode() for k in g["M/x"][()]]))
        elif case == "x longdouble inexact":
            x = g["M/x"][()].astype(np.longdouble)
            x[0] += np.longdouble(x[0]) * np.finfo(np.longdouble).eps
            if np.finfo(np.longdouble).eps >= np.finfo(np.float64).eps:
                pytest.skip("longdouble is float64 on this platform")
            replace(fh, f"{ROOT}/M/x", x)
        elif case == "mu 2-D":
            mu = g["vectors/mu"][()]
            replace(fh, f"{ROOT}/vectors/mu", np.vstack([mu, mu]))
        elif case == "dangling soft link":
            del g["vectors/w"]
            g["vectors/w"] = h5py.SoftLink("/nowhere")
        elif case == "missing external file":
            del g["vectors/w"]
            g["vectors/w"] = h5py.ExternalLink("missing-file.h5", "/w")
        elif case == "solution a dataset":
            fh["solution"] = np.zeros(3)
        elif case == "guesses count float":
            gg = fh.create_group("guesses")
            gg["number_of_guesses"] = np.array([0.0])
        elif case == "negative n":
            replace(fh, f"{ROOT}/H/n", np.array([-5], np.int32))
        elif case == "index out of range":
            i = g["M/i"][()]
            i[0] = 10**6
            replace(fh, f"{ROOT}/M/i", i)

    before = good.read_bytes()
    mutate(good, apply)
    mutated = good.read_bytes()
    one_line_error(capsys, "info", good, names=[good, *names])
    assert good.read_bytes() == mutated != before  # read, never written


def test_complex_x_is_not_solved_as_real(good):
    mutate(good, lambda fh: replace(fh, f"{ROOT}/M/x", fh[f"{ROOT}/M/x"][()] + 0j))
    with pytest.raises(rfverify.ProblemFileError, match="complex"):
        rfverify.load(good)


def test_all_zero_unwritten_solution_is_read(tmp_path):
    # Real files (the Siconos Chute file) declare /solution datasets whose data were never
    # written: they read as fill values (zeros), which info then reports; not an error.
    path = tmp_path / "unwritten.hdf5"
    p = random_problem(2, 3, seed=1)
    write_fclib(p, path)
    with h5py.File(path, "r+") as fh:
        fh.create_group("solution").create_dataset("v", shape=(p.n_dofs,), dtype="f8")
    q = rfverify.load(path)
    assert np.all(q.solution.v == 0)


def _unreadable_info(capsys, name: str, content: bytes):
    """`info` on a mode-000 file, run as an ordinary user (root drops to nobody: see
    tests/privileges.py), where the operating system really refuses the read."""
    with world_traversable_dir() as folder:
        path = folder / name
        path.write_bytes(content)
        path.chmod(0)
        with as_ordinary_user():
            with pytest.raises(PermissionError):
                open(path, "rb").close()
            one_line_error(capsys, "info", path, names=[path, "permission denied"])


def test_unreadable_hdf5(capsys, good):
    _unreadable_info(capsys, "good.hdf5", good.read_bytes())


def test_unreadable_dat(capsys):
    _unreadable_info(capsys, "locked.dat", local_dat().encode())


@pytest.mark.parametrize("name", ["p.hdf5", "p.dat"])
def test_permission_error_is_one_line_even_as_root(capsys, good, tmp_path, monkeypatch, name):
    """Root reads any file, so the unreadable case is also simulated: open() raising
    PermissionError, as it does for an ordinary user on a mode-000 file."""
    import builtins

    path = tmp_path / name
    path.write_bytes(good.read_bytes() if name.endswith(".hdf5") else local_dat().encode())
    real_open = builtins.open

    def guarded(file, *args, **kwargs):
        if str(file) == str(path):
            raise PermissionError(13, "Permission denied", str(file))
        return real_open(file, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", guarded)
    one_line_error(capsys, "info", path, names=[path, "permission denied", "chmod"])


def test_fifo_input_is_refused_without_blocking(capsys, tmp_path):
    fifo = tmp_path / "pipe.hdf5"
    os.mkfifo(fifo)
    one_line_error(capsys, "info", fifo, names=[fifo, "not a regular file"])


def test_huge_diagonal_is_not_smallest_eigenvalue_inf(capsys, tmp_path):
    p = random_problem(2, 3, seed=2)
    M = p.M.toarray()
    M[0, 0] = 1e308
    path = tmp_path / "big.hdf5"
    write_fclib(rfverify.Problem.from_arrays(M, p.H, p.f, p.w, p.mu, p.mu_r), path)
    code, out, err = run(capsys, "info", path)
    assert code == 0, err
    assert "eigenvalue inf" not in out and " inf" not in out
    line = next(x for x in out.splitlines() if "smallest block eigenvalue" in x)
    assert np.isfinite(float(line.split()[-1]))


# ---------------------------------------------------------------------- .dat files
def local_dat(q=None, W=None):
    """A one-contact local problem (dense W, column-major) as Siconos prints it."""
    W = np.diag([1.0, 1.01, 1.01, 1.0, 1.0]) if W is None else W
    q = [-8.9, 0.19, 0.0, 0.0, -1.0] if q is None else q
    flat = W.ravel(order="F")
    body = "\n".join(" ".join(f"{x:.17e}" for x in flat[5 * k:5 * k + 5]) for k in range(5))
    return ("5\n1\n0\n5\n5\n5\t5\n" + body + "\n" + " ".join(f"{x!r}" for x in q)
            + "\n0.6\n0.5\n")


def test_local_dat_is_read(capsys, tmp_path):
    path = tmp_path / "ok.dat"
    path.write_text(local_dat())
    code, _, err = run(capsys, "info", path)
    assert code == 0, err


def test_nan_in_q_is_reported_as_q(capsys, tmp_path):
    path = tmp_path / "nanq.dat"
    path.write_text(local_dat(q=[-8.9, float("nan"), 0.0, 0.0, -1.0]))
    err = one_line_error(capsys, "info", path, names=[path, "q[1]", "non-finite"], forbid=["w["])
    assert "w[" not in err
    with pytest.raises(rfverify.InvalidProblemError) as info:
        rfverify.load(path)
    assert info.value.field == "q" and info.value.index == 1 and info.value.path == str(path)


def test_utf8_dat_is_not_called_binary(capsys, tmp_path):
    path = tmp_path / "utf8.dat"
    path.write_text(local_dat().replace("-8.9", "\u22128.9"), encoding="utf-8")
    one_line_error(capsys, "info", path, names=[path, "UTF-8", "non-ASCII", "line 12"],
                   forbid=["binary"])


def test_binary_dat_is_called_binary(capsys, tmp_path):
    path = tmp_path / "bin.dat"
    path.write_bytes(b"5\n1\n" + bytes(range(128, 256)))
    one_line_error(capsys, "info", path, names=[path, "binary"])


@pytest.mark.parametrize("edit, names", [
    (lambda t: t.replace("5\n1\n0\n5\n5", "5\n1\n0\n500000000000\n5", 1), ["line", "more than the file"]),
    (lambda t: t.replace("5\n1\n0", "5\n99999999999\n0", 1), ["nc", "more than the file"]),
    (lambda t: t.replace("5\n1\n0", "5\n1234567890123456789012345\n0", 1), ["line 2", "integer"]),
    (lambda t: t.replace("5\n1\n0", "5\n1\n2", 1), ["line 6", "sparse origin"]),
    (lambda t: t.replace("0.6\n", "-0.6\n"), ["mu", "negative"]),
    (lambda t: t.replace("0.6\n", "inf\n"), ["mu[0]", "non-finite"]),
    (lambda t: t[: len(t) // 2], ["fix:"]),
])
def test_malformed_dat_is_one_line_exit_2(capsys, tmp_path, edit, names):
    path = tmp_path / "bad.dat"
    path.write_text(edit(local_dat()))
    one_line_error(capsys, "info", path, names=[path, *names])


def test_huge_entry_in_local_w_is_not_an_internal_error(capsys, tmp_path):
    W = np.diag([1e308, 1.01, 1.01, 1.0, 1.0])
    path = tmp_path / "bigw.dat"
    path.write_text(local_dat(W=W))
    code, out, err = run(capsys, "info", path)
    assert code in (0, 2) and "internal error" not in err
    if code == 0:
        assert " inf" not in out and "nan" not in out.lower()


# ---------------------------------------------------------------------- Python API types
@pytest.mark.parametrize("call", [
    lambda p: rfverify.load(None),
    lambda p: rfverify.load(3.5),
    lambda p: rfverify.load(""),
    lambda p: rfverify.load("bundled:sphere", max_asymmetry="big"),
    lambda p: rfverify.solve(p, tol="1e-8"),
    lambda p: rfverify.solve(p, "jqinv", "1e-8"),
    lambda p: rfverify.solve(p, tol=float("nan")),
    lambda p: rfverify.solve(p, tol=float("inf")),
    lambda p: rfverify.solve(p, tol=-1.0),
    lambda p: rfverify.solve(p, max_iter=2.5),
    lambda p: rfverify.solve(p, method="newton"),
    lambda p: rfverify.solve(p, no_such_option=True),
    lambda p: rfverify.solve(None),
    lambda p: rfverify.solve("bundled:sphere"),
    lambda p: rfverify.certify(None, np.zeros(3)),
    lambda p: rfverify.check_solution(None, None),
    lambda p: rfverify.diagnose(p, tol="small"),
    lambda p: rfverify.save(p, ""),
])
def test_api_wrong_types_raise_the_package_error(call):
    p = rfverify.load("bundled:sphere")
    with pytest.raises(RfverifyError) as info:
        call(p)
    assert "fix:" in str(info.value)
    assert not isinstance(info.value, (AttributeError, KeyError))


def test_invalid_argument_error_is_also_type_and_value_error():
    assert issubclass(InvalidArgumentError, TypeError) and issubclass(InvalidArgumentError, ValueError)
    assert issubclass(InvalidArgumentError, RfverifyError)


# ---------------------------------------------------------------------- CLI arguments
@pytest.mark.parametrize("argv", [
    ["solve", "bundled:sphere", "--tol", "inf"],
    ["solve", "bundled:sphere", "--tol", "nan"],
    ["solve", "bundled:sphere", "--tol", "-inf"],
    ["diagnose", "bundled:sphere", "--tol", "inf"],
    ["diagnose", "bundled:sphere", "--tol", "NaN"],
    ["info", "bundled:sphere", "--solution-tol", "inf"],
    ["bench", "bundled:sphere", "--out", "RUN", "--tol", "1e-8,inf"],
    ["bench", "bundled:sphere", "--out", "RUN", "--trajectory-tol", "inf"],
    ["solve", "bundled:sphere", "--out", ""],
    ["certify", "bundled:sphere", "--out", ""],
    ["generate", "chute", "--out", ""],
    ["bench", "bundled:sphere", "--out", ""],
])
def test_bad_arguments_are_refused_at_parsing(capsys, tmp_path, argv):
    argv = [str(tmp_path / a) if a == "RUN" else a for a in argv]
    with pytest.raises(SystemExit) as ex:
        main(argv)
    assert ex.value.code == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert not (tmp_path / "RUN").exists()
