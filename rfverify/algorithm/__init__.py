"""Algorithm 1 (DESIGN §4), written once for every precision.

:func:`loop.iterate` is the Mehrotra predictor–corrector loop with NT scaling, a dozen calls
against four small interfaces (:mod:`.interfaces`):

* a **Space** — the problem's data and vectors in one precision (``@`` with the data
  operators, ``+``/``-`` on vectors, ``dot``, ``norm2``, ``axpy``, ``move``);
* **Cones** — ``scaling(z, s)``, whose :class:`~.interfaces.Scaling` holds the NT point of
  that iterate and answers ``affine_rhs``, ``corrector_rhs``, ``max_step`` and ``quad``;
* a **Newton** solver — ``update(scaling, k, mu)`` and ``solve(a, b, c, phase)``, refinement
  inside (:class:`.newton.ReducedNewton` for the extended precisions, the float64 KKT forms of
  :mod:`rfverify.solver.kkt` through :mod:`rfverify.solver.ipm`);
* a **Policy** — when to stop, whether to switch precision, the σ rule and the step fraction
  (:mod:`.rules` holds the rules every policy shares).

Three precisions implement them: float64/longdouble numpy (:mod:`rfverify.solver.ipm`),
double-double (:mod:`rfverify.extended.ipm`) and ``bits``-bit mpfr
(:mod:`rfverify.extended.wide`).  The mpmath reference (:mod:`reference`) is the independent
second opinion and does not use any of this.
"""
