"""Algorithm 1 written once (issue 29): every precision — the double solver, the double-double
phase and the multiple-precision tail — runs :func:`rfverify.algorithm.loop.iterate`, and the
loop keeps its contract (a breakdown is the policy's verdict at its iteration, a switch of
precision keeps the judged μ, an unknown error is not swallowed)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import rfverify
from rfverify.algorithm import loop
from rfverify.algorithm.interfaces import PROMOTE, Breakdown, Policy
from rfverify.extended import ipm as dd_ipm
from rfverify.extended import wide
from rfverify.extended.data import ExtendedData
from rfverify.solver import ipm as double_ipm


def _spy(monkeypatch, module):
    """Record (space type, outcome) of every call of the loop made through ``module``."""
    calls = []
    real = module.iterate

    def spy(precision, policy, start, **kw):
        out = real(precision, policy, start, **kw)
        calls.append((type(precision.space).__name__, out))
        return out

    monkeypatch.setattr(module, "iterate", spy)
    return calls


def test_every_precision_runs_the_one_loop(monkeypatch):
    calls = {m: _spy(monkeypatch, m) for m in (double_ipm, dd_ipm, wide)}
    problem = rfverify.load("bundled:chute")
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.success
    # The double solve and the double-double phase are the loop's runs, ...
    assert [space for space, _ in calls[double_ipm]] and {s for s, _ in calls[double_ipm]} == {"_NumpySpace"}
    assert [space for space, _ in calls[dd_ipm]] == ["DDSpace"]
    dd_run = calls[dd_ipm][0][1]
    assert np.array_equal(out.extended.v.h, dd_run.iterate[0].h) and out.extended.nit == dd_run.k
    # ... and so is the multiple-precision tail, started from the double-double iterate.
    it = out.extended
    start = {"v": (it.v.h, it.v.l), "r_t": (it.r_t.h, it.r_t.l), "z": (it.z.h, it.z.l)}
    tail = wide.run(ExtendedData(problem), start, max_iter=1)
    assert [space for space, _ in calls[wide]] == ["_WideSpace"]
    assert tail.v is calls[wide][0][1].iterate[0] and tail.status == "MaxIterations" and len(tail.trace["sigma"]) == 1


# ---------------------------------------------------------------------- the loop's contract
class _Space:
    """A one-dimensional problem M = H = J = 1 in numpy (enough to reach the scaling)."""

    def __init__(self, dtype):
        one = sp.identity(1, dtype=dtype, format="csr")
        self.M = self.H = self.HT = self.J = self.JT = one
        self.f, self.w = np.ones(1, dtype=dtype), np.ones(1, dtype=dtype)
        self.tiny = 1e-300

    def velocity(self, v, r):
        return self.H @ v

    @staticmethod
    def dot(x, y):
        return float(x @ y)

    @staticmethod
    def norm2(x):
        return float(np.sqrt(np.sum(np.square(x.astype(np.float64)))))


class _RefusingCones:
    def scaling(self, z, s):
        raise Breakdown("cone 0 is not strictly interior")


class _Policy(Policy):
    gamma0 = 0.9

    def __init__(self, decisions):
        self.decisions = list(decisions)

    def observe(self, k, iterate, res, record):
        return self.decisions.pop(0) if self.decisions else None

    @staticmethod
    def breakdown(message):
        return ("NumericalError", message)


class _Promoting(loop.Precision):
    """Promotes to a longdouble space whose Jᵀ doubles r̃: the gap it computes is twice the
    judged one, so a loop that forgot the judged μ would hand the Newton solver another μ."""

    promotions = 0

    def promote(self, v, r, z):
        self.promotions += 1
        self.space = _Space(np.longdouble)
        self.space.JT = 2 * self.space.JT
        return v.astype(np.longdouble), r.astype(np.longdouble), z.astype(np.longdouble)


def _start(dtype=np.float64):
    return np.full(1, 0.5, dtype=dtype), np.full(1, 2.0, dtype=dtype), np.full(1, 3.0, dtype=dtype)


def test_a_breakdown_is_the_policys_verdict_at_its_iteration():
    out = loop.iterate(loop.Precision(_Space(np.float64), _RefusingCones(), None), _Policy([]), _start(),
                       n_contacts=1, n_cones=1, clock_origin=0.0)
    assert out.verdict == ("NumericalError", "iteration 0: cone 0 is not strictly interior")
    assert out.k == 0 and len(out.records) == 1
    # μ = zᵀs / n with s = Jᵀr̃; the paper's relative residuals of the start
    rec = out.records[0]
    assert rec["mu"] == 6.0 and rec["pinfeas"] == pytest.approx(1.5 / 3.0) and rec["dinfeas"] == pytest.approx(2.5 / 2.0)


def test_a_switch_of_precision_keeps_the_judged_mu_and_works_on_in_the_wider_one():
    seen, handed = [], []

    class Scaling:
        @staticmethod
        def describe():
            return {}

    class Cones:
        def scaling(self, z, s):
            seen.append((z.dtype, s.dtype, float(s[0])))
            return Scaling()

    class Newton:
        def update(self, scaling, k, mu):
            handed.append(mu)
            raise Breakdown("stop here")

    precision = _Promoting(_Space(np.float64), Cones(), Newton())
    out = loop.iterate(precision, _Policy([PROMOTE]), _start(), n_contacts=2, n_cones=1, clock_origin=0.0)
    assert precision.promotions == 1
    # the cones see the wider precision's s = Jᵀr̃ (doubled there), the Newton solver the judged μ
    assert seen == [(np.longdouble, np.longdouble, 4.0)] and handed == [3.0]
    assert out.records[0]["mu"] == 3.0 and out.verdict[1] == "iteration 0: stop here"


def test_an_error_the_precision_does_not_explain_is_not_swallowed():
    class Cones:
        def scaling(self, z, s):
            raise ZeroDivisionError("a bug")

    with pytest.raises(ZeroDivisionError, match="a bug"):
        loop.iterate(loop.Precision(_Space(np.float64), Cones(), None), _Policy([]), _start(), n_contacts=1,
                     n_cones=1, clock_origin=0.0)


def test_ctrl_c_is_the_policys_to_answer_and_by_default_goes_on():
    """The Policy protocol's default hook lets a KeyboardInterrupt through; a policy that keeps
    its best iterate answers it with a verdict instead (no probing for the hook)."""
    class Cones:
        def scaling(self, z, s):
            raise KeyboardInterrupt

    def run(policy):
        return loop.iterate(loop.Precision(_Space(np.float64), Cones(), None), policy, _start(), n_contacts=1,
                            n_cones=1, clock_origin=0.0)

    with pytest.raises(KeyboardInterrupt):
        run(_Policy([]))

    class Keeping(_Policy):
        def interrupted(self, k):
            return ("Stopped", f"interrupted at iteration {k}")

    assert run(Keeping([])).verdict == ("Stopped", "interrupted at iteration 0")


def test_the_reduced_newton_hooks_have_defaults_and_are_never_probed():
    """A back end that fills in no hook (the multiple-precision tail's) gets the protocol's
    defaults: nothing observed, no retry, no primal projection."""
    from rfverify.algorithm.interfaces import ReducedBackend
    from rfverify.extended.factored import FactoredBackend, NewtonBackend

    class Bare(ReducedBackend):
        name = "bare"

    bare = Bare()
    assert bare.observe(0, 1.0, None) is None and bare.retry_solve(1.0) is False and not bare.projects_primal
    assert NewtonBackend in FactoredBackend.__mro__ and FactoredBackend().retry_solve(1.0) is False
    assert dd_ipm.DDBackend.projects_primal


def test_a_stop_verdict_ends_the_run_before_any_scaling():
    class Cones:
        def scaling(self, z, s):
            raise AssertionError("no scaling after a stop")

    out = loop.iterate(loop.Precision(_Space(np.float64), Cones(), None), _Policy([("Stopped", "enough")]),
                       _start(), n_contacts=1, n_cones=1, clock_origin=0.0)
    assert out.verdict == ("Stopped", "enough") and out.k == 0


@pytest.mark.parametrize("steps_up", [0, 1, 2, 3])
def test_a_newton_solve_is_solved_again_after_each_step_up_of_its_back_end(monkeypatch, steps_up):
    """ReducedNewton.solve asks the back end again after each retry that did not settle — the
    contact-space form has two steps up (checked solves, then the double-double factor) — and
    stops at RETRIES, or as soon as a solve settles or the back end has nothing more."""
    from rfverify.algorithm.interfaces import ReducedBackend
    from rfverify.algorithm.newton import RETRIES, ReducedNewton

    class Ladder(ReducedBackend):
        name = "ladder"

        def __init__(self):
            self.asked = 0

        def retry_solve(self, residual):
            self.asked += 1
            return self.asked <= steps_up

    back = Ladder()
    newton = ReducedNewton(None, back, refine_max=3, floor=1e-30, inf=abs, enough=1e-8)
    calls = []

    def refined(self, a, b, c, enough):
        calls.append(enough)
        return 0.0, 0.0, 0.0, 1, 10.0 ** -len(calls), False  # never settles

    monkeypatch.setattr(ReducedNewton, "_refined", refined)
    d = newton.solve(1.0, 1.0, 1.0, "corrector")
    assert len(calls) == 1 + min(steps_up, RETRIES)
    assert back.asked == min(steps_up + 1, RETRIES)
    assert d.residual == 10.0 ** -len(calls) and d.steps == len(calls)
