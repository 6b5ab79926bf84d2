"""FCLIB 3-D Coulomb friction files: ``/fclib_global`` and ``/fclib_local`` (DESIGN §1, §7).

Layout (fclib.c, ``fclib_write_global`` / ``fclib_write_local`` / ``fclib_write_solution``)::

    /fclib_global/M, /H          matrix groups (m, n, nz, nzmax, p, i, x): M m×m, H m×3n
    /fclib_global/G              equality constraints (optional; refused)
    /fclib_global/vectors/       f (m), w (3n), mu (n); b (with G; refused)
    /fclib_local/W               matrix group, 3n×3n
    /fclib_local/V, /R           (optional, together; refused)
    /fclib_local/vectors/        q (3n), mu (n); s (with R; refused)
    /fclib_*/spacedim            [3]  (fclib also allows 2: refused, not supported)
    /fclib_*/info/               title, description, math_info (optional)
    /solution/                   global: v (m), u (3n), r (3n); local: u (3n), r (3n); l (with G/R)
    /guesses/number_of_guesses, /guesses/1/..., as /solution

Per contact the components are (N, T1, T2).  The convex relaxation of such a problem is exactly
the rolling problem with μr = 0 and no rolling rows, so rfverify reads it into the rolling
layout: each contact's (N, T1, T2) become the first three of (N, T1, T2, R1, R2), R1 = R2 = 0
(zero H columns, zero w entries), μr = 0.  The solver's cone reduction treats those contacts as
plain Coulomb cones.  A local problem (W, q) is lifted like the Siconos local ``.dat`` problems
(W = HᵀH from a symmetric eigendecomposition, M = I, f = 0, w = q; :func:`factor_delassus`),
on the 3n×3n W itself so that the rolling columns of H are exactly zero.

``Problem.provenance`` says what was done; ``Problem.native`` keeps the raw W and q of a local
problem so that :func:`rfverify.save` writes the problem back as it was read, with ``/solution``
3 per contact (a local file: u and r only; the v of the lifted problem is not a quantity of the
file, and is recovered from r as v = H r when a local solution is read, since M = I, f = 0).

When a file holds several problem groups, ``/fclib_global_rolling`` is read first, then
``/fclib_global``, then ``/fclib_local`` (fclib's own solution reader also prefers the global
problem); the groups left unread are named in ``provenance["ignored_groups"]`` and by ``info``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError, InvalidProblemError, ProblemFileError
from ..model.problem import DEFAULT_MAX_ASYMMETRY, SPACEDIM, Problem, StoredSolution, make_local_form
from ._hdf5 import (check_mass_declaration, h5py_module, matrix_meta, member, read_guesses, read_info, read_matrix,
                    read_scalar_int,
                    read_solution, read_vector, write_matrix, write_solution_arrays)
from .local_lift import LOCAL_DENSE_LIMIT, check_finite, factor_delassus

GLOBAL = "fclib_global"
LOCAL = "fclib_local"
ROLLING = "fclib_global_rolling"
FILE_SPACEDIM = 3
"""Components per contact in a 3-D FCLIB file: (N, T1, T2)."""

RELAXATION = "convex (De Saxcé term dropped)"
MU_R = "0 (3-D Coulomb embedded in the rolling layout)"
EMBEDDING = ("each contact's (N, T1, T2) is (N, T1, T2, R1, R2) of the rolling layout with "
             "R1 = R2 = 0: zero H columns and w entries, mu_r = 0")
LIFTING = "W = HᵀH (H = Λ^1/2 Vᵀ from (W + Wᵀ)/2 = V Λ Vᵀ), M = I, f = 0, w = q"

SOLUTION_LAYOUT = {
    ROLLING: "fclib_global_rolling: v (m), u and r 5 per contact (N, T1, T2, R1, R2)",
    GLOBAL: "fclib_global: v (m), u and r 3 per contact (N, T1, T2)",
    LOCAL: "fclib_local: u and r 3 per contact (N, T1, T2); no v (not a quantity of a local problem)",
}


@dataclass(frozen=True, eq=False)
class LocalData:
    """The raw data of an ``/fclib_local`` problem, kept to write it back exactly."""

    W: sp.csc_matrix
    q: np.ndarray
    storage: str


# ---------------------------------------------------------------------- layout maps
def _slots(n: int) -> np.ndarray:
    """Positions of the 3n file components inside the 5n rolling layout."""
    return (SPACEDIM * np.arange(n)[:, None] + np.arange(FILE_SPACEDIM)[None, :]).ravel()


def embed(x3, n: int | None = None) -> np.ndarray:
    """A contact vector of 3 per contact (N, T1, T2) → 5 per contact with R1 = R2 = 0."""
    x3 = np.asarray(x3, dtype=np.float64).ravel()
    n = x3.size // FILE_SPACEDIM if n is None else n
    out = np.zeros(SPACEDIM * n)
    out[_slots(n)] = x3
    return out


def extract(x5) -> np.ndarray:
    """A contact vector of 5 per contact → its 3 per contact (N, T1, T2)."""
    x5 = np.asarray(x5, dtype=np.float64).ravel()
    return x5[_slots(x5.size // SPACEDIM)].copy()


def embed_columns(A3) -> sp.csc_matrix:
    """rows × 3n → rows × 5n with zero rolling columns; entries (and their order) unchanged."""
    A3 = sp.csc_matrix(A3)
    rows, cols3 = A3.shape
    n = cols3 // FILE_SPACEDIM
    counts = np.zeros(SPACEDIM * n, dtype=np.int64)
    counts[_slots(n)] = np.diff(A3.indptr)
    indptr = np.concatenate(([0], np.cumsum(counts)))
    return sp.csc_matrix((A3.data.copy(), A3.indices.copy(), indptr), shape=(rows, SPACEDIM * n))


def embed_square(W3) -> sp.csr_matrix:
    """3n × 3n → 5n × 5n with zero rolling rows and columns; entries unchanged (a local W)."""
    n = sp.csc_matrix(W3).shape[0] // FILE_SPACEDIM
    slots = _slots(n)
    C = sp.coo_matrix(W3)
    return sp.csr_matrix((C.data.copy(), (slots[C.row], slots[C.col])), shape=(SPACEDIM * n, SPACEDIM * n))


def extract_columns(A5) -> sp.csc_matrix:
    """rows × 5n → rows × 3n (the N, T1, T2 columns), entries unchanged."""
    A5 = sp.csc_matrix(A5)
    return sp.csc_matrix(A5[:, _slots(A5.shape[1] // SPACEDIM)])


def file_layout(problem: Problem) -> str:
    """``"fclib_global"`` or ``"fclib_local"`` for a problem read from a 3-D FCLIB file,
    ``"fclib_global_rolling"`` otherwise."""
    fmt = problem.provenance.get("format")
    return fmt if fmt in (GLOBAL, LOCAL) else ROLLING


def check_embedded(problem: Problem) -> None:
    """Refuse to write ``problem`` as a 3-D file when its rolling part is not empty (it was
    changed after reading, or the provenance is wrong): nothing would be written for it."""
    layout = file_layout(problem)
    n = problem.n_contacts
    rolling = np.setdiff1d(np.arange(SPACEDIM * n), _slots(n))
    H_rolling = sp.csc_matrix(problem.H)[:, rolling]
    bad = []
    if H_rolling.count_nonzero():
        bad.append("H has non-zero rolling columns")
    if np.any(problem.w[rolling] != 0):
        bad.append("w has non-zero rolling entries")
    if np.any(problem.mu_r != 0):
        bad.append("mu_r is not 0")
    if layout == LOCAL and not isinstance(problem.native, LocalData):
        bad.append("the raw W and q of the local file are missing (problem.native)")
    if bad:
        raise InvalidArgumentError(
            "problem", f"cannot be written as /{layout} (3 per contact): {'; '.join(bad)}",
            fix="write a problem as rfverify.load read it, or build a rolling problem without "
                "provenance['format'] and save it as /fclib_global_rolling")


def solution_datasets(problem: Problem, solution: StoredSolution) -> dict:
    """``{"v", "u", "r"}`` → array or None, in the layout of the problem's file (see
    :func:`convert_for_file`)."""
    return convert_for_file(file_layout(problem), solution)


def symmetrised(problem: Problem) -> dict:
    """What was symmetrised for solving, with both measures (JSON-able): M for global problems,
    W for local ones (their M = I is exactly symmetric)."""
    if file_layout(problem) == LOCAL or "lift" in problem.provenance:
        lift = problem.provenance.get("lifted") or problem.provenance.get("lift") or {}
        at = lift.get("asymmetry_at")
        scaled = float(lift.get("asymmetry", 0.0))
        return {"matrix": "W", "entrywise": scaled, "normwise": float(lift.get("asymmetry_normwise", 0.0)),
                "at": None if at is None else list(at), "symmetrised": scaled > 0}
    return problem.symmetry.as_dict("M")


def describe_symmetrised(d: dict) -> str:
    """One line for ``info`` and the ``symmetrised`` attribute of ``/solution``."""
    X = d["matrix"]
    if not d["symmetrised"]:
        return f"nothing: {X} is exactly symmetric"
    at = "" if d["at"] is None else f" at ({d['at'][0]}, {d['at'][1]})"
    return (f"{X}: ({X} + {X}^T)/2 used for solving; entrywise asymmetry max|{X}_ij - {X}_ji|/"
            f"sqrt({X}_ii {X}_jj) = {d['entrywise']:.3g}{at}, normwise ||{X} - {X}^T||_F/||{X}||_F "
            f"= {d['normwise']:.3g}")


def solution_attributes(problem: Problem) -> dict:
    """Attributes written on ``/solution``: its layout, the problem it solves (``problem``, the
    statement every verdict prints; ``equations``: "symmetrised", "stored" or "symmetric" when
    the stored matrix is symmetric and both are the same) and what was symmetrised."""
    d = symmetrised(problem)
    return {"layout": SOLUTION_LAYOUT[file_layout(problem)],
            "problem": problem.statement,
            "equations": problem.equations if not problem.matrix_is_symmetric else "symmetric",
            "symmetrised": describe_symmetrised(d),
            "symmetrised_matrix": d["matrix"] if d["symmetrised"] else "",
            "asymmetry_entrywise": float(d["entrywise"]),
            "asymmetry_normwise": float(d["normwise"])}


# ---------------------------------------------------------------------- reading
def read_group(fh, root: str, path, max_asymmetry: float, ignored: list) -> Problem:
    """Read ``/fclib_global`` or ``/fclib_local`` of the open file ``fh``."""

    g = member(fh, root, path, h5py_module().Group)
    if root == GLOBAL:
        return _read_global(fh, g, path, max_asymmetry, ignored)
    return _read_local(fh, g, path, max_asymmetry, ignored)


def provenance_3d(root: str, ignored: list) -> dict:
    prov = {"format": root, "spacedim": FILE_SPACEDIM, "relaxation": RELAXATION, "mu_r": MU_R,
            "embedding": EMBEDDING}
    if ignored:
        prov["ignored_groups"] = [f"/{k}" for k in ignored]
    return prov


def _refuse(g, names, path, what: str, fix: str):
    for name in names:
        if g.get(name, getlink=True) is not None:
            raise ProblemFileError(path, what, location=f"{g.name}/{name}", fix=fix)


def _spacedim(g, path) -> int:

    ds = member(g, "spacedim", path, h5py_module().Dataset)
    d = read_scalar_int(ds, path)
    if d == FILE_SPACEDIM:
        return d
    if d == 2:
        what = "is 2: 2-D friction problems are not supported by rfverify"
        fix = "pass a 3-D problem (spacedim 3)"
    elif d == SPACEDIM:
        what = (f"is 5 in {g.name}: a rolling-friction problem (5 per contact) belongs in "
                "/fclib_global_rolling")
        fix = "store it as /fclib_global_rolling, or write a 3-D problem with spacedim 3"
    else:
        what = f"is {d}; {g.name} holds 3-D friction problems (spacedim 3, fclib allows 2 or 3)"
        fix = "write spacedim = 3 (N, T1, T2 per contact)"
    raise ProblemFileError(path, what, location=ds.name, fix=fix)


def _contact_vector_size(name: str, size: int, n: int, fix: str):
    if size != FILE_SPACEDIM * n:
        hint = (" (5 per contact: a rolling problem? it belongs in /fclib_global_rolling)"
                if size == SPACEDIM * n else "")
        raise InvalidProblemError(name, f"has {size} entries, expected 3n = {FILE_SPACEDIM * n} "
                                        f"from mu ({n} contacts){hint}", fix=fix)


def _vectors_without(g, group_members, vector_members, path, why, fix, *, mu_r_fix):
    """g/vectors, after refusing the members of g and of g/vectors that rfverify cannot model,
    and a rolling resistance mu_r (a 3-D Coulomb group has none)."""

    _refuse(g, group_members, path, why, fix=fix)
    vectors = member(g, "vectors", path, h5py_module().Group)
    _refuse(vectors, vector_members, path, why, fix=fix)
    _refuse(vectors, ["mu_r"], path, f"rolling resistance in a 3-D Coulomb problem: {g.name} has no mu_r",
            fix=mu_r_fix)
    return vectors


def _read_global(fh, g, path, max_asymmetry, ignored) -> Problem:

    vectors = _vectors_without(g, ["G"], ["b"], path, "equality constraints (G, b) are not supported by rfverify",
                               "eliminate the constraints (or remove G and b) before passing the problem",
                               mu_r_fix="store a rolling problem as /fclib_global_rolling (spacedim 5), or remove mu_r")
    f = read_vector(vectors, "f", path)
    w = read_vector(vectors, "w", path)
    mu = read_vector(vectors, "mu", path)
    _spacedim(g, path)
    M_meta = matrix_meta(g, "M", path)
    H_meta = matrix_meta(g, "H", path)
    m, n = f.size, mu.size
    check_mass_declaration(M_meta, m)
    if H_meta["n"] == SPACEDIM * n and n > 0:
        raise InvalidProblemError(
            "H", f"is declared {H_meta['m']}×{H_meta['n']}: 5 columns per contact ({n} contacts), the "
                 "rolling layout, in a 3-D file (spacedim 3: 3 columns per contact)",
            fix="store a rolling problem as /fclib_global_rolling (spacedim 5), or keep only the "
                "N, T1, T2 columns of each contact")
    if (H_meta["m"], H_meta["n"]) != (m, FILE_SPACEDIM * n):
        raise InvalidProblemError("H", f"is declared {H_meta['m']}×{H_meta['n']} (H/m, H/n), expected "
                                       f"(m, 3n) = ({m}, {FILE_SPACEDIM * n}) from f ({m} entries) and "
                                       f"mu ({n} contacts)",
                                  fix="H has one row per dof and 3 columns per contact (N, T1, T2)")
    _contact_vector_size("w", w.size, n, fix="w has 3 entries per contact (N, T1, T2)")
    M, M_fmt = read_matrix(M_meta, path)
    H3, H_fmt = read_matrix(H_meta, path)
    title, description, math_info = read_info(g, path)
    solution, guesses = _read_solutions(fh, path, m=m, n=n, local_H=None)
    return global_3d_problem(M, H3, f, w, mu, title=title, description=description, math_info=math_info,
                             solution=solution, guesses=guesses, storage={"M": M_fmt, "H": H_fmt},
                             max_asymmetry=max_asymmetry, source=str(path), provenance=provenance_3d(GLOBAL, ignored))


def global_3d_problem(M, H3, f, w3, mu, *, provenance: dict, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY,
                      **fields) -> Problem:
    """The rolling-layout :class:`Problem` of a 3-D global Coulomb problem M v = H r + f,
    u = Hᵀv + w (H m × 3n, w 3n: N, T1, T2 per contact): zero rolling columns, μr = 0.
    ``provenance`` (as :func:`_provenance` makes it) says so; ``fields`` go to
    :meth:`Problem.from_arrays` (title, source, storage, ...)."""
    n = np.asarray(mu).size
    problem = Problem.from_arrays(M, embed_columns(H3), f, embed(w3, n), mu, np.zeros(n),
                                  max_asymmetry=max_asymmetry, provenance=provenance, **fields)
    problem.provenance["symmetrised"] = symmetrised(problem)
    return problem


def _read_local(fh, g, path, max_asymmetry, ignored) -> Problem:

    vectors = _vectors_without(g, ["V", "R"], ["s"], path,
                               "the extra constraints V, R (and s) of a local problem are not supported by rfverify",
                               "eliminate them (or remove V, R and s) before passing the problem",
                               mu_r_fix="lift the local rolling problem to /fclib_global_rolling (spacedim 5), "
                                        "or remove mu_r")
    q = read_vector(vectors, "q", path)
    mu = read_vector(vectors, "mu", path)
    _spacedim(g, path)
    W_meta = matrix_meta(g, "W", path)
    n = mu.size
    if W_meta["m"] != W_meta["n"]:
        raise InvalidProblemError("W", f"is declared {W_meta['m']}×{W_meta['n']} (W/m, W/n), must be "
                                       f"square (3n×3n = {FILE_SPACEDIM * n}×{FILE_SPACEDIM * n})",
                                  fix="W is the 3n×3n Delassus matrix: 3 rows and 3 columns per contact")
    if W_meta["m"] != FILE_SPACEDIM * n:
        hint = " (5 per contact: the rolling layout)" if W_meta["m"] == SPACEDIM * n else ""
        raise InvalidProblemError("W", f"is declared {W_meta['m']}×{W_meta['n']}, expected 3n×3n = "
                                       f"{FILE_SPACEDIM * n}×{FILE_SPACEDIM * n} from mu ({n} contacts){hint}",
                                  fix="W has 3 rows and 3 columns per contact (N, T1, T2)")
    _contact_vector_size("q", q.size, n, fix="q has 3 entries per contact (N, T1, T2)")
    if W_meta["m"] > LOCAL_DENSE_LIMIT:
        raise ProblemFileError(path, f"W is {W_meta['m']}×{W_meta['n']}: too large for the dense "
                                     f"lifting of a local problem (limit {LOCAL_DENSE_LIMIT} rows)",
                               location=W_meta["loc"], fix="export the problem in global form (M, H)")
    W, W_fmt = read_matrix(W_meta, path)
    title, description, math_info = read_info(g, path)
    check_finite("q", q)
    check_finite("mu", mu)
    return local_3d_problem(W, q, mu, W_fmt, provenance=provenance_3d(LOCAL, ignored), max_asymmetry=max_asymmetry,
                            solutions=lambda H: _read_solutions(fh, path, m=H.shape[0], n=n, local_H=H),
                            title=title, description=description, math_info=math_info, source=str(path))


def local_3d_problem(W, q, mu, W_fmt: str, *, provenance: dict, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY,
                     significant_digits: int | None = None, solutions=None, **fields) -> Problem:
    """The rolling-layout :class:`Problem` of a 3-D local Coulomb problem u = W r + q (W 3n × 3n,
    sparse or dense; q 3n): lifted (:func:`factor_delassus`: M = I, W = HᵀH, f = 0, w = q) with
    zero rolling columns, μr = 0, the raw W and q kept (``native``, to write them back) and the
    file's own W for the extended phase and the proof (``local``).  ``solutions(H)`` gives the
    file's (solution, guesses) for the lifted H; ``fields`` go to :meth:`Problem.from_arrays`."""
    n = np.asarray(mu).size
    H3, report = factor_delassus(sp.csc_matrix(W).toarray(), significant_digits=significant_digits,
                                 rank_tol=None, max_asymmetry=max_asymmetry)
    H = embed_columns(sp.csc_matrix(H3))
    m = H.shape[0]
    solution, guesses = (None, []) if solutions is None else solutions(H)
    provenance["lifted"] = {"method": LIFTING, "W_size": int(W.shape[0]), **dataclasses.asdict(report)}
    problem = Problem.from_arrays(
        sp.identity(m, format="csc"), H, np.zeros(m), embed(q, n), mu, np.zeros(n), solution=solution,
        guesses=guesses, storage={"W": W_fmt}, max_asymmetry=max_asymmetry, provenance=provenance, **fields)
    problem.provenance["symmetrised"] = symmetrised(problem)
    Wf = sp.csc_matrix(W, copy=True)
    for arr in (Wf.data, Wf.indices, Wf.indptr):
        arr.setflags(write=False)
    qf = np.array(q, dtype=np.float64)
    qf.setflags(write=False)
    return dataclasses.replace(problem, native=LocalData(W=Wf, q=qf, storage=W_fmt),
                               local=make_local_form(embed_square(W), embed(q, n), significant_digits))


