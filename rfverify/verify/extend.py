"""The extended phases of the k-digit path (:func:`extend`): Algorithm 1 in double-double, then
where no proof succeeded the multiple-precision tail (:mod:`rfverify.extended.wide`) within its
factorisation budget (:data:`WIDE_MAX_FACTOR_OPS`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from ..extended import ipm as ext
from ..extended import wide, wide_factor
from ..extended.data import ExtendedData
from ..model.lifting import cone_words
from .driver import ProofDriver, point_from_iterate, site_words

WIDE_MAX_FACTOR_OPS = 2e7
"""Largest factorisation given the tail, in multiply-subtract pairs (Σ c_j² over the column
counts of L in its minimum-degree order): measured ~0.26 µs each at 320 bits (the whole
iteration ~2× its factorisation), so about 5 s per factorisation at the limit (a 274-contact
Lattice: 1.0e6, a 769-contact SpheresPile: 1.5e7).  This is the tail's only limit: its factor
is sparse (:class:`.extended.wide_cholesky.SparseWideCholesky`, memory O(nnz(L))), so the number
of dofs does not matter, only the fill (the 9675-contact GranularBed: 1.3e10, about 56 min per
factorisation; docs/DECISIONS.md, "The 10-digit path at scale")."""


WIDE_SECONDS_PER_OP = 0.26e-6
"""Measured cost of one multiply-subtract pair of the tail's factorisation (320 bits, this
machine), for the estimate the certificate states when the tail is skipped."""

WIDE_GIVE_UP = 5
"""The tail stops after this many invalid proofs in a row (measured: a Chute whose wedge
contacts leave no strictly feasible point stays outside K* at every one of 40 iterations)."""


def held_by(data: ExtendedData, limit) -> dict | None:
    """The cone that set a step to the boundary, ``limit`` = (cone, "z" or "s") of the lifted
    problem, as {"contact": index in the problem, "part": friction / rolling / normal, "side":
    velocity / reaction} (:meth:`rfverify.model.lifting.LiftedProblem.held_by`); None when
    unknown.  For a problem on a face (``data.contact_names``) the contact is the posed
    problem's, or None for an edge contact the face made (then "face_edge": its index among
    the face's edge contacts)."""
    if limit is None:
        return None
    out = data.lp.held_by(*limit)
    names = getattr(data, "contact_names", None)
    if names is not None:
        contact = out["contact"]
        out["contact"] = int(names[contact]) if names[contact] >= 0 else None
        if out["contact"] is None:
            out["face_edge"] = int(-1 - names[contact])
    return out


def step_words(data: ExtendedData, step) -> str:
    """The step that led to an iterate, for its progress line: "; step 0.955, held by contact
    453's rolling cone (reaction)" (the cone whose boundary cut it short), "; full step", or ""
    for the first iterate."""
    if step is None:
        return ""
    alpha, limit = step
    if alpha >= 1.0:
        return "; full step"
    held = held_by(data, limit)
    if held is None:
        return f"; step {alpha:.3g}"
    return f"; step {alpha:.3g}, held by {cone_words(held)}"


def steps_held(data: ExtendedData, trace: dict) -> list[dict]:
    """Each step of a run shorter than 1, with the cone that cut it short: [{"from_iteration" (the
    step from that iterate to the next), "alpha", "contact", "part", "side"}] (:func:`held_by`;
    the last three absent where the run does not know them)."""
    out = []
    for k, (alpha, limit) in enumerate(zip(trace.get("alpha", []), trace.get("limit", []))):
        if alpha < 1.0:
            out.append({"from_iteration": k, "alpha": float(alpha), **(held_by(data, limit) or {})})
    return out


@dataclass
class Extension:
    """What :func:`extend` ran: the double-double run, the multiple-precision tail (None if it
    did not run; ``wide_note`` says why), and their wall times without the proofs."""

    run: ext.ExtendedResult
    wide: wide.WideResult | None
    wide_note: str
    handover_iteration: int | None
    seconds_dd: float
    seconds_wide: float
    steps_held: list = field(default_factory=list)  # the double-double run's :func:`steps_held`
    wide_steps_held: list = field(default_factory=list)  # the tail's, where it ran

    @property
    def point_source(self) -> str:
        if self.wide is not None:
            return f"extended phase, then the {self.wide.bits}-bit multiple-precision tail"
        return "extended phase"

    def summary(self) -> dict:
        out = {"extended_status": self.run.status, "extended_iterations": self.run.nit, "backend": self.run.backend,
               "wide_tail": self.wide_note, "extended_steps_held": self.steps_held}
        if self.wide is not None:
            out.update(wide_status=self.wide.status, wide_iterations=self.wide.nit, wide_bits=self.wide.bits,
                       wide_handover_iteration=self.handover_iteration, wide_steps_held=self.wide_steps_held)
        return out


