"""The product cone's operations on object arrays of gmpy2 ``mpfr`` numbers (the
multiple-precision tail, :mod:`rfverify.extended.wide`), from the closed forms of
:mod:`._formulas` — the same formulas the float64 and longdouble routes evaluate — plus the
spectral form of Q_{p^k} the extended precisions use (no cancellation in the small
eigenvalues; :mod:`rfverify.extended.cones` compiles the same in double-double).

A cone vector holds the n3 three-dimensional Lorentz cones first, as consecutive triples,
then the n1 one-dimensional ones.  Nothing is rescaled or checked: the tail's iterates are
interior and their exponents far inside mpfr's range.  The working precision is the caller's
gmpy2 context.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import gmpy2
import numpy as np

from ._formulas import _arrow_solve, _bar_norm, _inverse_sqrt, _nt, _product, _quad, _root, _spec


def _rows(n3: int, x) -> np.ndarray:
    """The L3 part of a cone vector as (n3, 3) rows (a view)."""
    return x[:3 * n3].reshape(n3, 3)


def _join(n3: int, rows, tail) -> np.ndarray:
    out = np.empty(3 * n3 + len(tail), dtype=object)
    out[:3 * n3] = rows.reshape(-1)
    out[3 * n3:] = tail
    return out


def identity(n3: int, nz: int) -> np.ndarray:
    """e: (1, 0, 0) per L3 cone, 1 per L1 cone."""
    e = np.empty(nz, dtype=object)
    e[:] = gmpy2.mpfr(0)
    e[0:3 * n3:3] = gmpy2.mpfr(1)
    e[3 * n3:] = gmpy2.mpfr(1)
    return e


def lambda2(n3: int, x) -> np.ndarray:
    """Smallest eigenvalue of every cone: λ₂ for L3 cones, the entry for L1 cones."""
    return np.concatenate((_spec(_rows(n3, x))[1], x[3 * n3:]))


@dataclass
class Scaling:
    """NT scaling of every cone: p (Q_p z = Q_{p⁻¹} s = λ), λ, and the spectral data of p
    (a = λ₁(p), b = λ₂(p), unit direction (d1, d2) of p̄; L1 cones: q1 = p)."""

    p: np.ndarray
    lam: np.ndarray
    a: np.ndarray
    b: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    q1: np.ndarray


def nt_scaling(n3: int, z, s):
    """(Scaling, -1), or (None, index of the first cone where z or s is not strictly
    interior).  L3 cones by :func:`._formulas._nt`; an L1 cone's p is (s/z)^{1/4}, λ = √(zs)."""
    zr, sr = _rows(n3, z), _rows(n3, s)
    zt, st = z[3 * n3:], s[3 * n3:]
    l1z, l2z, _ = _spec(zr)
    l1s, l2s, _ = _spec(sr)
    inside = (np.concatenate((l2z, zt)) > 0).astype(bool) & (np.concatenate((l2s, st)) > 0).astype(bool)
    if not inside.all():
        return None, int(np.flatnonzero(~inside)[0])
    q, p, _, lam, v, _ = _nt(zr, sr, l1z, l2z, l1s, l2s)
    nv = _bar_norm(v[:, 1:])
    l1v = v[:, 0] + nv
    has_dir = (nv > 0).astype(bool)
    nv_safe = np.where(has_dir, nv, gmpy2.mpfr(1))
    d1 = np.where(has_dir, v[:, 1] / nv_safe, gmpy2.mpfr(1))
    d2 = np.where(has_dir, v[:, 2] / nv_safe, gmpy2.mpfr(0))
    qt = _root(_root(st / zt)) if len(zt) else zt
    return Scaling(p=_join(n3, p, qt), lam=_join(n3, lam, _root(zt * st) if len(zt) else zt), a=q * l1v,
                   b=q / l1v, d1=d1, d2=d2, q1=qt), -1


