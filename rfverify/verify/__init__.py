"""The verification paths: what proves, certifies and diagnoses an answer.

The k-digit path (:func:`~.digits.solve_to_digits`): :mod:`.digits` drives it (a double solve,
the double-double phase, the multiple-precision tail, a proof), :mod:`.prepare` builds the
double-double phase's set-up beside the double solve, :mod:`.driver` decides which iterates are
proven and keeps the best proof, :mod:`.extend` runs the extended phases.  :mod:`.certification`
proves a given solution (:func:`~.certification.certify`); :mod:`.certificate` is the
:class:`~.certificate.Certificate` both return.  :func:`~.diagnosis.diagnose` says why a double
run stalled: :mod:`.lockstep` (exact steps beside the double ones), :mod:`.cause` (the
counterfactual run, the remedies), :mod:`.witness` (the mpmath reference), on
:mod:`.exact` (Algorithm 1 continued in exact arithmetic from a double run's iterates).
"""
