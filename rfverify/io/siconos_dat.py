"""Siconos ``.dat`` text files of friction problems (DESIGN §7).

Four layouts, as written by Siconos' ``*_printInFile`` functions::

    local  (RFC3D, d = 5):   d  nc  W  q  mu  mu_r          W (5nc×5nc), q (5nc)
    global (GRFC3D, d = 5):  d  nc  M  H  f  w  mu  mu_r    M (m×m), H (m×5nc)
    local  (FC3D, d = 3):    d  nc  W  q  mu                W (3nc×3nc), q (3nc)
    global (GFC3D, d = 3):   d  nc  M  H  f  w  mu          M (m×m), H (m×3nc)

A 3-D Coulomb file (d = 3) is read as the FCLIB 3-D readers read the same problem
(:mod:`.fclib3d`: its convex relaxation in the rolling layout, μr = 0, a local W lifted).
Each matrix starts with three integer lines: storage type (0 dense, 1 Siconos sparse block,
2 sparse), number of rows, number of columns.  A dense matrix follows with a
line ``rows<TAB>cols`` and the entries in column-major order (``%32.24e``: full precision).
A sparse-block matrix follows as ``SBM_write_in_file`` prints it: its block structure, then
each block's entries column-major (``%32.24e`` in current Siconos, ``%e``'s 7 digits in older
files: the precision printed is recorded).
A sparse matrix follows with an integer line (the Siconos sparse origin) and a CSparse
``cs_print`` listing, either a triplet (``triplet: m-by-n, nzmax: .. nnz: ..`` then
``row col : value``) or compressed columns (``m-by-n, nzmax: .. nnz: .., 1-norm: ..`` then
``col j : locations a to b`` and ``row : value``).  CSparse prints values with ``%g``: **six
significant digits**, so such a problem is only known to about 5e-6 relative per entry;
the reader records this in ``problem.provenance["significant_digits"]``.  A (row, col) printed
more than once is summed exactly (:mod:`rfverify.io._exact`; refused, naming its line, when the
exact sum of the printed values is not a float64).

The file kind is recognised from the content: after the first matrix, a global file has a
second matrix header (a line holding one integer); a local file has the vector q (floats).
A local problem is lifted to global form by :mod:`.local_lift` (shared with ``/fclib_local``).
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidProblemError, ProblemFileError
from ..model.problem import DEFAULT_MAX_ASYMMETRY, SPACEDIM, Problem, make_local_form
from .fclib3d import FILE_SPACEDIM, GLOBAL, LOCAL, global_3d_problem, local_3d_problem, provenance_3d
from ._exact import FIX_INEXACT, exact_csc
from ._paths import read_head
from .local_lift import LOCAL_DENSE_LIMIT, LocalProblem, lift_local

STORAGE_DENSE = 0
STORAGE_SPARSE_BLOCK = 1
STORAGE_SPARSE = 2

CSPARSE_DIGITS = 6
"""Significant digits kept by CSparse's ``%g`` print-out."""

# Integers have at most 18 digits (they fit int64): a longer one is no plausible size or index.
_INT_RE = re.compile(r"^[+-]?\d{1,18}$")
_TRIPLET_HDR = re.compile(r"triplet:\s*(\d{1,18})-by-(\d{1,18}),\s*nzmax:\s*(\d{1,18})\s+nnz:\s*(\d{1,18})")
_CSC_HDR = re.compile(r"^(\d{1,18})-by-(\d{1,18}),\s*nzmax:\s*(\d{1,18})\s+nnz:\s*(\d{1,18})")
_TRIPLET_ENTRY = re.compile(r"^(\d{1,18})\s+(\d{1,18})\s*:\s*(\S+)$")
_CSC_COL = re.compile(r"^col\s+(\d{1,18})\s*:\s*locations\s+(\d{1,18})\s+to\s+(-?\d{1,18})$")
_CSC_ENTRY = re.compile(r"^(\d{1,18})\s*:\s*(\S+)$")

_FIX_FORMAT = ("correct the file there (layout of Siconos' *_printInFile: DESIGN §7), or "
               "re-export the problem")


