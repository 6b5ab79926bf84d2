"""Algorithm 1 continued in multiple precision (gmpy2 ``mpfr``), for the last iterations of the
k-digit path on problems that need a duality gap below what double-double resolves.

Why it exists (measured, DECISIONS "Multiple-precision tail"): the proof converts the M-norm
bound ε ≈ √(2 rᵀu) into per-component digits, so 10 relative digits of a v* that is tiny
against the data (a hyperstatic lattice at rest: ‖v*‖∞ ≈ 1e-10 of ‖M⁻¹f‖∞) need rᵀu ≈ 1e-48.
Double-double fails there twice: λ₂ of a cone whose λ₁ is O(1) falls below its unit roundoff
(the iterates leave the cones in exact arithmetic), and the Newton matrices have condition
≈ 1/μ along redundant sticking contacts, so their float64 and double-double factors lose
definiteness near μ = 1e-41 whatever precision the residuals have.

So everything is wider here: the iterate (v, r̃, z), the residuals, every cone kernel (NT
scaling, Q_{p^k}, products, step lengths; the formulas of :mod:`.cones`, vectorised over cones
in numpy object arrays) and the Newton solve — the dof-space matrix M + BᵀB, B = F⁻¹H̃, formed
and factored sparsely in ``bits``-bit arithmetic in a minimum-degree order
(:class:`SparseDofSpace`), each solve refined against the unreduced three-block system.  The
cost is Σ c_j² multiply-subtract pairs (O(m³) at worst), so the k-digit path runs this tail
only where double-double stalled and the factorisation is affordable (:mod:`rfverify.digits`).

gmpy2's precision is set in a local context for the duration of each call; nothing leaks.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import gmpy2
import numpy as np
import scipy.sparse as sp

from ..algorithm.interfaces import Breakdown
from ..algorithm.loop import Precision, iterate
from ..algorithm.newton import ReducedNewton
from ..algorithm.policy import UntilPolicy, extended_trace
from .ipm import ExtendedResult
from .ldl import _numeric_double, _symbolic, _workspace, fill_reducing_order
from .data import DDMatrix, ExtendedData, contact_dof_pattern, contact_local_H

DEFAULT_BITS = 320
"""Working precision: 96 decimal digits, enough for cones whose λ₂/λ₁ is 1e-60 with margin."""

_mpfr = np.frompyfunc(gmpy2.mpfr, 1, 1)
_sqrt = np.frompyfunc(gmpy2.sqrt, 1, 1)
_float = np.frompyfunc(float, 1, 1)


def _context(bits: int):
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


def _zeros(n: int) -> np.ndarray:
    out = np.empty(n, dtype=object)
    out[:] = gmpy2.mpfr(0)
    return out


def inf_norm(x: np.ndarray) -> float:
    return float(max((abs(t) for t in x), default=0.0))


def dot(x: np.ndarray, y: np.ndarray):
    return np.sum(x * y) if x.size else gmpy2.mpfr(0)


def two_norm(x: np.ndarray) -> float:
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
        out = _zeros(self.shape[0])
        if self.data.size:
            out[self.rows] = np.add.reduceat(self.data * x[self.indices], self.starts)
        return out


# ---------------------------------------------------------------------- cone kernels
# A cone vector holds the n3 three-dimensional Lorentz cones first, then the n1 one-dimensional
# ones (same layout as :mod:`.cones`); every kernel works on whole slices.

def _parts(n3: int, x):
    return x[0:3 * n3:3], x[1:3 * n3:3], x[2:3 * n3:3], x[3 * n3:]


def _lams(x0, x1, x2):
    nrm = _sqrt(x1 * x1 + x2 * x2)
    return x0 + nrm, x0 - nrm


def _join(n3: int, a0, a1, a2, t) -> np.ndarray:
    out = np.empty(3 * n3 + len(t), dtype=object)
    out[0:3 * n3:3], out[1:3 * n3:3], out[2:3 * n3:3], out[3 * n3:] = a0, a1, a2, t
    return out


def lambda2(n3: int, x) -> np.ndarray:
    """Smallest eigenvalue of every cone (mpfr): λ₂ for L3 cones, the entry for L1 cones."""
    x0, x1, x2, t = _parts(n3, x)
    return np.concatenate((_lams(x0, x1, x2)[1], t))


@dataclass
class Scaling:
    """NT scaling of every cone: p (Q_p z = Q_{p⁻¹} s = λ), λ, and the spectral data of p
    (a = λ₁(p), b = λ₂(p), unit direction (d1, d2) of p̄; L1 cones: a = b = p)."""

    p: np.ndarray
    lam: np.ndarray
    a: np.ndarray
    b: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    q1: np.ndarray  # L1 cones: p


def nt_scaling(n3: int, z, s):
    """(Scaling, -1), or (None, index of the first cone where z or s is not strictly interior).
    The formulas are those of :func:`.cones.nt_scaling`, in mpfr."""
    z0, z1, z2, zt = _parts(n3, z)
    s0, s1, s2, st = _parts(n3, s)
    l1z, l2z = _lams(z0, z1, z2)
    l1s, l2s = _lams(s0, s1, s2)
    bad = np.flatnonzero(~(np.concatenate((l2z, zt)) > 0).astype(bool) | ~(np.concatenate((l2s, st)) > 0).astype(bool))
    if bad.size:
        return None, int(bad[0])
    rz = _sqrt(l1z) * _sqrt(l2z)
    rs = _sqrt(l1s) * _sqrt(l2s)
    zb0, zb1, zb2 = z0 / rz, z1 / rz, z2 / rz
    sb0, sb1, sb2 = s0 / rs, s1 / rs, s2 / rs
    g = _sqrt((zb0 * sb0 + zb1 * sb1 + zb2 * sb2 + 1) / 2)
    w0, w1, w2 = (sb0 + zb0) / (2 * g), (sb1 - zb1) / (2 * g), (sb2 - zb2) / (2 * g)
    cc = _sqrt(2 * (w0 + 1))
    v0, v1, v2 = (w0 + 1) / cc, w1 / cc, w2 / cc
    q = _sqrt(_sqrt(rs / rz))
    nv = _sqrt(v1 * v1 + v2 * v2)
    l1v = v0 + nv
    has_dir = (nv > 0).astype(bool)
    nv_safe = np.where(has_dir, nv, gmpy2.mpfr(1))
    d1 = np.where(has_dir, v1 / nv_safe, gmpy2.mpfr(1))
    d2 = np.where(has_dir, v2 / nv_safe, gmpy2.mpfr(0))
    m = _sqrt(rs * rz)
    den = 2 * g + zb0 + sb0
    cs, cz = (g + zb0) / den, (g + sb0) / den
    lam = _join(n3, m * g, m * (cs * sb1 + cz * zb1), m * (cs * sb2 + cz * zb2), _sqrt(zt * st))
    qt = _sqrt(_sqrt(st / zt)) if len(zt) else zt
    p = _join(n3, q * v0, q * v1, q * v2, qt)
    return Scaling(p=p, lam=lam, a=q * l1v, b=q / l1v, d1=d1, d2=d2, q1=qt), -1


def quad_pow(n3: int, k: int, sc: Scaling, y) -> np.ndarray:
    """Q_{p^k} y (k in ±1, ±2) from the spectral sum of positive semidefinite terms (no
    cancellation in the small eigenvalues), as :func:`.cones.quad_pow`."""
    y0, y1, y2, yt = _parts(n3, y)
    A, B, Cc = sc.a ** (2 * k), sc.b ** (2 * k), (sc.a * sc.b) ** k
    t = sc.d1 * y1 + sc.d2 * y2
    s1, s2 = (y0 + t) / 2, (y0 - t) / 2
    s3 = sc.d1 * y2 - sc.d2 * y1
    a1, b2, c3 = A * s1, B * s2, Cc * s3
    dif = a1 - b2
    return _join(n3, a1 + b2, dif * sc.d1 - c3 * sc.d2, dif * sc.d2 + c3 * sc.d1, sc.q1 ** (2 * k) * yt)


def product(n3: int, x, y) -> np.ndarray:
    x0, x1, x2, xt = _parts(n3, x)
    y0, y1, y2, yt = _parts(n3, y)
    return _join(n3, x0 * y0 + x1 * y1 + x2 * y2, x0 * y1 + y0 * x1, x0 * y2 + y0 * x2, xt * yt)


def arrow_solve(n3: int, x, y) -> np.ndarray:
    """o with x ∘ o = y (x interior)."""
    x0, x1, x2, xt = _parts(n3, x)
    y0, y1, y2, yt = _parts(n3, y)
    l1, l2 = _lams(x0, x1, x2)
    o0 = (x0 * y0 - x1 * y1 - x2 * y2) / (l1 * l2)
    return _join(n3, o0, (y1 - o0 * x1) / x0, (y2 - o0 * x2) / x0, yt / xt)


def max_step(n3: int, x, dx) -> float:
    """Largest α with x + α·dx in the cone (x interior), as a float rounded down; inf when
    unbounded.  Through y = Q_{x^{-1/2}} dx: α = −1/λ₂(y) where λ₂(y) < 0."""
    x0, x1, x2, xt = _parts(n3, x)
    d0, d1, d2, dt = _parts(n3, dx)
    best = math.inf
    if n3:
        l1, l2 = _lams(x0, x1, x2)
        r1, r2 = _sqrt(l1), _sqrt(l2)
        t = r1 + r2
        rd = r1 * r2
        w0, w1, w2 = (t / 2) / rd, -(x1 / t) / rd, -(x2 / t) / rd
        m1, m2 = _lams(w0, w1, w2)
        det = m1 * m2
        s = 2 * (w0 * d0 + w1 * d1 + w2 * d2)
        y0, y1, y2 = s * w0 - det * d0, s * w1 + det * d1, s * w2 + det * d2
        ly2 = _lams(y0, y1, y2)[1]
        neg = (ly2 < 0).astype(bool)
        if neg.any():
            best = min(best, float(min(-1 / ly2[neg])))
    if len(xt):
        neg = (dt < 0).astype(bool)
        if neg.any():
            best = min(best, float(min(-xt[neg] / dt[neg])))
    return best


def identity(n3: int, nz: int) -> np.ndarray:
    e = _zeros(nz)
    e[0:3 * n3:3] = gmpy2.mpfr(1)
    e[3 * n3:] = gmpy2.mpfr(1)
    return e


def _quad_matrix(sc: Scaling, k: int, idx) -> np.ndarray:
    """Q_{p^k} of the L3 cones ``idx`` as (len(idx), 3, 3) mpfr matrices (spectral sum)."""
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


def contact_factor_inverse(data: ExtendedData, sc: Scaling) -> np.ndarray:
    """F_c⁻¹ per contact, (n, 5, 5) mpfr, for F_c F_cᵀ = G_c = J_c Q_{p⁻²} J_cᵀ: the formulas
    of :func:`.system.contact_factor_inverse` (Q_p for one cone, p² for a normal ray, (R⁻¹)ᵀ
    of a Householder QR of (J_c Q_{p⁻¹})ᵀ for a full contact), vectorised over contacts.
    Raises ArithmeticError if a factor is singular."""
    n = data.n
    F = np.empty((n, 5, 5), dtype=object)
    F[:] = gmpy2.mpfr(0)
    kinds = data.kinds
    ray = np.flatnonzero(kinds == 3)
    if ray.size:
        F[ray, 0, 0] = sc.q1[data.normal_cone[ray] - data.n3] ** 2
    for kind, cones in ((1, data.fric_cone), (2, data.roll_cone)):
        sel = np.flatnonzero(kinds == kind)
        if sel.size:
            F[sel, :3, :3] = _quad_matrix(sc, 1, cones[sel])
    full = np.flatnonzero(kinds == 0)
    if full.size:
        nf = full.size
        At = np.empty((nf, 6, 5), dtype=object)
        At[:] = gmpy2.mpfr(0)
        At[:, :3, :3] = _quad_matrix(sc, -1, data.fric_cone[full])
        At[:, 3:, [0, 3, 4]] = _quad_matrix(sc, -1, data.roll_cone[full])
        R = At
        for j in range(5):
            norm = _sqrt(np.sum(R[:, j:, j] * R[:, j:, j], axis=1))
            if not (norm > 0).astype(bool).all():
                raise ArithmeticError("a contact's factor is singular")
            alpha = np.where((R[:, j, j] > 0).astype(bool), -norm, norm)
            vcol = R[:, j:, j].copy()
            vcol[:, 0] = vcol[:, 0] - alpha
            beta = 2 / np.sum(vcol * vcol, axis=1)
            for c in range(j + 1, 5):
                proj = np.sum(vcol * R[:, j:, c], axis=1) * beta
                R[:, j:, c] = R[:, j:, c] - proj[:, None] * vcol
            R[:, j, j] = alpha
        Rinv_T = np.empty((nf, 5, 5), dtype=object)
        Rinv_T[:] = gmpy2.mpfr(0)
        for c in range(5):  # column c of R⁻¹, stored as row c of (R⁻¹)ᵀ
            for r in range(c, -1, -1):
                acc = np.full(nf, gmpy2.mpfr(1 if r == c else 0), dtype=object)
                for q in range(r + 1, c + 1):
                    acc = acc - R[:, r, q] * Rinv_T[:, c, q]
                Rinv_T[:, c, r] = acc / R[:, r, r]
        F[full] = Rinv_T
    return F


def centrality(n3: int, sc: Scaling, mu) -> float:
    """min over cones of λ₂(λ)/√μ_c, μ_c = zᵀs / (number of cones) (1 on the central path,
    → 0 as an iterate hugs a face).  λ = Q_p z is the scaled point; λ∘λ's smallest eigenvalue
    is λ₂(λ)², so this is the square root of the usual neighbourhood measure."""
    lam2 = lambda2(n3, sc.lam)
    return float(min(lam2) / gmpy2.sqrt(mu)) if lam2.size else 1.0


def dof_space_ordering(data: ExtendedData, CD=None):
    """(minimum-degree order of M + H̃ᵀG⁻¹H̃'s pattern, the number of multiply-subtract pairs
    its Cholesky factor costs in that order: Σ_j c_j² over the column counts c_j of L)."""
    CD = contact_dof_pattern(data) if CD is None else CD
    pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
    perm = fill_reducing_order(pattern)
    n = pattern.shape[0]
    P = (abs(pattern) + abs(pattern.T) + sp.identity(n, format="csc")).tocsc()
    U = sp.triu(P[perm][:, perm], format="csc")
    U.sort_indices()
    _, Lp = _symbolic(n, U.indptr.astype(np.int64), U.indices.astype(np.int64))
    counts = np.diff(Lp).astype(np.float64)
    return perm, float(np.sum(counts * counts))


class DenseDofSpace:
    """The dof-space Newton matrix S = M + H̃ᵀG⁻¹H̃ = M + BᵀB (B = F⁻¹H̃, per contact) as a
    dense m × m mpfr matrix with a Cholesky factor in its lower triangle, in a minimum-degree
    order that skips exact zeros: Σ c_j² multiply-subtract pairs per factorisation
    (:func:`dof_space_ordering`), O(m³) at worst.  The tail uses :class:`SparseDofSpace`
    (same order, same arithmetic, memory O(nnz(L))); this dense form is its reference.

    Why not the double-double back ends: S and the contact-space S' = I + F⁻¹W̃F⁻ᵀ both have
    condition numbers near 1/μ along redundant sticking contacts (W̃ singular), and near
    μ = 1e-40 their float64 and double-double factors lose definiteness (measured on a
    274-contact Lattice, DECISIONS).  A factor in ``bits``-bit arithmetic does not."""

    name = "dense dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"

    def __init__(self, data: ExtendedData, W: "WideData", perm: np.ndarray | None = None):
        m = data.m
        CD = self._ordered(data, W, perm)
        loc_dofs, Hh, Hl = contact_local_H(data, CD)
        self.valid = loc_dofs >= 0
        self.loc = np.where(self.valid, self.iperm[np.maximum(loc_dofs, 0)], -1)
        self.Hc = from_dd(Hh, Hl) if Hh.size else np.empty(Hh.shape, dtype=object)  # (n, 5, d)
        S = _zeros(m * m).reshape(m, m)
        mr, mc, mh, ml = data.M.coo()
        S[self.iperm[mr], self.iperm[mc]] = from_dd(mh, ml)
        self.M_dense = S
        self.L = None
        self.Finv = None

    def _ordered(self, data: ExtendedData, W: "WideData", perm):
        """Keep the data and put rows and columns in a minimum-degree order (``perm`` if the
        caller has it already): the factor keeps M + BᵀB's sparsity and the elimination skips
        the exact zeros.  Returns the contact–dof pattern."""
        self.data = data
        self.W = W
        CD = contact_dof_pattern(data)
        self.perm = dof_space_ordering(data, CD)[0] if perm is None else np.asarray(perm, dtype=np.int64)
        self.iperm = np.empty_like(self.perm)
        self.iperm[self.perm] = np.arange(data.m)
        return CD

    def update(self, sc: Scaling) -> bool:
        """Form and factor S at the scaling ``sc``; False if a pivot is not positive."""
        data, m = self.data, self.data.m
        self.Finv = contact_factor_inverse(data, sc)  # (n, 5, 5); zero past a contact's kept rows
        B = np.matmul(self.Finv, self.Hc)  # (n, 5, d)
        blocks = np.matmul(np.transpose(B, (0, 2, 1)), B)  # (n, d, d) = B_cᵀB_c
        S = self.M_dense.copy()
        d = self.loc.shape[1]
        ii = np.broadcast_to(self.loc[:, :, None], (data.n, d, d))
        jj = np.broadcast_to(self.loc[:, None, :], (data.n, d, d))
        ok = self.valid[:, :, None] & self.valid[:, None, :]
        np.add.at(S, (ii[ok], jj[ok]), blocks[ok])
        L = S
        for j in range(m):
            piv = L[j, j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            L[j, j] = piv
            rows = j + 1 + np.flatnonzero((L[j + 1:, j] != 0).astype(bool))
            if rows.size:
                col = L[rows, j] / piv
                L[rows, j] = col
                # the lower triangle only, one target column at a time (3× faster than the
                # full square update on a 600-dof Lattice; the upper triangle is never read)
                for t, target in enumerate(rows):
                    L[rows[t:], target] -= col[t:] * col[t]
        self.L = L
        return True

    def _G_inv(self, x):
        """G⁻¹x = F⁻ᵀ(F⁻¹x), contact by contact (x over the kept rows)."""
        data = self.data
        X = _zeros(data.n * 5).reshape(data.n, 5)
        rows_local = np.arange(data.nk) - np.repeat(data.row_start, data.row_count)
        cont = np.repeat(np.arange(data.n), data.row_count)
        X[cont, rows_local] = x
        Y = np.matmul(self.Finv, X[:, :, None])
        Z = np.matmul(np.transpose(self.Finv, (0, 2, 1)), Y)[:, :, 0]
        return Z[cont, rows_local]

    def _chol_solve(self, b):
        L, m = self.L, self.data.m
        y = b.copy()
        for j in range(m):
            y[j] = y[j] / L[j, j]
            y[j + 1:] -= L[j + 1:, j] * y[j]
        for j in range(m - 1, -1, -1):
            y[j] = (y[j] - dot(L[j + 1:, j], y[j + 1:])) / L[j, j]
        return y

    def solve(self, a, t):
        """(dv, dr̃) with M dv − H̃ᵀ dr̃ = a, H̃ dv + G dr̃ = t (mpfr)."""
        W = self.W
        rhs = a + W.HtT @ self._G_inv(t)
        dv = np.empty_like(rhs)
        dv[self.perm] = self._chol_solve(rhs[self.perm])
        dr = self._G_inv(t - W.Ht @ dv)
        return dv, dr


def _factor_pattern(pattern: sp.spmatrix, perm: np.ndarray):
    """The structure of the Cholesky factor of ``pattern`` in the order ``perm``: (Lp, Li) of
    its strictly lower part in CSC (rows ascending in each column), and the lower triangle of
    the permuted pattern (CSC, sorted), whose entries the factor reads."""
    n = pattern.shape[0]
    P = (abs(pattern) + abs(pattern.T) + sp.identity(n, format="csc")).tocsc()
    P = P[perm][:, perm].tocsc()
    U = sp.triu(P, format="csc")
    U.sort_indices()
    Ap, Ai = U.indptr.astype(np.int64), U.indices.astype(np.int64)
    parent, Lp = _symbolic(n, Ap, Ai)
    # the structure itself from a float64 factorisation of a strictly diagonally dominant
    # matrix on the pattern (its kernel writes every structural entry; no pivot can fail)
    vals = np.where(Ai == np.repeat(np.arange(n), np.diff(Ap)), float(n + 1), 1.0)
    Li, Lx = np.zeros(int(Lp[-1]), dtype=np.int64), np.zeros(int(Lp[-1]))
    if _numeric_double(n, Ap, Ai, vals, Lp, parent, Li, Lx, np.zeros(n), np.zeros(n), *_workspace(n)) >= 0:
        raise AssertionError("a diagonally dominant matrix lost a pivot")
    lower = sp.tril(P, format="csc")
    lower.sort_indices()
    return Lp, Li, lower


class SparseDofSpace(DenseDofSpace):
    """:class:`DenseDofSpace` with S = M + BᵀB stored and factored sparsely: the same
    minimum-degree order, the same multiply-subtract pairs (Σ c_j² over the column counts of
    L), but memory O(nnz(L)) mpfr numbers instead of a dense m × m array, so the tail has no
    limit in dofs, only in its predicted cost (:mod:`rfverify.digits`).

    The factorisation is left-looking by columns: column j of L gathers the updates of the
    columns k that have an entry in row j (one vectorised object-array operation per entry of
    L, the same count of Python-level steps as the dense version's per-target updates), then
    is scaled by its pivot √d_j.  A solve is two sweeps over the columns."""

    name = "sparse dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"

    def __init__(self, data: ExtendedData, W: "WideData", perm: np.ndarray | None = None):
        m = data.m
        CD = self._ordered(data, W, perm)
        pattern = (abs(data.M_pattern) + abs(CD.T @ CD)).tocsc()
        self.Lp, self.Li, lower = _factor_pattern(pattern, self.perm)
        self.S_indptr, self.S_indices = lower.indptr.astype(np.int64), lower.indices.astype(np.int64)
        keys = np.repeat(np.arange(m, dtype=np.int64), np.diff(self.S_indptr)) * m + self.S_indices

        def where(rows, cols):  # position in the lower CSC of permuted entries (rows ≥ cols)
            return np.searchsorted(keys, np.asarray(cols, dtype=np.int64) * m + np.asarray(rows, dtype=np.int64))

        loc_dofs, Hh, Hl = contact_local_H(data, CD)
        valid = loc_dofs >= 0
        loc = np.where(valid, self.iperm[np.maximum(loc_dofs, 0)], -1)
        self.Hc = from_dd(Hh, Hl) if Hh.size else np.empty(Hh.shape, dtype=object)  # (n, 5, d)
        d = loc.shape[1]
        ii = np.broadcast_to(loc[:, :, None], (data.n, d, d))
        jj = np.broadcast_to(loc[:, None, :], (data.n, d, d))
        self.block_take = valid[:, :, None] & valid[:, None, :] & (ii >= jj)  # lower half of each B_cᵀB_c
        self.block_pos = where(ii[self.block_take], jj[self.block_take])
        mr, mc, mh, ml = data.M.coo()
        pr, pc = self.iperm[mr], self.iperm[mc]
        low = pr >= pc
        self.M_values = _zeros(keys.size)
        np.add.at(self.M_values, where(pr[low], pc[low]), from_dd(mh[low], ml[low]))
        # row j of L: the columns k < j with an entry there, each with the offset of that entry
        # in column k (the column's entries at rows ≥ j start there: rows ascend)
        cols_of = np.repeat(np.arange(m, dtype=np.int64), np.diff(self.Lp))
        order = np.lexsort((cols_of, self.Li))
        self.row_ptr = np.concatenate(([0], np.cumsum(np.bincount(self.Li, minlength=m)))).astype(np.int64)
        self.row_cols = cols_of[order]
        self.row_entry = order.astype(np.int64)  # index into Li / Lx
        self.Lx = None
        self.Ld = None
        self.Finv = None

    @property
    def ops(self) -> float:
        """Multiply-subtract pairs per factorisation (Σ c_j² over the columns of L)."""
        c = np.diff(self.Lp).astype(np.float64) + 1.0
        return float(np.sum(c * c))

    def update(self, sc: Scaling) -> bool:
        """Form and factor S at the scaling ``sc``; False if a pivot is not positive."""
        data, m = self.data, self.data.m
        self.Finv = contact_factor_inverse(data, sc)
        B = np.matmul(self.Finv, self.Hc)  # (n, 5, d)
        blocks = np.matmul(np.transpose(B, (0, 2, 1)), B)  # (n, d, d) = B_cᵀB_c
        S = self.M_values.copy()
        np.add.at(S, self.block_pos, blocks[self.block_take])
        Lp, Li = self.Lp, self.Li
        Lx = np.empty(Li.size, dtype=object)
        Ld = np.empty(m, dtype=object)
        w = _zeros(m)  # the column being built, scattered by row
        for j in range(m):
            a, b = self.S_indptr[j], self.S_indptr[j + 1]
            w[self.S_indices[a:b]] = S[a:b]
            for t in range(self.row_ptr[j], self.row_ptr[j + 1]):
                e = self.row_entry[t]  # L[j, k]: the first entry of column k at a row ≥ j
                end = Lp[self.row_cols[t] + 1]
                w[Li[e:end]] -= Lx[e:end] * Lx[e]
            piv = w[j]
            if not piv > 0:
                return False
            piv = gmpy2.sqrt(piv)
            Ld[j] = piv
            rows = Li[Lp[j]:Lp[j + 1]]
            Lx[Lp[j]:Lp[j + 1]] = w[rows] / piv
            w[j] = gmpy2.mpfr(0)
            w[rows] = gmpy2.mpfr(0)
        self.Lx, self.Ld = Lx, Ld
        return True

    def _chol_solve(self, b):
        Lp, Li, Lx, Ld, m = self.Lp, self.Li, self.Lx, self.Ld, self.data.m
        y = b.copy()
        for j in range(m):
            y[j] = y[j] / Ld[j]
            a, e = Lp[j], Lp[j + 1]
            if e > a:
                y[Li[a:e]] -= Lx[a:e] * y[j]
        for j in range(m - 1, -1, -1):
            a, e = Lp[j], Lp[j + 1]
            y[j] = (y[j] - dot(Lx[a:e], y[Li[a:e]])) / Ld[j]
        return y


# ---------------------------------------------------------------------- driver
@dataclass
class WideIterate:
    """The state handed to the ``until`` callback: v (m,), r̃ (nk,), z (nz,) as mpfr arrays."""

    k: int
    v: np.ndarray
    r_t: np.ndarray
    z: np.ndarray
    mu: float
    pinfeas: float
    dinfeas: float
    bits: int
    wide_data: "WideData" = field(repr=False, default=None)

    def describe(self):
        """(rᵀu of the iterate, the point (v, r) as a float64 expansion, ‖v‖∞, ‖u‖∞) for the
        proof driver."""
        data = self.wide_data.data
        lp = data.lp
        terms = -(-self.bits // 53)
        with _context(self.bits):
            u_t = self.wide_data.Ht @ self.v + self.wide_data.w_t
            gap = float(abs(dot(self.r_t, u_t)))
            vp = expansion(self.v, terms)
            rp = expansion(self.r_t * from_dd(lp.scale), terms)
        R = np.zeros((terms, 5 * data.n))
        R[:, lp.keep] = rp
        from ..proof import Point

        point = Point(vp[0], vp[1], R[0], R[1], np.array(vp[2:]), R[2:])
        v_inf = float(np.max(np.abs(vp[0]), initial=0.0))
        u_inf = float(np.max(np.abs(data.problem.H.T @ vp[0] + data.problem.w), initial=0.0))
        return gap, point, v_inf, u_inf


def handover(data: ExtendedData, iterates, bits: int = DEFAULT_BITS, min_centrality: float = 1e-2,
             residual_margin: float = 1e4):
    """The latest double-double iterate from which the tail can start: strictly interior in
    ``bits``-bit arithmetic (the last iterates of a stalled double-double run are often not),
    centred (λ₂(λ)/√μ ≥ ``min_centrality`` in every cone), and with residuals within
    ``residual_margin`` of the best ones among ``iterates``.  None if there is none."""
    if not iterates:
        return None
    best_p = min(it.pinfeas for it in iterates)
    best_d = min(it.dinfeas for it in iterates)
    with _context(bits):
        JT = WideMatrix(data.JT)
        for it in reversed(iterates):
            if it.pinfeas > residual_margin * best_p or it.dinfeas > residual_margin * best_d:
                continue
            z = from_dd(it.z.h, it.z.l)
            s = JT @ from_dd(it.r_t.h, it.r_t.l)
            sc, _ = nt_scaling(data.n3, z, s)
            if sc is None:
                continue
            if centrality(data.n3, sc, dot(z, s) / (data.n3 + data.n1)) >= min_centrality:
                return it
    return None


@dataclass
class WideResult(ExtendedResult):
    """Outcome of :func:`run`: as :class:`.ipm.ExtendedResult`, with v, r̃, z as mpfr arrays
    and the working precision ``bits``."""

    bits: int = DEFAULT_BITS


class WideData:
    """The lifted data of :class:`ExtendedData` as mpfr (built inside the precision context)."""

    def __init__(self, data: ExtendedData):
        self.data = data
        self.M, self.Ht, self.HtT = WideMatrix(data.M), WideMatrix(data.Ht), WideMatrix(data.HtT)
        self.J, self.JT = WideMatrix(data.J), WideMatrix(data.JT)
        self.f = from_dd(*data.f)
        self.w_t = from_dd(*data.w_t)


class _WideSpace:
    """The lifted problem in ``bits``-bit mpfr (:class:`~rfverify.algorithm.interfaces.Space`):
    :class:`WideData`'s operators, object arrays as vectors."""

    tiny = 1e-300

    def __init__(self, W: WideData):
        self.M, self.H, self.HT, self.J, self.JT = W.M, W.Ht, W.HtT, W.J, W.JT
        self.f, self.w = W.f, W.w_t

    def velocity(self, v, r):
        return self.H @ v

    dot = staticmethod(dot)
    norm2 = staticmethod(two_norm)

    @staticmethod
    def axpy(x, a, y):
        return x + a * y

    move = axpy


class _WideScaling:
    """The NT scaling of one mpfr iterate and its cone operations."""

    def __init__(self, n3: int, n_cones: int, e, z, s):
        sc, bad = nt_scaling(n3, z, s)
        if sc is None:
            raise Breakdown(f"cone {bad} is not strictly interior")
        self.n3, self.n_cones, self.e, self.z, self.s, self.sc = n3, n_cones, e, z, s, sc

    def describe(self) -> dict:
        return {"centrality": centrality(self.n3, self.sc, dot(self.z, self.s) / self.n_cones)}

    def quad(self, k: int, y):
        return quad_pow(self.n3, k, self.sc, y)

    def affine_rhs(self):
        return -self.sc.lam

    def corrector_rhs(self, target, dz_aff, ds_aff):
        n3, lam = self.n3, self.sc.lam
        xi = target * self.e - product(n3, lam, lam) - product(n3, self.quad(1, dz_aff), self.quad(-1, ds_aff))
        return arrow_solve(n3, lam, xi)

    def max_step(self, dz, ds) -> float:
        return min(max_step(self.n3, self.z, dz), max_step(self.n3, self.s, ds))


class _WideCones:
    def __init__(self, n3: int, nz: int, n_cones: int):
        self.n3, self.n_cones, self.e = n3, n_cones, identity(n3, nz)

    def scaling(self, z, s):
        return _WideScaling(self.n3, self.n_cones, self.e, z, s)


class _WideBackend:
    """A dof-space factor seen through the Newton interface (it takes the scaling's
    :class:`Scaling` and mpfr vectors as they are)."""

    def __init__(self, factor):
        self.factor = factor
        self.name = factor.name

    def update(self, scaling: _WideScaling) -> bool:
        return self.factor.update(scaling.sc)

    def solve(self, a, t):
        return self.factor.solve(a, t)


def run(data: ExtendedData, start: dict, *, until=None, max_iter: int = 30, bits: int = DEFAULT_BITS,
        refine_max: int = 8, gamma_max: float = 0.99, perm=None, progress=None, sparse: bool = True) -> WideResult:
    """Algorithm 1 (:func:`rfverify.algorithm.loop.iterate`) in ``bits``-bit arithmetic from
    ``start`` = {"v", "r_t", "z"}, each a (hi, lo) pair of float64 arrays (a double-double
    iterate) or an mpfr array.  ``until(WideIterate)`` is called at every iterate; True stops
    the run ("Stopped").  Same policy as :func:`.ipm.run` (the paper's σ rule, the capped step
    rule).  ``perm``: the factor's ordering from :func:`dof_space_ordering`, if the caller
    computed it.  ``sparse``: the factor is :class:`SparseDofSpace` (default; memory
    O(nnz(L))), else :class:`DenseDofSpace` (m × m; kept as the reference the sparse one is
    tested against)."""
    t0 = time.perf_counter()
    n_cones = data.n3 + data.n1
    with _context(bits):
        W = WideData(data)
        factor = (SparseDofSpace if sparse else DenseDofSpace)(data, W, perm=perm)
        space = _WideSpace(W)
        newton = ReducedNewton(space, _WideBackend(factor), refine_max=refine_max, floor=2.0 ** (-bits + 24),
                               inf=inf_norm)
        policy = UntilPolicy(until, progress, max_iter,
                             lambda k, it, res: WideIterate(k, *it, res.mu, res.pinfeas, res.dinfeas, bits, W),
                             gamma_max, "stopped by the proof driver")

        def lift(x):
            return from_dd(*x) if isinstance(x, tuple) else np.asarray(x, dtype=object) + 0

        begin = tuple(lift(start[key]) for key in ("v", "r_t", "z"))
        out = iterate(Precision(space, _WideCones(data.n3, data.nz, n_cones), newton), policy, begin,
                      n_contacts=data.n, n_cones=n_cones, clock_origin=t0)
    status, message = out.verdict
    return WideResult(*out.iterate, status, message, out.k, extended_trace(out.records), factor.name,
                      time.perf_counter() - t0, bits=bits)
