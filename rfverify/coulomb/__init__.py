"""The physical problem: Coulomb friction and rolling resistance with De Saxcé's term (issue 51).

rfverify's default problem is the convex relaxation (DESIGN §1).  This package solves the
physical one — r ∈ K, ũ = u + (μ‖u_T‖ + μr‖u_R‖)e_N ∈ K*, rᵀũ = 0 — as a fixed point of the
shift s in the convex problem with w_N + s (:mod:`.model`, :mod:`.outer`), and certifies an
answer by a proven backward error (:mod:`.backward`): the exact solution of the shifted convex
problem solves the physical problem exactly for data whose w_N differs from the file's by δ,
with |δ| rigorously bounded.  Physical solutions need not be unique; the certificate says so.
"""

from .api import certify_coulomb, check_problem_kind, coulomb_to_digits, solve_coulomb
from .model import PROBLEMS, phi, physical_residuals, physical_velocity, shifted_problem
from .outer import OUTER_METHODS
from .result import CoulombCertificate, CoulombDigits, CoulombSolution

__all__ = ["PROBLEMS", "OUTER_METHODS", "solve_coulomb", "coulomb_to_digits", "certify_coulomb",
           "check_problem_kind", "CoulombSolution", "CoulombDigits", "CoulombCertificate", "phi",
           "physical_velocity", "physical_residuals", "shifted_problem"]