def _read_solutions(fh, path, *, m: int, n: int, local_H):
    """``/solution`` and ``/guesses`` in the file's layout (3 per contact; local: u, r), checked
    for size and embedded in the rolling layout.  A local problem's v (not stored) is H r."""

    h5py = h5py_module()
    solution, guesses = None, ()
    if fh.get("solution", getlink=True) is not None:
        grp = member(fh, "solution", path, h5py.Group)
        solution = _embed_solution(read_solution(grp, path), grp.name, path, m, n, local_H)
    if fh.get("guesses", getlink=True) is not None:
        grp = member(fh, "guesses", path, h5py.Group)
        raw = read_guesses(grp, path)
        keys = sorted((k for k in grp.keys() if k.isdigit()), key=int)
        guesses = tuple(_embed_solution(s, f"{grp.name}/{k}", path, m, n, local_H)
                        for s, k in zip(raw, keys))
    return solution, guesses


def _embed_solution(s: StoredSolution, loc: str, path, m: int, n: int, local_H) -> StoredSolution:
    vals = {}
    for key in ("u", "r"):
        arr = getattr(s, key)
        if arr is None:
            continue
        if arr.size != FILE_SPACEDIM * n:
            raise ProblemFileError(path, f"has {arr.size} entries, expected 3n = {FILE_SPACEDIM * n} "
                                         f"(3 per contact for {n} contacts)", location=f"{loc}/{key}",
                                   fix="store u and r with 3 entries per contact (N, T1, T2)")
        vals[key] = embed(arr, n)
    if local_H is None:
        if s.v is not None and s.v.size != m:
            raise ProblemFileError(path, f"has {s.v.size} entries, expected m = {m} (one per dof of M)",
                                   location=f"{loc}/v", fix="store v with one entry per dof")
        vals["v"] = s.v
    elif "r" in vals:  # local: v of the lifted problem (M = I, f = 0) is H r; a stored v is ignored
        vals["v"] = local_H @ vals["r"]
    return StoredSolution(**vals)


