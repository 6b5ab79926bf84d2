"""The lifted problem and its vectors in ``bits``-bit gmpy2 ``mpfr`` arithmetic (numpy object
arrays), for the multiple-precision tail (:mod:`.wide`): conversions from double-double and
back to float64 expansions, norms, products, and the data of :class:`.data.ExtendedData` as
mpfr matrices.  The precision is the caller's gmpy2 context (:func:`context`)."""

from __future__ import annotations

import gmpy2
import numpy as np

from .data import DDMatrix, ExtendedData

_mpfr = np.frompyfunc(gmpy2.mpfr, 1, 1)
_float = np.frompyfunc(float, 1, 1)


def context(bits: int):
    """A gmpy2 context of ``bits`` bits (use ``with context(bits):``; nothing leaks)."""
    return gmpy2.context(gmpy2.get_context(), precision=int(bits))


def from_dd(h, l=None) -> np.ndarray:
    """The double-double numbers h + l as mpfr (exact when ``bits`` ≥ the span of h and l)."""
    x = _mpfr(np.asarray(h, dtype=np.float64))
    if l is not None:
        x = x + _mpfr(np.asarray(l, dtype=np.float64))
    return np.asarray(x, dtype=object)


def expansion(x: np.ndarray, terms: int) -> list:
    """``terms`` float64 arrays whose exact sum is x rounded to about 53·terms bits; the first
    is x rounded to nearest."""
    parts = []
    rest = np.asarray(x, dtype=object)
    for _ in range(terms):
        p = _float(rest).astype(np.float64) if rest.size else np.zeros(0)
        parts.append(p)
        rest = rest - p
    return parts


def zeros(n: int) -> np.ndarray:
    """n mpfr zeros."""
    out = np.empty(n, dtype=object)
    out[:] = gmpy2.mpfr(0)
    return out


def inf_norm(x: np.ndarray) -> float:
    """‖x‖∞ as a float."""
    return float(max((abs(t) for t in x), default=0.0))


def dot(x: np.ndarray, y: np.ndarray):
    """xᵀy in mpfr."""
    return np.sum(x * y) if x.size else gmpy2.mpfr(0)


def two_norm(x: np.ndarray) -> float:
    """‖x‖₂ as a float."""
    return float(gmpy2.sqrt(dot(x, x)))


class WideMatrix:
    """A :class:`DDMatrix` with mpfr entries (hi + lo, exact at ``bits`` ≥ 107)."""

    def __init__(self, A: DDMatrix):
        self.shape = A.shape
        self.indices = A.indices
        counts = np.diff(A.indptr)
        self.rows = np.flatnonzero(counts > 0)
        self.starts = A.indptr[:-1][self.rows]
        self.data = from_dd(A.hi, A.lo)

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        out = zeros(self.shape[0])
        if self.data.size:
            out[self.rows] = np.add.reduceat(self.data * x[self.indices], self.starts)
        return out


class WideData:
    """The lifted data of :class:`ExtendedData` as mpfr (built inside the precision context)."""

    def __init__(self, data: ExtendedData):
        self.data = data
        self.M, self.Ht, self.HtT = WideMatrix(data.M_eq), WideMatrix(data.Ht), WideMatrix(data.HtT)
        self.J, self.JT = WideMatrix(data.J), WideMatrix(data.JT)
        self.f = from_dd(*data.f)
        self.w_t = from_dd(*data.w_t)
