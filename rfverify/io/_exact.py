"""Sparse matrices from (row, col, value) entries whose repeated positions are summed exactly.

FCLIB triplets (and compressed storage, and Siconos CSparse print-outs) may store one position
several times; the matrix holds the sum.  scipy sums such entries in floating point, in storage
order, so the matrix read could depend on the order of the terms (2^53, 1, −2^53, 1 gives 1,
not 2).  Here each group of repeated entries is summed **exactly**: the result is the float64
equal to the exact (rational) sum, and a group whose exact sum is not a float64 is refused
(the reader raises its own file error), never rounded.

Conventions:

* a position stored once is kept bit for bit (explicit zeros and −0.0 included);
* an exact zero sum is stored as an explicit zero, like scipy's ``sum_duplicates`` does:
  −0.0 when every term is −0.0 (IEEE addition), else +0.0;
* a group holding Inf or NaN is summed in float in storage order (the result is not finite,
  and the problem's validation refuses it with the position named);
* duplicates are found vectorised (one stable sort of the position keys); each group is first
  summed in storage order with the error of every addition computed exactly (TwoSum), and
  only the groups where some addition was inexact are summed as exact rationals (integers over
  a common power of two), then rounded once and compared with ``fractions.Fraction``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction

import numpy as np
import scipy.sparse as sp

FIX_INEXACT = ("store each (row, col) once with its intended float64 value (e.g. write the "
               "problem with rfverify.save), or repeated entries whose exact sum is a float64")

_VECTOR_TERMS = 64
"""Groups with more terms than this skip the vectorised TwoSum pass (one numpy pass per term
would be slow for a huge group) and are summed as exact rationals directly."""


def exact_csc(rows, cols, vals, shape, *, matrix: str,
              refuse: Callable[[int, str], Exception]) -> sp.csc_matrix:
    """The m×n CSC matrix with ``A[rows[k], cols[k]] += vals[k]`` summed exactly.

    Parameters
    ----------
    rows, cols : integer arrays, already checked to lie in ``0..m-1`` and ``0..n-1``.
    vals : float64 array of the same length.
    matrix : name used in the message (``"M"``, ``"H"``, ``"W"``).
    refuse : ``refuse(k, message)`` returns the exception to raise when a group's exact sum is
        not a float64; ``k`` is the storage index (in ``vals``) of the group's first term, so
        that the reader can say where it is (an HDF5 dataset, a line).  The message names the
        matrix, the (row, col) position, the number of terms and the nearest float64; the
        reader adds the file and the fix (:data:`FIX_INEXACT`).
    """
    m, n = shape
    rows = np.asarray(rows, dtype=np.int64)
    cols = np.asarray(cols, dtype=np.int64)
    vals = np.asarray(vals, dtype=np.float64)
    rows, cols, vals = _summed_unique(rows, cols, vals, m, matrix, refuse)
    # No position is repeated any more, so scipy only reorders the entries (bit for bit).
    return sp.csc_matrix((vals, (rows, cols)), shape=(m, n))


def _summed_unique(rows, cols, vals, m, matrix, refuse):
    nnz = vals.size
    if nnz < 2:
        return rows, cols, vals
    key = cols * np.int64(max(m, 1)) + rows  # < 2^62: m, n ≤ 2^31 − 1
    order = np.argsort(key, kind="stable")  # stable: each group keeps its storage order
    ks = key[order]
    first = np.empty(nnz, dtype=bool)
    first[0] = True
    np.not_equal(ks[1:], ks[:-1], out=first[1:])
    if first.all():
        return rows, cols, vals
    starts = np.flatnonzero(first)
    sizes = np.diff(np.append(starts, nnz))
    sv = vals[order]
    sums = sv[starts].copy()
    exact = np.ones(starts.size, dtype=bool)
    repeated = np.flatnonzero(sizes > 1)
    big = repeated[sizes[repeated] > _VECTOR_TERMS]
    exact[big] = False
    active = repeated[sizes[repeated] <= _VECTOR_TERMS]
    k = 1
    with np.errstate(over="ignore", invalid="ignore"):
        while active.size:
            a, b = sums[active], sv[starts[active] + k]
            t = a + b
            bb = t - a
            err = (a - (t - bb)) + (b - bb)  # TwoSum: a + b = t + err exactly, unless t overflows
            exact[active] &= err == 0  # NaN (overflow, Inf terms) compares unequal: summed below
            sums[active] = t
            k += 1
            active = active[sizes[active] > k]
    # Groups not summed exactly in storage order, in storage order of their first term, so the
    # position refused is the first one a reader of the file meets.
    redo = np.flatnonzero(~exact)
    redo = redo[np.argsort(order[starts[redo]], kind="stable")]
    for g in redo.tolist():
        terms = sv[starts[g]:starts[g] + sizes[g]]
        value = _exact_sum(terms)
        if value is None:
            at = int(order[starts[g]])
            raise refuse(at, _message(matrix, int(rows[at]), int(cols[at]), terms))
        sums[g] = value
    lead = order[starts]
    return rows[lead], cols[lead], sums


def _exact_sum(terms: np.ndarray) -> float | None:
    """The float64 equal to the exact sum of ``terms``; None when there is none.  Terms with
    Inf or NaN are summed in float in storage order (validation refuses the result)."""
    values = terms.tolist()
    if not all(math.isfinite(v) for v in values):
        total = values[0]
        for v in values[1:]:
            total += v
        return total
    exact = _rational_sum(values)
    if exact == 0:
        return -0.0 if all(math.copysign(1.0, v) < 0 for v in values) else 0.0
    try:
        value = float(exact)  # int / int: correctly rounded
    except OverflowError:
        return None
    if math.isinf(value) or Fraction(value) != exact:
        return None
    return value


def _rational_sum(values: list) -> Fraction:
    """The exact sum of finite floats: each is n / 2^k, so all are put over the largest 2^k and
    added as integers (one normalisation at the end, not one gcd per term as Fraction sums)."""
    ratios = [v.as_integer_ratio() for v in values]
    shift = max(d.bit_length() for _, d in ratios) - 1
    total = sum(n << (shift - d.bit_length() + 1) for n, d in ratios)
    return Fraction(total, 1 << shift)


def _message(matrix: str, row: int, col: int, terms: np.ndarray) -> str:
    try:
        nearest = f"the nearest float64 is {float(_rational_sum(terms.tolist()))!r}"
    except OverflowError:
        nearest = "it overflows float64"
    return (f"matrix {matrix}: entry ({row}, {col}) is stored as {terms.size} repeated terms whose "
            f"exact sum is not a float64 ({nearest}), so reading it would round the data")
