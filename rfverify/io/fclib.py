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
import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import DataWarning, InvalidArgumentError, InvalidProblemError, ProblemFileError
from ..problem import DEFAULT_MAX_ASYMMETRY, SPACEDIM, Problem, StoredSolution
from ._exact import FIX_INEXACT, exact_csc
from ._paths import read_head
from .output import OutputTarget, atomic_output, check_output_file

ROOT = "fclib_global_rolling"
NZ_CSC = -1
NZ_CSR = -2
STORAGE_FORMATS = ("triplet", "csc", "csr")


def _h5py():
    import h5py  # imported lazily: `rfverify --help` should not pay for it

    return h5py


MAX_INDEX = 2**31 - 1
"""Largest size or index an FCLIB file can hold (fclib.c stores them as int32)."""

_PLAUSIBLE_BYTES = 2**30
_PLAUSIBLE_RATIO = 64
"""A dataset over 1 GiB declared in a file 64 times smaller is refused before it is read
(unwritten HDF5 data read as fill values; real FCLIB data do not compress that well)."""

_EXACT_INT = 2**53
"""Integers up to this magnitude convert to float64 exactly."""

_FIX_LAYOUT = ("write the file with rfverify.save or fclib's fclib_write_global_rolling "
               "(layout: DESIGN §7; 3-D files: fclib_write_global/fclib_write_local)")
_FIX_INT = "store sizes and indices as integers (int32, as fclib.c writes them)"
_FIX_REAL = "store the data as float64 (real numbers)"


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
    h5py = _h5py()
    path = Path(path)
    read_head(path, "an FCLIB .hdf5 file")
    if not h5py.is_hdf5(path):
        raise ProblemFileError(path, "is not an HDF5 file (wrong format, or truncated: the "
                                     "HDF5 signature is missing)",
                               fix="pass an FCLIB .hdf5 file (or a Siconos .dat file)")
    try:
        with h5py.File(path, "r") as fh:
            return _read_open_file(fh, path, max_asymmetry)
    except InvalidProblemError as exc:
        raise exc.with_path(path) from None
    except ProblemFileError:
        raise
    except (OSError, KeyError, RuntimeError) as exc:  # truncated or corrupt inside
        raise ProblemFileError(path, f"cannot be read as HDF5 ({_first_line(exc)})",
                               fix="the file is probably truncated or corrupt: re-create or "
                                   "re-download it") from None


def _read_open_file(fh, path, max_asymmetry):
    from .fclib3d import GLOBAL, LOCAL, read_group

    h5py = _h5py()
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
    g = _member(fh, ROOT, path, h5py.Group)
    vectors = _member(g, "vectors", path, h5py.Group)
    if g.get("G", getlink=True) is not None or vectors.get("b", getlink=True) is not None:
        raise ProblemFileError(path, "equality constraints (G, b) are not supported by rfverify",
                               location=f"/{ROOT}/G",
                               fix="remove G and b (rfverify solves problems without them)")
    # Vectors first: their sizes come from data actually stored, and bound every declared size.
    f = _read_vector(vectors, "f", path)
    w = _read_vector(vectors, "w", path)
    mu = _read_vector(vectors, "mu", path)
    mu_r = _read_vector(vectors, "mu_r", path)
    spacedim = _scalar_int(_member(g, "spacedim", path, h5py.Dataset), path)
    M_meta = _matrix_meta(g, "M", path)
    H_meta = _matrix_meta(g, "H", path)
    _check_declared_sizes(M_meta, H_meta, f.size, mu.size, spacedim)
    M, M_fmt = _read_matrix(M_meta, path)
    H, H_fmt = _read_matrix(H_meta, path)
    title, description, math_info = _read_info(g, path)
    solution = None
    if fh.get("solution", getlink=True) is not None:
        solution = _read_solution(_member(fh, "solution", path, h5py.Group), path)
    guesses = ()
    if fh.get("guesses", getlink=True) is not None:
        guesses = _read_guesses(_member(fh, "guesses", path, h5py.Group), path)
    ignored = {"ignored_groups": [f"/{k}" for k in present[1:]]} if present[1:] else None
    return Problem.from_arrays(
        M, H, f, w, mu, mu_r, title=title, description=description, math_info=math_info,
        solution=solution, guesses=guesses, storage={"M": M_fmt, "H": H_fmt},
        max_asymmetry=max_asymmetry, spacedim=spacedim, source=str(path), provenance=ignored,
    )


