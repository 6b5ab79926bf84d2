"""Exact arithmetic on vectors of dyadic rationals (numbers n·2^e with integer n, e).

Every float64, longdouble and double-double number is dyadic, and sums and products of
dyadic numbers are dyadic, so the residuals of a candidate point can be computed *exactly*:
no rounding, no error analysis.  A :class:`Dyadic` vector stores Python integers (numpy
object arrays, so the arithmetic is vectorised over entries) with one common binary exponent;
numpy ufuncs on object arrays call Python's exact integer operations.  Integers grow to a few
hundred bits for double-double points and float64 data, which Python multiplies in about
0.1 µs.

Conversion back to float64 is the only rounding, and it is directed: :meth:`Dyadic.upper`
and :meth:`Dyadic.lower` return float64 bounds that are guaranteed to enclose the exact value
(used to report proven bounds, never to continue exact computations).
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass
from fractions import Fraction

import numpy as np
import scipy.sparse as sp

_BIT_LENGTH = np.frompyfunc(int.bit_length, 1, 1)
_RSHIFT = np.frompyfunc(operator.rshift, 2, 1)
_LSHIFT = np.frompyfunc(operator.lshift, 2, 1)
_TINY_NORMAL = np.finfo(np.float64).tiny


def _float_parts(a: np.ndarray, mant_bits: int):
    """Integer mantissas and exponents with a = mant·2^exp exactly (a finite)."""
    a = np.asarray(a)
    if not np.all(np.isfinite(a)):
        raise ValueError("exact arithmetic needs finite numbers (found NaN or Inf)")
    m, e = np.frexp(a)
    mant = (m * a.dtype.type(2) ** mant_bits)  # exact: |m| < 1 has at most mant_bits bits
    return mant, e.astype(np.int64) - mant_bits


@dataclass(frozen=True)
class Dyadic:
    """A vector of exact dyadic rationals ``ints[i] · 2**exp`` (``ints`` an object array of
    Python ints, one common exponent).  Immutable by convention."""

    ints: np.ndarray
    exp: int

    # ------------------------------------------------------------------ construction
    @staticmethod
    def zeros(n: int) -> "Dyadic":
        out = np.empty(n, dtype=object)
        out[:] = 0
        return Dyadic(out, 0)

    @staticmethod
    def from_float(a) -> "Dyadic":
        """Exact image of a float64 (or float32/int) array."""
        a = np.asarray(a, dtype=np.float64).ravel()
        if a.size == 0:
            return Dyadic.zeros(0)
        mant, e = _float_parts(a, 53)
        return _from_parts(mant.astype(np.int64), e)

    @staticmethod
    def from_longdouble(a) -> "Dyadic":
        """Exact image of a numpy.longdouble array (any mantissa width up to 113 bits)."""
        a = np.asarray(a, dtype=np.longdouble).ravel()
        if a.size == 0:
            return Dyadic.zeros(0)
        bits = np.finfo(np.longdouble).nmant + 1
        mant, e = _float_parts(a, bits)
        # Split the (exact, integral) longdouble mantissa into two exact float64 halves.
        hi = np.floor(mant / np.longdouble(2) ** 32)
        lo = mant - hi * np.longdouble(2) ** 32
        ints = np.array([int(h) * (1 << 32) + int(l) for h, l in zip(hi.astype(object), lo.astype(object))],
                        dtype=object)
        return _from_parts(ints, e)

    @staticmethod
    def from_dd(hi, lo) -> "Dyadic":
        """Exact image of the double-double numbers hi + lo."""
        return Dyadic.from_float(hi) + Dyadic.from_float(lo)

    @staticmethod
    def from_mpf(values) -> "Dyadic":
        """Exact image of a sequence of mpmath mpf numbers (binary floating point)."""
        mans, exps = [], []
        for x in values:
            sign, man, exp, _ = x._mpf_  # x = (−1)^sign · man · 2^exp exactly
            man = int(man)
            if man == 0 and exp != 0:
                raise ValueError("exact arithmetic needs finite numbers (found an mpf NaN or Inf)")
            mans.append(-man if sign else man)
            exps.append(int(exp))
        if not mans:
            return Dyadic.zeros(0)
        return _from_parts(np.array(mans, dtype=object), np.array(exps, dtype=np.int64))

    @staticmethod
    def from_fractions_exact(values) -> "Dyadic":
        """Exact image of Fractions whose denominators are powers of two."""
        mans, exps = [], []
        for q in values:
            q = Fraction(q)
            d = q.denominator
            if d & (d - 1):
                raise ValueError(f"{q} is not dyadic")
            mans.append(q.numerator)
            exps.append(-(d.bit_length() - 1))
        return _from_parts(np.array(mans, dtype=object), np.array(exps, dtype=np.int64))

    # ------------------------------------------------------------------ arithmetic
    def __len__(self) -> int:
        return int(self.ints.size)

    def _shifted(self, exp: int) -> np.ndarray:
        """ints rescaled to the (smaller or equal) exponent ``exp``."""
        if exp == self.exp:
            return self.ints
        return self.ints * (1 << (self.exp - exp))

    def __add__(self, other: "Dyadic") -> "Dyadic":
        e = min(self.exp, other.exp)
        return Dyadic(self._shifted(e) + other._shifted(e), e)

    def __sub__(self, other: "Dyadic") -> "Dyadic":
        e = min(self.exp, other.exp)
        return Dyadic(self._shifted(e) - other._shifted(e), e)

    def __neg__(self) -> "Dyadic":
        return Dyadic(-self.ints, self.exp)

    def __mul__(self, other: "Dyadic") -> "Dyadic":
        """Elementwise product."""
        return Dyadic(self.ints * other.ints, self.exp + other.exp)

    def __getitem__(self, idx) -> "Dyadic":
        return Dyadic(np.asarray(self.ints[idx], dtype=object).ravel(), self.exp)

    def scale2(self, k: int) -> "Dyadic":
        """Multiply by 2**k (exact)."""
        return Dyadic(self.ints, self.exp + k)

    def times_int(self, k: int) -> "Dyadic":
        """Multiply by the integer ``k`` (exact)."""
        return self if k == 1 else Dyadic(self.ints * k, self.exp)

    def square(self) -> "Dyadic":
        return Dyadic(self.ints * self.ints, 2 * self.exp)

    def total(self) -> Fraction:
        """Exact sum of the entries as a Fraction."""
        return _frac(int(np.sum(self.ints)) if self.ints.size else 0, self.exp)

    def dot(self, other: "Dyadic") -> Fraction:
        return (self * other).total()

    def segment_sums(self, starts: np.ndarray, stops: np.ndarray) -> "Dyadic":
        """Exact sums over the index ranges [starts[i], stops[i]) (empty ranges give 0)."""
        return Dyadic(_segment_sums(self.ints, starts, stops), self.exp)

    def sign(self) -> np.ndarray:
        """-1, 0 or 1 per entry (exact)."""
        return (self.ints > 0).astype(np.int64) - (self.ints < 0).astype(np.int64)

    def fraction(self, i: int) -> Fraction:
        return _frac(int(self.ints[i]), self.exp)

    def fractions(self) -> list:
        return [_frac(int(n), self.exp) for n in self.ints]

    def abs(self) -> "Dyadic":
        return Dyadic(np.abs(self.ints), self.exp)

    # ------------------------------------------------------------------ directed rounding
    def upper(self) -> np.ndarray:
        """float64 numbers ≥ the exact values (+inf where they overflow)."""
        return _directed(self.ints, self.exp, up=True)

    def lower(self) -> np.ndarray:
        """float64 numbers ≤ the exact values (−inf where they overflow)."""
        return -_directed(-self.ints, self.exp, up=True)

    def abs_upper(self) -> np.ndarray:
        """float64 upper bounds of |x_i|."""
        return _directed(np.abs(self.ints), self.exp, up=True)

    def nearest(self) -> np.ndarray:
        """float64 roundings (not directed; for display and starting guesses only)."""
        up, lo = self.upper(), self.lower()
        return np.where(up == lo, up, lo + (up - lo) / 2)

    def max_abs_upper(self) -> float:
        return float(np.max(self.abs_upper(), initial=0.0))


def _frac(n: int, e: int) -> Fraction:
    return Fraction(n << e) if e >= 0 else Fraction(n, 1 << -e)


def _from_parts(mant: np.ndarray, e: np.ndarray) -> Dyadic:
    mant = np.asarray(mant, dtype=object)
    nz = np.asarray(mant != 0, dtype=bool)
    if not np.any(nz):
        out = np.empty(mant.size, dtype=object)
        out[:] = 0
        return Dyadic(out, 0)
    e0 = int(np.min(e[nz]))
    shift = np.where(nz, e - e0, 0).astype(object)
    return Dyadic(_LSHIFT(mant, shift).astype(object), e0)


def _segment_sums(ints: np.ndarray, starts: np.ndarray, stops: np.ndarray) -> np.ndarray:
    out = np.empty(len(starts), dtype=object)
    out[:] = 0
    starts = np.asarray(starts, dtype=np.int64)
    stops = np.asarray(stops, dtype=np.int64)
    nonempty = np.flatnonzero(stops > starts)
    if nonempty.size:
        sums = np.add.reduceat(ints, starts[nonempty]) if ints.size else np.zeros(0, dtype=object)
        # reduceat sums from starts[i] to the next listed start; the non-empty segments are
        # contiguous and ordered, so the next start is the end of the segment except for gaps.
        ends_ok = np.append(starts[nonempty][1:], ints.size) == stops[nonempty]
        if np.all(ends_ok):
            out[nonempty] = sums
        else:
            for k, i in enumerate(nonempty):
                out[i] = sums[k] if ends_ok[k] else int(np.sum(ints[starts[i]:stops[i]]))
    return out


def _directed(ints: np.ndarray, exp: int, up: bool = True) -> np.ndarray:
    """Round n·2^exp to float64 towards +inf."""
    ints = np.asarray(ints, dtype=object)
    out = np.zeros(ints.size, dtype=np.float64)
    if ints.size == 0:
        return out
    neg = np.asarray(ints < 0, dtype=bool)
    mag = np.abs(ints)
    bl = _BIT_LENGTH(mag).astype(np.int64)
    shift = np.maximum(bl - 53, 0)
    top = _RSHIFT(mag, shift.astype(object))
    truncated = np.asarray(_LSHIFT(top, shift.astype(object)) != mag, dtype=bool)
    # Round the magnitude away from zero for positive numbers (upper bound) and towards zero
    # for negative ones (a larger negative number is a smaller value).
    bump = truncated & ~neg
    mant = top.astype(np.float64) + bump  # ≤ 2^53: exact
    e = shift + exp
    with np.errstate(over="ignore", under="ignore"):
        val = np.ldexp(mant, np.clip(e, -2000, 2000).astype(np.int64))
    # ldexp rounds to nearest in the subnormal range (possibly up to the smallest normal) and
    # flushes to 0: make it directed.
    small = (np.abs(val) <= _TINY_NORMAL) & (mag != 0)
    small = np.asarray(small, dtype=bool)
    if np.any(small & ~neg):
        val[small & ~neg] = np.nextafter(val[small & ~neg], np.inf)
    if np.any(small & neg):  # a smaller magnitude is the upper bound of a negative number
        val[small & neg] = np.nextafter(val[small & neg], 0.0)
    out[:] = np.where(neg, -val, val)
    # For negative numbers the truncated magnitude is below the true one: −top·2^e ≥ value.
    big = np.asarray(e > 900, dtype=bool) & np.isinf(val)
    out[big & ~neg] = np.inf
    out[big & neg] = -np.finfo(np.float64).max
    return out


@dataclass(frozen=True)
class DyadicCSR:
    """An exact sparse matrix (CSR) with dyadic entries; ``matvec`` is exact."""

    shape: tuple
    indptr: np.ndarray
    indices: np.ndarray
    data: Dyadic

    @staticmethod
    def from_scipy(A) -> "DyadicCSR":
        A = sp.csr_matrix(A)
        A.sum_duplicates()
        return DyadicCSR(A.shape, A.indptr.astype(np.int64), A.indices.astype(np.int64),
                         Dyadic.from_float(A.data))

    def transpose(self) -> "DyadicCSR":
        coo_rows = np.repeat(np.arange(self.shape[0]), np.diff(self.indptr))
        order = np.lexsort((coo_rows, self.indices))
        counts = np.bincount(self.indices, minlength=self.shape[1])
        indptr = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
        return DyadicCSR((self.shape[1], self.shape[0]), indptr, coo_rows[order],
                         Dyadic(self.data.ints[order], self.data.exp))

    def matvec(self, x: Dyadic) -> Dyadic:
        if len(x) != self.shape[1]:
            raise ValueError(f"matvec: x has {len(x)} entries, the matrix {self.shape[1]} columns")
        prod = self.data.ints * x.ints[self.indices]
        return Dyadic(_segment_sums(prod, self.indptr[:-1], self.indptr[1:]), self.data.exp + x.exp)


def fraction_upper_float(q: Fraction) -> float:
    """Smallest-ish float64 ≥ q (rigorous: rounds to nearest, then one step up if below)."""
    f = float(q)  # correctly rounded
    if Fraction(f) < q:
        f = math.nextafter(f, math.inf)
    return f


def fraction_lower_float(q: Fraction) -> float:
    f = float(q)
    if Fraction(f) > q:
        f = math.nextafter(f, -math.inf)
    return f


def sqrt_upper(q: Fraction) -> float:
    """float64 ≥ √q for a Fraction q ≥ 0."""
    if q < 0:
        raise ValueError("sqrt_upper of a negative number")
    if q == 0:
        return 0.0
    f = math.sqrt(fraction_upper_float(q))
    f = math.nextafter(f, math.inf)
    while Fraction(f) ** 2 < q:  # never more than a step or two
        f = math.nextafter(f, math.inf)
    return f


@dataclass(frozen=True)
class Quotient:
    """A vector of exact rationals ``num / den``: a :class:`Dyadic` numerator over one common
    positive integer denominator (odd, or 1).  A point moved exactly onto a face of the cones
    (:mod:`.face`) is rational but not dyadic; cone membership, being homogeneous, is decided on
    the numerator, and the proof divides its bounds by ``den`` with outward rounding."""

    num: Dyadic
    den: int

    def __post_init__(self):
        if not (isinstance(self.den, int) and self.den >= 1):
            raise ValueError(f"the denominator must be a positive integer, got {self.den!r}")

    def __len__(self) -> int:
        return len(self.num)

    @staticmethod
    def from_fractions(values) -> "Quotient":
        """Exact image of a sequence of Fractions (common denominator: the lcm of their odd parts)."""
        values = [Fraction(q) for q in values]
        den = 1
        for q in values:
            d = q.denominator
            d >>= (d & -d).bit_length() - 1  # odd part
            den = den * d // math.gcd(den, d)
        return Quotient(Dyadic.from_fractions_exact([q * den for q in values]) if values else Dyadic.zeros(0), den)

    def fractions(self) -> list:
        return [q / self.den for q in self.num.fractions()]

    def _shifted_floor(self, ints) -> tuple[np.ndarray, int]:
        """floor(ints·2^K / den) and K, K large enough to keep 64 bits beyond den's."""
        k = 64 + self.den.bit_length()
        return (np.asarray(ints, dtype=object) * (1 << k)) // self.den, k

    def upper(self) -> np.ndarray:
        """float64 numbers ≥ the exact values."""
        if self.den == 1:
            return self.num.upper()
        neg_floor, k = self._shifted_floor(-self.num.ints)  # −floor(−x) = ceil(x)
        return _directed(-neg_floor, self.num.exp - k, up=True)

    def lower(self) -> np.ndarray:
        """float64 numbers ≤ the exact values."""
        if self.den == 1:
            return self.num.lower()
        fl, k = self._shifted_floor(self.num.ints)
        return -_directed(-fl, self.num.exp - k, up=True)

    def abs_upper(self) -> np.ndarray:
        """float64 upper bounds of |x_i|."""
        return np.maximum(self.upper(), -self.lower())


def divide_upper(x, den: int) -> np.ndarray:
    """float64 ≥ x / den for float64 x ≥ 0 (rounded up) and a positive integer ``den``."""
    x = np.asarray(x, dtype=np.float64)
    if den == 1:
        return x
    lo = fraction_lower_float(Fraction(den))  # ≤ den, so x / lo ≥ x / den
    return np.nextafter(x / lo, np.inf)
