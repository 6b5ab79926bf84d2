"""The proven backward error of an answer to the physical problem (issue 51, DESIGN §1).

Let ŝ be the shift the answer was solved with, exactly as applied: ŝ_i = w'_N,i − w_N,i (q for
a local file), w' the float64 data of the shifted problem; (v*, u'*, r*) the exact solution of
that convex problem, u* = u'* − ŝ e_N.  As Φ reads only u_T and u_R, which the shift leaves
alone, (v*, r*) solves the physical problem *exactly* for the data with w_N + δ,

    δ_i = ŝ_i − Φ_i(u*),    |δ_i| ≤ |ŝ_i − Φ_i(û)| + μ_i‖û_T − u*_T‖ + μr_i‖û_R − u*_R‖

(û the returned u' of the shifted problem; the reverse triangle inequality), and the inner
proof bounds ‖û − u'*‖∞ ≤ e_u, so ‖û_T − u*_T‖₂ ≤ √2·e_u.  The first term is evaluated from the
float64 numbers with every operation rounded outward (``np.nextafter`` after each correctly
rounded IEEE operation, as :mod:`rfverify.proof.bound` does), so the bound is rigorous.

On a contact proven *open* δ_i = 0 is taken instead: where the box û_i ± e_u lies inside
int K*_i, every solution has r*_i = 0 (complementarity with u'*_i interior), and where moreover
u*_N,i = u'*_N,i − ŝ_i ≥ 0 is proven, contact i meets the physical conditions (r_i ∈ K,
u_N + Φ_i ≥ Φ_i, i.e. ũ_i ∈ K*, and r_iᵀũ_i = 0) for the file's own data, whatever ŝ_i is.  A
slowly drifting shift on a contact that carries nothing (a sphere in flight beside a pile whose
Φ changes with the others' shifts) is then no backward error at all.

The physical u = Hᵀv + w of the returned v (W r + q) differs from û − ŝ e_N by an exactly
computed amount (dyadic rationals), so its distance to u* is bounded by that plus e_u.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..model.problem import SPACEDIM, Problem
from ..proof.quantity import DATA_SCALE_NAMES, DATA_SCALE_NAMES_LOCAL, QuantityBound
from ..proof.quantity import quantity_bound as quantity_record
from ..model.directed import bound_text
from ..proof.dyadic import Dyadic
from .model import offsets

SQRT2_UP = float(np.nextafter(math.sqrt(2.0), np.inf))


def _up(x):
    return np.nextafter(np.asarray(x, dtype=np.float64), np.inf)


def _down(x):
    return np.nextafter(np.asarray(x, dtype=np.float64), -np.inf)


@dataclass
class BackwardError:
    """The proven bound on the data change δ (n,) for which the answer's exact companion
    (v*, r*) solves the physical problem exactly (module docstring).

    ``delta`` per contact, ≥ |δ_i| (rigorous, rounded up; inf where nothing is proven);
    ``absolute`` = max_i; ``relative`` = absolute / ``scale`` (rounded up), ``scale`` the proven
    lower bound of the data scale of u (``scale_name``); ``fixed_point_part`` max_i of the
    bound on |ŝ_i − Φ_i(û)|, ``proof_part`` max_i of μ_i√2e_u + μr_i√2e_u; ``proven`` False when
    the inner proof gave no finite bound on u (``note`` says why)."""

    delta: np.ndarray
    absolute: float
    relative: float
    scale: float
    scale_name: str
    fixed_point_part: float
    proof_part: float
    proven: bool
    note: str = ""
    psd_part: float = 0.0
    """max_i of D_max·‖r*_i‖∞ where the local W was shifted to W + D (``--psd-shift``): the solution
    of W + D with data q solves the file's W with q + D r*, so that change is part of δ; else 0."""
    open_contacts: int = 0
    """Contacts proven open with u*_N ≥ 0, where δ_i = 0 (module docstring); the parts above are
    maxima over the others."""

    def describe(self) -> str:
        if not self.proven:
            return f"backward error not proven ({self.note})"
        psd = f", W's diagonal shift D r* {self.psd_part:.1e}" if self.psd_part else ""
        opened = (f"; δ = 0 on {self.open_contacts} contact(s) proven open, where the shift is immaterial"
                  if self.open_contacts else "")
        return (f"backward error |δ| ≤ {bound_text(self.absolute)} (relative {bound_text(self.relative, 1)} of the "
                f"data scale "
                f"{self.scale_name} = {self.scale:.2e}; largest parts over the contacts: fixed point "
                f"{self.fixed_point_part:.1e}, inner proof "
                f"{self.proof_part:.1e}{psd}{opened})")

    def as_dict(self) -> dict:
        return {"absolute": self.absolute, "relative": self.relative, "scale": self.scale,
                "scale_name": self.scale_name, "fixed_point_part": self.fixed_point_part,
                "proof_part": self.proof_part, "psd_part": self.psd_part, "open_contacts": self.open_contacts,
                "proven": self.proven, "note": self.note,
                "worst_contact": int(np.argmax(self.delta)) if self.delta.size else None}


