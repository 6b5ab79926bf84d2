"""Exact changes of units by powers of two, for data at the ends of the float64 range.

The problem class is invariant under exact power-of-two scalings: with

    M ← 2^a M,  H ← 2^b H,  f ← 2^(a+k) f,  w ← 2^(b+k) w

(μ and μr unchanged) the solution maps to v ← 2^k v, r ← 2^(a+k−b) r, u ← 2^(b+k) u, Hr ←
2^(a+k) Hr, and every relative quantity (digits, the criterion) is unchanged.  Multiplying a
float64 by a power of two is exact unless the result leaves the range (overflow, or a
subnormal that loses bits), which :func:`binary_scaling` checks entry by entry.

A problem whose largest entries of M, of the lifted H̃ = P Hᵀ (μ and μr included) or of f and
w̃ = P w lie beyond 2^±:data:`SAFE_EXPONENT` is solved and proven in scaled units, where the
solver's squares and the proof's verified floating point neither overflow nor underflow, and
the answers are scaled back exactly.  Where no exact scaling brings the data into that range,
the problem is refused (:class:`rfverify.errors.InvalidProblemError`, exit 2) naming the field
and the range of its entries.

The same exact change of units also brings grossly mismatched units back to 1: where the scale
of the velocities or of the reactions, estimated from the data's largest entries, lies beyond
2^±:data:`UNIT_EXPONENT`, it is moved to about 1 (:func:`_unit_shift`).  The interior-point
start (v = 0, r̃_N = 1, z = e) has no units, so an equivalent problem in other units cost about
one iteration per factor 2 and failed from about 2^20: the bundled Chute with its forces in
units 2^20 smaller (M and f ×2^20) ended InsufficientProgress at 6.9e-06.  Problems inside both
ranges are never touched: their answers stay bit for bit the same.

A local problem (u = W r + q) has a = 0: W ← 2^(2b) W with its lifting's H ← 2^b H where W's
largest entries lie beyond the safe range and every entry survives exactly (else b = 0), and
q ← 2^(b+k) q; r ← 2^(k−b) r, u ← 2^(b+k) u.
Scaling q alone left a W of 2^830 beside reactions of 2^-841, where the double solve failed.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidProblemError
from .problem import SPACEDIM, Problem

SAFE_EXPONENT = 200
"""Data whose largest magnitudes lie within 2^±200 (≈ 1e±60) are used as they are: squares and
products of a few such numbers stay far inside float64's range (2^±1022)."""


UNIT_EXPONENT = 16
"""Velocity and reaction scales (estimated as powers of two) within 2^±16 of 1 are used as
they are; beyond, they are moved to about 1 (measured on the Chute: +5 iterations at 2^±10,
+14 at 2^±20 on velocities, failures from 2^20 on reactions)."""


def _unit_shift(e_M, e_H, e_f, e_w) -> tuple[int, int]:
    """(Δa, Δk) bringing the estimated scales of u and r to about 2^0, or (0, 0) where both lie
    within 2^±UNIT_EXPONENT: u ~ HᵀM⁻¹f + w ≈ 2^max(e_H + e_f − e_M, e_w), r ~ f/H ≈ 2^(e_f − e_H)
    (with f = 0, u/W ≈ 2^(e_u − 2e_H + e_M)).  Exponents of largest entries: a change of units
    by 2^j moves each estimate by j exactly, so every unit variant of a problem gets the same
    scaled problem."""
    if e_M is None or e_H is None or (e_f is None and e_w is None):
        return 0, 0
    e_u = max(e for e in ((None if e_f is None else e_H + e_f - e_M), e_w) if e is not None)
    e_r = e_f - e_H if e_f is not None else e_u - 2 * e_H + e_M
    if max(abs(e_u), abs(e_r)) <= UNIT_EXPONENT:
        return 0, 0
    return e_u - e_r, -e_u  # r ← 2^(Δa + Δk) r, u ← 2^Δk u


def _max_exponent(values) -> int | None:
    """e with 2^(e−1) ≤ max|x| < 2^e (frexp's exponent), None when every entry is 0."""
    x = np.asarray(values, dtype=np.float64)
    big = float(np.max(np.abs(x), initial=0.0))
    return None if big == 0 else math.frexp(big)[1]