INFO_FIELDS = ("title", "description", "math_info")


def _read_info(g, path) -> tuple:
    """(title, description, math_info) of a problem group ("" when absent).

    These strings are optional metadata that never change the problem, so nothing in them
    refuses the file: bytes that are not UTF-8 are decoded with U+FFFD in their place (a real
    LMGC90 file has a Latin-1 byte 0xA8 in its description), several strings are joined with
    newlines, and what is no string at all (numbers, a group, a broken link, an unreadable
    type) is read as "".  Each change is announced by a :class:`~rfverify.errors.DataWarning`
    naming the file, the dataset and what was done.
    """
    if g.get("info", getlink=True) is None:
        return "", "", ""
    try:
        info = _member(g, "info", path, _h5py().Group)
    except ProblemFileError as exc:
        _info_warning(path, exc.location or _loc(g, "info"), exc.problem,
                      "ignored: title, description and math_info read as empty strings")
        return "", "", ""
    return tuple(_read_string(info, name, path) for name in INFO_FIELDS)


def _info_warning(path, location, problem: str, done: str) -> None:
    warnings.warn(DataWarning(f"{path}: {location}: {problem}; {done} (optional metadata: the "
                              "problem itself is read unchanged)"), stacklevel=2)


# ---------------------------------------------------------------------- typed access
def _loc(group, name) -> str:
    return f"{group.name.rstrip('/')}/{name}"


def _kind_name(obj) -> str:
    h5py = _h5py()
    if isinstance(obj, h5py.Group):
        return "a group"
    if isinstance(obj, h5py.Dataset):
        return "a dataset"
    if isinstance(obj, h5py.Datatype):
        return "a named datatype"
    return type(obj).__name__


def _member(group, name, path, kind):
    """``group[name]`` checked to exist, to be reachable (links) and to be a ``kind``
    (h5py.Group or h5py.Dataset)."""
    h5py = _h5py()
    loc = _loc(group, name)
    what = "group" if kind is h5py.Group else "dataset"
    link = group.get(name, getlink=True)
    if link is None:
        raise ProblemFileError(path, f"missing {what} {loc}", location=loc, fix=_FIX_LAYOUT)
    try:
        obj = group[name]
    except (KeyError, OSError, RuntimeError, ValueError) as exc:
        raise ProblemFileError(path, f"is a link ({type(link).__name__}) that cannot be followed "
                                     f"({_first_line(exc)})", location=loc,
                               fix="replace the link by the data it should point to") from None
    if not isinstance(obj, kind):
        extra = ""
        if kind is h5py.Group and isinstance(obj, h5py.Dataset) and name in ("M", "H"):
            extra = " (a dense matrix?); FCLIB stores a matrix as a group m, n, nz, nzmax, p, i, x"
        raise ProblemFileError(path, f"is {_kind_name(obj)}, expected a {what}{extra}",
                               location=loc, fix=_FIX_LAYOUT)
    return obj


def _dtype(ds, path):
    try:
        return ds.dtype
    except (TypeError, ValueError) as exc:  # bitfield, reference, ...: no numpy equivalent
        raise ProblemFileError(path, f"has an HDF5 type rfverify cannot read ({_first_line(exc)})",
                               location=ds.name, fix=_FIX_REAL) from None


