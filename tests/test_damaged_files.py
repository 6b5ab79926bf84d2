"""Issue 48 item 5: a damaged HDF5 file is called damaged, with the fix that helps (restore it
from a backup or write it again), never advice about links the user never made.

Copies of the bundled Chute file are damaged at the object headers of its datasets and groups
(found through HDF5 itself, so the offsets follow the file), at a member name in a group's
heap, and by truncation; every command answers with one line on stderr and exit code 2.
A link a user made (a soft link to nothing, an external link to a missing file) keeps its own
words and advice.
"""

from __future__ import annotations

import shutil

import h5py
import pytest

from rfverify import data
from rfverify.cli import main
from pathlib import Path

CHUTE = Path(data.__file__).resolve().parent / "Chute-ndof-768-nc-4-3.hdf5"
RESTORE = "restore the file from a backup, or write it again"


def damaged_copy(tmp_path, offset: int, count: int = 8) -> Path:
    path = tmp_path / "damaged.hdf5"
    shutil.copy(CHUTE, path)
    with open(path, "r+b") as fh:
        fh.seek(offset)
        fh.write(b"\xa5" * count)
    return path


def header_address(name: str) -> int:
    with h5py.File(CHUTE, "r") as fh:
        return int(h5py.h5o.get_info(fh[name].id).addr)


def one_line_error(capsys, *argv) -> str:
    code = main(list(argv))
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 1, (code, err)
    return lines[0]


@pytest.mark.parametrize("name", ["fclib_global_rolling/M/x", "fclib_global_rolling/H",
                                  "fclib_global_rolling/vectors/f", "solution/r"])
@pytest.mark.parametrize("rel", [0, 4, 16])
def test_an_overwritten_object_header_is_called_damaged(tmp_path, capsys, name, rel):
    path = damaged_copy(tmp_path, header_address(name) + rel)
    line = one_line_error(capsys, "info", str(path))
    assert f"/{name}: is damaged" in line and RESTORE in line, line
    assert "replace the link" not in line and "HardLink" not in line


def test_every_command_says_so(tmp_path, capsys):
    path = damaged_copy(tmp_path, header_address("fclib_global_rolling/M/x") + 16)
    for argv in (["solve", str(path)], ["certify", str(path)], ["solve", str(path), "--digits", "10"]):
        line = one_line_error(capsys, *argv)
        assert "is damaged" in line and RESTORE in line, line


def test_an_overwritten_member_name_is_called_damaged_not_missing(tmp_path, capsys):
    at = CHUTE.read_bytes().find(b"vectors\x00")
    assert at > 0
    path = damaged_copy(tmp_path, at, len("vectors"))
    line = one_line_error(capsys, "info", str(path))
    assert "/fclib_global_rolling/vectors: is missing, and /fclib_global_rolling looks damaged" in line, line
    assert "not text" in line and RESTORE in line


@pytest.mark.parametrize("keep", [100, 20000, CHUTE.stat().st_size - 100])
def test_a_truncated_copy_is_called_truncated(tmp_path, capsys, keep):
    path = tmp_path / "cut.hdf5"
    path.write_bytes(CHUTE.read_bytes()[:keep])
    line = one_line_error(capsys, "info", str(path))
    assert f"is truncated: it has {keep} bytes, its HDF5 header records {CHUTE.stat().st_size}" in line, line
    assert RESTORE in line


def test_an_overwritten_signature_mentions_damage(tmp_path, capsys):
    line = one_line_error(capsys, "info", str(damaged_copy(tmp_path, 0)))
    assert "is not an HDF5 file" in line and "damaged" in line and "restore it from a backup" in line


@pytest.mark.parametrize("make, words", [
    (lambda: h5py.SoftLink("/nowhere"), "is a soft link (SoftLink) to /nowhere, which does not exist in the file"),
    (lambda: h5py.SoftLink("/fclib_global_rolling/vectors/w"), "that cannot be followed"),
    (lambda: h5py.ExternalLink("missing-file.h5", "/w"), "is an external link (ExternalLink) to /w in missing-file.h5"),
])
def test_links_a_user_made_keep_their_advice(tmp_path, capsys, make, words):
    path = tmp_path / "linked.hdf5"
    shutil.copy(CHUTE, path)
    with h5py.File(path, "r+") as fh:
        del fh["fclib_global_rolling/vectors/w"]
        fh["fclib_global_rolling/vectors/w"] = make()
    line = one_line_error(capsys, "info", str(path))
    assert words in line and "replace the link by the data it should point to" in line, line
    assert "damaged" not in line
