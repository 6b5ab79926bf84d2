"""FCLIB HDF5 files: read and write (DESIGN §7).

``/fclib_global_rolling`` (rolling friction, 5 per contact) is read here; the 3-D Coulomb
friction groups ``/fclib_global`` and ``/fclib_local`` (3 per contact) are read into the same
rolling layout by :mod:`rfverify.io.fclib3d`, and written back in their own layout.  A file
holding several groups is read from the first of /fclib_global_rolling, /fclib_global,
/fclib_local.

Layout::

    /fclib_global_rolling/M, /H        matrix groups: m, n, nz, nzmax, p, i, x
    /fclib_global_rolling/vectors/     f, w, mu, mu_r
    /fclib_global_rolling/spacedim     [5]
    /fclib_global_rolling/info/        title, description, math_info   (optional)
    /solution/                         v, u, r                           (optional)
    /guesses/number_of_guesses, /guesses/1/{v,u,r}, /guesses/2/...      (optional)

Matrix storage is told by ``nz``: ``nz ≥ 0`` triplet with **i = row, p = column** (the comment
in fclib.h has it backwards; the files and fclib.c agree with this); ``nz = −1`` CSC
(p = column pointers, i = row indices); ``nz = −2`` CSR (p = row pointers, i = column
indices).  In every storage a repeated (row, col) is summed **exactly**
(:mod:`rfverify.io._exact`) and refused when its exact sum is not a float64: never rounded.
Index arrays are written as int32 like fclib.c, values as float64.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from ..errors import InvalidArgumentError, InvalidProblemError, ProblemFileError
from ..model.problem import DEFAULT_MAX_ASYMMETRY, Problem, StoredSolution
from ._hdf5 import (STORAGE_FORMATS, check_declared_sizes, damaged, first_line, h5py_module, matrix_meta, member,
                    read_guesses, read_info, read_matrix, read_scalar_int, read_solution, read_vector,
                    write_matrix, write_solution)
from ._paths import read_head
from .fclib3d import (GLOBAL, LOCAL, ROLLING, check_embedded, convert_for_file, detect_layout, file_layout,
                      read_group, solution_attributes, write_group, write_info_and_solutions)
from .output import OutputTarget, atomic_output, check_output_file

ROOT = "fclib_global_rolling"


def read_fclib(path, *, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY) -> Problem:
    """Read a ``fclib_global_rolling`` HDF5 file into a validated :class:`Problem`.

    Every dataset is checked for its HDF5 object kind, dtype and shape before it is read, and
    the declared sizes are checked against each other before any matrix is allocated: what
    cannot be read exactly (float or fractional indices, complex or compound values, strings
    where numbers belong) is refused, never converted.

    Raises
    ------
    ProblemFileError
        missing/unreadable/non-HDF5 file, missing or mistyped group or dataset (its HDF5 path
        is named), inconsistent matrix storage.
    InvalidProblemError
        the data read are not a valid problem (see :meth:`Problem.from_arrays`); its message
        names the file.
    """
    h5py = h5py_module()
    path = Path(path)
    read_head(path, "an FCLIB .hdf5 file")
    if not h5py.is_hdf5(path):
        raise ProblemFileError(path, "is not an HDF5 file (wrong format, or damaged: the "
                                     "HDF5 signature is missing)",
                               fix="pass an FCLIB .hdf5 file (or a Siconos .dat file); if this was one, it is damaged: "
                                   "restore it from a backup, or write it again")
    try:
        with h5py.File(path, "r") as fh:
            return _read_open_file(fh, path, max_asymmetry)
    except InvalidProblemError as exc:
        raise exc.with_path(path) from None
    except ProblemFileError:
        raise
    except (OSError, KeyError, RuntimeError) as exc:  # truncated or damaged inside
        raise damaged(path, None, "its HDF5 structure cannot be read", exc) from None


def _read_open_file(fh, path, max_asymmetry):

    h5py = h5py_module()
    present = [k for k in (ROOT, GLOBAL, LOCAL) if fh.get(k, getlink=True) is not None]
    if not present:
        other = [k for k in fh.keys() if k.startswith("fclib_")]
        hint = f" (it holds /{other[0]}: not a problem group rfverify reads)" if other else ""
        raise ProblemFileError(path, f"missing group /{ROOT} (nor /{GLOBAL} or /{LOCAL}){hint}",
                               location=f"/{ROOT}",
                               fix="pass an FCLIB problem file: /fclib_global_rolling (rolling "
                                   "friction), /fclib_global or /fclib_local (3-D friction)")
    if present[0] != ROOT:
        return read_group(fh, present[0], path, max_asymmetry, present[1:])
    g = member(fh, ROOT, path, h5py.Group)
    vectors = member(g, "vectors", path, h5py.Group)
    if g.get("G", getlink=True) is not None or vectors.get("b", getlink=True) is not None:
        raise ProblemFileError(path, "equality constraints (G, b) are not supported by rfverify",
                               location=f"/{ROOT}/G",
                               fix="remove G and b (rfverify solves problems without them)")
    # Vectors first: their sizes come from data actually stored, and bound every declared size.
    f = read_vector(vectors, "f", path)
    w = read_vector(vectors, "w", path)
    mu = read_vector(vectors, "mu", path)
    mu_r = read_vector(vectors, "mu_r", path)
    spacedim = read_scalar_int(member(g, "spacedim", path, h5py.Dataset), path)
    M_meta = matrix_meta(g, "M", path)
    H_meta = matrix_meta(g, "H", path)
    check_declared_sizes(M_meta, H_meta, f.size, mu.size, spacedim)
    M, M_fmt = read_matrix(M_meta, path)
    H, H_fmt = read_matrix(H_meta, path)
    title, description, math_info = read_info(g, path)
    solution = None
    if fh.get("solution", getlink=True) is not None:
        solution = read_solution(member(fh, "solution", path, h5py.Group), path)
    guesses = ()
    if fh.get("guesses", getlink=True) is not None:
        guesses = read_guesses(member(fh, "guesses", path, h5py.Group), path)
    ignored = {"ignored_groups": [f"/{k}" for k in present[1:]]} if present[1:] else None
    return Problem.from_arrays(
        M, H, f, w, mu, mu_r, title=title, description=description, math_info=math_info,
        solution=solution, guesses=guesses, storage={"M": M_fmt, "H": H_fmt},
        max_asymmetry=max_asymmetry, spacedim=spacedim, source=str(path), provenance=ignored,
    )


# ---------------------------------------------------------------------- writing
def write_fclib(problem: Problem, path, *, storage: dict | str | None = None,
                overwrite: bool = True, extra=None) -> Path:
    """Write ``problem`` (its raw, unsymmetrised M) to ``path`` in FCLIB layout: the layout
    it was read in (a problem read from ``/fclib_global`` or ``/fclib_local`` is written back
    there, 3 per contact, a local one from its raw W and q), else ``/fclib_global_rolling``.

    Parameters
    ----------
    path : str, Path or rfverify.io.output.OutputTarget
        A regular file (new or existing) in an existing, writable directory; a symbolic link
        is written through.  Directories, FIFOs, devices and sockets are refused
        (:class:`~rfverify.errors.OutputPathError`).
    storage : "triplet" | "csc" | "csr" | dict, optional
        Matrix storage; a dict may give one per matrix (``{"M": "csc", "H": "triplet"}``;
        ``{"W": ...}`` for a local problem).
        Defaults to the format the problem was read in (``"csc"`` for problems built in memory;
        ``"dense"`` and Siconos ``"sparse-block"`` sources are written as ``"csc"``).
    extra : callable, optional
        ``extra(h5py_file)`` writes more groups (a ``/certificate``) into the temporary file
        before it is renamed into place, so the whole file appears at once.
    overwrite : bool
        Refuse to replace an existing file when False.

    The file is written to a temporary file beside the target and renamed over it when
    complete.  Reading it back gives bit-identical arrays (M, H, f, w, mu, mu_r, solution,
    guesses; for a local problem W, q, u and r, and v = H r).  ``/solution`` gets the
    attributes ``layout`` and ``symmetrised`` (what was symmetrised for solving, with the
    entrywise and normwise asymmetry: ``asymmetry_entrywise``, ``asymmetry_normwise``).
    """

    h5py = h5py_module()
    layout = file_layout(problem)
    if layout != ROLLING:
        check_embedded(problem)
    target = path if isinstance(path, OutputTarget) else None
    path = target.path if target is not None else Path(path)
    if path.exists() and not overwrite:
        raise ProblemFileError(path, "exists already (pass overwrite=True to replace it)",
                               fix="choose another path or pass overwrite=True")
    fmts = {}
    for name in (("W",) if layout == LOCAL else ("M", "H")):
        fmt = storage.get(name) if isinstance(storage, dict) else storage
        fmt = fmt or problem.storage.get(name, "csc")
        if fmt in ("dense", "sparse-block"):  # a .dat file's storages, which FCLIB does not have
            fmt = "csc"
        if fmt not in STORAGE_FORMATS:
            raise InvalidArgumentError("storage", f"for {name}: {fmt!r} is not one of {STORAGE_FORMATS}",
                                       fix="use 'triplet', 'csc' or 'csr'")
        fmts[name] = fmt
    target = target or check_output_file(path, option="path")
    with atomic_output(target) as tmp:
        with h5py.File(tmp, "w") as fh:
            if layout != ROLLING:
                write_group(fh, problem, fmts)  # /fclib_global or /fclib_local, 3 per contact
            else:
                _write_rolling(fh, problem, fmts)
            if extra is not None:  # more groups (a certificate), written before the rename
                extra(fh)
    return path


def _write_rolling(fh, problem, fmts):
    g = fh.create_group(ROOT)
    write_matrix(g, "M", problem.M, fmts["M"])
    write_matrix(g, "H", problem.H, fmts["H"])
    vec = g.create_group("vectors")
    for name in ("f", "w", "mu", "mu_r"):
        vec.create_dataset(name, data=np.asarray(getattr(problem, name), dtype=np.float64))
    g.create_dataset("spacedim", data=np.array([problem.spacedim], dtype=np.int32))
    write_info_and_solutions(fh, g, problem, write_solution)


def write_solution_in_place(target, solution: StoredSolution, *, extra=None, problem=None) -> Path:
    """Replace ``/solution/{v, u, r}`` of an existing FCLIB file and keep every other group,
    dataset and attribute (user data, ``info`` extras, ``/guesses``, other attributes of
    ``/solution`` itself) exactly as they are.

    ``solution`` is in rfverify's rolling layout (5 per contact).  It is written in the layout
    of the file's problem group (the one :func:`read_fclib` reads): 5 per contact for
    ``/fclib_global_rolling``, 3 per contact for ``/fclib_global``, and only u and r for
    ``/fclib_local`` (a ``/solution/v`` there is removed: it is not a quantity of the file).
    With ``problem`` (the problem read from this file), ``/solution`` also gets the attributes
    ``layout``, ``symmetrised``, ``symmetrised_matrix``, ``asymmetry_entrywise`` and
    ``asymmetry_normwise`` (what was symmetrised for solving).

    Any ``/certificate`` of the file is removed (it was about the old solution); ``extra``
    writes the new one where there is one.

    FCLIB keeps ``/solution`` beside the problem, so ``solve in.hdf5 --out in.hdf5`` is a
    reasonable request; the file is copied, the copy updated and renamed over the original,
    so an interrupted write leaves the original untouched.
    """

    h5py = h5py_module()
    target = target if isinstance(target, OutputTarget) else check_output_file(target, option="path")
    if not target.real.exists():
        raise ProblemFileError(target.path, "does not exist, so there is no file to add /solution to",
                               fix="use write_fclib to write a new file")
    with atomic_output(target) as tmp:
        shutil.copyfile(target.real, tmp)
        with h5py.File(tmp, "r+") as fh:
            link = fh.get("solution", getlink=True)
            if link is not None and not (isinstance(link, h5py.HardLink)
                                         and isinstance(fh["solution"], h5py.Group)):
                del fh["solution"]  # a link or a dataset: only the name /solution is replaced
            grp = fh.require_group("solution")
            layout = detect_layout(fh)
            if problem is not None and file_layout(problem) != layout:
                raise ProblemFileError(target.path, f"holds /{layout}, but the problem was read as "
                                                    f"/{file_layout(problem)}", location="/solution",
                                       fix="write the solution into the file the problem was read from")
            datasets = convert_for_file(layout, solution)
            for key in ("v", "u", "r"):
                if grp.get(key, getlink=True) is not None:
                    del grp[key]
                arr = datasets[key]
                if arr is not None:
                    grp.create_dataset(key, data=np.asarray(arr, dtype=np.float64))
            if problem is not None:
                for key, val in solution_attributes(problem).items():
                    grp.attrs[key] = val
            # A certificate is about the solution it was written with: a new /solution voids it
            # (``extra`` writes a new one where there is one).
            if fh.get("certificate", getlink=True) is not None:
                del fh["certificate"]
            if extra is not None:  # e.g. /certificate beside the new /solution, in the same copy
                extra(fh)
    return target.path


