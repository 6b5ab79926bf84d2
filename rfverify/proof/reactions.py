"""The bound on r − r* where r* is unique (DESIGN §6): contacts proven open, and the full column
rank of H on the others, in the problem's units or in equilibrated ones."""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from ..model.problem import SPACEDIM
from .dyadic import Dyadic, sqrt_upper
from .massbounds import ETA, gamma, inflate, verify_lambda_min_sparse
from .quantity import down, up


def proven_open(u_p: Dyadic, u_radius, mu, mur, n: int) -> np.ndarray:
    """Contacts where u* ∈ int K*_i is proven (so r*_i = 0 for every solution): the whole box
    u_p ± radius lies inside.  A sufficient test in float64 with every rounding pushed against it."""
    lo, hi = u_p.lower(), u_p.upper()
    uc_lo, uc_hi = lo.reshape(n, SPACEDIM), hi.reshape(n, SPACEDIM)
    rad = np.asarray(u_radius).reshape(n, SPACEDIM)
    mag_hi = up(np.maximum(np.abs(uc_lo), np.abs(uc_hi)) + rad)
    nT = up(np.hypot(mag_hi[:, 1], mag_hi[:, 2]))
    nR = up(np.hypot(mag_hi[:, 3], mag_hi[:, 4]))
    rhs = inflate(mu * nT + mur * nR, 6)
    lhs = down(down(uc_lo[:, 0] - rad[:, 0]) * (1 - 4 * 2.0 ** -53))
    return lhs > rhs


def r_bound(problem, exact, mass, u_p, u_radius, point_r, Hr_p, g, eps, r, stored: bool = False, den: int = 1):
    """Per-component bound on r − r* when r* is unique on the loaded contacts, else None
    (g = g_num / ``den``: the residual of a point moved onto a face is rational).

    ‖r_S − r*_S‖₂ ≤ ‖H_S r_S − Hr*‖₂ / σmin(H_S), tried first in the problem's units; where
    σmin(H_S) > 0 cannot be proven there (rows of H in badly scaled units), in equilibrated
    ones: with S the exact power-of-two equilibration of M (:mod:`.massbounds`) and C that of
    the columns of S H_S, |r_j − r*_j| ≤ c_j ‖S(H_S r_S − Hr*)‖₂ / σmin(S H_S C) (the same
    identity, S H_S C (C⁻¹d) = S(H_S r_S − Hr*)), and ‖S M(v − v*)‖₂ ≤ √λmax(S M_s S)·ε."""
    n = problem.n_contacts
    mu, mur = problem.mu, problem.mu_r
    open_ = proven_open(u_p, u_radius, mu, mur, n)
    S = np.flatnonzero(~open_)
    terms = {"contacts_proven_open": int(open_.sum()), "contacts_possibly_loaded": int(S.size)}
    kept = [np.zeros(S.size, dtype=bool) + True, mu[S] > 0, mu[S] > 0, mur[S] > 0, mur[S] > 0]
    cols = np.concatenate([SPACEDIM * S[kept[k]] + k for k in range(SPACEDIM)]) if S.size else np.zeros(0, dtype=np.int64)
    cols = np.sort(cols)
    m = problem.n_dofs
    if cols.size > m:
        return None, (f"H has {cols.size} columns on the {S.size} possibly loaded contacts and only {m} rows: "
                      "r may not be unique (hyperstatic), Hr is"), terms
    e = np.abs(r).astype(np.float64)  # off S (and dropped components): r* = 0 there
    r_S = np.zeros_like(r)
    r_S[cols] = r[cols]
    d = exact.H.matvec(Dyadic.from_float(r_S)) - Hr_p
    if cols.size == 0:
        e_S, total = None, 0.0
    else:
        e_S, total, why = r_bound_in(problem, exact, mass, cols, d, g, eps, stored, terms, scaled=False, den=den)
        if why:
            e_S, total, why_s = r_bound_in(problem, exact, mass, cols, d, g, eps, stored, terms, scaled=True, den=den)
            if why_s:
                return None, (f"full column rank of H on the {S.size} possibly loaded contacts not proven ({why}; "
                              f"with rows and columns equilibrated: {why_s}): r may not be unique, Hr is"), terms
    if e_S is not None:
        e[cols] = e_S
    terms["r_residual_2norm"] = total
    note = (f"unique: {int(open_.sum())} contacts proven open (r* = 0), H of full column rank on the other "
            f"{S.size}")
    return e, note, terms