TINY = 5e-324  # the smallest subnormal: the most a part scaled into the subnormals is rounded by
SMALLEST_NORMAL = 2.2250738585072014e-308


def _norm_bounds(a, b):
    """Lower and upper bounds of √(a² + b²), elementwise, from float64 a, b.  The squares are
    formed in units of the power of two of max(|a|, |b|), so that they neither overflow (|a| up
    to float64's largest) nor vanish; exactly 0 where a = b = 0."""
    a, b = np.abs(np.asarray(a, dtype=np.float64)), np.abs(np.asarray(b, dtype=np.float64))
    _, k = np.frexp(np.maximum(a, b))  # max(|a|, |b|) = f·2^k with f in [0.5, 1) (k = 0 for 0)
    A, B = np.ldexp(a, -k), np.ldexp(b, -k)  # exact, but where a part lands in the subnormals

    def widened(x):  # (lower, upper) bounds of the exact scaled part
        sub = x < SMALLEST_NORMAL
        return np.where(sub, np.maximum(x - TINY, 0.0), x), np.where(sub, x + TINY, x)

    (A_lo, A_hi), (B_lo, B_hi) = widened(A), widened(B)
    hi = _up(np.sqrt(_up(_up(A_hi * A_hi) + _up(B_hi * B_hi))))
    lo = _down(np.sqrt(np.maximum(_down(_down(A_lo * A_lo) + _down(B_lo * B_lo)), 0.0)))
    with np.errstate(over="ignore", under="ignore"):  # inf is an upper bound; a subnormal result rounds
        hi, lo = _up(np.ldexp(hi, k)), _down(np.ldexp(np.maximum(lo, 0.0), k))
    zero = (a == 0) & (b == 0)
    return np.where(zero, 0.0, np.maximum(lo, 0.0)), np.where(zero, 0.0, hi)


def phi_bounds(problem: Problem, u) -> tuple[np.ndarray, np.ndarray]:
    """Rigorous (lower, upper) bounds of Φ_i(u) = μ_i‖u_T‖ + μr_i‖u_R‖ for a float64 u (5n,);
    exactly 0 where both terms are (a zero coefficient or a zero part)."""
    U = np.asarray(u, dtype=np.float64).reshape(-1, SPACEDIM)
    mu, mur = np.asarray(problem.mu, dtype=np.float64), np.asarray(problem.mu_r, dtype=np.float64)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        t_lo, t_hi = _norm_bounds(U[:, 1], U[:, 2])
        r_lo, r_hi = _norm_bounds(U[:, 3], U[:, 4])
        lo = _down(_down(mu * t_lo) + _down(mur * r_lo))
        hi = _up(_up(mu * t_hi) + _up(mur * r_hi))
    zero = ((mu == 0) | (t_hi == 0)) & ((mur == 0) | (r_hi == 0))
    return np.where(zero, 0.0, np.maximum(lo, 0.0)), np.where(zero, 0.0, hi)


def _difference_bounds(x, y):
    """(lower, upper) bounds of x − y elementwise, exact where float64's x − y is: the rounding
    error of the difference (TwoSum, Knuth) says which way, if any, it was rounded."""
    x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow gives ±inf, an outward bound
        d = x - y
        z = d - x
        err = (x - (d - z)) + (-y - z)  # x − y = d + err exactly (no overflow)
        finite = np.isfinite(err)
        return (np.where(finite & (err >= 0), d, _down(d)), np.where(finite & (err <= 0), d, _up(d)))