def _read(ds, path) -> np.ndarray:
    """All of ``ds``, after checking that its declared size is plausible: HDF5 datasets may be
    declared far larger than the data stored (unwritten parts read as fill values), and a
    hostile declaration must not exhaust memory."""
    dt = _dtype(ds, path)
    if ds.size > MAX_INDEX:
        raise ProblemFileError(path, f"declares {ds.size} values, more than an FCLIB file can "
                                     f"index ({MAX_INDEX})", location=ds.name, fix=_FIX_LAYOUT)
    nbytes = ds.size * dt.itemsize
    file_size = Path(ds.file.filename).stat().st_size
    if nbytes > _PLAUSIBLE_BYTES and nbytes > _PLAUSIBLE_RATIO * file_size:
        raise ProblemFileError(path, f"declares {ds.size} values ({nbytes / 2**30:.1f} GiB) in a "
                                     f"file of {file_size} bytes; refusing to allocate them",
                               location=ds.name, fix="check the file: its sizes are implausible")
    try:
        return np.asarray(ds[()])
    except MemoryError:
        raise ProblemFileError(path, f"is too large to read into memory ({ds.size} values)",
                               location=ds.name, fix="check the file: its sizes are implausible") from None
    except (OSError, TypeError, ValueError, RuntimeError, KeyError) as exc:
        raise ProblemFileError(path, f"cannot be read ({_first_line(exc)})", location=ds.name,
                               fix="the file is probably truncated or corrupt: re-create it") from None


def _refuse_kind(dt, ds, path, expected: str, fix: str):
    kind, why = dt.kind, ""
    if dt.names is not None or kind == "V":
        what = "a compound (record) dtype" if dt.names is not None else f"an opaque dtype ({dt})"
    elif kind == "c":
        what = f"complex values ({dt})"
        why = "; dropping the imaginary part would change the problem"
    elif kind in "SUO":
        what = "strings"
    elif kind == "b":
        what = "booleans"
    elif kind == "f":
        what = f"floating-point values ({dt})"
        why = "; sizes and indices are read exactly, never rounded"
    else:
        what = f"dtype {dt}"
    raise ProblemFileError(path, f"holds {what}, expected {expected}{why}", location=ds.name, fix=fix)


def _check_shape(ds, path, *, vector: bool):
    shape = ds.shape
    if shape is None:  # HDF5 null dataspace
        raise ProblemFileError(path, "is an empty (null) dataset", location=ds.name, fix=_FIX_LAYOUT)
    if len(shape) <= 1 or (len(shape) == 2 and 1 in shape):
        return
    expected = "a vector (1-D dataset)" if vector else "one value"
    raise ProblemFileError(path, f"has shape {shape}, expected {expected}", location=ds.name,
                           fix=_FIX_LAYOUT)


def _real(ds, path) -> np.ndarray:
    """A numeric dataset as a flat float64 array, refused unless every value is exact."""
    dt = _dtype(ds, path)
    if dt.names is not None or dt.kind not in "fiu":
        _refuse_kind(dt, ds, path, "real numbers", _FIX_REAL)
    _check_shape(ds, path, vector=True)
    arr = _read(ds, path).ravel()
    if dt.kind in "iu":
        if arr.size and np.max(np.abs(arr.astype(np.float64))) > _EXACT_INT:
            raise ProblemFileError(path, f"holds integers beyond 2^53 that float64 cannot "
                                         "represent exactly", location=ds.name, fix=_FIX_REAL)
        return arr.astype(np.float64)
    if dt.itemsize > 8:  # longdouble data: keep it only if float64 holds every value exactly
        with np.errstate(over="ignore"):
            back = arr.astype(np.float64).astype(arr.dtype)
        if not np.array_equal(back, arr, equal_nan=True):
            raise ProblemFileError(path, f"holds {dt} values that float64 cannot represent "
                                         "exactly", location=ds.name, fix=_FIX_REAL)
    return arr.astype(np.float64)


def _integers(ds, path, *, vector: bool = True) -> np.ndarray:
    """An integer dataset as a flat int64 array; floats (even integral ones) are refused."""
    dt = _dtype(ds, path)
    if dt.names is not None or dt.kind not in "iu":
        _refuse_kind(dt, ds, path, "integers", _FIX_INT)
    _check_shape(ds, path, vector=vector)
    arr = _read(ds, path).ravel()
    if dt.kind == "u" and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise ProblemFileError(path, f"holds an index {arr.max()} beyond any FCLIB size",
                               location=ds.name, fix=_FIX_INT)
    return arr.astype(np.int64)


def _scalar_int(ds, path) -> int:
    arr = _integers(ds, path, vector=False)
    if arr.size != 1:
        found = "no value (empty dataset)" if arr.size == 0 else f"{arr.size} values"
        raise ProblemFileError(path, f"holds {found}, expected exactly one integer",
                               location=ds.name, fix=_FIX_LAYOUT)
    return int(arr[0])


