"""The problem model: what a rolling-friction problem is and how it is judged.

:mod:`.problem` the validated :class:`~.problem.Problem` (with :mod:`.massmatrix`, the symmetry
and block definiteness of M, :mod:`.definiteness` the verified definiteness test, and
:mod:`._arrays` the checked, read-only arrays); :mod:`.scaling` the exact power-of-two change of
units for data beyond float64's safe range; :mod:`.lifting` the rolling cone lifted to L3 × L3
(DESIGN §2); :mod:`.measures` the one criterion of "solved" (DESIGN §4.5) and :mod:`.check` the
check of a stored solution; :mod:`.summary` what ``rfverify info`` says.  No module here imports
a solver.
"""


def __getattr__(name: str):
    """``rfverify.model.<module>`` without importing it first (PEP 562), as before the move."""
    import importlib

    try:
        return importlib.import_module(f"{__name__}.{name}")
    except ModuleNotFoundError as exc:
        if exc.name != f"{__name__}.{name}":
            raise
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
