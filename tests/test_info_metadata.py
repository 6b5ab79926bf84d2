"""Optional metadata never blocks a problem (DESIGN §7.1, rfverify.io._hdf5.read_info).

``info/title``, ``info/description`` and ``info/math_info`` do not change the problem.  A real
LMGC90 FCLIB file has the Latin-1 byte 0xA8 in its description: such a file is read (the bytes
decoded with U+FFFD in their place) and solved, with a :class:`rfverify.DataWarning` naming the
file, the dataset and what was done; the CLI prints it as one line on stderr and exits 0.
Anything else odd under ``info`` (numbers, a group, several strings, a broken link) is read
with a warning too.  Errors in the *problem data* are still refused (tests/test_hardening_inputs.py).
"""

from __future__ import annotations

import shutil

import h5py
import numpy as np
import pytest

import rfverify
from rfverify import DataWarning, Status
from rfverify.cli import main
from rfverify.io import bundled_problems

from test_fclib3d import GLOBAL_SCENES, LOCAL_SCENE, local_from, scene_3d, write_global, write_local

LMGC90 = b"LMGC90 \xa8 cube"  # 0xA8 is '¨' in Latin-1, no UTF-8 sequence
READ_AS = "LMGC90 \ufffd cube"
ROLLING = "fclib_global_rolling"


def put_description(group, kind: str, data=LMGC90):
    """info/description as a fixed-length or a variable-length bytes dataset."""
    info = group.require_group("info")
    if "description" in info:
        del info["description"]
    if kind == "fixed":
        info.create_dataset("description", data=np.bytes_(data))
    elif kind == "vlen":
        info.create_dataset("description", data=data, dtype=h5py.string_dtype("ascii"))
    else:  # variable length, tagged UTF-8 although it is not
        info.create_dataset("description", data=data, dtype=h5py.string_dtype("utf-8"))


def chute_copy(tmp_path, kind):
    path = tmp_path / f"chute-{kind}.hdf5"
    shutil.copyfile(bundled_problems()["chute"], path)
    with h5py.File(path, "r+") as fh:
        put_description(fh[ROLLING], kind)
    return path


def global_3d(tmp_path, kind):
    M, H3, f, w3, mu = scene_3d(GLOBAL_SCENES[0])
    return write_global(tmp_path / f"g3-{kind}.hdf5", M, H3, f, w3, mu,
                        mutate=lambda fh: put_description(fh["fclib_global"], kind))


def local_3d(tmp_path, kind):
    M, H3, f, w3, mu = scene_3d(LOCAL_SCENE)
    W, q = local_from(M, H3, f, w3)
    return write_local(tmp_path / f"l3-{kind}.hdf5", W, q, mu,
                       mutate=lambda fh: put_description(fh["fclib_local"], kind))


MAKERS = {"rolling": chute_copy, "global-3d": global_3d, "local-3d": local_3d}
KINDS = ["fixed", "vlen", "vlen-utf8"]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("layout", sorted(MAKERS))
def test_non_utf8_description_is_read_with_a_warning_and_solved(tmp_path, layout, kind):
    path = MAKERS[layout](tmp_path, kind)
    with pytest.warns(DataWarning) as caught:
        p = rfverify.load(path)
    assert p.description == READ_AS
    [w] = [w for w in caught if issubclass(w.category, DataWarning)]
    msg = str(w.message)
    for text in (str(path), "info/description", "not valid UTF-8", "byte 7 is 0xa8", "U+FFFD",
                 "problem itself is read unchanged"):
        assert text in msg, (text, msg)
    res = rfverify.solve(p)
    assert res.status is Status.SOLVED, res.message


def test_the_problem_read_is_the_one_without_the_odd_description(tmp_path):
    """Only the description differs: every array is the bundled file's, bit for bit."""
    ref = rfverify.load("bundled:chute")
    with pytest.warns(DataWarning):
        p = rfverify.load(chute_copy(tmp_path, "fixed"))
    for name in ("f", "w", "mu", "mu_r"):
        assert np.array_equal(np.asarray(getattr(p, name)).view(np.uint64),
                              np.asarray(getattr(ref, name)).view(np.uint64)), name
    for name in ("M", "H"):
        assert (getattr(p, name) != getattr(ref, name)).nnz == 0, name
    assert p.title == ref.title and p.math_info == ref.math_info


@pytest.mark.parametrize("command", [["info"], ["info", "--json"], ["solve"], ["solve", "--json"]])
@pytest.mark.parametrize("layout", sorted(MAKERS))
def test_cli_shows_one_warning_line_and_exits_0(tmp_path, capsys, layout, command):
    path = MAKERS[layout](tmp_path, "fixed")
    capsys.readouterr()
    code = main([command[0], str(path), *command[1:]])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert err.startswith(f"rfverify {command[0]}: warning: {path}: /"), err
    assert "info/description" in err and "UTF-8" in err and "Traceback" not in err
    if "--json" in command:  # stdout stays strict JSON
        import json

        json.loads(out)