class _Lines:
    """Non-empty, stripped lines with their 1-based line numbers, consumed in order."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.chars = len(text)
        self.items = [(k + 1, s.strip()) for k, s in enumerate(text.splitlines()) if s.strip()]
        self.pos = 0

    def peek(self):
        return self.items[self.pos] if self.pos < len(self.items) else (None, None)

    def next(self, what: str):
        if self.pos >= len(self.items):
            raise ProblemFileError(self.path, f"file ends early: expected {what}",
                                   location=f"line {self.items[-1][0] + 1 if self.items else 1}",
                                   fix="the file is truncated: re-export or re-download it")
        item = self.items[self.pos]
        self.pos += 1
        return item

    def error(self, lineno, msg, fix=_FIX_FORMAT):
        return ProblemFileError(self.path, msg, location=f"line {lineno}", fix=fix)

    def size(self, lineno, value: int, what: str) -> int:
        """A declared size, refused when the file is too short to hold that many entries
        (every dimension of a valid file is the length of a printed vector)."""
        if value > self.chars:
            raise self.error(lineno, f"{what} = {value} is more than the file ({self.chars} "
                                     "characters) can hold")
        return value

    def integer(self, what: str) -> int:
        lineno, s = self.next(what)
        if not _INT_RE.match(s):
            raise self.error(lineno, f"expected {what} (an integer), found {s[:40]!r}")
        return int(s)


def read_siconos_dat(path, *, max_asymmetry: float = DEFAULT_MAX_ASYMMETRY,
                     rank_tol: float | None = None) -> Problem:
    """Read a Siconos rolling-friction ``.dat`` file as a global :class:`Problem`.

    A local file is lifted to global form with :func:`lift_local` (M = I, H from W = HᵀH,
    f = 0, w = q); ``problem.provenance`` records the kind, the print precision and the
    lifting report.
    """
    kind, data, digits = parse_siconos_dat(path)
    if kind.endswith("-3d"):
        return _read_3d(path, kind, data, digits, max_asymmetry)
    provenance = {"format": "siconos-dat", "kind": kind, "significant_digits": digits}
    try:
        if kind == "local":
            lifted, report = lift_local(data, rank_tol=rank_tol, max_asymmetry=max_asymmetry)
            provenance["lift"] = report.__dict__
            lifted = dataclasses.replace(lifted, local=make_local_form(data.W, data.q, digits))
            return _with_provenance(lifted, provenance, str(path))
        M, H, f, w, mu, mu_r, storage = data
        problem = Problem.from_arrays(M, H, f, w, mu, mu_r, storage=storage,
                                      max_asymmetry=max_asymmetry, source=str(path),
                                      title=Path(path).stem,
                                      description="read from a Siconos global rolling .dat file")
    except InvalidProblemError as exc:
        raise exc.with_path(path) from None
    return _with_provenance(problem, provenance, str(path))


def _read_3d(path, kind: str, data, digits, max_asymmetry) -> Problem:
    """A 3-D Coulomb ``.dat`` file (FC3D local, GFC3D global) read as the FCLIB 3-D readers read
    the same problem (:mod:`.fclib3d`: the convex relaxation in the rolling layout, μr = 0, a local
    W lifted), so that it is solved, proven, written back 3 per contact and named alike; the
    provenance adds the file it came from."""
    fields = {"title": Path(path).stem, "source": str(path), "max_asymmetry": max_asymmetry}
    try:
        if kind == "global-3d":
            M, H, f, w, mu, storage, notes = data
            prov = {**provenance_3d(GLOBAL, []), "read_from": "Siconos GFC3D", "significant_digits": digits,
                    "ignored": notes}
            return global_3d_problem(M, H, f, w, mu, provenance=prov, storage=storage,
                                     description="read from a Siconos global 3-D (GFC3D) .dat file", **fields)
        W, q, mu, W_fmt, notes = data
        prov = {**provenance_3d(LOCAL, []), "read_from": "Siconos FC3D", "significant_digits": digits,
                "ignored": notes}
        return local_3d_problem(W, q, mu, W_fmt, provenance=prov, significant_digits=digits,
                                description="read from a Siconos local 3-D (FC3D) .dat file", **fields)
    except InvalidProblemError as exc:
        raise exc.with_path(path) from None


def _with_provenance(problem: Problem, provenance: dict, source: str) -> Problem:
    return dataclasses.replace(problem, provenance=provenance, source=source)


def parse_siconos_dat(path):
    """Parse a ``.dat`` file.  Returns ``(kind, data, significant_digits)``: ``kind == "local"``
    and ``data`` a :class:`LocalProblem`, or ``kind == "global"`` and
    ``data = (M, H, f, w, mu, mu_r, storage)`` for a rolling file (d = 5); for a 3-D Coulomb file
    (d = 3: Siconos's FC3D and GFC3D, no μr) ``kind`` is ``"local-3d"`` with
    ``data = (W, q, mu, storage, notes)`` or ``"global-3d"`` with
    ``data = (M, H, f, w, mu, storage, notes)``, 3 entries per contact (``notes``: what was
    ignored, see :func:`_trailing_flag`)."""
    path = Path(path)
    read_head(path, "a Siconos .dat file")
    text = _decode(path, path.read_bytes())
    lines = _Lines(path, text)
    d = lines.integer("the dimension d")
    if d not in (FILE_SPACEDIM, SPACEDIM):
        raise ProblemFileError(path, f"dimension d = {d}: neither a rolling-friction problem (d = {SPACEDIM}) "
                                     f"nor a 3-D Coulomb friction problem (d = {FILE_SPACEDIM})",
                               location="line 1",
                               fix="pass a 3-D problem: rolling (RFC3D/GRFC3D, d = 5) or Coulomb (FC3D/GFC3D, d = 3)")
    nc = lines.integer("the number of contacts nc")
    if nc <= 0:
        raise ProblemFileError(path, f"number of contacts nc = {nc} must be positive",
                               location="line 2", fix=_FIX_FORMAT)
    lines.size(2, nc, "the number of contacts nc")
    A, A_fmt, A_digits = _read_matrix(lines, "first matrix")
    lineno, nxt = lines.peek()
    is_global = nxt is not None and _INT_RE.match(nxt) is not None
    digits = A_digits
    vectors = [("mu", nc)] + ([("mu_r", nc)] if d == SPACEDIM else [])
    per = "5 (N, T1, T2, R1, R2)" if d == SPACEDIM else "3 (N, T1, T2)"
    if is_global:
        M = A
        H, H_fmt, H_digits = _read_matrix(lines, "H")
        digits = _min_digits(A_digits, H_digits)
        m = M.shape[0]
        if H.shape != (m, d * nc):
            raise ProblemFileError(path, f"H is {H.shape[0]}×{H.shape[1]}, expected "
                                         f"{m}×{d * nc} (m × {d}nc)", location="H header",
                                   fix=f"H has one row per dof of M and {per} columns per contact")
        tokens = _remaining_floats(lines)
        spec = [("f", m), ("w", d * nc)] + vectors
        notes = _trailing_flag(lines, tokens, spec) if d == FILE_SPACEDIM else []
        f, w, mu, *mu_r = _split(path, tokens, spec)
        storage = {"M": A_fmt, "H": H_fmt}
        if d == FILE_SPACEDIM:
            return "global-3d", (M, H, f, w, mu, storage, notes), digits
        return "global", (M, H, f, w, mu, mu_r[0], storage), digits
    if A.shape != (d * nc, d * nc):
        raise ProblemFileError(path, f"W is {A.shape[0]}×{A.shape[1]}, expected "
                                     f"{d * nc}×{d * nc} ({d}nc × {d}nc)", location="W header",
                               fix=f"W has {per} rows and columns per contact")
    if A.shape[0] > LOCAL_DENSE_LIMIT:
        raise ProblemFileError(path, f"W is {A.shape[0]}×{A.shape[1]}: too large for the dense "
                                     f"lifting of a local problem (limit {LOCAL_DENSE_LIMIT} rows)",
                               location="W header", fix="export the problem in global form (M, H)")
    tokens = _remaining_floats(lines)
    spec = [("q", d * nc)] + vectors
    notes = _trailing_flag(lines, tokens, spec) if d == FILE_SPACEDIM else []
    q, mu, *mu_r = _split(path, tokens, spec)
    if d == FILE_SPACEDIM:
        return "local-3d", (A, q, mu, A_fmt, notes), digits
    W = A.toarray()
    return "local", LocalProblem(W=W, q=q, mu=mu, mu_r=mu_r[0], significant_digits=digits), digits


def _decode(path: Path, data: bytes) -> str:
    """The file's text; a .dat problem is ASCII, so anything else is named precisely."""
    if b"\x00" in data:
        raise ProblemFileError(path, "is not a text file (binary content: it contains NUL bytes)",
                               fix="pass a Siconos .dat text file (or an FCLIB .hdf5 file)")
    try:
        return data.decode("ascii")
    except UnicodeDecodeError as exc:
        bad_at = exc.start
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise ProblemFileError(path, f"is not a text file (binary content: byte {bad_at} is "
                                     f"0x{data[bad_at]:02x}, not ASCII or UTF-8)",
                               fix="pass a Siconos .dat text file (or an FCLIB .hdf5 file)") from None
    line = data[:bad_at].count(b"\n") + 1
    char = text[bad_at]  # everything before it is ASCII: one byte per character
    raise ProblemFileError(path, f"is UTF-8 text with a non-ASCII character {char!r}; a Siconos "
                                 ".dat file holds only ASCII numbers and headers",
                           location=f"line {line}",
                           fix="remove the non-ASCII characters (e.g. typographic minus signs)")


def _min_digits(a, b):
    vals = [x for x in (a, b) if x is not None]
    return min(vals) if vals else None


def _read_matrix(lines: _Lines, what: str):
    lineno, _ = lines.peek()
    storage = lines.integer(f"the storage type of {what}")
    rows = lines.integer(f"the number of rows of {what}")
    cols = lines.integer(f"the number of columns of {what}")
    if rows < 0 or cols < 0:
        raise lines.error(lineno, f"{what} has negative size {rows}×{cols}")
    lines.size(lineno, rows, f"the number of rows of {what}")
    lines.size(lineno, cols, f"the number of columns of {what}")
    if storage == STORAGE_DENSE:
        lines.size(lineno, rows * cols, f"the number of dense entries of {what}")
        ln, s = lines.next(f"the dense header of {what}")
        if [t for t in s.split()] != [str(rows), str(cols)]:
            raise lines.error(ln, f"dense header of {what} is {s!r}, expected '{rows} {cols}'")
        vals = []
        while len(vals) < rows * cols:
            ln, s = lines.next(f"{rows * cols} entries of {what}")
            vals.extend(_floats(lines, ln, s))
        if len(vals) != rows * cols:
            raise lines.error(ln, f"{what} has {len(vals)} dense entries, expected {rows * cols}")
        dense = np.array(vals, dtype=np.float64).reshape((rows, cols), order="F")
        return sp.csc_matrix(dense), "dense", None
    if storage == STORAGE_SPARSE:
        lines.integer(f"the sparse origin of {what}")
        ln, s = lines.next(f"the CSparse banner of {what}")
        if not s.startswith("CSparse"):
            raise lines.error(ln, f"expected a CSparse print-out of {what}, found {s[:40]!r}")
        ln, hdr = lines.next(f"the CSparse header of {what}")
        if (mt := _TRIPLET_HDR.match(hdr)):
            return _read_cs_triplet(lines, ln, mt, rows, cols, what), "triplet", CSPARSE_DIGITS
        if (mc := _CSC_HDR.match(hdr)):
            return _read_cs_csc(lines, ln, mc, rows, cols, what), "csc", CSPARSE_DIGITS
        raise lines.error(ln, f"unrecognised CSparse header for {what}: {hdr[:60]!r}")
    if storage == STORAGE_SPARSE_BLOCK:
        return (*_read_sparse_block(lines, lineno, rows, cols, what),)
    raise lines.error(lineno, f"unknown storage type {storage} for {what} (0 dense, 1 sparse block, 2 sparse)")


def _int_line(lines: _Lines, count: int, what: str) -> np.ndarray:
    """One line of ``count`` integers (Siconos prints them tab-separated)."""
    ln, s = lines.next(what)
    toks = s.split()
    if len(toks) != count or not all(_INT_RE.match(t) for t in toks):
        raise lines.error(ln, f"expected {what}: {count} integer(s) on one line, found {s[:60]!r}")
    return np.array([int(t) for t in toks], dtype=np.int64)


def _read_sparse_block(lines: _Lines, lineno: int, rows: int, cols: int, what: str):
    """A Siconos sparse-block matrix (``SBM_write_in_file``): the number of blocks; the numbers
    of block rows and columns; their cumulative sizes; ``filled1`` and ``filled2``; the block-row
    pointers (``index1_data``) and block columns (``index2_data``); then each block, by block row,
    as its number and its entries column-major (``%32.24e``: full precision)."""
    nb = lines.size(lineno, lines.integer(f"the number of blocks of {what}"), f"the number of blocks of {what}")
    if nb == 0:
        return sp.csc_matrix((rows, cols)), "sparse-block", None
    bn0 = lines.size(lineno, lines.integer(f"the number of block rows of {what}"), f"block rows of {what}")
    bn1 = lines.size(lineno, lines.integer(f"the number of block columns of {what}"), f"block columns of {what}")
    ends0 = _int_line(lines, bn0, f"the cumulative block-row sizes of {what}")
    ends1 = _int_line(lines, bn1, f"the cumulative block-column sizes of {what}")
    for ends, total, name in ((ends0, rows, "row"), (ends1, cols, "column")):
        if np.any(np.diff(np.r_[0, ends]) <= 0) or ends[-1] != total:
            raise lines.error(lineno, f"{what}: the cumulative block-{name} sizes {ends.tolist()[:8]} are not "
                                      f"increasing to {total}")
    filled1 = lines.integer(f"filled1 of {what}")
    filled2 = lines.integer(f"filled2 of {what}")
    if filled1 != bn0 + 1 or filled2 != nb:
        raise lines.error(lineno, f"{what}: filled1 = {filled1}, filled2 = {filled2}; expected {bn0 + 1} "
                                  f"(block rows + 1) and {nb} (blocks)")
    index1 = _int_line(lines, filled1, f"the block-row pointers of {what}")
    index2 = _int_line(lines, filled2, f"the block columns of {what}")
    if index1[0] != 0 or index1[-1] != nb or np.any(np.diff(index1) < 0) or np.any((index2 < 0) | (index2 >= bn1)):
        raise lines.error(lineno, f"{what}: inconsistent block pointers {index1.tolist()[:8]} or block columns")
    starts0, starts1 = np.r_[0, ends0[:-1]], np.r_[0, ends1[:-1]]
    r_all, c_all, x_all, printed = [], [], [], 0
    for i in range(bn0):
        for k in range(index1[i], index1[i + 1]):
            ln, s = lines.next(f"block {k} of {what}")
            if s != str(k):
                raise lines.error(ln, f"expected the number of block {k} of {what}, found {s[:40]!r}")
            j = index2[k]
            nr, nc_ = ends0[i] - starts0[i], ends1[j] - starts1[j]
            vals = []
            while len(vals) < nr * nc_:
                ln, s = lines.next(f"the {nr}×{nc_} entries of block {k} of {what}")
                vals.extend(_floats(lines, ln, s))
                printed = max(printed, _mantissa_digits(s))
            if len(vals) != nr * nc_:
                raise lines.error(ln, f"block {k} of {what} has {len(vals)} entries, expected {nr * nc_}")
            jj, ii = np.divmod(np.arange(nr * nc_), nr)  # column-major
            r_all.append(starts0[i] + ii)
            c_all.append(starts1[j] + jj)
            x_all.append(np.array(vals, dtype=np.float64))
    r, c, x = np.concatenate(r_all), np.concatenate(c_all), np.concatenate(x_all)
    if np.unique(r * cols + c).size != r.size:  # two blocks at one (block row, block column)
        raise lines.error(lineno, f"{what}: two blocks overlap")
    keep = x != 0.0
    digits = printed if 0 < printed < 17 else None  # 17 significant digits: every float64 exactly
    return sp.csc_matrix((x[keep], (r[keep], c[keep])), shape=(rows, cols)), "sparse-block", digits


def _mantissa_digits(text: str) -> int:
    """The most significant digits printed in any number of ``text`` (Siconos versions print
    sparse-block entries with ``%32.24e`` or with ``%e``'s 6 digits): the data's precision."""
    most = 0
    for tok in text.split():
        mant = tok.lower().lstrip("+-").split("e")[0].replace(".", "").lstrip("0")
        most = max(most, len(mant))
    return most


def _read_cs_triplet(lines, hdr_line, match, rows, cols, what):
    m, n, _nzmax, nnz = (int(g) for g in match.groups())
    if (m, n) != (rows, cols):
        raise lines.error(hdr_line, f"{what}: CSparse says {m}-by-{n}, header said {rows}×{cols}")
    lines.size(hdr_line, nnz, f"nnz of {what}")
    r = np.empty(nnz, dtype=np.int64)
    c = np.empty(nnz, dtype=np.int64)
    x = np.empty(nnz)
    at = np.empty(nnz, dtype=np.int64)  # line of each entry, to name a refused repeated entry
    for k in range(nnz):
        ln, s = lines.next(f"entry {k + 1} of {nnz} of {what}")
        me = _TRIPLET_ENTRY.match(s)
        if not me:
            raise lines.error(ln, f"expected 'row col : value' for {what}, found {s[:40]!r}")
        row, col = int(me.group(1)), int(me.group(2))
        if row >= m or col >= n:
            raise lines.error(ln, f"entry ({row}, {col}) outside {m}×{n} in {what}")
        r[k], c[k], at[k] = row, col, ln
        x[k] = _float(lines, ln, me.group(3))
    return _exact_matrix(lines, r, c, x, at, (m, n), what)


def _read_cs_csc(lines, hdr_line, match, rows, cols, what):
    m, n, _nzmax, nnz = (int(g) for g in match.groups())
    if (m, n) != (rows, cols):
        raise lines.error(hdr_line, f"{what}: CSparse says {m}-by-{n}, header said {rows}×{cols}")
    indptr = np.zeros(n + 1, dtype=np.int64)  # n was bounded by the file's size
    idx, vals, at = [], [], []
    for j in range(n):
        ln, s = lines.next(f"column {j} of {what}")
        mc = _CSC_COL.match(s)
        if not mc or int(mc.group(1)) != j:
            raise lines.error(ln, f"expected 'col {j} : locations a to b' in {what}, found {s[:40]!r}")
        a, b = int(mc.group(2)), int(mc.group(3))
        if a != len(idx) or b < a - 1:
            raise lines.error(ln, f"column {j} of {what} has inconsistent locations {a} to {b}")
        for _ in range(b - a + 1):
            ln, s = lines.next(f"an entry of column {j} of {what}")
            me = _CSC_ENTRY.match(s)
            if not me:
                raise lines.error(ln, f"expected 'row : value' in {what}, found {s[:40]!r}")
            row = int(me.group(1))
            if row >= m:
                raise lines.error(ln, f"row {row} outside 0..{m - 1} in {what}")
            idx.append(row)
            vals.append(_float(lines, ln, me.group(2)))
            at.append(ln)
        indptr[j + 1] = len(idx)
    if len(idx) != nnz:
        raise lines.error(hdr_line, f"{what} lists {len(idx)} entries, header says nnz = {nnz}")
    col_of = np.repeat(np.arange(n, dtype=np.int64), np.diff(indptr))
    return _exact_matrix(lines, np.array(idx, dtype=np.int64), col_of,
                         np.array(vals, dtype=np.float64), at, (m, n), what)


def _exact_matrix(lines, rows, cols, vals, at, shape, what):
    """The CSC matrix of the entries, a repeated (row, col) summed exactly (refused, naming the
    line of its first term, when the exact sum is not a float64)."""
    def refuse(k, msg):
        return lines.error(at[k], msg, fix=FIX_INEXACT)

    name = "M (W of a local file)" if what == "first matrix" else what
    return exact_csc(rows, cols, vals, shape, matrix=name, refuse=refuse)


def _float(lines, ln, s):
    try:
        return float(s)
    except ValueError:
        raise lines.error(ln, f"{s[:40]!r} is not a number") from None


def _floats(lines, ln, s):
    return [_float(lines, ln, t) for t in s.split()]


def _remaining_floats(lines: _Lines):
    out = []
    while lines.peek()[0] is not None:
        ln, s = lines.next("vector data")
        out.extend((ln, v) for v in _floats(lines, ln, s))
    return out


def _trailing_flag(lines: _Lines, tokens: list, spec) -> list:
    """Siconos's FC3D/GFC3D files of its own test data end with one more line holding a lone
    integer after μ (``GFC3D_TwoRods1.dat``: ``1``); Siconos's reader stops after μ and never
    reads it.  Such a line is dropped from ``tokens`` and named in the returned notes; anything
    else extra is left for :func:`_split` to refuse."""
    total = sum(size for _, size in spec)
    if len(tokens) != total + 1 or not lines.items:
        return []
    ln, text = lines.items[-1]
    if tokens[-1][0] != ln or not _INT_RE.match(text):
        return []
    tokens.pop()
    return [f"line {ln}: a lone integer ({text}) after mu, which Siconos's reader does not read, was ignored"]


def _split(path, tokens, spec):
    """Cut the trailing float tokens into the named vectors, checking the counts."""
    total = sum(size for _, size in spec)
    pos = 0
    result = []
    for name, size in spec:
        if pos + size > len(tokens):
            raise ProblemFileError(path, f"vector {name} is short: the file has {len(tokens)} numbers "
                                         f"after the matrices, {total} expected "
                                         f"({', '.join(f'{n}:{s}' for n, s in spec)})",
                                   location="end of file",
                                   fix="the file is truncated or nc is wrong: re-export it")
        result.append(np.array([v for _, v in tokens[pos:pos + size]], dtype=np.float64))
        pos += size
    if pos != len(tokens):
        ln = tokens[pos][0]
        raise ProblemFileError(path, f"{len(tokens) - pos} unexpected numbers after {spec[-1][0]} "
                                     f"({total} expected after the matrices)", location=f"line {ln}",
                               fix="remove the extra numbers, or correct nc (line 2)")
    return result
