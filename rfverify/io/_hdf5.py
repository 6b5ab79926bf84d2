"""Typed access to the HDF5 files FCLIB writes: checked members, datasets read as the types
the layout declares, sparse matrices in FCLIB's three storages, solutions and guesses; and
their writing.  Shared by the rolling reader (:mod:`.fclib`) and the 3-D one (:mod:`.fclib3d`),
so that neither imports the other's internals."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import DataWarning, InvalidProblemError, ProblemFileError
from ..model.problem import SPACEDIM, StoredSolution
from ._exact import FIX_INEXACT, exact_csc

NZ_CSC = -1
NZ_CSR = -2
STORAGE_FORMATS = ("triplet", "csc", "csr")


def h5py_module():
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

FIX_LAYOUT = ("write the file with rfverify.save or fclib's fclib_write_global_rolling "
               "(layout: DESIGN §7; 3-D files: fclib_write_global/fclib_write_local)")
FIX_INT = "store sizes and indices as integers (int32, as fclib.c writes them)"
FIX_DAMAGED = ("restore the file from a backup, or write it again (with the program that made it; "
               "rfverify's own files: rfverify generate, solve --out or rfverify.save)")
"""The fix of a file whose HDF5 structure is damaged (overwritten bytes, a truncated copy)."""
FIX_REAL = "store the data as float64 (real numbers)"



INFO_FIELDS = ("title", "description", "math_info")


def read_info(g, path) -> tuple:
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
        info = member(g, "info", path, h5py_module().Group)
    except ProblemFileError as exc:
        info_warning(path, exc.location or member_path(g, "info"), exc.problem,
                      "ignored: title, description and math_info read as empty strings")
        return "", "", ""
    return tuple(read_string(info, name, path) for name in INFO_FIELDS)


def info_warning(path, location, problem: str, done: str) -> None:
    warnings.warn(DataWarning(f"{path}: {location}: {problem}; {done} (optional metadata: the "
                              "problem itself is read unchanged)"), stacklevel=2)


# ---------------------------------------------------------------------- typed access
def member_path(group, name) -> str:
    return f"{group.name.rstrip('/')}/{name}"


def kind_name(obj) -> str:
    h5py = h5py_module()
    if isinstance(obj, h5py.Group):
        return "a group"
    if isinstance(obj, h5py.Dataset):
        return "a dataset"
    if isinstance(obj, h5py.Datatype):
        return "a named datatype"
    return type(obj).__name__


def damaged(path, location, what: str, exc) -> ProblemFileError:
    """The error of a file whose HDF5 structure cannot be read: "is truncated" (HDF5 says the
    file ends before the size its header records) or "is damaged: ``what``", with HDF5's own
    words, and the fix: restore or rewrite the file."""
    import re

    detail = first_line(exc)
    cut = re.search(r"truncated file: eof = (\d+).*stored_eof = (\d+)", detail)
    if cut:
        problem = (f"is truncated: it has {cut.group(1)} bytes, its HDF5 header records {cut.group(2)} "
                   f"(the end of the file is missing)")
    else:
        problem = f"is damaged: {what} (HDF5: {detail.strip(chr(39))})"
    return ProblemFileError(path, problem, location=location, fix=FIX_DAMAGED)


def _garbled_names(group) -> str:
    """"" when the member names of ``group`` read as text; else why the group looks damaged (a
    name that is not text, or a list of names HDF5 cannot read)."""
    try:
        names = list(group.keys())
    except (KeyError, OSError, RuntimeError, ValueError) as exc:
        return f"the names of its members cannot be read (HDF5: {first_line(exc)})"
    bad = [n for n in names if not isinstance(n, str) or not n.isprintable()]
    return f"it holds a member whose name is not text ({bad[0]!r})" if bad else ""


def member(group, name, path, kind):
    """``group[name]`` checked to exist, to be reachable (links) and to be a ``kind``
    (h5py.Group or h5py.Dataset).  A hard link that cannot be followed, or a group whose member
    names are not text, means a damaged file (:func:`damaged`); a soft or external link that
    leads nowhere is named as such."""
    h5py = h5py_module()
    loc = member_path(group, name)
    what = "group" if kind is h5py.Group else "dataset"
    link = group.get(name, getlink=True)
    if link is None:
        garbled = _garbled_names(group)
        if garbled:
            raise ProblemFileError(path, f"is missing, and {group.name} looks damaged: {garbled}", location=loc,
                                   fix=FIX_DAMAGED)
        raise ProblemFileError(path, f"missing {what} {loc}", location=loc, fix=FIX_LAYOUT)
    try:
        obj = group[name]
    except (KeyError, OSError, RuntimeError, ValueError) as exc:
        if isinstance(link, h5py.SoftLink):  # made by a user: a link to nothing, or a loop
            try:
                target = group.get(link.path, getlink=True)
            except (KeyError, OSError, RuntimeError, ValueError):
                target = None
            why = ", which does not exist in the file" if target is None else f" that cannot be followed ({first_line(exc)})"
            raise ProblemFileError(path, f"is a soft link (SoftLink) to {link.path}{why}", location=loc,
                                   fix="replace the link by the data it should point to") from None
        if isinstance(link, h5py.ExternalLink):
            raise ProblemFileError(path, f"is an external link (ExternalLink) to {link.path} in {link.filename}, which cannot be "
                                         f"followed ({first_line(exc)})", location=loc,
                                   fix="replace the link by the data it should point to (rfverify reads one "
                                       "self-contained file)") from None
        # A hard link always points into this file: an object there that cannot be opened is damage.
        raise damaged(path, loc, f"the {what} this name points to cannot be opened", exc) from None
    if not isinstance(obj, kind):
        extra = ""
        if kind is h5py.Group and isinstance(obj, h5py.Dataset) and name in ("M", "H"):
            extra = " (a dense matrix?); FCLIB stores a matrix as a group m, n, nz, nzmax, p, i, x"
        raise ProblemFileError(path, f"is {kind_name(obj)}, expected a {what}{extra}",
                               location=loc, fix=FIX_LAYOUT)
    return obj


def dataset_dtype(ds, path):
    try:
        return ds.dtype
    except (TypeError, ValueError) as exc:  # bitfield, reference, ...: no numpy equivalent
        raise ProblemFileError(path, f"has an HDF5 type rfverify cannot read ({first_line(exc)})",
                               location=ds.name, fix=FIX_REAL) from None


def read_dataset(ds, path) -> np.ndarray:
    """All of ``ds``, after checking that its declared size is plausible: HDF5 datasets may be
    declared far larger than the data stored (unwritten parts read as fill values), and a
    hostile declaration must not exhaust memory."""
    dt = dataset_dtype(ds, path)
    if ds.size > MAX_INDEX:
        raise ProblemFileError(path, f"declares {ds.size} values, more than an FCLIB file can "
                                     f"index ({MAX_INDEX})", location=ds.name, fix=FIX_LAYOUT)
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
        raise damaged(path, ds.name, "its data cannot be read", exc) from None


def refuse_kind(dt, ds, path, expected: str, fix: str):
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


def check_shape(ds, path, *, vector: bool):
    shape = ds.shape
    if shape is None:  # HDF5 null dataspace
        raise ProblemFileError(path, "is an empty (null) dataset", location=ds.name, fix=FIX_LAYOUT)
    if len(shape) <= 1 or (len(shape) == 2 and 1 in shape):
        return
    expected = "a vector (1-D dataset)" if vector else "one value"
    raise ProblemFileError(path, f"has shape {shape}, expected {expected}", location=ds.name,
                           fix=FIX_LAYOUT)


def read_real(ds, path) -> np.ndarray:
    """A numeric dataset as a flat float64 array, refused unless every value is exact."""
    dt = dataset_dtype(ds, path)
    if dt.names is not None or dt.kind not in "fiu":
        refuse_kind(dt, ds, path, "real numbers", FIX_REAL)
    check_shape(ds, path, vector=True)
    arr = read_dataset(ds, path).ravel()
    if dt.kind in "iu":
        values = arr.astype(np.float64)
        # Beyond 2^53 only some integers are float64 numbers: compare each such one exactly.
        beyond = np.flatnonzero(np.abs(values) >= _EXACT_INT)
        inexact = [int(i) for i, x, y in zip(beyond.tolist(), arr[beyond].tolist(), values[beyond].tolist())
                   if int(y) != x]
        if inexact:
            raise ProblemFileError(path, f"holds integers that float64 cannot represent exactly "
                                         f"({len(inexact)}; the first, {arr[inexact[0]]} at index {inexact[0]}, "
                                         f"would be read as {values[inexact[0]]:.17g})", location=ds.name,
                                   fix=FIX_REAL)
        return values
    if dt.itemsize > 8:  # longdouble data: keep it only if float64 holds every value exactly
        with np.errstate(over="ignore"):
            back = arr.astype(np.float64).astype(arr.dtype)
        if not np.array_equal(back, arr, equal_nan=True):
            raise ProblemFileError(path, f"holds {dt} values that float64 cannot represent "
                                         "exactly", location=ds.name, fix=FIX_REAL)
    return arr.astype(np.float64)


def read_integers(ds, path, *, vector: bool = True) -> np.ndarray:
    """An integer dataset as a flat int64 array; floats (even integral ones) are refused."""
    dt = dataset_dtype(ds, path)
    if dt.names is not None or dt.kind not in "iu":
        refuse_kind(dt, ds, path, "integers", FIX_INT)
    check_shape(ds, path, vector=vector)
    arr = read_dataset(ds, path).ravel()
    if dt.kind == "u" and arr.size and arr.max() > np.iinfo(np.int64).max:
        raise ProblemFileError(path, f"holds an index {arr.max()} beyond any FCLIB size",
                               location=ds.name, fix=FIX_INT)
    return arr.astype(np.int64)


def read_scalar_int(ds, path) -> int:
    arr = read_integers(ds, path, vector=False)
    if arr.size != 1:
        found = "no value (empty dataset)" if arr.size == 0 else f"{arr.size} values"
        raise ProblemFileError(path, f"holds {found}, expected exactly one integer",
                               location=ds.name, fix=FIX_LAYOUT)
    return int(arr[0])


def read_vector(group, name, path) -> np.ndarray:
    return read_real(member(group, name, path, h5py_module().Dataset), path)


def read_string(group, name, path) -> str:
    """One optional info string (see :func:`read_info`): never an error, at worst a warning."""
    if group.get(name, getlink=True) is None:
        return ""
    loc = member_path(group, name)
    try:
        ds = member(group, name, path, h5py_module().Dataset)
        dt = dataset_dtype(ds, path)
        if dt.kind not in "SUO":
            info_warning(path, loc, f"holds {dt} values, not a string",
                          "ignored: read as an empty string")
            return ""
        if ds.shape is None:  # HDF5 null dataspace: no string at all
            return ""
        val = read_dataset(ds, path)
    except ProblemFileError as exc:
        info_warning(path, loc, exc.problem, "ignored: read as an empty string")
        return ""
    items = np.atleast_1d(val).ravel().tolist() if isinstance(val, np.ndarray) else [val]
    if not all(isinstance(v, str | bytes) for v in items):
        kinds = sorted({type(v).__name__ for v in items if not isinstance(v, str | bytes)})
        info_warning(path, loc, f"holds {', '.join(kinds)} objects, not strings",
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
        info_warning(path, loc, f"is not valid UTF-8 ({undecodable[0]}{more})",
                      "read with U+FFFD in place of the undecodable bytes")
    if len(texts) > 1:
        info_warning(path, loc, f"holds {len(texts)} strings, expected one",
                      "read as one string, joined with newlines")
    return "\n".join(texts)


# ---------------------------------------------------------------------- matrices
def matrix_meta(g, name, path) -> dict:
    """A matrix group's sizes and storage code, checked; nothing of size n or nnz is read."""
    h5py = h5py_module()
    grp = member(g, name, path, h5py.Group)
    meta = {"name": name, "group": grp, "loc": grp.name}
    for key in ("m", "n", "nz", "nzmax"):
        meta[key] = read_scalar_int(member(grp, key, path, h5py.Dataset), path)
    for key in ("m", "n", "nzmax"):
        if not 0 <= meta[key] <= MAX_INDEX:
            raise ProblemFileError(path, f"{key} = {meta[key]} is outside 0..{MAX_INDEX}",
                                   location=member_path(grp, key), fix=FIX_LAYOUT)
    if meta["nz"] < NZ_CSR or meta["nz"] > MAX_INDEX:
        raise ProblemFileError(path, f"unknown storage nz = {meta['nz']} (expected ≥ 0 triplet, "
                                     "-1 CSC or -2 CSR)", location=member_path(grp, "nz"), fix=FIX_LAYOUT)
    for key in ("p", "i", "x"):
        meta[key] = member(grp, key, path, h5py.Dataset)
    return meta


