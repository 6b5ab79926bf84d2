"""Safe output: what every command that writes a file goes through.

Guarantees (docs/REFERENCE.md, "Guarantees"):

- an output path that is also an input of the same command is refused, unless the caller
  declares the write *in place* (``solve in.hdf5 --out in.hdf5`` adds ``/solution`` to the
  problem file and keeps everything else: see :func:`rfverify.io.fclib.write_solution_in_place`);
- an existing target that is not a regular file (directory, FIFO, device, socket) is refused;
  a symbolic link is written *through* (its target is replaced, the link stays a link);
- the directory must exist and be writable, checked by :func:`check_output_file` before the
  expensive work, not after;
- a regular file is written to a temporary file beside it and renamed over the target only when
  complete (never a half-written file under the final name); the old file's permission bits
  are kept.

It also holds the strict JSON encoder used for every ``--json`` output and every record: non-
finite numbers become ``null`` (bare ``NaN``/``Infinity`` are not JSON).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import stat
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError, OutputPathError
from ._paths import BUNDLED_PREFIX, bundled_problems, resolve_path

__all__ = ["OutputTarget", "check_output_file", "check_output_dir", "atomic_output",
           "write_text_atomic", "write_bytes_atomic", "json_safe", "dumps", "tag_floats",
           "untag_floats"]


@dataclass(frozen=True)
class OutputTarget:
    """A checked output path: ``path`` as given, ``real`` with symbolic links resolved (where
    the bytes go), ``in_place`` when it is an input of the same command written in place."""

    path: Path
    real: Path
    option: str
    in_place: bool = False
    input_spec: str | None = None


def _kind(mode: int) -> str | None:
    """What a non-regular file is, in words (None for a regular file)."""
    if stat.S_ISREG(mode):
        return None
    if stat.S_ISDIR(mode):
        return "a directory"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe)"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a regular file"


def _as_path(path, option) -> Path:
    if isinstance(path, bytes) or not isinstance(path, (str, os.PathLike)):
        raise InvalidArgumentError(option, f"expected a file path, got {type(path).__name__}",
                                   fix="pass a str or pathlib.Path")
    if str(path) == "":
        raise OutputPathError("", "is an empty path, so nothing would be written", option=option,
                              fix=f"give a file name to {option}, or leave the option out")
    return Path(path)


def _input_path(spec) -> tuple[Path | None, bool]:
    """The file an input spec names (bundled: resolved) and whether it is a bundled problem."""
    text = str(spec)
    try:
        p = resolve_path(text)
    except Exception:  # an unknown bundled name: no file, so no clash possible
        return None, False
    return p, text.startswith(BUNDLED_PREFIX)


def _refuse_non_regular(real: Path, path: Path, option: str):
    try:
        st = os.stat(real)
    except FileNotFoundError:
        return False
    except OSError as exc:
        raise OutputPathError(path, f"cannot be examined ({exc.strerror or exc})", option=option,
                              fix="choose another path") from None
    kind = _kind(st.st_mode)
    if kind is not None:
        raise OutputPathError(path, f"exists and is {kind}, not a regular file; rfverify only "
                                    "writes regular files", option=option,
                              fix="name a regular file (new or existing) instead")
    return True


def _probe_directory(directory: Path, path: Path, option: str):
    """Create and delete a temporary file in ``directory``: the only reliable writability test
    (permissions, read-only mounts, ACLs, quotas)."""
    if not directory.exists():
        raise OutputPathError(path, f"directory {directory} does not exist", option=option,
                              fix=f"create it first (mkdir -p {directory}) or choose another path")
    if not directory.is_dir():
        raise OutputPathError(path, f"{directory} is not a directory", option=option,
                              fix="choose a path inside an existing directory")
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".rfverify-probe-")
    except OSError as exc:
        raise OutputPathError(path, f"directory {directory} is not writable "
                                    f"({exc.strerror or type(exc).__name__})", option=option,
                              fix="choose a writable directory or change its permissions") from None
    os.close(fd)
    os.unlink(probe)


def check_output_file(path, *, inputs=(), option: str = "--out",
                      in_place_ok: bool = False) -> OutputTarget:
    """Check an output file path before any work is done (see the module docstring).

    ``inputs`` are the files (or ``bundled:NAME`` specs; None entries are skipped) the same
    command reads, the problem first.  When the target is one of them it is refused, unless it
    is the problem and ``in_place_ok`` (the caller then writes in place and must preserve the rest
    of the file); any other input (a ``--start`` or ``--solution`` file) is never written, nor is
    a bundled problem.

    Raises
    ------
    OutputPathError
        with the reason and the fix.
    """
    path = _as_path(path, option)
    if str(path).startswith(BUNDLED_PREFIX):
        raise OutputPathError(path, "names a problem bundled with rfverify, which is never written "
                                    "(and no file of that name could be read back)", option=option,
                              fix="give a file path, e.g. answer.h5")
    real = Path(os.path.realpath(path))
    exists = _refuse_non_regular(real, path, option)
    in_place, spec = False, None
    if exists:
        for name, shipped in bundled_problems().items():  # whatever this command reads
            if shipped.exists() and os.path.samefile(real, shipped):
                raise OutputPathError(path, f"is the problem file bundled with rfverify (bundled:{name}); "
                                            "it is never written", option=option, fix="choose another output path")
        for position, item in enumerate(inputs):
            if item is None:
                continue
            inp, bundled = _input_path(item)
            if inp is None or not inp.exists():
                continue
            try:
                same = os.path.samefile(real, inp)
            except OSError:
                same = False
            if not same:
                continue
            if bundled:
                raise OutputPathError(path, f"is the problem file bundled with rfverify ({item}); "
                                            "it is never written", option=option,
                                      fix="choose another output path")
            if not (in_place_ok and (position == 0 or in_place)):  # another input that is the problem file
                raise OutputPathError(path, f"is also an input of this command ({item}); writing "
                                            "would replace it", option=option,
                                      fix=f"choose a different {option} path")
            if position == 0:
                in_place, spec = True, str(item)
        if not os.access(real, os.W_OK):
            raise OutputPathError(path, "exists and is read-only", option=option,
                                  fix="make it writable (chmod u+w) or choose another path")
    _probe_directory(real.parent, path, option)
    return OutputTarget(path=path, real=real, option=option, in_place=in_place, input_spec=spec)


def check_output_dir(path, *, option: str = "--out") -> Path:
    """Check a directory the command will create or fill: it must be a directory if it exists,
    otherwise its nearest existing ancestor must be a writable directory."""
    path = _as_path(path, option)
    real = Path(os.path.realpath(path))
    if real.exists():
        if not real.is_dir():
            raise OutputPathError(path, "exists and is not a directory", option=option,
                                  fix="name a new or existing directory (the files are written inside it)")
        _probe_directory(real, path, option)
        return path
    ancestor = real.parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(path, f"{ancestor} is not a directory", option=option,
                              fix="choose a path under an existing directory")
    _probe_directory(ancestor, path, option)
    return path


def _new_file_mode() -> int:
    """Mode a plain ``open(..., "w")`` would give: 0o666 less the umask."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


