"""The Newton driver's projection of the primal residual (ReducedNewton._project_primal): it
zeroes the primal row's error through the least-‖Q_pδ‖ δ with Jδ = −e_b (DDSpace.lift, exact in
J however ill-conditioned G is), is kept only where it lowers the larger block-relative residual,
and saves float64 solves without changing what is proven."""

from __future__ import annotations

import numpy as np
import pytest

import rfverify
from rfverify.algorithm import newton as N
from rfverify.algorithm.loop import residuals
from rfverify.verify.prepare import start_from
from rfverify.extended import dd
from rfverify.extended import ipm as X
from rfverify.extended.data import ExtendedData
from rfverify.extended.system import choose_backend
from rfverify.scenes.random_problems import random_problem


@pytest.fixture(scope="module")
def started():
    problem = random_problem(40, 90, seed=23)
    data = ExtendedData(problem)
    return data, start_from(data, rfverify.solve(problem, tol=1e-10))


def _spy(monkeypatch, kept: list, tried: list):
    real = N.ReducedNewton._project_primal

    def spy(self, b, c, dv, dr, dz):
        out = real(self, b, c, dv, dr, dz)
        tried.append(1)
        kept.append(out is not dz)
        return out

    monkeypatch.setattr(N.ReducedNewton, "_project_primal", spy)


def test_the_projection_zeroes_the_primal_row_and_keeps_the_complementarity_row_small(started):
    """One Newton solve at the start iterate: after the reduced solve the primal row's residual
    is far above η‖b‖ (the reduced right-hand side is dominated by its c part); with δ added it
    falls by orders of magnitude while the complementarity row's residual stays below η‖c‖."""
    data, start = started
    backend = choose_backend(data)
    space = X.DDSpace(data)
    newton = N.ReducedNewton(space, X.DDBackend(backend), refine_max=12, floor=1e-31, inf=X.V.inf,
                             enough=N.NEWTON_ENOUGH)
    v, r, z = (X.V(*dd.from_longdouble(start[k])) for k in ("v", "r_t", "z"))
    res = residuals(space, v, r, z, data.n)
    sc = X.DDCones(data).scaling(z, res.s)
    newton.update(sc, 0, res.mu)
    a, b, c = -res.r_d, -res.r_p, sc.affine_rhs()
    sp, q = space, sc.quad
    dv, dr = newton.backend.solve(a, b + sp.J @ q(-1, c))
    dz = q(-1, c - q(-1, sp.JT @ dr))
    projected = newton._project_primal(b, c, dv, dr, dz)
    assert projected is not dz and newton.projections == 1

    def rows(dz_):
        e = newton._unreduced_residual(a, b, c, dv, dr, dz_)
        return e[1].inf() / b.inf(), e[2].inf() / c.inf()

    (pb0, pc0), (pb1, pc1) = rows(dz), rows(projected)
    assert pb0 > N.NEWTON_ENOUGH  # without it the solve would need refinement
    assert pb1 < 1e-4 * pb0 and pc1 < N.NEWTON_ENOUGH, (pb0, pb1, pc0, pc1)  # both within η now


def test_a_projection_that_would_not_help_is_dropped(started, monkeypatch):
    """With the lift off by a factor of 1000 the step δ overshoots the primal row a thousandfold:
    it must be dropped every time, and the run must end as it does without any projection."""
    data, start = started
    kept, tried = [], []
    _spy(monkeypatch, kept, tried)
    real = X.DDSpace.lift
    monkeypatch.setattr(X.DDSpace, "lift", lambda self, e, scaling: real(self, e, scaling).scaled(1000.0))
    off = X.run(data, start, max_iter=8, backend=choose_backend(data))
    assert tried and not any(kept)
    monkeypatch.setattr(N.ReducedNewton, "_project_primal", lambda self, b, c, dv, dr, dz: dz)
    none = X.run(data, start, max_iter=8, backend=choose_backend(data))
    for key in ("v", "r_t", "z"):
        assert np.array_equal(getattr(off, key).h, getattr(none, key).h)
        assert np.array_equal(getattr(off, key).l, getattr(none, key).l)


def test_the_projection_saves_float64_solves_and_changes_no_proven_digit(monkeypatch):
    """The 10-digit path with and without the projection on a random problem it was not tuned
    on: the same iterations and proven digits (to 0.05), fewer float64 solves with it."""
    problem = random_problem(60, 150, seed=31)
    kept, tried = [], []
    _spy(monkeypatch, kept, tried)
    with_it = rfverify.solve_to_digits(problem, digits=10)
    assert with_it.certificate.certified and any(kept)
    monkeypatch.setattr(N.ReducedNewton, "_project_primal", lambda self, b, c, dv, dr, dz: dz)
    without = rfverify.solve_to_digits(problem, digits=10)
    assert without.certificate.certified and with_it.extended.nit == without.extended.nit
    for name, q in with_it.certificate.quantities.items():
        other = without.certificate.quantities[name]
        if q.digits is not None:
            assert abs(q.digits - other.digits) < 0.05, name
    assert with_it.extended.stats["solves"] < without.extended.stats["solves"]