def r_bound_in(problem, exact, mass, cols, d: Dyadic, g: Dyadic, eps, stored: bool, terms: dict, scaled: bool,
                den: int = 1):
    """(bounds on |r_j − r*_j| for j in cols, the residual norm bound, "") or (None, nan, why),
    in the problem's units or (``scaled``) in equilibrated ones (:func:`r_bound`)."""
    from ..model.definiteness import equilibration_exponents, ldexp_up, scale_rows, scale_symmetric

    HS = sp.csc_matrix(problem.H[:, cols])
    if scaled:
        rows, bad = scale_rows(HS, mass.exponents)
        if bad.any():
            return None, math.nan, "the row scaling underflows"
        HS = rows.tocsc()
        col_e = equilibration_exponents(np.asarray(HS.multiply(HS).sum(axis=0)).ravel())
        HS_c = sp.csc_matrix((np.ldexp(HS.data, np.repeat(col_e, np.diff(HS.indptr))), HS.indices, HS.indptr),
                             shape=HS.shape)
        if not np.array_equal(np.ldexp(HS_c.data, -np.repeat(col_e, np.diff(HS.indptr))), HS.data):
            return None, math.nan, "the column scaling underflows"
        HS = HS_c
    A = (HS.T @ HS).tocsc()
    absHS = abs(HS)
    kmax = int(np.max(np.diff(HS.indptr), initial=1))
    A_err = (absHS.T @ absHS) * gamma(kmax + 2)
    lam, why = verify_lambda_min_sparse(A, A_err)
    terms["sigma_min_HS_sq_lower" + ("_equilibrated" if scaled else "")] = lam
    if why:
        return None, math.nan, why
    if scaled:
        two_e = Dyadic.from_float(np.ldexp(1.0, mass.exponents))
        d, g = d * two_e, g * two_e
        # ‖S M d‖₂ ≤ √λmax(S M_s S)·ε (row sums of |S M_s S|), plus ‖S K S‖₂ ε/√λmin(S M_s S) for
        # the skew part K of a stored M (the M_s-norm of v − v* is the 2-norm of S⁻¹(v − v*) in S M_s S)
        SMS, under = scale_symmetric(problem.M_sym, mass.exponents)
        absS = abs(SMS)
        absS.data = absS.data + np.where(under, ETA, 0.0)
        k = int(np.max(np.diff(SMS.indptr), initial=1)) + 2
        lam_max = float(inflate(np.max(np.asarray(absS.sum(axis=1)).ravel(), initial=0.0) * (1 + 4 * 2.0 ** -53), k))
        gain = float(up(math.sqrt(lam_max)))
        if stored:
            Mr = sp.csr_matrix(problem.M)
            K, under_k = scale_symmetric((Mr - Mr.T) * 0.5, mass.exponents)
            K.data = up(np.abs(K.data) * (1 + 2.0 ** -52)) + np.where(under_k, ETA, 0.0)
            kk = int(np.max(np.diff(K.indptr), initial=1)) + 2
            rsum = float(np.max(inflate(np.asarray(K.sum(axis=1)).ravel(), kk), initial=0.0))
            csum = float(np.max(inflate(np.asarray(K.sum(axis=0)).ravel(), kk), initial=0.0))
            skew = float(up(math.sqrt(float(up(rsum * csum)))))
            lam_min = float(np.nanmin(mass.lam_scaled))
            gain = float(up(gain + float(up(skew / float(down(math.sqrt(lam_min) * (1 - 4 * 2.0 ** -53)))))))
    else:
        # ‖M d‖₂ ≤ √λmax(M_s)·ε, plus ‖A‖₂‖d‖₂ ≤ ‖A‖₂ ε/√λmin(M_s) for the skew part A of a stored M
        gain = float(up(math.sqrt(mass.lam_max_upper)))
        if stored:
            lam_min = float(np.nanmin(mass.lam_lower))
            gain = float(up(gain + float(up(exact.skew_norm_upper() / float(down(math.sqrt(lam_min)
                                                                                      * (1 - 4 * 2.0 ** -53)))))))
    # ‖H_S r_S − Hr*‖₂ ≤ ‖H_S r_S − H r_p‖₂ + ‖g‖₂ + gain·ε (each scaled by S in equilibrated units)
    dist = sqrt_upper(d.square().total())
    gnorm = sqrt_upper(g.square().total() / (den * den))  # g = g_num / den
    if dist == 0 and gnorm == 0 and eps == 0:  # an exact point, the returned r on it: H_S r_S = Hr*
        return np.zeros(cols.size), 0.0, ""
    total = float(up(up(dist + gnorm) + up(gain * eps)))
    total = float(up(total + float(up(gain * 4 * 2.0 ** -53 * eps))))
    e_S = float(up(total / float(down(math.sqrt(lam) * (1 - 4 * 2.0 ** -53)))))
    if scaled:
        return ldexp_up(np.full(cols.size, e_S), col_e), total, ""
    return np.full(cols.size, e_S), total, ""
