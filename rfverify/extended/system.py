"""The Newton system of the extended-precision phase, and the choice of the back end that
solves it.

Every back end solves the same 2×2 block system (dz already eliminated)

    [ M    −H̃ᵀ ] [dv ]   [a]
    [ H̃     G  ] [dr̃] = [t],      G = J Q_{p⁻²} Jᵀ  (block diagonal, one block per contact),

and differs only in what it factors (both are symmetric positive definite):

* :class:`.dofspace.DofSpace` — S_v = M + H̃ᵀ G⁻¹ H̃ (m × m), with G⁻¹ in closed form per
  contact.  The pattern couples bodies that share a contact: least fill for rigid-body scenes.
* :class:`.contactspace.ContactSpace` — S_r = H̃ M⁻¹ H̃ᵀ + G (nk × nk), the reference
  implementation's form, with W̃ = H̃ M⁻¹ H̃ᵀ computed once.  Cheaper when H̃ is dense (lifted
  local problems).
* :class:`Hybrid` — the first while it is accurate, then the second.

A back end is a :class:`.factored.NewtonBackend` (a typing.Protocol with default hooks):
``name``, ``update(ph, pl, pih, pil, spec) -> bool``, ``solve(a, t)``,
and the hooks the hybrid (``observe``) and the contact-space forms (``retry_solve``,
``prepare``) fill in; ``stats()`` from :class:`.factored.FactoredBackend`.
:func:`choose_backend` builds one.
"""

from __future__ import annotations

from .contactspace import NEWTON_REFINED_TARGET, ContactSpace
from .data import ExtendedData
from .dofspace import DofSpace
from .factored import FactoredBackend


class Hybrid(FactoredBackend):
    """The dof-space form while it is accurate, then the contact-space form.

    The dof-space Schur complement M + H̃ᵀG⁻¹H̃ is 7–12× cheaper to factor on rigid-body
    problems (1.5e7 against 1.1e8 flops on a 769-contact SpheresPile, 2.0e8 against 2.6e9 on a
    2269-contact random problem), but its ill-conditioning is not diagonal: H̃ᵀG⁻¹H̃ carries
    1/μ along sticking contacts, and on that pile its primal residual blew up once μ fell below
    about 1e-9 of its starting value (μ ≈ 2e-21), while the scaled contact-space form reached
    μ = 1e-33.  So the run switches for good when μ falls below ``switch`` × its first value,
    or as soon as a dof-space solve refines badly (relative residual above ``bad_solve``).
    """

    def __init__(self, data: ExtendedData, switch: float = 1e-6, bad_solve: float = 1e-22,
                 dof: DofSpace | None = None, contact: ContactSpace | None = None):
        self.dof = dof or DofSpace(data)
        self.contact = contact or ContactSpace(data)
        self.current = self.dof
        self.switch = switch
        self.bad_solve = bad_solve
        self._mu0 = None
        self.switched_at = None
        self.name = "hybrid: dof-space, then contact-space"

    @property
    def factorisations(self):
        return self.dof.factorisations + self.contact.factorisations

    def observe(self, k: int, mu: float, solve_residual: float | None):
        """Called by the driver once per iteration (before the factorisation)."""
        if self._mu0 is None:
            self._mu0 = mu
        if self.current is self.dof and (mu < self.switch * self._mu0
                                          or (solve_residual is not None and solve_residual > self.bad_solve)):
            self.current = self.contact
            self.switched_at = k

    def describe_cost(self) -> str:
        dof = self.dof.describe_cost()
        if self.switched_at is None:
            return f"dof-space: {dof}"
        return f"dof-space: {dof}; contact-space from iteration {self.switched_at}: {self.contact.describe_cost()}"

    def retry_solve(self, residual: float) -> bool:
        """The contact-space form's safety net (:meth:`.ContactSpace.retry_solve`) while it is in use."""
        return self.current is self.contact and self.contact.retry_solve(residual)

    def update(self, ph, pl, pih, pil, spec) -> bool:
        ok = self.current.update(ph, pl, pih, pil, spec)
        if not ok and self.current is self.dof:  # lost definiteness: switch now
            self.current = self.contact
            ok = self.current.update(ph, pl, pih, pil, spec)
        return ok

    def solve(self, a, t):
        return self.current.solve(a, t)

    def set_accuracy(self, residual_norm: float | None) -> None:
        self.dof.set_accuracy(residual_norm)
        self.contact.set_accuracy(residual_norm)

    def stats(self) -> dict:
        """{}: the hybrid holds two factors, not one."""
        return {}


def choose_backend(data: ExtendedData, backend: str = "auto", engine: str = "auto"):
    """The back end asked for.  ``auto`` is the scaled contact-space form with a float64
    factorisation refined in double-double (:class:`.contactspace.ContactSpace`): with the factorisation in
    float64 it is as fast as or faster than the dof-space and hybrid forms on every problem
    measured (docs/DECISIONS.md), and its accuracy does not depend on μ.  ``contact-dd`` factors
    in double-double throughout; ``dof`` and ``hybrid`` are the dof-space forms.  ``engine``
    (:func:`.contactspace.resolve_engine`) is the float64 factorisation of the contact-space form:
    chosen by size ("auto"), or forced ("cholmod", "ldl").  The contact-space solves are refined
    only to :data:`.contactspace.NEWTON_REFINED_TARGET`: the back end serves the extended IPM,
    whose Newton driver refines each solve against the unreduced system."""
    if data.local and backend in ("dof", "hybrid"):
        from ..errors import InvalidArgumentError

        raise InvalidArgumentError("backend", f"{backend!r} works in the dofs of a global problem; a local "
                                              "problem has none", fix="use backend 'auto', 'contact' or 'contact-dd'")
    if backend == "dof":
        return DofSpace(data, max_local_dofs=10**9)
    if backend in ("auto", "contact"):
        return ContactSpace(data, engine=engine, backward_target=NEWTON_REFINED_TARGET)
    if backend == "contact-dd":
        return ContactSpace(data, mixed=False)
    if backend == "hybrid":
        return Hybrid(data, contact=ContactSpace(data, engine=engine, backward_target=NEWTON_REFINED_TARGET))
    from ..errors import InvalidArgumentError

    raise InvalidArgumentError("backend", f"{backend!r} is not one of auto, contact, contact-dd, hybrid, dof",
                               fix="use backend='auto' (the default)")
