"""The certificate of a proof: what :func:`rfverify.certify` and the k-digit path return, with a
verdict that claims exactly what was proven.  Its own module so that both paths import it and
neither imports the other."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ..model.directed import digits_text
from ..model.problem import PSD_SHIFT_MARK
from ..proof import Point, Proof
from ..solver.result import ResultAliases, Status, alias


class VerdictResult(ResultAliases):
    """The fields every result has (docs/RESULTS.md), read from a certificate's ``certified``,
    ``verdict`` and ``extra`` (its ``time_limit``): the base of :class:`Certificate` and of the
    physical problem's :class:`rfverify.coulomb.CoulombCertificate`."""

    @property
    def status(self) -> Status:
        """``Status.CERTIFIED``, ``NOT_CERTIFIED``, or ``MAX_TIME`` when a time limit ended the
        search for a proof point short of the requested digits."""
        if self.certified:
            return Status.CERTIFIED
        return Status.MAX_TIME if self.extra.get("time_limit") is not None else Status.NOT_CERTIFIED

    success = alias("certified", "``certified`` (SciPy's name).")
    message = alias("verdict", "The verdict: what was proven, or why not.")

    @property
    def headline(self) -> str:
        """The verdict's first sentence: what was proven, for which problem."""
        return self.verdict.split(". ")[0]


class CertifiedResult(ResultAliases):
    """``status``, ``success`` and ``message`` of an answer that carries its proof as
    ``certificate`` (a :class:`VerdictResult`): the certificate's.  The base of
    :class:`rfverify.DigitsSolution` and of :class:`rfverify.coulomb.CoulombDigits`."""

    success = alias("certificate.certified", "The certificate's ``certified``.")
    status = alias("certificate.status", "``Status.CERTIFIED``, ``NOT_CERTIFIED``, or ``MAX_TIME`` when "
                   "the time limit ended the run short of the requested digits (the best proof reached "
                   "is the certificate).")
    message = alias("certificate.verdict", "The certificate's verdict: what was proven, or why not.")


@dataclass
class Certificate(VerdictResult):
    """Result of :func:`certify` (and of the k-digit path).

    ``certified`` is True only when the proof shows at least ``requested`` digits in v, u, Hr
    and, where r is unique, r.  ``digits`` maps each certified-or-not quantity to its proven
    digits (None where no relative digits exist); ``bounds`` to the proven ∞-norm bound on
    its error; ``quantities`` holds the full per-quantity record (scale used, mode).
    ``proof`` is the :class:`rfverify.proof.Proof`; ``cross_check`` the reference agreement
    when asked for.  ``status``/``success``/``message``/``nit``/``timings`` (and the aliases
    ``iterations``, ``solve_time``) are the fields every result has (docs/RESULTS.md).
    """

    requested: int
    certified: bool
    verdict: str
    proof: Proof | None = None
    point: Point | None = None
    cross_check: dict | None = None
    extra: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def digits(self) -> dict:
        if self.proof is None:
            return {}
        return {k: q.digits for k, q in self.proof.quantities.items() if q.mode != "information"}

    @property
    def bounds(self) -> dict:
        if self.proof is None:
            return {}
        return {k: q.abs_bound for k, q in self.proof.quantities.items() if q.mode != "information"}

    @property
    def quantities(self) -> dict:
        return {} if self.proof is None else self.proof.quantities

    @property
    def statement(self) -> str:
        """The problem the proof is about, in words (e.g. "the convex relaxation with
        (M + Mᵀ)/2"; DESIGN §6.4)."""
        return "" if self.proof is None else self.proof.statement

    @property
    def stored_equations(self) -> Proof | None:
        """Where the proof is about (M + Mᵀ)/2 of an unsymmetric stored M: the same answer proven
        against the stored equations (their solution differs), else None."""
        return None if self.proof is None else self.proof.stored_equations

    @property
    def r_unique(self) -> bool | None:
        if self.proof is None or "r" not in self.proof.quantities:
            return None
        return self.proof.quantities["r"].mode != "information"

    @property
    def nit(self) -> int:
        """Iterations run to find the proof point: 0 when the given point or the candidate
        itself was proven, else the double solve's, the double-double phase's and the
        multiple-precision tail's."""
        return sum(int(self.extra.get(k) or 0)
                   for k in ("double_iterations", "extended_iterations", "wide_iterations"))

    @property
    def timings(self) -> dict:
        """Seconds: ``total`` (= ``seconds``, the whole of :func:`certify`)."""
        return {"total": self.seconds}

    def __repr__(self) -> str:
        return f"Certificate(status={self.status}, requested={self.requested}, nit={self.nit}, time={self.time:.3g} s,\n" \
               f"    {self.headline!r})"

    def as_dict(self) -> dict:
        """The JSON-able certificate ``rfverify certify --json`` prints."""
        p = self.proof
        return {"status": str(self.status), "success": self.success, "message": self.message,
                "nit": self.nit, "time": self.time,
                "requested_digits": self.requested, "certified": self.certified, "verdict": self.verdict,
                "method": "proof" if p is not None else None,
                "valid_proof": None if p is None else p.valid,
                "failure": None if p is None else (p.failure or None),
                "quantities": {} if p is None else {k: q.as_dict() for k, q in p.quantities.items()},
                "terms": {} if p is None else p.terms,
                "arithmetic": None if p is None else p.arithmetic,
                "problem": self.statement or None,
                "equations": None if p is None else p.equations,
                "stored_equations": _stored_dict(self.stored_equations),
                "cross_check": self.cross_check, "seconds": self.seconds, **self.extra}


