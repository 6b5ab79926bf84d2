"""Problem files: FCLIB HDF5 and Siconos ``.dat`` text; bundled example problems.

:func:`load` picks the reader from the file's content (HDF5 signature) and suffix;
:func:`save` writes FCLIB HDF5 in the problem's own layout (``/fclib_global_rolling``, or
``/fclib_global`` / ``/fclib_local`` with 3 per contact for problems read from 3-D files).
"""

from __future__ import annotations

import numbers
from pathlib import Path

from ..errors import InvalidArgumentError, ProblemFileError
from ..model.problem import DEFAULT_MAX_ASYMMETRY, Problem
from ._paths import BUNDLED_PREFIX, bundled_problems, read_head, resolve_path
from .fclib import read_fclib, write_fclib, write_solution_in_place
from .local_lift import LocalProblem, lift_local
from .siconos_dat import parse_siconos_dat, read_siconos_dat

__all__ = ["load", "save", "read_fclib", "write_fclib", "write_solution_in_place", "read_siconos_dat", "parse_siconos_dat",
           "lift_local", "LocalProblem", "bundled_problems", "resolve_path", "BUNDLED_PREFIX"]


def load(path, *, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY) -> Problem:
    """Read a problem file (FCLIB ``.hdf5``/``.h5`` or Siconos ``.dat``) into a validated
    :class:`~rfverify.model.problem.Problem`.  ``path`` may be ``"bundled:NAME"`` (see
    :func:`bundled_problems`).  A local ``.dat`` problem is lifted to global form.

    FCLIB files: ``/fclib_global_rolling`` (rolling friction) is read as it is; the 3-D Coulomb
    friction groups ``/fclib_global`` and ``/fclib_local`` are read as their convex relaxation,
    embedded in the rolling layout with μr = 0 and zero rolling rows (a local problem is then
    lifted: W = HᵀH, M = I, f = 0, w = q); ``problem.provenance`` says what was done (see
    :mod:`rfverify.io.fclib3d`).  A file holding several of these groups is read from the first
    of /fclib_global_rolling, /fclib_global, /fclib_local.  ``max_asymmetry`` limits the
    entrywise asymmetry of M (of W for local problems).

    Raises
    ------
    ProblemFileError
        the file is missing, unreadable or malformed (path and location named).
    InvalidProblemError
        the data are not a valid problem (file, field and index named).
    InvalidArgumentError
        ``path`` is not a path, or ``max_asymmetry`` is not a number ≥ 0.
    """
    p = resolve_path(path)
    if isinstance(max_asymmetry, bool) or not isinstance(max_asymmetry, numbers.Real) \
            or not float(max_asymmetry) >= 0:
        raise InvalidArgumentError("max_asymmetry", f"is {max_asymmetry!r}, expected a number ≥ 0",
                                   fix="pass e.g. max_asymmetry=1e-2 (or float('inf') to accept any)")
    head = read_head(p, "an FCLIB .hdf5 file or a Siconos .dat file")
    if head == b"\x89HDF\r\n\x1a\n" or p.suffix.lower() in {".hdf5", ".h5", ".hdf"}:
        return read_fclib(p, max_asymmetry=max_asymmetry)
    if p.suffix.lower() == ".dat" or head[:1].isdigit():
        return read_siconos_dat(p, max_asymmetry=max_asymmetry)
    raise ProblemFileError(p, "unrecognised format: expected an FCLIB HDF5 file or a Siconos .dat file",
                           fix="pass a .hdf5/.h5 (FCLIB) or .dat (Siconos) problem file")


def save(problem: Problem, path, **kwargs) -> Path:
    """Write ``problem`` as an FCLIB HDF5 file in its own layout (see :func:`write_fclib`): a
    problem read from ``/fclib_global`` or ``/fclib_local`` is written back there, with
    ``/solution`` and ``/guesses`` 3 per contact (local: u and r only)."""
    return write_fclib(problem, path, **kwargs)
