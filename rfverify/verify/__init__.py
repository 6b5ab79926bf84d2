"""The verification paths: what proves, certifies and diagnoses an answer.

:mod:`.digits` the k-digit path (:func:`~.digits.solve_to_digits`: a double solve, the
double-double phase, the multiple-precision tail, a proof), :mod:`.certification` the proof of a
given solution (:func:`~.certification.certify`), :mod:`.certificate` the
:class:`~.certificate.Certificate` both return, :mod:`.diagnosis` why a double run stalled
(:func:`~.diagnosis.diagnose`) and :mod:`.exact` Algorithm 1 continued in exact arithmetic from a
double run's iterates, which the diagnosis uses.
"""


def __getattr__(name: str):
    """``rfverify.verify.<module>`` without importing it first (PEP 562), as before the move."""
    import importlib

    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