def _lifted_exponent(values, per_component) -> int | None:
    """frexp exponent of max_j |x_j|·P_j without forming the products (which may overflow):
    ``values`` (…, 5n) columns or entries, ``per_component`` the exponent of P_j per entry."""
    x = np.abs(np.asarray(values, dtype=np.float64))
    nz = x > 0
    if not np.any(nz):
        return None
    return int(np.max(np.frexp(x[nz])[1] + per_component[nz]))


@dataclass(frozen=True)
class BinaryScaling:
    """M ← 2^a M, H ← 2^b H, v ← 2^k v (the rest follows, module docstring).  ``exponent(name)``
    gives the power of two of each quantity ("M", "H", "f", "w", "v", "u", "Hr", "r")."""

    a: int
    b: int
    k: int

    def exponent(self, name: str) -> int:
        a, b, k = self.a, self.b, self.k
        return {"M": a, "H": b, "W": a + 2 * b, "f": a + k, "Hr": a + k, "w": b + k, "q": b + k, "u": b + k, "v": k,
                "r": a + k - b}[name]

    def as_dict(self) -> dict:
        return {name: self.exponent(name) for name in ("M", "H", "f", "w", "v", "u", "Hr", "r")}

    def describe(self, what: str = "solved and proven") -> str:
        e = self.as_dict()
        return (f"{what} in units scaled by exact powers of two (M·2^{e['M']}, H·2^{e['H']}, "
                f"f·2^{e['f']}, w·2^{e['w']}; answers scaled back)")

    # ---- vectors
    def scale(self, name: str, x, inverse: bool = False) -> np.ndarray | None:
        """x·2^e (x·2^−e with ``inverse``) if that is exact for every entry, else None."""
        if x is None:
            return None
        x = np.asarray(x, dtype=np.float64)
        e = -self.exponent(name) if inverse else self.exponent(name)
        with np.errstate(all="ignore"):  # an entry that leaves the range is reported as None, not warned about
            y = np.ldexp(x, e)
        return y if exact_ldexp(x, y, e) else None

    def back(self, name: str, x) -> np.ndarray:
        """x·2^−e in float64 as it rounds: the one way an answer in scaled units returns to the
        problem's (an entry rounded to a subnormal loses bits, one too large becomes ±inf)."""
        with np.errstate(all="ignore"):
            return np.ldexp(np.asarray(x, dtype=np.float64), -self.exponent(name))

    def scale_bound_back(self, name: str, bound: float, up: bool = True) -> float:
        """A bound in scaled units back in the problem's units, rounded outwards (a bound that
        underflows becomes the smallest subnormal, never 0 unless it was 0)."""
        if not math.isfinite(bound) or bound == 0:
            return bound
        y = math.ldexp(bound, -self.exponent(name))
        if y == 0:
            return math.ulp(0.0) if up else 0.0
        if up and math.ldexp(y, self.exponent(name)) < bound:
            y = math.nextafter(y, math.inf)
        if not up and math.ldexp(y, self.exponent(name)) > bound:
            y = math.nextafter(y, 0.0)
        return y


def in_scaled_units(problem: Problem, run, unscale):
    """The one wrapper of every entry point (:func:`rfverify.solve`,
    :func:`rfverify.solve_to_digits`, :func:`rfverify.certify`) for data beyond float64's safe
    range.  None when ``problem``'s data lie inside it (the caller goes on as it is: its answers
    stay bit for bit the same); else the whole run in units scaled by exact powers of two,
    ``run(scaled_problem, scaling)``, and its answer in the problem's units,
    ``unscale(answer, scaled_problem, scaling)``.  ``run`` may decline by returning None (a
    candidate that does not scale exactly): the result is then None too."""
    scaling = binary_scaling(problem)
    if scaling is None:
        return None
    scaled = scaled_problem(problem, scaling)
    out = run(scaled, scaling)
    return None if out is None else unscale(out, scaled, scaling)


def exact_ldexp(x: np.ndarray, y: np.ndarray, e: int) -> bool:
    """True when y = x·2^e holds exactly for every entry (finite and reversible)."""
    return bool(np.all(np.isfinite(y)) and np.array_equal(np.ldexp(y, -e), x))