@contextlib.contextmanager
def atomic_output(target, *, option: str = "--out"):
    """Yield a temporary path beside the (checked) target; on success rename it over the
    target's real path (symbolic links are written through), on failure delete it.

    ``target`` is an :class:`OutputTarget` or a path (checked here with no inputs)."""
    t = target if isinstance(target, OutputTarget) else check_output_file(target, option=option)
    directory = t.real.parent
    try:
        fd, tmp_name = tempfile.mkstemp(dir=directory, prefix=f".{t.real.name}.", suffix=".partial")
    except OSError as exc:
        raise OutputPathError(t.path, f"cannot write in {directory} ({exc.strerror or exc})",
                              option=t.option, fix="choose a writable directory") from None
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        # The target may have changed since it was checked: never rename over a non-regular file.
        existed = _refuse_non_regular(t.real, t.path, t.option)
        mode = stat.S_IMODE(os.stat(t.real).st_mode) if existed else _new_file_mode()
        os.chmod(tmp, mode)
        os.replace(tmp, t.real)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text_atomic(path, text: str, *, option: str = "RUN_DIR") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`atomic_output`)."""
    with atomic_output(path, option=option) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes_atomic(path, data: bytes, *, option: str = "RUN_DIR") -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_output`)."""
    with atomic_output(path, option=option) as tmp:
        tmp.write_bytes(data)
    return Path(path)


# ---------------------------------------------------------------------- strict JSON
def _plain(obj, non_finite):
    """A copy of ``obj`` in the types JSON encodes: dict keys as strings, tuples as lists, numpy
    arrays and scalars as Python lists and numbers, and a non-finite float (Python or numpy) as
    ``non_finite(obj)``; other objects are left for ``json.dumps``'s ``default`` (or its error)."""
    if isinstance(obj, (float, np.floating)) and not math.isfinite(obj):
        return non_finite(obj)
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if isinstance(obj, dict):
        return {(k if isinstance(k, str) else str(k)): _plain(v, non_finite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v, non_finite) for v in obj]
    if isinstance(obj, np.ndarray):
        return _plain(obj.tolist(), non_finite)
    if isinstance(obj, np.generic):
        return _plain(obj.item(), non_finite)
    return obj


def json_safe(obj):
    """A copy of ``obj`` that strict JSON can encode: numpy scalars and arrays become Python
    numbers and lists, non-finite floats become None, tuples become lists; other objects are
    left for ``json.dumps``'s ``default`` (or its error)."""
    return _plain(obj, lambda x: None)


def dumps(obj, **kwargs) -> str:
    """``json.dumps`` that never emits ``NaN``/``Infinity`` (non-finite numbers are ``null``)."""
    kwargs.setdefault("default", _default)
    return json.dumps(json_safe(obj), allow_nan=False, **kwargs)


def tag_floats(obj):
    """Like :func:`json_safe`, but a non-finite float becomes ``{"$float": "nan"|"inf"|"-inf"}``
    so that a cache written as strict JSON reads back exactly (see :func:`untag_floats`)."""
    return _plain(obj, lambda x: {"$float": "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")})


def untag_floats(obj):
    """Inverse of :func:`tag_floats`."""
    if isinstance(obj, dict):
        if set(obj) == {"$float"} and obj["$float"] in ("nan", "inf", "-inf"):
            return float(obj["$float"])
        return {k: untag_floats(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [untag_floats(v) for v in obj]
    return obj


def _default(obj):
    if isinstance(obj, Path):
        return str(obj)
    raise TypeError(f"not JSON serialisable: {type(obj).__name__}")
