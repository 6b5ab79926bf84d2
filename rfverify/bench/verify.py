"""High-precision recheck of a candidate (v, u, r): the bench counts a run as solved only on
this verdict, never on the solver's word.

The measures are rfverify's one definition (:mod:`rfverify.model.measures`: dynamics, velocity,
cone, complementarity, with scales that do not vanish at a correct solution), evaluated in
mpmath at ``dps`` digits from the exact double data, so no solver arithmetic and no
longdouble rounding enters the verdict.  ``max`` is the criterion: a run meets ``tol`` when
``max ≤ tol``.
"""

from __future__ import annotations

import numpy as np

from ..model.measures import CRITERION, MeasureData
from ..model.problem import SPACEDIM, Problem

MEASURES = CRITERION


class HighPrecisionChecker:
    """Converts a problem's data to mpmath once, then rechecks many candidates (e.g. every
    iterate of a trajectory).  Precision is local (``mpmath.workdps``)."""

    def __init__(self, problem: Problem, dps: int = 30):
        self.problem = problem
        self.dps = dps
        self._data = MeasureData.of(problem, int(dps))

    def criterion(self, v, u, r) -> dict:
        """The measures for one candidate (float arrays of shapes (m,), (5n,), (5n,)), as a
        dict of floats with ``max`` and ``finite``."""
        p = self.problem
        v, u, r = (np.asarray(x, dtype=np.float64) for x in (v, u, r))
        if v.shape != (p.n_dofs,) or u.shape != (SPACEDIM * p.n_contacts,) or r.shape != u.shape:
            raise ValueError(f"candidate shapes v{v.shape}, u{u.shape}, r{r.shape} do not match the "
                             f"problem (m = {p.n_dofs}, 5n = {SPACEDIM * p.n_contacts})")
        out = self._data.measures(v, u, r).as_dict()
        out["finite"] = bool(np.all(np.isfinite(v)) and np.all(np.isfinite(u)) and np.all(np.isfinite(r)))
        return out


def verified_criterion(problem: Problem, v, u, r, dps: int = 30) -> dict:
    """One-off :meth:`HighPrecisionChecker.criterion`."""
    return HighPrecisionChecker(problem, dps).criterion(v, u, r)


def forward_digits(x, x_ref, *scale_terms) -> float:
    """Correct significant digits of ``x`` against ``x_ref``: −log10(‖x − x_ref‖∞ / scale),
    scale = max(‖x_ref‖∞, ‖terms‖∞) (see :mod:`rfverify.verify.certification` for why u and Hr need
    the terms they are computed from).  inf when identical, 0 when no digit is right."""
    x = np.asarray(x, dtype=np.float64)
    x_ref = np.asarray(x_ref, dtype=np.float64)
    if not np.all(np.isfinite(x)):
        return 0.0
    scale = max([np.max(np.abs(x_ref), initial=0.0)] + [np.max(np.abs(t), initial=0.0) for t in scale_terms])
    err = np.max(np.abs(x - x_ref), initial=0.0)
    if err == 0:
        return float("inf")
    if scale == 0:
        return 0.0
    return float(max(0.0, -np.log10(err / scale)))