def binary_scaling(problem: Problem) -> BinaryScaling | None:
    """The exact scaling that brings the problem's largest data into 2^±SAFE_EXPONENT, or None
    when they already are there (the problem is then used as it is).  Raises
    :class:`InvalidProblemError` naming the field when the data need scaling and no exact one
    keeps every entry representable."""
    n = problem.n_contacts
    mu_e = np.zeros((n, SPACEDIM), dtype=np.int64)
    with np.errstate(all="ignore"):
        mu_e[:, 1:3] = np.where(problem.mu > 0, np.frexp(problem.mu)[1] - 1, 0)[:, None]
        mu_e[:, 3:5] = np.where(problem.mu_r > 0, np.frexp(problem.mu_r)[1] - 1, 0)[:, None]
    P_e = mu_e.ravel()
    local = problem.local is not None
    if local:
        a, b = 0, 0
        W_data = sp.coo_matrix(problem.local.W).data
        e_W = _max_exponent(W_data)
        if e_W is not None and abs(e_W + int(P_e.max(initial=0))) > SAFE_EXPONENT:  # W ← 2^(2b) W, H ← 2^b H
            b = -((e_W + int(P_e.max(initial=0))) // 2)
            trial = BinaryScaling(0, b, 0)
            if trial.scale("W", W_data) is None or trial.scale("H", problem.H.data) is None:
                b = 0  # W's small entries would not survive: q alone, as before W was scaled
        e_q = _lifted_exponent(problem.local.q, P_e)
        e_fw = None if e_q is None else e_q + b
    else:
        e_M = _max_exponent(problem.M.data)
        Hc = sp.coo_matrix(problem.H)
        e_H = _lifted_exponent(Hc.data, P_e[Hc.col])
        e_f = _max_exponent(problem.f)
        e_w = _lifted_exponent(problem.w, P_e)
        a = -e_M if e_M is not None and abs(e_M) > SAFE_EXPONENT else 0
        b = -e_H if e_H is not None and abs(e_H) > SAFE_EXPONENT else 0
        cands = [e for e in ((None if e_f is None else e_f + a), (None if e_w is None else e_w + b)) if e is not None]
        e_fw = max(cands) if cands else None
    k = -e_fw if e_fw is not None and abs(e_fw) > SAFE_EXPONENT else 0
    fields = [("q", problem.local.q), ("W", W_data), ("H", problem.H.data),
              ("w", problem.w)] if local else [("M", problem.M.data), ("H", problem.H.data),
                                               ("f", problem.f), ("w", problem.w)]
    if not local:  # grossly mismatched units too, where the result stays exact and in the safe range
        shifted = lambda e, d: None if e is None else e + d  # noqa: E731
        da, dk = _unit_shift(shifted(e_M, a), shifted(e_H, b), shifted(e_f, a + k), shifted(e_w, b + k))
        units = BinaryScaling(a + da, b, k + dk)
        if (da or dk) and _in_safe_range(units, e_M, e_H, e_f, e_w) and \
                all(units.scale(name, values) is not None for name, values in fields):
            return units  # every entry checked exact just now
    if a == b == k == 0:
        return None
    scaling = BinaryScaling(a, b, k)
    for name, values in fields:
        if scaling.scale(name, values) is None:
            x = np.abs(np.asarray(values, dtype=np.float64))
            nz = x[x > 0]
            raise InvalidProblemError(
                name, f"entries span {nz.min():.3g} … {nz.max():.3g}: the data lie beyond float64's safe range "
                      f"(2^±{SAFE_EXPONENT} after μ and μr multiply H and w), and no exact power-of-two change of "
                      f"units (here {name}·2^{scaling.exponent(name)}) keeps every entry representable",
                fix="express the problem in units where its data span less of the float64 range (the smallest "
                    "entries here would underflow)")
    return scaling


def _in_safe_range(scaling: BinaryScaling, e_M, e_H, e_f, e_w) -> bool:
    """Whether the largest entries of M, H̃, f and w̃ stay within 2^±SAFE_EXPONENT scaled."""
    return all(e is None or abs(e + scaling.exponent(name)) <= SAFE_EXPONENT
               for name, e in (("M", e_M), ("H", e_H), ("f", e_f), ("w", e_w)))


def scaled_problem(problem: Problem, scaling: BinaryScaling) -> Problem:
    """The problem in scaled units (exactly; equations, provenance and title kept)."""
    if problem.local is not None:
        q = scaling.scale("q", problem.local.q)
        w = scaling.scale("w", problem.w)
        H = sp.csc_matrix(problem.H, copy=True)
        H.data = scaling.scale("H", H.data)
        W = sp.csr_matrix(problem.local.W, copy=True)
        W.data = scaling.scale("W", W.data)
        out = Problem.from_arrays(problem.M, H, problem.f, w, problem.mu, problem.mu_r,
                                  title=problem.title, max_asymmetry=np.inf, source=problem.source,
                                  provenance=problem.provenance)
        local = dataclasses.replace(problem.local, W=W, q=q)
        out = dataclasses.replace(out, local=local, equations=problem.equations)
    else:
        M = sp.csc_matrix(problem.M, copy=True)
        M.data = scaling.scale("M", M.data)
        H = sp.csc_matrix(problem.H, copy=True)
        H.data = scaling.scale("H", H.data)
        out = Problem.from_arrays(M, H, scaling.scale("f", problem.f), scaling.scale("w", problem.w), problem.mu,
                                  problem.mu_r, title=problem.title, max_asymmetry=np.inf, source=problem.source,
                                  provenance=problem.provenance)
        out = out.stored_equations(problem.equations == "stored")
    return out


CONTACT_UNIT_EXPONENT = 8
"""Contacts whose reactions are in units more than 2^8 from the median contact's are brought
back to it.  A contact's unit is read from the largest entry of its normal column of H (a unit
vector, with lever arms, in a problem built from contact frames: within a factor of 2 or 4 of
the median on every scene generated or shipped); a user who measures one contact's reactions
in units 2^e smaller multiplies its five columns of H and its rows of w by 2^e.  The problem is
the same, but the interior-point start (r̃_N = 1 at every contact) is not: the double solve of a
1355-contact Chute ended InsufficientProgress at 5e-5 with per-contact units spread over 2^±12
(Solved, and proven to 10 digits, with the units brought back)."""


@dataclass(frozen=True)
class ContactUnits:
    """Per-contact exact changes of units: contact c's five columns of H and its five rows of w
    multiplied by 2^e_c (``exponents``, (n,)), so that r_c ← 2^−e_c r_c and u_c ← 2^e_c u_c;
    v, Hr, M and f are unchanged.  The same interface as :class:`BinaryScaling` for the vectors a
    point and an answer are made of (``scale``, ``back``)."""

    exponents: np.ndarray

    def _entries(self, name: str, size: int) -> np.ndarray | int:
        if name in ("v", "M", "f", "Hr"):
            return 0
        e = np.repeat(np.asarray(self.exponents, dtype=np.int64), SPACEDIM)
        if e.size != size:
            raise ValueError(f"{name} has {size} entries, the contact units are for {e.size}")
        return -e if name == "r" else e  # "u", "w", and H's columns

    def scale(self, name: str, x, inverse: bool = False) -> np.ndarray | None:
        """x in the scaled units (the problem's with ``inverse``), or None where not exact."""
        if x is None:
            return None
        x = np.asarray(x, dtype=np.float64)
        e = self._entries(name, x.shape[-1])
        e = -e if inverse else e
        with np.errstate(all="ignore"):
            y = np.ldexp(x, e)
        return y if exact_ldexp(x, y, e) else None

    def back(self, name: str, x) -> np.ndarray:
        """x in the problem's units as float64 rounds it (exact unless an entry leaves the range)."""
        x = np.asarray(x, dtype=np.float64)
        with np.errstate(all="ignore"):
            return np.ldexp(x, -self._entries(name, x.shape[-1]))

    def describe(self, proof: bool = False) -> str:
        e = np.asarray(self.exponents)
        moved = int(np.count_nonzero(e))
        return (f"{'solved and proven' if proof else 'solved'} with the reactions of {moved} of {e.size} contacts "
                f"in units moved by exact powers of two (2^{int(e.min())} … 2^{int(e.max())}) to the median "
                f"contact's; {'answers and proof' if proof else 'answers judged'} in the problem's own units")


def contact_units(problem: Problem) -> ContactUnits | None:
    """The per-contact change of units that brings every contact's reactions within
    2^±:data:`CONTACT_UNIT_EXPONENT` of the median contact's, or None where they already are
    (or the problem is local, or the change is not exact for every entry of H and w)."""
    n = problem.n_contacts
    if problem.local is not None or n < 2 or not (np.any(problem.f) or np.any(problem.w)):
        return None  # a zero-data problem is answered exactly, in any units
    if any(e is not None and abs(e) > SAFE_EXPONENT - 2 * CONTACT_UNIT_EXPONENT
           for e in map(_max_exponent, (problem.M.data, problem.H.data, problem.f, problem.w))):
        return None  # the whole problem is scaled first (binary_scaling), and its proof made in scaled units
    H = sp.csc_matrix(problem.H)
    e, loaded = normal_exponents(H, n)
    if np.count_nonzero(loaded) < 2:
        return None
    median = int(np.round(np.median(e[loaded])))
    shift = np.where(loaded, median - e, 0)
    if int(np.max(np.abs(shift))) <= CONTACT_UNIT_EXPONENT:
        return None
    units = ContactUnits(shift)
    if not exact_ldexp(H.data, columns_in_contact_units(H, shift), column_exponents(H, shift)):
        return None
    if units.scale("w", problem.w) is None:
        return None
    return units


def normal_exponents(H: sp.csc_matrix, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(e, loaded): per contact, the frexp exponent of the largest |entry| of its normal column
    of H (0 where the column is zero), and whether it has one: the contact's unit."""
    big = np.asarray(abs(H[:, SPACEDIM * np.arange(n)]).max(axis=0).todense()).ravel()
    loaded = big > 0
    return np.where(loaded, np.frexp(big)[1], 0).astype(np.int64), loaded


def column_exponents(H: sp.csc_matrix, shift) -> np.ndarray:
    """The power of two of each stored value of H when contact c's columns move by 2^shift_c."""
    return np.repeat(np.asarray(shift, dtype=np.int64), SPACEDIM)[np.repeat(np.arange(H.shape[1]), np.diff(H.indptr))]


def columns_in_contact_units(H: sp.csc_matrix, shift) -> np.ndarray:
    """H's stored values with contact c's five columns multiplied by 2^shift_c (as ldexp rounds)."""
    with np.errstate(all="ignore"):
        return np.ldexp(H.data, column_exponents(H, shift))


def problem_in_contact_units(problem: Problem, units: ContactUnits) -> Problem:
    """The problem with its contacts' reactions in the units of ``units`` (exactly)."""
    H = sp.csc_matrix(problem.H, copy=True)
    H.data = columns_in_contact_units(H, units.exponents)
    out = Problem.from_arrays(problem.M, H, problem.f, units.scale("w", problem.w), problem.mu, problem.mu_r,
                              title=problem.title, max_asymmetry=np.inf, source=problem.source,
                              provenance=problem.provenance)
    return out.stored_equations(problem.equations == "stored")


def in_contact_units(problem: Problem, run, unscale):
    """Like :func:`in_scaled_units`, for reactions in grossly mismatched units from contact to
    contact (:func:`contact_units`), and called before it (whose estimate of the problem's units
    the largest contacts would otherwise set): None where they are not; else ``run(scaled_problem,
    units)`` and its answer in the problem's units, ``unscale(answer, problem, scaled_problem,
    units)`` (the proof is made again there: relative digits depend on the units)."""
    units = contact_units(problem)
    if units is None:
        return None
    scaled = problem_in_contact_units(problem, units)
    if binary_scaling(scaled) is not None:
        # one change of units only: a run in contact units whose problem the exact binary scaling would
        # change again proves in those units, and its points fell short in the problem's own (r 9.9 for 10
        # on exact 8-contact problems at 2^±14 that the binary scaling alone proves)
        return None
    out = run(scaled, units)
    return None if out is None else unscale(out, problem, scaled, units)
