"""Naming and opening an input file (``bundled:NAME`` included), with one-line errors for every
way it can fail."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import InvalidArgumentError, ProblemFileError

BUNDLED_PREFIX = "bundled:"


def read_head(path: Path, expected: str, size: int = 8) -> bytes:
    """The first ``size`` bytes of ``path``; ProblemFileError (naming the fix) when the file is
    missing, a directory, unreadable or otherwise cannot be opened.  ``expected`` says what
    kind of file was wanted ("an FCLIB .hdf5 file", ...)."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        mode = None  # reported by open() below, with its precise reason
    if mode is not None and not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        # Opening a FIFO would block until a writer appears; a device is no problem file.
        raise ProblemFileError(path, f"is not a regular file, expected {expected}",
                               fix="name a regular problem file")
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except FileNotFoundError:
        raise ProblemFileError(path, "no such file",
                               fix=f"check the path (expected {expected})") from None
    except IsADirectoryError:
        raise ProblemFileError(path, f"is a directory, expected {expected}",
                               fix="name the problem file inside it") from None
    except PermissionError:
        raise ProblemFileError(path, "cannot be read: permission denied",
                               fix="make it readable (chmod u+r) or copy it somewhere readable") from None
    except OSError as exc:
        raise ProblemFileError(path, f"cannot be read ({exc.strerror or type(exc).__name__})",
                               fix=f"check the path (expected {expected})") from None


def bundled_problems() -> dict[str, Path]:
    """Problems shipped inside the package: short name → path.

    ``chute`` is the Siconos Chute FCLIB file (4 contacts, 768 dofs; Apache-2.0, from the
    Siconos/FCLIB collections); the others are small Siconos ``.dat`` problems.
    """
    from .. import data

    root = Path(data.__file__).parent
    return {
        "chute": root / "Chute-ndof-768-nc-4-3.hdf5",
        "chute-dat": root / "GRFC3D_Chute-ndof-768-nc-4-3.dat",
        "sphere": root / "RFC3D_sphere_1.dat",
        "cube": root / "RFC3D_cube_1.dat",
        "sphere-from-global": root / "rfc3d_sphere_from_grfc3d.dat",
    }


def resolve_path(spec) -> Path:
    """``bundled:NAME`` → the bundled file's path; anything else → ``Path(spec)``."""
    if isinstance(spec, bytes) or not isinstance(spec, (str, os.PathLike)):
        raise InvalidArgumentError("path", f"expected a file path or 'bundled:NAME', got "
                                           f"{type(spec).__name__}",
                                   fix="pass a str or pathlib.Path naming a problem file")
    text = str(spec)
    if text == "":
        raise InvalidArgumentError("path", "is empty", fix="name a problem file")
    if text.startswith(BUNDLED_PREFIX):
        name = text[len(BUNDLED_PREFIX):]
        table = bundled_problems()
        if name not in table:
            raise ProblemFileError(text, f"no bundled problem named {name!r}",
                                   fix=f"use one of the bundled problems: {', '.join('bundled:' + k for k in sorted(table))}")
        return table[name]
    return Path(spec)