def quad_pow(n3: int, k: int, sc: Scaling, y) -> np.ndarray:
    """Q_{p^k} y (k in ±1, ±2) from the spectral sum of positive semidefinite terms (no
    cancellation in the small eigenvalues)."""
    y0, y1, y2, yt = y[0:3 * n3:3], y[1:3 * n3:3], y[2:3 * n3:3], y[3 * n3:]
    A, B, Cc = sc.a ** (2 * k), sc.b ** (2 * k), (sc.a * sc.b) ** k
    t = sc.d1 * y1 + sc.d2 * y2
    s1, s2 = (y0 + t) / 2, (y0 - t) / 2
    s3 = sc.d1 * y2 - sc.d2 * y1
    a1, b2, c3 = A * s1, B * s2, Cc * s3
    dif = a1 - b2
    rows = np.stack((a1 + b2, dif * sc.d1 - c3 * sc.d2, dif * sc.d2 + c3 * sc.d1), axis=1) if n3 else \
        np.empty((0, 3), dtype=object)
    return _join(n3, rows, sc.q1 ** (2 * k) * yt)


def quad_matrix(sc: Scaling, k: int, idx) -> np.ndarray:
    """Q_{p^k} of the L3 cones ``idx`` as (len(idx), 3, 3) matrices (the spectral sum)."""
    a, b, d1, d2 = sc.a[idx], sc.b[idx], sc.d1[idx], sc.d2[idx]
    A, B, Cc = a ** (2 * k), b ** (2 * k), (a * b) ** k
    one = np.full(len(idx), gmpy2.mpfr(1), dtype=object)
    zero = np.full(len(idx), gmpy2.mpfr(0), dtype=object)
    d = (one, d1, d2)
    y = (zero, -d2, d1)
    Q = np.empty((len(idx), 3, 3), dtype=object)
    for r in range(3):
        for t in range(3):
            sign = 1 if (r == 0) == (t == 0) else -1
            Q[:, r, t] = (A + sign * B) * (d[r] * d[t]) / 2 + Cc * (y[r] * y[t])
    return Q


def product(n3: int, x, y) -> np.ndarray:
    """x∘y."""
    return _join(n3, _product(_rows(n3, x), _rows(n3, y)), x[3 * n3:] * y[3 * n3:])


def arrow_solve(n3: int, x, y) -> np.ndarray:
    """o with x ∘ o = y (x interior)."""
    xr = _rows(n3, x)
    l1, l2, _ = _spec(xr)
    return _join(n3, _arrow_solve(xr, _rows(n3, y), l1, l2), y[3 * n3:] / x[3 * n3:])


def max_step(n3: int, x, dx) -> float:
    """Largest α with x + α·dx in the cone (x interior), as a float; inf when unbounded.
    Through y = Q_{x^{-1/2}} dx: α = −1/λ₂(y) where λ₂(y) < 0."""
    return max_step_at(n3, x, dx)[0]


def max_step_at(n3: int, x, dx) -> tuple[float, int]:
    """(:func:`max_step`, the cone that sets it): cone c < n3 is the L3 cone of entries
    3c … 3c+2, cone n3 + k the L1 cone of entry 3·n3 + k; the first such cone on ties, -1 when
    unbounded."""
    best, at = math.inf, -1
    if n3:
        xr = _rows(n3, x)
        l1, l2, _ = _spec(xr)
        w = _inverse_sqrt(xr, l1, l2)
        m1, m2, _ = _spec(w)
        ly2 = _spec(_quad(w, _rows(n3, dx), m1 * m2))[1]
        neg = np.flatnonzero((ly2 < 0).astype(bool))
        if neg.size:
            steps = -1 / ly2[neg]
            j = int(np.argmin(steps))  # the first of equal minima
            best, at = float(steps[j]), int(neg[j])
    xt, dt = x[3 * n3:], dx[3 * n3:]
    if len(xt):
        neg = np.flatnonzero((dt < 0).astype(bool))
        if neg.size:
            steps = -xt[neg] / dt[neg]
            j = int(np.argmin(steps))
            if float(steps[j]) < best:
                best, at = float(steps[j]), n3 + int(neg[j])
    return best, at


def centrality(n3: int, sc: Scaling, mu) -> float:
    """min over cones of λ₂(λ)/√μ_c, μ_c = zᵀs / (number of cones) (1 on the central path,
    → 0 as an iterate hugs a face).  λ = Q_p z is the scaled point; λ∘λ's smallest eigenvalue
    is λ₂(λ)², so this is the square root of the usual neighbourhood measure."""
    lam2 = lambda2(n3, sc.lam)
    return float(min(lam2) / gmpy2.sqrt(mu)) if lam2.size else 1.0
