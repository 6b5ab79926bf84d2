"""The k-digit path's second start: where, under ``method="auto"``, the search for a proof point
stalled from the double answer and proved nothing, the path runs once more from another form's
double answer and keeps the better proof (docs/DECISIONS.md, "Two audits of the eighth session")."""

from __future__ import annotations

import dataclasses
import time

from .certificate import certificate_from_proof
from .driver import ProofDriver


SECOND_START = "noscaling"
"""The double solve's form from whose answer the k-digit path starts again where, from auto's, the
search for a proof point stalled and proved nothing: a fresh MassRatio problem at mass ratio 1e16
(20 spheres, μ = 1, tilt 20°, seed 21212) stalled at steps of 1e-6 from the jqinv answer, held by
one rolling cone, and is proven to 10.4 digits from noscaling's (docs/DECISIONS.md)."""


def second_start(run):
    """``run`` (the k-digit path), and where it stalled without proving anything from the double
    answer of ``method="auto"``, once more from :data:`SECOND_START`'s; the better of the two."""
    import functools

    @functools.wraps(run)
    def path(problem, digits=10, method="auto", *args, **kwargs):
        t0 = time.perf_counter()
        out = run(problem, digits, method, *args, **kwargs)
        cert = out.certificate
        if (method != "auto" or kwargs.get("_on_face") is not None or cert.certified or out.timed_out
                or out.interrupted or "search_stopped" not in cert.extra or out.double.method == SECOND_START):
            return out
        if kwargs.get("time_limit") is not None:
            left = kwargs["time_limit"] - (time.perf_counter() - t0)
            if left <= 0:
                return out
            kwargs = {**kwargs, "time_limit": left, "_named_limit": kwargs.get("_named_limit") or kwargs["time_limit"]}
        say = kwargs.get("progress") or (lambda message: None)
        say(f"the search stalled from the {out.double.method} double answer without a proof: once more from "
            f"the {SECOND_START} form's")
        again = run(problem, digits, SECOND_START, *args, **kwargs)
        first, second = cert.proof, again.certificate.proof
        if not (again.certificate.certified or (second is not None and (
                first is None or ProofDriver.score(second) > ProofDriver.score(first)))):
            return out
        note = (f"found from the {SECOND_START} double answer; from auto's ({out.double.method}) "
                f"{cert.extra['search_stopped']}")
        proof, extra = again.certificate.proof, {**again.certificate.extra, "second_start": note}
        cert = certificate_from_proof(proof, again.certificate.point, extra, again.certificate.seconds) \
            if proof is not None else dataclasses.replace(again.certificate, extra=extra)
        cert.cross_check = again.certificate.cross_check
        first_start = out.timings.get("total", 0.0)  # the first start's whole path, spent too
        timings = {**again.timings, "first_start": first_start, "total": again.timings.get("total", 0.0) + first_start}
        return dataclasses.replace(again, certificate=cert, timings=timings)

    return path