def extend(data: ExtendedData, start: dict, driver: ProofDriver, system, *, max_iter: int = 80,
           wide_tail: bool = True, wide_bits: int = wide.DEFAULT_BITS, wide_max_iter: int = 40, say=None,
           verbose: bool = False) -> Extension:
    """Algorithm 1 in double-double from ``start`` until ``driver`` accepts a proof or the run
    stalls; then, if no proof succeeded and the tail's factor is within
    ``WIDE_MAX_FACTOR_OPS``, the multiple-precision tail (:mod:`.extended.wide`) from the latest healthy double-double
    iterate.  At the end, if nothing was certified, the last iterates are proven so that the
    driver's best proof reports the best digits reached."""
    say = say or (lambda msg: None)

    def tick(phase):
        return (lambda k, mu, pinf, dinf, step=None: say(
            f"  {phase} iteration {k}: μ = {mu:.2e}, pinfeas = {pinf:.1e}, dinfeas = {dinf:.1e}"
            + step_words(data, step))) if verbose else None

    t0 = time.perf_counter()
    p0 = driver.proof_seconds
    named = [system.name]

    def extended_tick(k, mu, pinf, dinf, step=None):  # a change of the factorisation is said when it happens
        if system.name != named[-1]:
            named.append(system.name)
            say(f"  extended iteration {k}: the last step's factorisation changed: {system.name}")
        if verbose:
            tick("extended")(k, mu, pinf, dinf, step)

    run = ext.run(data, start, until=driver, max_iter=max_iter, backend=system, progress=extended_tick,
                  offer_predicted=True)
    seconds_dd = time.perf_counter() - t0 - (driver.proof_seconds - p0)
    if run.status == "MaxTime":  # a long kernel was stopped at the time limit (.extended.stoppable)
        driver.timed_out = True
    tail, note, hand_k, seconds_wide = None, "not needed", None, 0.0
    if not driver.certified:
        if driver.timed_out:
            note = "not run (the time limit was reached)"
        elif not wide_tail:
            note = "not run (switched off)"
        elif driver.hopeless:
            note = "not run (the candidate is farther from the point than any tail could fix)"
        elif data.local:
            note = "not run (the tail works in the dofs of a global problem; a local problem has none)"
        elif driver.face is None and (driver.ctx.self_stresses() or (driver.recent and not isinstance(driver.recent[-1], wide.WideIterate)
                                            and driver.ctx.look_for_self_stress(point_from_iterate(
                                                data, driver.recent[-1].v, driver.recent[-1].r_t).r_hi))):
            note = ("not run (a self-stress leaves the feasible set no interior: more precision cannot help, "
                    "the problem is solved on its face instead)")
        elif (ordering := wide_factor.dof_space_ordering(data))[1] > WIDE_MAX_FACTOR_OPS:
            ops = ordering[1]
            note = (f"not run (its factorisation would take {ops:.1e} multiply-subtract pairs > "
                    f"{WIDE_MAX_FACTOR_OPS:.0e}, about {ops * WIDE_SECONDS_PER_OP:.0f} s per factorisation)")
        else:
            it = wide.handover(data, driver.recent, bits=wide_bits)
            if it is None:
                note = "not run (no interior, centred double-double iterate to start from)"
            else:
                hand_k = it.k
                say(f"multiple-precision tail: {wide_bits}-bit mpfr, sparse dof-space factor, from extended "
                    f"iteration {it.k} (μ = {it.mu:.2e})")
                driver.restart(invalid_limit=WIDE_GIVE_UP)
                t1 = time.perf_counter()
                p1 = driver.proof_seconds
                tail = wide.run(data, {"v": (it.v.h, it.v.l), "r_t": (it.r_t.h, it.r_t.l), "z": (it.z.h, it.z.l)},
                                until=driver, max_iter=wide_max_iter, bits=wide_bits, perm=ordering[0],
                                progress=tick("multiple-precision"), offer_predicted=True)
                seconds_wide = time.perf_counter() - t1 - (driver.proof_seconds - p1)
                note = f"{tail.status}: {tail.message}" + (f"; {driver.gave_up}" if driver.gave_up else "")
    if not driver.certified:
        # No proof succeeded: prove the last iterates (the final one may have left a cone
        # after a failed step) so that the verdict reports the best proven digits.
        again = [it for it in driver.recent[-3:] if ("dd", it.k) not in driver.proven_keys
                 and ("wide", it.k) not in driver.proven_keys]
        for it in again:
            driver(it, force=True, quiet=True)
        if again and driver.best is not None:
            # one line, not one per iterate: the progress goes forward
            say(f"the last iterates ({', '.join(str(it.k) for it in again)}) proven too, in case the final one "
                f"left a cone: the best proof is {site_words(driver.best_at)}'s: {driver.best[1].summary()}")
    return Extension(run, tail, note, hand_k, seconds_dd, seconds_wide, steps_held(data, run.trace),
                     [] if tail is None else steps_held(data, tail.trace))