def certificate_from_proof(proof: Proof, point: Point | None = None, extra: dict | None = None,
                           seconds: float = 0.0) -> Certificate:
    """The certificate of a proof, with a verdict that claims exactly what was proven, and of
    which problem: "proven to K digits" only when every quantity has K relative digits; a
    quantity proven zero at the data scale is stated as "zero within e" (DESIGN §6.3), never as
    digits; the problem (:attr:`Proof.statement`) ends the first sentence, and where the stored
    M is unsymmetric a second one says how many digits of the stored equations' solution the
    answer has.  Where ``extra["proven_at"]`` (:meth:`rfverify.verify.digits.ProofDriver.proven_at`)
    says the proof's point is not the last one proven, the first sentence names it."""
    req = proof.requested
    about = f" for {proof.statement}" if proof.statement else ""
    if not proof.valid:
        verdict = f"not certified{about}: {proof.failure}"
    elif proof.certified:
        if any(q.mode == "absolute" for q in proof.quantities.values()):
            verdict = f"certified ({req} digits requested; zero quantities bounded absolutely){about}: {proof.summary()}"
        else:
            verdict = f"proven to {req} digits ({proof.summary()}){about}"
    else:
        worst = proof.weakest()
        q = proof.quantities[worst]
        have = "no relative digits" if q.digits is None else f"{digits_text(q.digits)} proven digits"
        why = f"; {q.note}" if q.digits is None and q.note else ""
        verdict = f"not proven to {req} digits{about}: {worst} has {have} ({proof.summary()}){why}"
    at = (extra or {}).get("proven_at")
    if at and at.get("proofs", 0) > 1 and at.get("last") != at.get("where"):
        # the last progress lines are about another point: say which one this verdict is about
        verdict += f" (proof point: {at['where']}, the best of {at['proofs']} proven; the last was {at['last']})"
    stopped = (extra or {}).get("search_stopped")
    if stopped and not proof.certified:  # why no later point was tried (the words name their iteration)
        verdict += f" ({stopped})"
    if (extra or {}).get("second_start"):  # the double answer the point was found from, and why that one
        verdict += f" ({extra['second_start']})"
    verdict += stored_sentence(proof)
    limit = (extra or {}).get("time_limit")
    if limit is not None and not proof.certified:
        verdict += _time_limit_note(limit)
    return Certificate(req, proof.certified, verdict, proof, point, None, dict(extra or {}), seconds)


def _time_limit_note(limit: float) -> str:
    return f" (the search for a proof point stopped at the time limit of {limit:g} s)"


def cut_short(cert: Certificate, limit: float) -> Certificate:
    """``cert`` (not certified) as a search the time limit stopped: status MaxTime, and the verdict says so."""
    if cert.certified or "time_limit" in cert.extra:
        return cert
    return dataclasses.replace(cert, extra={**cert.extra, "time_limit": limit},
                               verdict=cert.verdict + _time_limit_note(limit))