def backward_bound(problem: Problem, shifted: Problem, u_inner, e_u: float, scale: float,
                   scale_name: str, *, diag_shift: float = 0.0, r_upper=None) -> BackwardError:
    """The :class:`BackwardError` of the answer whose shifted u is ``u_inner`` (5n,), with
    ``e_u`` ≥ ‖u_inner − u'*‖∞ from the inner proof and ``scale`` a proven lower bound of the
    data scale of u.  ``diag_shift`` ≥ max_k D_kk where the local W was shifted to W + D, with
    ``r_upper`` (n,) ≥ ‖r*_i‖∞ per contact: each contact's data change then also holds D r*_i."""
    n = problem.n_contacts
    if not (e_u >= 0 and math.isfinite(e_u)) or not np.all(np.isfinite(u_inner)):
        inf = np.full(n, math.inf)
        return BackwardError(inf, math.inf, math.inf, scale, scale_name, math.inf, math.inf, False,
                             "the inner proof gives no finite bound on u")
    a = offsets(shifted)[0::SPACEDIM]
    b = offsets(problem)[0::SPACEDIM]
    with np.errstate(over="ignore"):
        s_lo, s_hi = _difference_bounds(a, b)  # ŝ = a − b exactly lies between
        p_lo, p_hi = phi_bounds(problem, u_inner)
        fixed = np.maximum(np.maximum(_difference_bounds(s_hi, p_lo)[1], _difference_bounds(p_hi, s_lo)[1]), 0.0)
        e_vec = _up(SQRT2_UP * e_u)
        lip = _up(_up(problem.mu * e_vec) + _up(problem.mu_r * e_vec)) if e_u > 0 else np.zeros(n)
        lip = np.where((problem.mu == 0) & (problem.mu_r == 0), 0.0, lip)  # Φ is then 0 whatever u is
        delta = np.where((fixed == 0) | (lip == 0), fixed + lip, _up(fixed + lip))  # (exact where a term is 0)
        psd = np.zeros(n)
        if diag_shift:
            psd = np.full(n, math.inf) if r_upper is None else _up(diag_shift * np.asarray(r_upper, dtype=np.float64))
            delta = _up(delta + psd)
        opened = proven_open_and_apart(problem, u_inner, e_u, s_hi)
        fixed, lip, psd, delta = (np.where(opened, 0.0, x) for x in (fixed, lip, psd, delta))
    absolute = float(np.max(delta, initial=0.0))
    if absolute == 0:
        relative = 0.0
    elif scale > 0:
        relative = float(_up(absolute / scale))
    else:
        relative = math.inf
    proven = bool(np.all(np.isfinite(delta)))
    return BackwardError(delta, absolute, relative, scale, scale_name, float(np.max(fixed, initial=0.0)),
                         float(np.max(lip, initial=0.0)), proven, "" if proven else "a bound overflowed (or r* is "
                         "not bounded where W was shifted)", psd_part=float(np.max(psd, initial=0.0)),
                         open_contacts=int(opened.sum()))


def proven_open_and_apart(problem: Problem, u_inner, e_u: float, s_hi) -> np.ndarray:
    """(n,) True where the box û_i ± e_u lies in int K*_i (so r*_i = 0 for every solution of the
    shifted problem) and u*_N,i = u'*_N,i − ŝ_i ≥ 0 (ŝ_i ≤ ``s_hi``): every rounding against it."""
    U = np.asarray(u_inner, dtype=np.float64).reshape(-1, SPACEDIM)
    e2 = _up(SQRT2_UP * e_u)
    with np.errstate(over="ignore", invalid="ignore"):
        t_hi = _up(_up(np.hypot(np.abs(U[:, 1]), np.abs(U[:, 2]))) + e2)
        r_hi = _up(_up(np.hypot(np.abs(U[:, 3]), np.abs(U[:, 4]))) + e2)
        need = _up(_up(_up(problem.mu * t_hi) + _up(problem.mu_r * r_hi)) * (1 + 4 * 2.0 ** -53))
        normal = _down(U[:, 0] - e_u)
        return (normal > need) & (_down(normal - s_hi) >= 0)


def physical_u_bound(problem: Problem, shifted: Problem, u_phys, u_inner, e_u: float) -> np.ndarray:
    """≥ |u_phys − u*| elementwise (5n,), u* = u'* − ŝ e_N the physical u of the exact companion:
    |u_phys − (u_inner − ŝ e_N)| exactly (dyadic) plus e_u, rounded up."""
    diff = (Dyadic.from_float(u_phys) - Dyadic.from_float(u_inner) + Dyadic.from_float(offsets(shifted))
            - Dyadic.from_float(offsets(problem)))
    with np.errstate(over="ignore"):
        upper = diff.abs_upper()
        return np.where((upper == 0) | (e_u == 0), upper + e_u, _up(upper + e_u))  # (exact where a term is 0)


def physical_quantities(problem: Problem, shifted: Problem, proof, u_phys, u_inner, scales: dict,
                        requested: int, relative: bool = False) -> dict:
    """The inner proof's per-quantity records with u replaced by the physical u's (its bound
    from :func:`physical_u_bound`, digits against its own proven norm or the problem's data
    scale of u); v, Hr and r are the same vectors in both problems, their records kept."""
    out = dict(proof.quantities)
    q_u = proof.quantities.get("u")
    if q_u is None:
        return out
    names = DATA_SCALE_NAMES_LOCAL if problem.local is not None else DATA_SCALE_NAMES
    if not proof.valid or not math.isfinite(q_u.abs_bound):
        out["u"] = QuantityBound("u", math.inf, float(np.max(np.abs(u_phys), initial=0.0)), 0.0, scales["u"],
                                 names["u"], None, "relative", False, "no proof")
        return out
    e = physical_u_bound(problem, shifted, u_phys, u_inner, q_u.abs_bound)
    out["u"] = quantity_record("u", e, u_phys, scales, requested, names=names, relative=relative)
    return out
