"""Exception hierarchy of rfverify.

Every error the library raises on purpose derives from :class:`RfverifyError`, so a caller
(and the CLI) can tell a diagnosed problem from a bug.  Each message names *what* is wrong
(the field, index or operation), *why*, and *how to fix it*.
"""

from __future__ import annotations


class RfverifyError(Exception):
    """Base class of all errors raised deliberately by rfverify."""


class InvalidProblemError(RfverifyError, ValueError):
    """The problem data violate a precondition (shape, finiteness, sign, symmetry, definiteness).

    Attributes
    ----------
    field : str
        Name of the offending field (``"M"``, ``"H"``, ``"f"``, ``"w"``, ``"mu"``, ``"mu_r"``,
        ``"spacedim"``, ...).
    index : object or None
        Position of the first offending entry (an int, a (row, col) pair, or a block/contact
        description), when there is one.
    fix : str
        What the user can do about it.
    """

    def __init__(self, field: str, problem: str, *, index=None, fix: str = ""):
        self.field = field
        self.index = index
        self.problem = problem
        self.fix = fix
        where = f"{field}" if index is None else f"{field}[{_fmt_index(index)}]"
        msg = f"{where}: {problem}"
        if fix:
            msg += f"; fix: {fix}"
        super().__init__(msg)


class ProblemFileError(RfverifyError, OSError):
    """A problem file cannot be read: missing, unreadable, truncated, not the expected format,
    or missing a required group/dataset.  ``path`` and (when known) ``location`` (HDF5 path or
    line number) say where."""

    def __init__(self, path, problem: str, *, location: str | None = None):
        self.path = str(path)
        self.location = location
        self.problem = problem
        where = self.path if location is None else f"{self.path} [{location}]"
        super().__init__(f"{where}: {problem}")


class ConeDomainError(RfverifyError, ArithmeticError):
    """A Jordan-algebra operation was given an argument outside its domain, e.g. the square
    root of a vector outside the Lorentz cone, or the inverse of an element with det = 0.

    Attributes
    ----------
    operation : str
        Name of the operation (``"inverse"``, ``"sqrt"``, ``"nt_scaling"``, ...).
    cone : int or None
        Index of the first offending cone along the leading (batch) axis, ``None`` for a single
        vector.
    value : float
        The offending quantity (e.g. ``λ2`` or ``det``) as a Python float.
    """

    def __init__(self, operation: str, problem: str, *, cone=None, value=None):
        self.operation = operation
        self.cone = cone
        self.value = value
        where = operation if cone is None else f"{operation} (cone {cone})"
        super().__init__(f"{where}: {problem}")


def _fmt_index(index) -> str:
    if isinstance(index, tuple):
        return ", ".join(str(i) for i in index)
    return str(index)
