"""The proof at the predictor's point: before each corrector the k-digit path offers its proof
driver the point PREDICTED_FRACTION of the way along the predictor's direction to the cones'
boundary, and stops there when that point is proven (docs/DECISIONS.md, "A proof at the
predictor's point")."""

from __future__ import annotations

import rfverify
from rfverify.algorithm.policy import PREDICTED_FRACTION, UntilPolicy
from rfverify.extended import ipm as X
from rfverify.verify import driver as D
from rfverify.verify import extend as E


def _policy(until, make_predicted):
    return UntilPolicy(until, None, 10, lambda k, it, res: it, 0.99, "accepted", make_predicted=make_predicted)


def test_the_policy_offers_the_point_short_of_the_boundary_and_stops_only_when_accepted():
    asked = []

    def point_at(alpha):
        asked.append(alpha)
        return ("v", "r", "z"), 1e-30

    offered = []
    accept = _policy(lambda it: offered.append(it) or True, lambda k, point, mu: (k, point, mu, "predicted"))
    verdict, point = accept.after_predictor(7, 0.8, point_at)
    assert asked == [PREDICTED_FRACTION * 0.8] and 0 < PREDICTED_FRACTION < 1
    assert offered == [(7, ("v", "r", "z"), 1e-30, "predicted")] and point == ("v", "r", "z")
    assert verdict[0] == "Stopped" and "iteration 7's predictor point" in verdict[1]

    reject = _policy(lambda it: False, lambda k, point, mu: (k, point, mu))
    assert reject.after_predictor(7, 0.8, point_at) is None
    # no step at all (α_aff = 0) offers nothing
    assert reject.after_predictor(7, 0.0, point_at) is None and len(asked) == 2


def test_a_run_that_did_not_ask_for_predicted_points_never_shows_them_to_its_callback():
    """``until`` callbacks written for iterates (tests, user code) keep seeing iterates only."""
    called = []
    quiet = _policy(lambda it: called.append(it) or True, None)
    assert quiet.after_predictor(3, 0.9, lambda a: (("v", "r", "z"), 1.0)) is None and called == []

    from rfverify.extended.data import ExtendedData
    from rfverify.verify.prepare import start_from

    problem = rfverify.load("bundled:sphere")
    data = ExtendedData(problem)
    seen = []
    X.run(data, start_from(data, rfverify.solve(problem, tol=1e-10)), max_iter=4,
          until=lambda it: seen.append(it.predicted) and False)
    assert seen and not any(seen)


def _path(monkeypatch, offer: bool):
    """solve_to_digits on the bundled sphere with predicted points offered or not, and what the
    driver was called with (predicted?, its stall count and recent iterates before and after)."""
    real_run, real_call = X.run, D.ProofDriver.__call__
    calls = []

    def run(*args, **kw):
        kw["offer_predicted"] = offer and kw.get("offer_predicted", False)
        return real_run(*args, **kw)

    def call(self, it, *args, **kw):
        before = (self._since, len(self.recent))
        out = real_call(self, it, *args, **kw)
        calls.append((getattr(it, "predicted", False), before, (self._since, len(self.recent)), it.mu, it.k))
        return out

    monkeypatch.setattr(E.ext, "run", run)
    monkeypatch.setattr(D.ProofDriver, "__call__", call)
    sol = rfverify.solve_to_digits(rfverify.load("bundled:sphere"), digits=10)
    return sol, calls


def test_the_sphere_is_proven_at_a_predictor_point_iterations_earlier(monkeypatch):
    sol, calls = _path(monkeypatch, offer=True)
    assert sol.certificate.certified and sol.digits["r"] >= 10  # a local problem: u is zero, bounded absolutely
    at = sol.certificate.extra["proven_at"]
    assert at["predicted"] is True and at["where"].endswith("'s predictor point")
    # a predicted point counts neither towards a stall nor among the recent iterates
    predicted = [c for c in calls if c[0]]
    assert predicted and all(before == after for _, before, after, _, _ in predicted)
    # the proven point is iteration k's predictor point, with a μ far below iterate k's
    k = at["iteration"]
    mu_iterate = {c[4]: c[3] for c in calls if not c[0]}
    assert predicted[-1][4] == k and predicted[-1][3] < 0.1 * mu_iterate[k]

    plain, plain_calls = _path(monkeypatch, offer=False)
    assert plain.certificate.certified and not any(c[0] for c in plain_calls)
    assert not plain.certificate.extra["proven_at"].get("predicted")
    assert sol.as_dict()["extended_iterations"] < plain.as_dict()["extended_iterations"]


def test_the_answer_proven_at_a_predictor_point_is_proven_again_from_scratch(monkeypatch):
    """The point is only a proof point: the returned float64 answer, rechecked by certify with
    no point given, is proven to the requested digits too."""
    sol, _ = _path(monkeypatch, offer=True)
    assert sol.certificate.extra["proven_at"]["predicted"]
    again = rfverify.certify(rfverify.load("bundled:sphere"), sol.v, sol.u, sol.r, digits=10)
    assert again.certified


def test_a_face_sub_runs_predictor_point_keeps_its_name():
    """A problem with a self-stress is solved on its face; where the face's run is proven at a
    predictor point, the certificate's proven_at says so (the relabelling onto the face kept only
    phase and iteration; found by the seventh session's audit on corner_problem(17))."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).parent))
    from corner_problems import corner_problem

    sol = rfverify.solve_to_digits(corner_problem(17), digits=10)
    at = sol.certificate.extra["proven_at"]
    assert sol.certificate.certified and at["on_face"], at
    assert at["predicted"] and at["where"].endswith("'s predictor point on the face"), at


def test_the_result_line_names_a_predictor_point(capsys):
    """The text output's first line counts the extended iterations; where the proof was made at
    a predictor point it says so, since the count alone reads as the proof at that iterate."""
    from rfverify.cli import main

    assert main(["solve", "bundled:sphere", "--digits", "10", "--quiet"]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    assert first.endswith("; the proof's point: extended iteration 4's predictor point"), first
