"""A local problem whose W is not positive semidefinite as stored, made provable by naming a nearby
one: W + D, D ≥ 0 diagonal (``--psd-shift``, Python :func:`shift_to_psd`).

Siconos computes a local file's W = H M⁻¹ Hᵀ in floating point, and on real piles the rounding
leaves (W + Wᵀ)/2 slightly indefinite: the 286-contact Capsules file of Siconos's test data has
an eigenvalue −4e-15 of ‖W‖ = 13, FCLIB's 48-contact Boxes Stack a 2×2 minor of −2.5e-19.  The
problem of the file is then not convex, and nothing about it can be proven.  Its nearest
provable neighbour is W' = W + D with D = diag(ε) on the rows with a nonzero diagonal (ε the
smallest power of two, from about 4·|λmin| up by factors of 2, whose W' the verified test of
:func:`rfverify.proof.local.prove_psd` proves PSD), and every claim is then about W' — named
so in the problem's statement.  A solution (u*, r*) of W' is exactly a solution of the file's
own W for the data q + D r*: the shift is a backward error of at most max_k D_kk · ‖r*‖∞ on q,
which the physical problem's certificate adds to its bound on δ.  Refused when the shift needed
is above :data:`MAX_RELATIVE` of ‖W‖ (more than rounding: the data are wrong).
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError, InvalidProblemError
from ..io.local_lift import eigenvalue_range, factor_delassus
from ..model.problem import Problem, StoredSolution, make_local_form
from ..model.directed import bound_text
from .local import prove_psd
from .massbounds import verify_mass_matrix

MAX_RELATIVE = 1e-8
"""Largest shift accepted, relative to ‖W‖: an indefiniteness above it is not rounding."""

MAX_TRIES = 40
"""Shifts tried at most (each 2× the last) before refusing."""


@dataclasses.dataclass(frozen=True)
class PsdShift:
    """What :func:`shift_to_psd` did: ``epsilon`` (the power of two added), ``largest_change``
    (≥ max_k of W'_kk − W_kk, exact differences rounded up: the rounding of W_kk + ε), the
    float64 estimates ``min_eigenvalue`` and ``norm`` of (W + Wᵀ)/2, and ``how`` W' was proven."""

    epsilon: float
    largest_change: float
    min_eigenvalue: float
    norm: float
    rows: int
    how: str

    @property
    def relative(self) -> float:
        return self.largest_change / self.norm if self.norm > 0 else math.inf

    def phrase(self) -> str:
        return (f"W + D (D ≥ 0 diagonal, ≤ {bound_text(self.largest_change)} = {bound_text(self.relative, 1)}·‖W‖ on {self.rows} rows: "
                f"W as stored is not positive semidefinite, smallest eigenvalue ≈ {self.min_eigenvalue:.1e})")

    def as_dict(self) -> dict:
        return {**dataclasses.asdict(self), "relative": self.relative}


def shift_to_psd(problem: Problem) -> Problem:
    """``problem`` with its local W replaced by W + D (module docstring), or ``problem`` itself
    when its W is proven PSD as stored.  The lifting is recomputed from W + D; the raw W and q
    (``problem.native``) are kept, so that what is written back is the file's data.  The
    provenance gets ``"psd_shift"`` (:meth:`PsdShift.as_dict`), which the statement names.

    Raises
    ------
    InvalidArgumentError
        ``problem`` is not a local problem (there is no W to shift).
    InvalidProblemError
        field ``"W"``: no shift up to :data:`MAX_RELATIVE`·‖W‖ makes it provably PSD.
    """
    if problem.local is None:
        raise InvalidArgumentError("psd_shift", "applies to a local problem (u = W r + q) only: this problem is "
                                                "global (M, H), whose M is already proven positive definite",
                                   fix="drop --psd-shift (psd_shift)")
    W = sp.csr_matrix(problem.local.W)
    if prove_psd(W).psd:
        return problem
    lam_min, lam_max = eigenvalue_range(W)
    norm = max(lam_max, abs(lam_min))
    rows = np.flatnonzero(W.diagonal() != 0)
    # From a few times the estimated λmin up, ×2 each try (D r* is a backward error: no more of it
    # than a factor 2 beyond need): the verified test proves λmin > 0 only above its own rounding
    # bound (residual and a-priori terms, a few hundred ulps of ‖W‖ on a nearly singular W).
    start = max(4.0 * abs(min(lam_min, 0.0)), 16.0 * np.finfo(float).eps * norm, np.finfo(float).tiny)
    eps = math.ldexp(1.0, math.frexp(start)[1])  # the power of two at or above the start
    for _ in range(MAX_TRIES):
        if eps > MAX_RELATIVE * norm:
            break
        shifted = (W + sp.csr_matrix((np.full(rows.size, eps), (rows, rows)), shape=W.shape)).tocsr()
        # the verified floating-point test only (fast): prove_psd's exact fallback is for singular W
        if verify_mass_matrix(shifted[rows][:, rows]).proven and (facts := prove_psd(shifted)).psd:
            return _with_shift(problem, shifted, PsdShift(eps, _largest_change(W, shifted, rows), lam_min, norm,
                                                          int(rows.size), facts.how))
        eps *= 2.0
    raise InvalidProblemError(
        "W", f"is not positive semidefinite as stored (smallest eigenvalue ≈ {lam_min:.2e} of ‖W‖ ≈ {norm:.2e}), "
             f"and no diagonal shift up to {MAX_RELATIVE:.0e}·‖W‖ is proven to make it so: more than rounding",
        fix="check the data: a Delassus matrix W = H M⁻¹ Hᵀ is positive semidefinite")


def _largest_change(W, shifted, rows) -> float:
    """max_k (W'_kk − W_kk), each difference exact (rationals) and the maximum rounded up."""
    old, new = W.diagonal()[rows], shifted.diagonal()[rows]
    worst = max((Fraction(float(b)) - Fraction(float(a)) for a, b in zip(old, new)), default=Fraction(0))
    out = float(worst)
    return out if Fraction(out) >= worst else math.nextafter(out, math.inf)


def _with_shift(problem: Problem, shifted: sp.csr_matrix, shift: PsdShift) -> Problem:
    H, _ = factor_delassus(shifted.toarray(), max_asymmetry=math.inf)
    H = sp.csc_matrix(H)
    m = H.shape[0]
    provenance = {**problem.provenance, "psd_shift": shift.as_dict()}
    out = Problem.from_arrays(sp.identity(m, format="csc"), H, np.zeros(m), problem.w, problem.mu, problem.mu_r,
                              title=problem.title, description=problem.description, math_info=problem.math_info,
                              solution=relifted(problem.solution, H), storage=dict(problem.storage),
                              guesses=tuple(relifted(g, H) for g in problem.guesses), max_asymmetry=math.inf,
                              source=problem.source, provenance=provenance)
    local = make_local_form(shifted, problem.local.q, problem.local.significant_digits)
    return dataclasses.replace(out, native=problem.native, local=local)


def relifted(solution: StoredSolution | None, H) -> StoredSolution | None:
    """A stored local solution with v recomputed as H r for the lifting H of W + D (v is no
    quantity of a local file: the lifting's own, v = H r)."""
    if solution is None:
        return None
    v = None if solution.r is None else np.asarray(H @ np.asarray(solution.r, dtype=np.float64))
    return StoredSolution(v=v, u=solution.u, r=solution.r)
