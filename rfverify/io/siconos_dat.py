"""Siconos ``.dat`` text files of rolling-friction problems (DESIGN §7).

Two layouts, as written by Siconos' ``*_printInFile`` functions::

    local  (RFC3D):   d  nc  W  q  mu  mu_r                 W (5nc×5nc), q (5nc)
    global (GRFC3D):  d  nc  M  H  f  w  mu  mu_r           M (m×m), H (m×5nc)

Each matrix starts with three integer lines: storage type (0 dense, 2 sparse; 1 = sparse
block is not supported), number of rows, number of columns.  A dense matrix follows with a
line ``rows<TAB>cols`` and the entries in column-major order (``%32.24e``: full precision).
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


def _with_provenance(problem: Problem, provenance: dict, source: str) -> Problem:
    return dataclasses.replace(problem, provenance=provenance, source=source)


def parse_siconos_dat(path):
    """Parse a ``.dat`` file.  Returns ``(kind, data, significant_digits)`` with
    ``kind == "local"`` and ``data`` a :class:`LocalProblem`, or ``kind == "global"`` and
    ``data = (M, H, f, w, mu, mu_r, storage)``."""
    path = Path(path)
    read_head(path, "a Siconos .dat file")
    text = _decode(path, path.read_bytes())
    lines = _Lines(path, text)
    d = lines.integer("the dimension d")
    if d != SPACEDIM:
        raise ProblemFileError(path, f"dimension d = {d}: not a rolling-friction problem "
                                     f"(expected {SPACEDIM})", location="line 1",
                               fix="pass a rolling-friction problem (RFC3D/GRFC3D, d = 5)")
    nc = lines.integer("the number of contacts nc")
    if nc <= 0:
        raise ProblemFileError(path, f"number of contacts nc = {nc} must be positive",
                               location="line 2", fix=_FIX_FORMAT)
    lines.size(2, nc, "the number of contacts nc")
    A, A_fmt, A_digits = _read_matrix(lines, "first matrix")
    lineno, nxt = lines.peek()
    is_global = nxt is not None and _INT_RE.match(nxt) is not None
    digits = A_digits
    if is_global:
        M = A
        H, H_fmt, H_digits = _read_matrix(lines, "H")
        digits = _min_digits(A_digits, H_digits)
        m = M.shape[0]
        if H.shape != (m, SPACEDIM * nc):
            raise ProblemFileError(path, f"H is {H.shape[0]}×{H.shape[1]}, expected "
                                         f"{m}×{SPACEDIM * nc} (m × 5nc)", location="H header",
                                   fix="H has one row per dof of M and 5 columns per contact")
        tokens = _remaining_floats(lines)
        f, w, mu, mu_r = _split(path, tokens, [("f", m), ("w", SPACEDIM * nc), ("mu", nc), ("mu_r", nc)])
        return "global", (M, H, f, w, mu, mu_r, {"M": A_fmt, "H": H_fmt}), digits
    if A.shape != (SPACEDIM * nc, SPACEDIM * nc):
        raise ProblemFileError(path, f"W is {A.shape[0]}×{A.shape[1]}, expected "
                                     f"{SPACEDIM * nc}×{SPACEDIM * nc} (5nc × 5nc)", location="W header",
                               fix="W has 5 rows and 5 columns per contact")
    if A.shape[0] > LOCAL_DENSE_LIMIT:
        raise ProblemFileError(path, f"W is {A.shape[0]}×{A.shape[1]}: too large for the dense "
                                     f"lifting of a local problem (limit {LOCAL_DENSE_LIMIT} rows)",
                               location="W header", fix="export the problem in global form (M, H)")
    tokens = _remaining_floats(lines)
    q, mu, mu_r = _split(path, tokens, [("q", SPACEDIM * nc), ("mu", nc), ("mu_r", nc)])
    W = A.toarray()
    return "local", LocalProblem(W=W, q=q, mu=mu, mu_r=mu_r, significant_digits=digits), digits


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
        raise lines.error(lineno, f"{what} is stored as a Siconos sparse-block matrix (type 1), "
                                  "which rfverify does not read",
                          fix="re-export it dense (type 0) or sparse (type 2)")
    raise lines.error(lineno, f"unknown storage type {storage} for {what} (0 dense, 2 sparse)")


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
        raise ProblemFileError(path, f"{len(tokens) - pos} unexpected numbers after mu_r "
                                     f"({total} expected after the matrices)", location=f"line {ln}",
                               fix="remove the extra numbers, or correct nc (line 2)")
    return result