def check_declared_sizes(M, H, m_f, n_mu, spacedim):
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


def read_matrix(meta, path):
    name, loc, m, n, nz = meta["name"], meta["loc"], meta["m"], meta["n"], meta["nz"]

    def bad(msg, where=loc):
        return ProblemFileError(path, f"matrix {name}: {msg}", location=where, fix=FIX_LAYOUT)

    def inexact(k, msg):
        return ProblemFileError(path, msg, location=f"{loc}/x[{k}]", fix=FIX_INEXACT)

    sizes = {k: meta[k].size for k in ("p", "i", "x")}
    if nz >= 0:
        if min(sizes.values()) < nz:
            raise bad(f"triplet with nz = {nz} but p/i/x hold {sizes['p']}/{sizes['i']}/"
                      f"{sizes['x']} entries")
        p = read_integers(meta["p"], path)[:nz]
        i = read_integers(meta["i"], path)[:nz]
        x = read_real(meta["x"], path)[:nz]
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
    ptr = read_integers(meta["p"], path)[:outer + 1]
    if ptr[0] != 0 or np.any(np.diff(ptr) < 0):
        raise bad(f"{kind} pointer array p is not non-decreasing from 0", f"{loc}/p")
    nnz = int(ptr[-1])
    if sizes["i"] < nnz or sizes["x"] < nnz:
        raise bad(f"{kind} needs {nnz} entries, i/x hold {sizes['i']}/{sizes['x']}")
    idx = read_integers(meta["i"], path)[:nnz]
    x = read_real(meta["x"], path)[:nnz]
    if nnz and (idx.min() < 0 or idx.max() >= inner):
        raise bad(f"index out of range 0..{inner - 1} in i (holds {idx.min()}..{idx.max()})",
                  f"{loc}/i")
    outer_of = np.repeat(np.arange(outer, dtype=np.int64), np.diff(ptr))
    rows, cols = (idx, outer_of) if nz == NZ_CSC else (outer_of, idx)
    return exact_csc(rows, cols, x, (m, n), matrix=name, refuse=inexact), kind