def _read_vector(group, name, path) -> np.ndarray:
    return _real(_member(group, name, path, _h5py().Dataset), path)


def _read_string(group, name, path) -> str:
    """One optional info string (see :func:`_read_info`): never an error, at worst a warning."""
    if group.get(name, getlink=True) is None:
        return ""
    loc = _loc(group, name)
    try:
        ds = _member(group, name, path, _h5py().Dataset)
        dt = _dtype(ds, path)
        if dt.kind not in "SUO":
            _info_warning(path, loc, f"holds {dt} values, not a string",
                          "ignored: read as an empty string")
            return ""
        if ds.shape is None:  # HDF5 null dataspace: no string at all
            return ""
        val = _read(ds, path)
    except ProblemFileError as exc:
        _info_warning(path, loc, exc.problem, "ignored: read as an empty string")
        return ""
    items = np.atleast_1d(val).ravel().tolist() if isinstance(val, np.ndarray) else [val]
    if not all(isinstance(v, str | bytes) for v in items):
        kinds = sorted({type(v).__name__ for v in items if not isinstance(v, str | bytes)})
        _info_warning(path, loc, f"holds {', '.join(kinds)} objects, not strings",
                      "ignored: read as an empty string")
        return ""
    texts, undecodable = [], []
    for k, v in enumerate(items):
        if isinstance(v, bytes):
            try:
                v = v.decode("utf-8")
            except UnicodeDecodeError as exc:
                undecodable.append(f"byte {exc.start} is 0x{v[exc.start]:02x}"
                                   + (f" in string {k}" if len(items) > 1 else ""))
                v = v.decode("utf-8", errors="replace")
        texts.append(v)
    if undecodable:
        more = f", and {len(undecodable) - 1} more string(s)" if len(undecodable) > 1 else ""
        _info_warning(path, loc, f"is not valid UTF-8 ({undecodable[0]}{more})",
                      "read with U+FFFD in place of the undecodable bytes")
    if len(texts) > 1:
        _info_warning(path, loc, f"holds {len(texts)} strings, expected one",
                      "read as one string, joined with newlines")
    return "\n".join(texts)


# ---------------------------------------------------------------------- matrices
def _matrix_meta(g, name, path) -> dict:
    """A matrix group's sizes and storage code, checked; nothing of size n or nnz is read."""
    h5py = _h5py()
    grp = _member(g, name, path, h5py.Group)
    meta = {"name": name, "group": grp, "loc": grp.name}
    for key in ("m", "n", "nz", "nzmax"):
        meta[key] = _scalar_int(_member(grp, key, path, h5py.Dataset), path)
    for key in ("m", "n", "nzmax"):
        if not 0 <= meta[key] <= MAX_INDEX:
            raise ProblemFileError(path, f"{key} = {meta[key]} is outside 0..{MAX_INDEX}",
                                   location=_loc(grp, key), fix=_FIX_LAYOUT)
    if meta["nz"] < NZ_CSR or meta["nz"] > MAX_INDEX:
        raise ProblemFileError(path, f"unknown storage nz = {meta['nz']} (expected ≥ 0 triplet, "
                                     "-1 CSC or -2 CSR)", location=_loc(grp, "nz"), fix=_FIX_LAYOUT)
    for key in ("p", "i", "x"):
        meta[key] = _member(grp, key, path, h5py.Dataset)
    return meta


def _check_declared_sizes(M, H, m_f, n_mu, spacedim):
    """The declared m, n of M and H against the stored vectors, before anything of those sizes
    is allocated (a file declaring m = 2^31 − 1 with a 768-entry f is refused here)."""
    if spacedim != SPACEDIM:
        return  # Problem.from_arrays explains a wrong spacedim better
    check_mass_declaration(M, m_f)
    if (H["m"], H["n"]) != (m_f, SPACEDIM * n_mu):
        raise InvalidProblemError("H", f"is declared {H['m']}×{H['n']} (H/m, H/n), expected "
                                       f"(m, 5n) = ({m_f}, {SPACEDIM * n_mu}) from f ({m_f} "
                                       f"entries) and mu ({n_mu} contacts)",
                                  fix="H has one row per dof and 5 columns per contact")