def stored_sentence(proof: Proof) -> str:
    """The verdict's second sentence when the proof is about (M + Mᵀ)/2 of an unsymmetric M:
    what the same answer is proven to be for the equations with M as stored ("" otherwise)."""
    st = proof.stored_equations
    if st is None:
        return ""
    X = ("W + D" if PSD_SHIFT_MARK in proof.statement else "W") if proof.local else "M"
    if not st.valid:
        return f". For {X} as stored (unsymmetric) nothing is proven: {st.failure}"
    if st.certified:
        return f". It is also proven to {st.requested} digits for {X} as stored (unsymmetric): {st.summary()}"
    fewest = st.fewest_digits()
    have = "no relative digits" if fewest is None else f"{digits_text(fewest)} proven digits"
    how = "; --as-stored (as_stored=True) solves and proves those" if X == "M" else ""
    return (f". {X} as stored is unsymmetric and its equations have another solution, of which this answer has "
            f"{have} ({st.summary()}){how}")


def _stored_dict(st: Proof | None) -> dict | None:
    if st is None:
        return None
    return {"certified": st.certified, "valid_proof": st.valid, "failure": st.failure or None,
            "fewest_digits": st.fewest_digits(), "eps_M": st.eps_M,
            "digits": {k: q.digits for k, q in st.quantities.items() if q.mode != "information"},
            "bounds": {k: q.abs_bound for k, q in st.quantities.items() if q.mode != "information"}}


def candidate_point(v, r) -> Point:
    """The float64 candidate (v, r) as an exact proof point (no low parts)."""
    v = np.asarray(v, dtype=np.float64).copy()
    r = np.asarray(r, dtype=np.float64).copy()
    return Point(v, np.zeros_like(v), r, np.zeros_like(r))


def unscaled_proof(proof: Proof | None, scaling) -> Proof | None:
    """A proof made in units scaled by exact powers of two (:mod:`rfverify.model.scaling`) with its
    per-quantity bounds, norms and scales in the problem's units (bounds rounded up, lower
    bounds down; digits and verdicts are scale-invariant).  ``terms`` stay in the scaled units
    (``terms_units`` says so)."""
    import dataclasses

    if proof is None:
        return None
    quantities = {}
    for name, q in proof.quantities.items():
        quantities[name] = dataclasses.replace(
            q, abs_bound=scaling.scale_bound_back(name, q.abs_bound), norm=scaling.scale_bound_back(name, q.norm),
            own_scale=scaling.scale_bound_back(name, q.own_scale, up=False),
            data_scale=scaling.scale_bound_back(name, q.data_scale, up=False))
    terms = dict(proof.terms, terms_units="scaled: " + ", ".join(f"{k}·2^{e}" for k, e in scaling.as_dict().items()))
    return dataclasses.replace(proof, quantities=quantities, terms=terms,
                               stored_equations=unscaled_proof(proof.stored_equations, scaling))


def unscaled_point(point: Point | None, scaling) -> Point | None:
    """The point in the problem's units (None when a term would leave float64's range: the
    point then exists only in the scaled units its proof was made in)."""
    return _point_in(point, scaling, inverse=True)


def scaled_point(point: Point | None, scaling) -> Point | None:
    """The point in scaled units (None when not exact)."""
    return _point_in(point, scaling, inverse=False)


def _point_in(point: Point | None, scaling, inverse: bool) -> Point | None:
    if point is None:
        return None
    parts = {}
    for key in ("v_hi", "v_lo", "r_hi", "r_lo", "v_more", "r_more"):
        x = getattr(point, key)
        parts[key] = None if x is None else scaling.scale(key[0], x, inverse=inverse)
        if x is not None and parts[key] is None:
            return None
    return Point(**parts)


def unscaled_certificate(cert: Certificate, scaling) -> Certificate:
    """A certificate made in scaled units, in the problem's units (its verdict re-worded from the
    unscaled proof, the scaling recorded in ``extra["binary_scaling"]``)."""
    proof = unscaled_proof(cert.proof, scaling)
    extra = dict(cert.extra, binary_scaling=scaling.describe())
    if proof is None:
        return Certificate(cert.requested, cert.certified, cert.verdict, None, None, cert.cross_check, extra,
                           cert.seconds)
    out = certificate_from_proof(proof, unscaled_point(cert.point, scaling), extra, cert.seconds)
    out.cross_check = cert.cross_check
    return out
