"""The verification paths: what proves, certifies and diagnoses an answer.

:mod:`.digits` the k-digit path (:func:`~.digits.solve_to_digits`: a double solve, the
double-double phase, the multiple-precision tail, a proof), :mod:`.certification` the proof of a
given solution (:func:`~.certification.certify`), :mod:`.certificate` the
:class:`~.certificate.Certificate` both return, :mod:`.diagnosis` why a double run stalled
(:func:`~.diagnosis.diagnose`) and :mod:`.exact` Algorithm 1 continued in exact arithmetic from a
double run's iterates, which the diagnosis uses.
"""