def check_mass_declaration(M_meta, m: int) -> None:
    """M's declared shape (M/m, M/n) is square and matches the m entries of vectors/f."""
    if M_meta["m"] != M_meta["n"]:
        raise InvalidProblemError("M", f"is declared {M_meta['m']}×{M_meta['n']} (M/m, M/n), must be square",
                                  fix="M is the m×m mass matrix")
    if M_meta["m"] != m:
        raise InvalidProblemError("M", f"declares m = {M_meta['m']} dofs (M/m) but vectors/f has {m} entries",
                                  fix="f has one entry per dof of M: make M/m, M/n and f agree")


def _read_matrix(meta, path):
    name, loc, m, n, nz = meta["name"], meta["loc"], meta["m"], meta["n"], meta["nz"]

    def bad(msg, where=loc):
        return ProblemFileError(path, f"matrix {name}: {msg}", location=where, fix=_FIX_LAYOUT)

    def inexact(k, msg):
        return ProblemFileError(path, msg, location=f"{loc}/x[{k}]", fix=FIX_INEXACT)

    sizes = {k: meta[k].size for k in ("p", "i", "x")}
    if nz >= 0:
        if min(sizes.values()) < nz:
            raise bad(f"triplet with nz = {nz} but p/i/x hold {sizes['p']}/{sizes['i']}/"
                      f"{sizes['x']} entries")
        p = _integers(meta["p"], path)[:nz]
        i = _integers(meta["i"], path)[:nz]
        x = _real(meta["x"], path)[:nz]
        rows, cols, vals = i, p, x
        if nz and (rows.min() < 0 or rows.max() >= m):
            raise bad(f"row index out of range 0..{m - 1} (i holds {rows.min()}..{rows.max()})",
                      f"{loc}/i")
        if nz and (cols.min() < 0 or cols.max() >= n):
            raise bad(f"column index out of range 0..{n - 1} (p holds {cols.min()}..{cols.max()})",
                      f"{loc}/p")
        return exact_csc(rows, cols, vals, (m, n), matrix=name, refuse=inexact), "triplet"
    outer, inner = (n, m) if nz == NZ_CSC else (m, n)
    kind = "csc" if nz == NZ_CSC else "csr"
    if sizes["p"] < outer + 1:
        raise bad(f"{kind} pointer array p has {sizes['p']} entries, needs {outer + 1}", f"{loc}/p")
    ptr = _integers(meta["p"], path)[:outer + 1]
    if ptr[0] != 0 or np.any(np.diff(ptr) < 0):
        raise bad(f"{kind} pointer array p is not non-decreasing from 0", f"{loc}/p")
    nnz = int(ptr[-1])
    if sizes["i"] < nnz or sizes["x"] < nnz:
        raise bad(f"{kind} needs {nnz} entries, i/x hold {sizes['i']}/{sizes['x']}")
    idx = _integers(meta["i"], path)[:nnz]
    x = _real(meta["x"], path)[:nnz]
    if nnz and (idx.min() < 0 or idx.max() >= inner):
        raise bad(f"index out of range 0..{inner - 1} in i (holds {idx.min()}..{idx.max()})",
                  f"{loc}/i")
    outer_of = np.repeat(np.arange(outer, dtype=np.int64), np.diff(ptr))
    rows, cols = (idx, outer_of) if nz == NZ_CSC else (outer_of, idx)
    return exact_csc(rows, cols, x, (m, n), matrix=name, refuse=inexact), kind


# ---------------------------------------------------------------------- solutions
def _read_solution(grp, path) -> StoredSolution:
    vals = {}
    for key in ("v", "u", "r"):
        if grp.get(key, getlink=True) is not None:
            vals[key] = _real(_member(grp, key, path, _h5py().Dataset), path)
    return StoredSolution(**vals)


