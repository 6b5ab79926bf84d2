"""The float64 factorisation engines, shared by the double solver (:mod:`rfverify.solver`) and
the extended phase's refined float64 factors (:mod:`rfverify.extended.mixed`), as Clarabel's
``ldlsolvers/`` serve its solver.

:mod:`.factor` the engines behind one :class:`~.factor.FactorEngine` interface (``factor(K)``,
``solve(rhs)``): QDLDL, SuperLU and CHOLMOD; :mod:`.cholmod_nogil` CHOLMOD called through ctypes
on cvxopt's own libcholmod, releasing the GIL.  Nothing here imports a solver.
"""