# ---------------------------------------------------------------------- solutions
def read_solution(grp, path) -> StoredSolution:
    vals = {}
    for key in ("v", "u", "r"):
        if grp.get(key, getlink=True) is not None:
            vals[key] = read_real(member(grp, key, path, h5py_module().Dataset), path)
    return StoredSolution(**vals)


def read_guesses(grp, path) -> tuple:
    h5py = h5py_module()
    keys = sorted((k for k in grp.keys() if k.isdigit()), key=int)
    declared = len(keys)
    if grp.get("number_of_guesses", getlink=True) is not None:
        declared = read_scalar_int(member(grp, "number_of_guesses", path, h5py.Dataset), path)
    if declared != len(keys):
        raise ProblemFileError(path, f"number_of_guesses = {declared} but {len(keys)} guess groups "
                                     "are present", location="/guesses",
                               fix="make number_of_guesses match the groups /guesses/1, /guesses/2, ...")
    return tuple(read_solution(member(grp, k, path, h5py.Group), path) for k in keys)


# ---------------------------------------------------------------------- writing
def write_matrix(g, name, A: sp.spmatrix, fmt: str):
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


def write_solution(grp, s: StoredSolution):
    write_solution_arrays(grp, {key: getattr(s, key) for key in ("v", "u", "r")})


def write_solution_arrays(grp, arrays: dict):
    for key in ("v", "u", "r"):
        arr = arrays.get(key)
        if arr is not None:
            grp.create_dataset(key, data=np.asarray(arr, dtype=np.float64))


def first_line(exc) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
