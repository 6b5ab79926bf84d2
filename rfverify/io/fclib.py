"""FCLIB ``/fclib_global_rolling`` HDF5 files: read and write (DESIGN §7).

Layout::

    /fclib_global_rolling/M, /H        matrix groups: m, n, nz, nzmax, p, i, x
    /fclib_global_rolling/vectors/     f, w, mu, mu_r
    /fclib_global_rolling/spacedim     [5]
    /fclib_global_rolling/info/        title, description, math_info   (optional)
    /solution/                         v, u, r                           (optional)
    /guesses/number_of_guesses, /guesses/1/{v,u,r}, /guesses/2/...      (optional)

Matrix storage is told by ``nz``: ``nz ≥ 0`` triplet with **i = row, p = column** (the comment
in fclib.h has it backwards; the files and fclib.c agree with this), duplicates summed;
``nz = −1`` CSC (p = column pointers, i = row indices); ``nz = −2`` CSR (p = row pointers,
i = column indices).  Index arrays are written as int32 like fclib.c, values as float64.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidProblemError, ProblemFileError
from ..problem import DEFAULT_MAX_ASYMMETRY, Problem, StoredSolution

ROOT = "fclib_global_rolling"
NZ_CSC = -1
NZ_CSR = -2
STORAGE_FORMATS = ("triplet", "csc", "csr")


def _h5py():
    import h5py  # imported lazily: `rfverify --help` should not pay for it

    return h5py


def read_fclib(path, *, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY) -> Problem:
    """Read a ``fclib_global_rolling`` HDF5 file into a validated :class:`Problem`.

    Raises
    ------
    ProblemFileError
        missing/unreadable/non-HDF5 file, missing group or dataset (its HDF5 path is named),
        inconsistent matrix storage.
    InvalidProblemError
        the data read are not a valid problem (see :meth:`Problem.from_arrays`).
    """
    h5py = _h5py()
    path = Path(path)
    if not path.exists():
        raise ProblemFileError(path, "no such file")
    if path.is_dir():
        raise ProblemFileError(path, "is a directory, expected an FCLIB .hdf5 file")
    if not h5py.is_hdf5(path):
        raise ProblemFileError(path, "is not an HDF5 file (wrong format, or truncated: the "
                                     "HDF5 signature is missing)")
    try:
        with h5py.File(path, "r") as fh:
            return _read_open_file(fh, path, max_asymmetry)
    except (InvalidProblemError, ProblemFileError):
        raise
    except (OSError, KeyError, RuntimeError) as exc:  # truncated or corrupt inside
        raise ProblemFileError(path, f"cannot be read as HDF5 ({_first_line(exc)}); "
                                     "the file is probably truncated or corrupt") from None


def _read_open_file(fh, path, max_asymmetry):
    if ROOT not in fh:
        other = [k for k in fh.keys() if k.startswith("fclib_")]
        hint = f" (it holds {other[0]}: not a rolling-friction problem)" if other else ""
        raise ProblemFileError(path, f"missing group /{ROOT}{hint}", location=f"/{ROOT}")
    g = fh[ROOT]
    if "G" in g or "b" in g.get("vectors", {}):
        raise ProblemFileError(path, "equality constraints (G, b) are not supported by rfverify",
                               location=f"/{ROOT}/G")
    M, M_fmt = _read_matrix(g, "M", path)
    H, H_fmt = _read_matrix(g, "H", path)
    vectors = _require(g, "vectors", path)
    f = _read_vector(vectors, "f", path)
    w = _read_vector(vectors, "w", path)
    mu = _read_vector(vectors, "mu", path)
    mu_r = _read_vector(vectors, "mu_r", path)
    spacedim = int(_scalar(_require(g, "spacedim", path), path))
    info = g.get("info")
    title = description = math_info = ""
    if info is not None:
        title = _read_string(info, "title")
        description = _read_string(info, "description")
        math_info = _read_string(info, "math_info")
    solution = _read_solution(fh["solution"], path, "/solution") if "solution" in fh else None
    guesses = _read_guesses(fh["guesses"], path) if "guesses" in fh else ()
    return Problem.from_arrays(
        M, H, f, w, mu, mu_r, title=title, description=description, math_info=math_info,
        solution=solution, guesses=guesses, storage={"M": M_fmt, "H": H_fmt},
        max_asymmetry=max_asymmetry, spacedim=spacedim, source=str(path),
    )


def _require(group, name, path):
    if name not in group:
        raise ProblemFileError(path, f"missing {'group' if name in ('vectors', 'info') else 'dataset'}"
                                     f" {group.name}/{name}", location=f"{group.name}/{name}")
    return group[name]


def _scalar(ds, path):
    arr = np.asarray(ds[()]).ravel()
    if arr.size != 1:
        raise ProblemFileError(path, f"expected one value, found {arr.size}", location=ds.name)
    return arr[0]


def _read_vector(group, name, path) -> np.ndarray:
    ds = _require(group, name, path)
    arr = np.asarray(ds[()])
    if arr.dtype.kind not in "fiu":
        raise ProblemFileError(path, f"has dtype {arr.dtype}, expected numbers", location=ds.name)
    return np.asarray(arr, dtype=np.float64).ravel()


def _read_string(group, name) -> str:
    if name not in group:
        return ""
    val = group[name][()]
    if isinstance(val, np.ndarray):
        val = val.ravel()[0] if val.size else b""
    if isinstance(val, bytes):
        return val.decode("utf-8", errors="replace")
    return str(val)


def _read_matrix(g, name, path):
    grp = _require(g, name, path)
    loc = grp.name
    fields = {}
    for key in ("m", "n", "nz", "nzmax", "p", "i", "x"):
        if key not in grp:
            raise ProblemFileError(path, f"matrix {name} lacks dataset '{key}'", location=f"{loc}/{key}")
        fields[key] = np.asarray(grp[key][()])
    m, n, nz = (int(np.ravel(fields[k])[0]) for k in ("m", "n", "nz"))
    p = fields["p"].astype(np.int64).ravel()
    i = fields["i"].astype(np.int64).ravel()
    x = np.asarray(fields["x"], dtype=np.float64).ravel()
    if m < 0 or n < 0:
        raise ProblemFileError(path, f"matrix {name} has negative size {m}×{n}", location=loc)

    def bad(msg):
        return ProblemFileError(path, f"matrix {name}: {msg}", location=loc)

    if nz >= 0:
        if min(p.size, i.size, x.size) < nz:
            raise bad(f"triplet with nz = {nz} but p/i/x hold {p.size}/{i.size}/{x.size} entries")
        rows, cols, vals = i[:nz], p[:nz], x[:nz]
        if nz and (rows.min() < 0 or rows.max() >= m):
            raise bad(f"row index out of range 0..{m - 1} (i holds {rows.min()}..{rows.max()})")
        if nz and (cols.min() < 0 or cols.max() >= n):
            raise bad(f"column index out of range 0..{n - 1} (p holds {cols.min()}..{cols.max()})")
        A = sp.coo_matrix((vals, (rows, cols)), shape=(m, n)).tocsc()  # sums duplicates
        return A, "triplet"
    if nz in (NZ_CSC, NZ_CSR):
        outer, inner = (n, m) if nz == NZ_CSC else (m, n)
        kind = "csc" if nz == NZ_CSC else "csr"
        if p.size < outer + 1:
            raise bad(f"{kind} pointer array p has {p.size} entries, needs {outer + 1}")
        ptr = p[:outer + 1]
        if ptr[0] != 0 or np.any(np.diff(ptr) < 0):
            raise bad(f"{kind} pointer array p is not non-decreasing from 0")
        nnz = int(ptr[-1])
        if i.size < nnz or x.size < nnz:
            raise bad(f"{kind} needs {nnz} entries, i/x hold {i.size}/{x.size}")
        idx = i[:nnz]
        if nnz and (idx.min() < 0 or idx.max() >= inner):
            raise bad(f"index out of range 0..{inner - 1} in i")
        cls = sp.csc_matrix if nz == NZ_CSC else sp.csr_matrix
        A = cls((x[:nnz], idx, ptr), shape=(m, n))
        A = sp.csc_matrix(A)
        A.sum_duplicates()
        return A, kind
    raise bad(f"unknown storage nz = {nz} (expected ≥ 0 triplet, -1 CSC or -2 CSR)")


def _read_solution(grp, path, where) -> StoredSolution:
    vals = {}
    for key in ("v", "u", "r"):
        if key in grp:
            arr = np.asarray(grp[key][()])
            if arr.dtype.kind not in "fiu":
                raise ProblemFileError(path, f"has dtype {arr.dtype}, expected numbers",
                                       location=f"{where}/{key}")
            vals[key] = np.asarray(arr, dtype=np.float64).ravel()
    return StoredSolution(**vals)


def _read_guesses(grp, path) -> tuple:
    keys = sorted((k for k in grp.keys() if k.isdigit()), key=int)
    declared = int(_scalar(grp["number_of_guesses"], path)) if "number_of_guesses" in grp else len(keys)
    if declared != len(keys):
        raise ProblemFileError(path, f"number_of_guesses = {declared} but {len(keys)} guess groups "
                                     "are present", location="/guesses")
    return tuple(_read_solution(grp[k], path, f"/guesses/{k}") for k in keys)


# ---------------------------------------------------------------------- writing
def write_fclib(problem: Problem, path, *, storage: dict | str | None = None,
                overwrite: bool = True) -> Path:
    """Write ``problem`` (its raw, unsymmetrised M) to ``path`` in FCLIB layout.

    Parameters
    ----------
    storage : "triplet" | "csc" | "csr" | dict, optional
        Matrix storage; a dict may give one per matrix (``{"M": "csc", "H": "triplet"}``).
        Defaults to the format the problem was read in (``"csc"`` for problems built in memory;
        ``"dense"`` sources are written as ``"csc"``).
    overwrite : bool
        Refuse to replace an existing file when False.

    Reading the file back gives bit-identical arrays (M, H, f, w, mu, mu_r, solution, guesses).
    """
    h5py = _h5py()
    path = Path(path)
    if path.exists() and not overwrite:
        raise ProblemFileError(path, "exists already (pass overwrite=True to replace it)")
    fmts = {}
    for name in ("M", "H"):
        fmt = storage.get(name) if isinstance(storage, dict) else storage
        fmt = fmt or problem.storage.get(name, "csc")
        if fmt == "dense":
            fmt = "csc"
        if fmt not in STORAGE_FORMATS:
            raise ValueError(f"storage for {name}: {fmt!r} is not one of {STORAGE_FORMATS}")
        fmts[name] = fmt
    tmp = path.with_name(path.name + ".partial")
    if not path.parent.is_dir():
        raise ProblemFileError(path, f"cannot write: directory {path.parent} does not exist")
    try:
        fh_ctx = h5py.File(tmp, "w")
    except OSError as exc:
        raise ProblemFileError(path, f"cannot write ({_first_line(exc)})") from None
    try:
        with fh_ctx as fh:
            g = fh.create_group(ROOT)
            _write_matrix(g, "M", problem.M, fmts["M"])
            _write_matrix(g, "H", problem.H, fmts["H"])
            vec = g.create_group("vectors")
            for name in ("f", "w", "mu", "mu_r"):
                vec.create_dataset(name, data=np.asarray(getattr(problem, name), dtype=np.float64))
            g.create_dataset("spacedim", data=np.array([problem.spacedim], dtype=np.int32))
            info = g.create_group("info")
            for name in ("title", "description", "math_info"):
                info.create_dataset(name, data=np.bytes_(getattr(problem, name).encode("utf-8")))
            if problem.solution is not None:
                _write_solution(fh.create_group("solution"), problem.solution)
            if problem.guesses:
                gg = fh.create_group("guesses")
                gg.create_dataset("number_of_guesses", data=np.array([len(problem.guesses)], dtype=np.int32))
                for k, guess in enumerate(problem.guesses, start=1):
                    _write_solution(gg.create_group(str(k)), guess)
        tmp.replace(path)  # never leave a half-written file under the final name
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


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
    for key in ("v", "u", "r"):
        arr = getattr(s, key)
        if arr is not None:
            grp.create_dataset(key, data=np.asarray(arr, dtype=np.float64))


def _first_line(exc) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
