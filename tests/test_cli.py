"""`rfverify info`: output, JSON, one-line errors with exit code 2, --help."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from rfverify.cli import build_parser, main


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_info_json_chute(capsys, real_data):
    code, out, err = run(capsys, "info", str(real_data / "Chute-ndof-768-nc-4-3.hdf5"), "--json")
    assert code == 0, err
    s = json.loads(out)
    assert s["n"] == 4 and s["m"] == 768
    assert s["nnz"] == {"M": 1536, "H": 91}
    assert s["M_asymmetry"]["scaled"] > 0 and s["M_asymmetry"]["symmetrised"]
    assert s["storage"] == {"M": "triplet", "H": "triplet"}
    assert s["mu"] == {"min": 1.0, "max": 1.0, "zero_count": 0}
    assert s["mu_r"]["zero_count"] == 0
    assert s["solution"]["consistent"] is False
    assert sorted(s["solution"]["zero"]) == ["r", "v"]
    assert s["M_blocks"]["contact_free_dofs"] == 768 - 24  # 4 bodies touched, 124 free


def test_info_text_bundled(capsys):
    code, out, err = run(capsys, "info", "bundled:chute")
    assert code == 0, err
    assert "m = 768 dofs, n = 4 contacts" in out
    assert "v, r all zero" in out
    assert "symmetrised" in out


@pytest.mark.parametrize("name", ["chute-dat", "sphere", "cube", "sphere-from-global"])
def test_info_every_bundled(capsys, name):
    code, out, err = run(capsys, "info", f"bundled:{name}", "--json")
    assert code == 0, err
    json.loads(out)


def test_max_asymmetry_option(capsys):
    code, out, err = run(capsys, "info", "bundled:chute", "--max-asymmetry", "1e-4")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "M[" in err and "max_asymmetry" in err
    code, _, _ = run(capsys, "info", "bundled:chute", "--max-asymmetry", "inf")
    assert code == 0


def _one_line_error(capsys, *argv, expect=""):
    code, out, err = run(capsys, *argv)
    assert code == 2
    assert out == ""
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert "Traceback" not in err
    assert expect in err, err
    return err


def test_errors_missing_file(capsys, tmp_path):
    _one_line_error(capsys, "info", str(tmp_path / "none.hdf5"), expect="no such file")


def test_errors_truncated(capsys, real_data, tmp_path):
    p = tmp_path / "t.hdf5"
    p.write_bytes((real_data / "Chute-ndof-768-nc-4-3.hdf5").read_bytes()[:5000])
    _one_line_error(capsys, "info", str(p), expect="t.hdf5")


def test_errors_not_hdf5(capsys, tmp_path):
    p = tmp_path / "x.hdf5"
    p.write_text("nope")
    _one_line_error(capsys, "info", str(p), expect="not an HDF5 file")


def _replace(fh, name, value):
    del fh[name]
    fh[name] = value


def _set_entry(fh, name, index, value):
    fh[name][index] = value


DAMAGED_CHUTE = [  # (what is done to a copy of the Chute file, what the error line must name)
    pytest.param(lambda fh: fh.__delitem__("fclib_global_rolling/vectors"),
                 "/fclib_global_rolling/vectors", id="missing-group"),
    pytest.param(lambda fh: _set_entry(fh, "fclib_global_rolling/M/x", 3, np.nan), "M[", id="nan"),
    pytest.param(lambda fh: _replace(fh, "fclib_global_rolling/vectors/mu_r", np.array([0.1, 0.1, 0.1])),
                 "mu_r", id="wrong-sizes"),
]


@pytest.mark.parametrize("damage, expect", DAMAGED_CHUTE)
def test_errors_damaged_file(capsys, real_data, tmp_path, damage, expect):
    p = tmp_path / "damaged.hdf5"
    shutil.copy(real_data / "Chute-ndof-768-nc-4-3.hdf5", p)
    p.chmod(0o644)
    with h5py.File(p, "r+") as fh:
        damage(fh)
    _one_line_error(capsys, "info", str(p), expect=expect)


def test_errors_bad_option(capsys):
    with pytest.raises(SystemExit) as ex:
        main(["info", "bundled:chute", "--solution-tol", "-1"])
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "must be > 0" in err


def test_help_documents_every_option():
    parser = build_parser()
    info = parser._subparsers._group_actions[0].choices["info"]
    text = info.format_help()
    for action in info._actions:
        for opt in action.option_strings:
            assert opt in text
        if action.dest != "help":
            assert action.help, f"option {action.dest} lacks help"


def test_console_script_one_line_error(tmp_path):
    # The installed entry point (or `python -m rfverify`) behaves the same as main().
    exe = shutil.which("rfverify")
    cmd = [exe] if exe else [sys.executable, "-m", "rfverify"]
    proc = subprocess.run(cmd + ["info", str(tmp_path / "missing.hdf5")], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and "no such file" in proc.stderr


def test_solve_out_to_missing_directory_is_one_line(capsys, tmp_path):
    _one_line_error(capsys, "solve", "bundled:cube", "--out", str(tmp_path / "no" / "x.h5"),
                    expect="does not exist")


def test_solve_quiet_silences_the_progress_lines(capsys):
    """TUTORIAL: the `rfverify solve:` progress lines of --digits go to stderr and --quiet
    silences them; the result still goes to stdout."""
    from rfverify.cli import main

    assert main(["solve", "bundled:sphere", "--digits", "6"]) == 0
    loud = capsys.readouterr()
    assert "rfverify solve: extended phase" in loud.err
    assert main(["solve", "bundled:sphere", "--digits", "6", "--quiet"]) == 0
    quiet = capsys.readouterr()
    assert quiet.err == "" and quiet.out.splitlines()[1].startswith("certified (6 digits requested")


def test_every_subcommand_help_states_its_exit_codes(capsys):
    """Issue 28: `--help` of every command lists its exit codes (0, 2 and 3 at least)."""
    import pytest

    from rfverify.cli.app import COMMANDS

    for command in COMMANDS:
        name = command.__name__.rsplit(".", 1)[-1]
        with pytest.raises(SystemExit):
            from rfverify.cli import main

            main([name, "--help"])
        text = " ".join(capsys.readouterr().out.split())
        assert "Exit codes: 0 " in text, name
        codes = text.split("Exit codes: ", 1)[1]
        assert "; 2 bad input" in codes and "; 3 internal error" in codes, name