def write_group(fh, problem: Problem, fmts: dict) -> None:
    """Write ``problem`` (read from a 3-D file) into the open h5py file ``fh`` as it was read:
    its group, ``/solution`` and ``/guesses`` 3 per contact."""

    layout = file_layout(problem)
    check_embedded(problem)
    g = fh.create_group(layout)
    vec = g.create_group("vectors")
    if layout == GLOBAL:
        write_matrix(g, "M", problem.M, fmts["M"])
        write_matrix(g, "H", extract_columns(problem.H), fmts["H"])
        vec.create_dataset("f", data=np.asarray(problem.f, dtype=np.float64))
        vec.create_dataset("w", data=extract(problem.w))
    else:
        write_matrix(g, "W", problem.native.W, fmts["W"])
        vec.create_dataset("q", data=np.asarray(problem.native.q, dtype=np.float64))
    vec.create_dataset("mu", data=np.asarray(problem.mu, dtype=np.float64))
    g.create_dataset("spacedim", data=np.array([FILE_SPACEDIM], dtype=np.int32))
    write_info_and_solutions(fh, g, problem, lambda grp, sol: write_solution_arrays(
        grp, solution_datasets(problem, sol)))


def detect_layout(fh) -> str:
    """The problem group a file's ``/solution`` belongs to, by the reader's preference order."""
    for root in (ROLLING, GLOBAL, LOCAL):
        if fh.get(root, getlink=True) is not None:
            return root
    return ROLLING


def convert_for_file(layout: str, solution: StoredSolution) -> dict:
    """A rolling-layout solution as the datasets ``{"v", "u", "r"}`` (array or None: absent) of
    a file of ``layout``: 5 per contact for rolling files, 3 per contact for 3-D ones, and no v
    for local ones."""
    if layout == ROLLING:
        return {k: getattr(solution, k) for k in ("v", "u", "r")}
    out = {k: None if getattr(solution, k) is None else extract(getattr(solution, k)) for k in ("u", "r")}
    out["v"] = None if layout == LOCAL else solution.v
    return out


__all__ = ["GLOBAL", "LOCAL", "ROLLING", "FILE_SPACEDIM", "LocalData", "embed", "extract",
           "embed_columns", "extract_columns", "file_layout", "solution_datasets", "convert_for_file",
           "detect_layout", "solution_attributes", "symmetrised", "describe_symmetrised", "read_group",
           "write_group", "global_3d_problem", "local_3d_problem", "provenance_3d"]


def write_info_and_solutions(fh, g, problem, write_solution) -> None:
    """g/info (title, description, math_info), /solution with its attributes, and /guesses;
    ``write_solution(group, solution)`` writes one solution's datasets."""
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