def test_solve_out_writes_the_replacement_and_rereads_silently(tmp_path, capsys):
    path = chute_copy(tmp_path, "vlen")
    out = tmp_path / "solved.hdf5"
    assert main(["solve", str(path), "--out", str(out)]) == 0
    assert "warning:" in capsys.readouterr().err
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        assert rfverify.load(out).description == READ_AS  # valid UTF-8 now


def test_a_problem_error_is_still_one_line_even_with_a_bad_description(tmp_path, capsys):
    """A file that is refused for its data says only that (one line), not the info warning."""
    path = chute_copy(tmp_path, "fixed")
    with h5py.File(path, "r+") as fh:
        f = fh[f"{ROLLING}/vectors/f"]
        data = f[()]
        data[0] = np.nan
        f[...] = data
    capsys.readouterr()
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("rfverify info: error: ") and "warning" not in err


# ---------------------------------------------------------------------- other odd info
def _replace(fh, name, data=None, **kw):
    if fh.get(name, getlink=True) is not None:
        del fh[name]
    if data is not None:
        fh.create_dataset(name, data=data, **kw)


ODD_INFO = {
    # case: (how to make it, title read, words of the warning; None: no warning)
    "title a number": (lambda fh: _replace(fh, f"{ROLLING}/info/title", np.array([3.0])),
                       "", ["info/title", "float64 values, not a string", "empty string"]),
    "title an integer scalar": (lambda fh: _replace(fh, f"{ROLLING}/info/title", np.int32(7)),
                                "", ["info/title", "int32", "empty string"]),
    "title compound": (lambda fh: _replace(fh, f"{ROLLING}/info/title",
                                           np.zeros(1, dtype=[("a", "f8"), ("b", "i4")])),
                       "", ["info/title", "not a string"]),
    "title several strings": (lambda fh: _replace(fh, f"{ROLLING}/info/title",
                                                  np.array([b"line 1", b"line \xff2"])),
                              "line 1\nline \ufffd2", ["info/title", "2 strings", "joined with newlines",
                                                       "not valid UTF-8", "in string 1"]),
    "title an empty array": (lambda fh: _replace(fh, f"{ROLLING}/info/title", np.array([], dtype="S3")),
                             "", None),
    "title null dataspace": (lambda fh: _replace(fh, f"{ROLLING}/info/title", h5py.Empty("S10")),
                             "", None),
    "title a group": (lambda fh: (_replace(fh, f"{ROLLING}/info/title"),
                                  fh.create_group(f"{ROLLING}/info/title")),
                      "", ["info/title", "is a group, expected a dataset", "empty string"]),
    "title a dangling link": (lambda fh: (_replace(fh, f"{ROLLING}/info/title"),
                                          fh[f"{ROLLING}/info"].__setitem__("title", h5py.SoftLink("/nowhere"))),
                              "", ["info/title", "SoftLink", "empty string"]),
    "vlen ints": (lambda fh: (_replace(fh, f"{ROLLING}/info/title"),
                              fh.create_dataset(f"{ROLLING}/info/title", shape=(1,),
                                                dtype=h5py.vlen_dtype(np.int64)).__setitem__(0, np.arange(3))),
                  "", ["info/title", "ndarray objects, not strings"]),
    "info a dataset": (lambda fh: (_replace(fh, f"{ROLLING}/info"), fh.create_dataset(f"{ROLLING}/info", data=[1.0])),
                       "", ["/fclib_global_rolling/info", "expected a group", "title, description and math_info"]),
}


@pytest.mark.parametrize("case", sorted(ODD_INFO))
def test_odd_info_never_blocks_the_problem(tmp_path, capsys, case):
    make, title, words = ODD_INFO[case]
    path = tmp_path / "odd.hdf5"
    shutil.copyfile(bundled_problems()["chute"], path)
    with h5py.File(path, "r+") as fh:
        make(fh)
    import warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        p = rfverify.load(path)
    data_warnings = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert p.title == title
    if words is None:
        assert data_warnings == []
    else:
        text = " | ".join(data_warnings)
        assert data_warnings and all(str(path) in w for w in data_warnings), text
        for word in words:
            assert word in text, (word, text)
    ref = rfverify.load("bundled:chute")
    assert (p.M != ref.M).nnz == 0 and np.array_equal(p.f, ref.f)
    capsys.readouterr()
    assert main(["info", str(path)]) == 0
    err = capsys.readouterr().err
    assert all(line.startswith("rfverify info: warning: ") for line in err.splitlines()), err
    assert len(err.splitlines()) == (0 if words is None else len(set(data_warnings)))
