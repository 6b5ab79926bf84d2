"""Double-double arithmetic (about 32 significant digits) compiled with numba.

A double-double number is an unevaluated sum hi + lo of two float64 with |lo| ≤ ½ulp(hi).
The algorithms are the classical error-free transformations (Dekker 1971, Knuth TwoSum) and
the "accurate" double-double operations of Hida, Li and Bailey's QD library: relative error
about 2⁻¹⁰⁴ per addition and multiplication, a few units more for division and square root.

They rely on every float64 operation being correctly rounded *and not fused*: numba compiles
without fast-math, so LLVM neither reassociates nor contracts a·b + c into an FMA.  The test
``tests/test_extended_dd.py`` checks the operations against mpmath, which would catch a
compiler that broke this.

Functions take and return tuples ``(hi, lo)``; arrays are stored as two float64 arrays.
"""

from __future__ import annotations

import math

import numba
import numpy as np

_SPLITTER = 134217729.0  # 2^27 + 1
# Not inline="always": numba's IR-level inlining re-types every inlined copy, and a kernel
# such as cones.nt_scaling makes a hundred nested calls (20 s of a cold start's 80 s).  As
# separate compiled functions each is typed once and LLVM still inlines the small ones into
# the kernels at machine level; without fast-math either way, so the results are identical.
# The elementwise vector operations below stay compiled: as numpy expressions they cost
# 10-20 µs a call more, which is most of a small problem's warm double-double phase.
jit = numba.njit(cache=True, nogil=True)


@jit
def two_sum(a, b):
    s = a + b
    bb = s - a
    e = (a - (s - bb)) + (b - bb)
    return s, e


@jit
def quick_two_sum(a, b):
    s = a + b
    e = b - (s - a)
    return s, e


@jit
def split(a):
    t = _SPLITTER * a
    hi = t - (t - a)
    return hi, a - hi


@jit
def two_prod(a, b):
    p = a * b
    ah, al = split(a)
    bh, bl = split(b)
    e = ((ah * bh - p) + ah * bl + al * bh) + al * bl
    return p, e


@jit
def add(ah, al, bh, bl):
    s1, s2 = two_sum(ah, bh)
    t1, t2 = two_sum(al, bl)
    s2 += t1
    s1, s2 = quick_two_sum(s1, s2)
    s2 += t2
    return quick_two_sum(s1, s2)


@jit
def sub(ah, al, bh, bl):
    return add(ah, al, -bh, -bl)


@jit
def add_d(ah, al, b):
    s1, s2 = two_sum(ah, b)
    s2 += al
    return quick_two_sum(s1, s2)


@jit
def mul(ah, al, bh, bl):
    p1, p2 = two_prod(ah, bh)
    p2 += ah * bl + al * bh
    return quick_two_sum(p1, p2)


@jit
def mul_d(ah, al, b):
    p1, p2 = two_prod(ah, b)
    p2 += al * b
    return quick_two_sum(p1, p2)


@jit
def div(ah, al, bh, bl):
    q1 = ah / bh
    th, tl = mul_d(bh, bl, q1)
    rh, rl = sub(ah, al, th, tl)
    q2 = rh / bh
    th, tl = mul_d(bh, bl, q2)
    rh, rl = sub(rh, rl, th, tl)
    q3 = rh / bh
    q1, q2 = quick_two_sum(q1, q2)
    return add_d(q1, q2, q3)


@jit
def sqrt(ah, al):
    if ah <= 0.0:
        return 0.0, 0.0
    x = 1.0 / math.sqrt(ah)
    y = ah * x
    ph, pl = two_prod(y, y)
    rh, rl = sub(ah, al, ph, pl)
    return add_d(y, 0.0, rh * (x * 0.5))


@jit
def fma_acc(ch, cl, ah, al, bh, bl):
    """c + a·b."""
    ph, pl = mul(ah, al, bh, bl)
    return add(ch, cl, ph, pl)


@jit
def fms_acc(ch, cl, ah, al, bh, bl):
    """c − a·b."""
    ph, pl = mul(ah, al, bh, bl)
    return add(ch, cl, -ph, -pl)


# ---------------------------------------------------------------------- array helpers (numpy side)
def from_float(x) -> tuple:
    x = np.ascontiguousarray(x, dtype=np.float64)
    return x.copy(), np.zeros_like(x)


def from_longdouble(x) -> tuple:
    """Exact for longdouble with at most 106 mantissa bits (x86 80-bit: 64 bits)."""
    x = np.asarray(x, dtype=np.longdouble)
    hi = x.astype(np.float64)
    lo = (x - hi.astype(np.longdouble)).astype(np.float64)
    return np.ascontiguousarray(hi), np.ascontiguousarray(lo)


def to_longdouble(hi, lo) -> np.ndarray:
    return np.asarray(hi, dtype=np.longdouble) + np.asarray(lo, dtype=np.longdouble)


@numba.njit(cache=True, nogil=True)
def vadd(ah, al, bh, bl, oh, ol):
    for i in range(ah.size):
        oh[i], ol[i] = add(ah[i], al[i], bh[i], bl[i])


@numba.njit(cache=True, nogil=True)
def vaxpy(alpha_h, alpha_l, xh, xl, yh, yl):
    """y += α x in place."""
    for i in range(xh.size):
        yh[i], yl[i] = fma_acc(yh[i], yl[i], alpha_h, alpha_l, xh[i], xl[i])


@numba.njit(cache=True, nogil=True)
def vdot(ah, al, bh, bl):
    sh, sl = 0.0, 0.0
    for i in range(ah.size):
        sh, sl = fma_acc(sh, sl, ah[i], al[i], bh[i], bl[i])
    return sh, sl


@numba.njit(cache=True, nogil=True)
def vnorm2(ah, al):
    """‖a‖₂ in double-double (scaled by the largest |hi| to avoid overflow)."""
    big = 0.0
    for i in range(ah.size):
        big = max(big, abs(ah[i]))
    if big == 0.0:
        return 0.0, 0.0
    sh, sl = 0.0, 0.0
    inv = 1.0 / big
    for i in range(ah.size):
        th, tl = mul_d(ah[i], al[i], inv)
        sh, sl = fma_acc(sh, sl, th, tl, th, tl)
    rh, rl = sqrt(sh, sl)
    return mul_d(rh, rl, big)


@numba.njit(cache=True, nogil=True)  # nogil: run on threads by .workers
def csr_matvec(indptr, indices, dh, dl, xh, xl, oh, ol):
    """o = A x for a CSR matrix with double-double entries (dh, dl)."""
    for i in range(indptr.size - 1):
        sh, sl = 0.0, 0.0
        for k in range(indptr[i], indptr[i + 1]):
            j = indices[k]
            sh, sl = fma_acc(sh, sl, dh[k], dl[k], xh[j], xl[j])
        oh[i] = sh
        ol[i] = sl


@numba.njit(cache=True, nogil=True)
def vsub(ah, al, bh, bl, oh, ol):
    for i in range(ah.size):
        oh[i], ol[i] = add(ah[i], al[i], -bh[i], -bl[i])


@numba.njit(cache=True, nogil=True)
def vscale(alpha_h, alpha_l, xh, xl, oh, ol):
    for i in range(xh.size):
        oh[i], ol[i] = mul(alpha_h, alpha_l, xh[i], xl[i])


@numba.njit(cache=True, nogil=True)
def vmul_d(d, xh, xl, oh, ol):
    """o = d ∘ x with a float64 vector d (entrywise)."""
    for i in range(xh.size):
        oh[i], ol[i] = mul_d(xh[i], xl[i], d[i])