def _read_guesses(grp, path) -> tuple:
    h5py = _h5py()
    keys = sorted((k for k in grp.keys() if k.isdigit()), key=int)
    declared = len(keys)
    if grp.get("number_of_guesses", getlink=True) is not None:
        declared = _scalar_int(_member(grp, "number_of_guesses", path, h5py.Dataset), path)
    if declared != len(keys):
        raise ProblemFileError(path, f"number_of_guesses = {declared} but {len(keys)} guess groups "
                                     "are present", location="/guesses",
                               fix="make number_of_guesses match the groups /guesses/1, /guesses/2, ...")
    return tuple(_read_solution(_member(grp, k, path, h5py.Group), path) for k in keys)


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
        ``"dense"`` sources are written as ``"csc"``).
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
    from .fclib3d import LOCAL, ROLLING, check_embedded, file_layout, write_group

    h5py = _h5py()
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
        if fmt == "dense":
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
    _write_matrix(g, "M", problem.M, fmts["M"])
    _write_matrix(g, "H", problem.H, fmts["H"])
    vec = g.create_group("vectors")
    for name in ("f", "w", "mu", "mu_r"):
        vec.create_dataset(name, data=np.asarray(getattr(problem, name), dtype=np.float64))
    g.create_dataset("spacedim", data=np.array([problem.spacedim], dtype=np.int32))
    write_info_and_solutions(fh, g, problem, _write_solution)


def write_info_and_solutions(fh, g, problem, write_solution) -> None:
    """g/info (title, description, math_info), /solution with its attributes, and /guesses;
    ``write_solution(group, solution)`` writes one solution's datasets."""
    from .fclib3d import solution_attributes

    info = g.create_group("info")
    for name in ("title", "description", "math_info"):
        info.create_dataset(name, data=np.bytes_(getattr(problem, name).encode("utf-8")))
    if problem.solution is not None:
        sg = fh.create_group("solution")
        write_solution(sg, problem.solution)
        for key, val in solution_attributes(problem).items():
            sg.attrs[key] = val
    if problem.guesses:
        gg = fh.create_group("guesses")
        gg.create_dataset("number_of_guesses", data=np.array([len(problem.guesses)], dtype=np.int32))
        for k, guess in enumerate(problem.guesses, start=1):
            write_solution(gg.create_group(str(k)), guess)


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

    FCLIB keeps ``/solution`` beside the problem, so ``solve in.hdf5 --out in.hdf5`` is a
    reasonable request; the file is copied, the copy updated and renamed over the original,
    so an interrupted write leaves the original untouched.
    """
    from .fclib3d import convert_for_file, detect_layout, file_layout, solution_attributes

    h5py = _h5py()
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
            if extra is not None:  # e.g. /certificate beside the new /solution, in the same copy
                extra(fh)
    return target.path


def _write_matrix(g, name, A: sp.spmatrix, fmt: str):
    grp = g.create_group(name)
    A = sp.csc_matrix(A)
    m, n = A.shape
    if fmt == "triplet":
        coo = A.tocoo()
        p, i, x, nz = coo.col, coo.row, coo.data, coo.nnz
    elif fmt == "csc":
        p, i, x, nz = A.indptr, A.indices, A.data, NZ_CSC
    else:
        csr = A.tocsr()
        p, i, x, nz = csr.indptr, csr.indices, csr.data, NZ_CSR
    grp.create_dataset("m", data=np.array([m], dtype=np.int32))
    grp.create_dataset("n", data=np.array([n], dtype=np.int32))
    grp.create_dataset("nz", data=np.array([nz], dtype=np.int32))
    grp.create_dataset("nzmax", data=np.array([len(x)], dtype=np.int32))
    grp.create_dataset("p", data=np.asarray(p, dtype=np.int32))
    grp.create_dataset("i", data=np.asarray(i, dtype=np.int32))
    grp.create_dataset("x", data=np.asarray(x, dtype=np.float64))


def _write_solution(grp, s: StoredSolution):
    _write_solution_arrays(grp, {key: getattr(s, key) for key in ("v", "u", "r")})


def _write_solution_arrays(grp, arrays: dict):
    for key in ("v", "u", "r"):
        arr = arrays.get(key)
        if arr is not None:
            grp.create_dataset(key, data=np.asarray(arr, dtype=np.float64))


def _first_line(exc) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
