"""Opening an input file for reading, with one-line errors for every way it can fail."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import ProblemFileError


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
