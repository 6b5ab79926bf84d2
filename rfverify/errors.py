"""Exception hierarchy of rfverify.

Every error the library raises on purpose derives from :class:`RfverifyError`, so a caller
(and the CLI) can tell a diagnosed problem from a bug.  Each message names *where* (the file,
when there is one), *what* is wrong (the field, index, option or operation) and *how to fix
it*, in the order ``<file>: <field>: <what>; fix: <what to do>``.
"""

from __future__ import annotations

import math
import numbers


class RfverifyError(Exception):
    """Base class of all errors raised deliberately by rfverify."""


def _compose(path, where, problem, fix) -> str:
    parts = [str(p) for p in (path, where) if p not in (None, "")]
    msg = ": ".join(parts + [problem])
    if fix:
        msg += f"; fix: {fix}"
    return msg


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
    path : str or None
        File the data came from, when known (set by :func:`rfverify.load`).
    """

    def __init__(self, field: str, problem: str, *, index=None, fix: str = "", path=None):
        self.field = field
        self.index = index
        self.problem = problem
        self.fix = fix
        self.path = None if path is None else str(path)
        where = f"{field}" if index is None else f"{field}[{_fmt_index(index)}]"
        super().__init__(_compose(self.path, where, problem, fix))

    def with_path(self, path) -> "InvalidProblemError":
        """The same error, its message naming the file ``path`` the data came from."""
        if self.path is not None:
            return self
        return InvalidProblemError(self.field, self.problem, index=self.index, fix=self.fix, path=path)


class ProblemFileError(RfverifyError, OSError):
    """A problem file cannot be read: missing, unreadable, truncated, not the expected format,
    or missing a required group/dataset.  ``path`` and (when known) ``location`` (HDF5 path or
    line number) say where; ``fix`` says what to do."""

    def __init__(self, path, problem: str, *, location: str | None = None, fix: str = ""):
        self.path = str(path)
        self.location = location
        self.problem = problem
        self.fix = fix
        super().__init__(_compose(self.path, location, problem, fix))

    def __str__(self) -> str:  # OSError.__str__ would print the errno tuple form
        return self.args[0]


class DataWarning(UserWarning):
    """Something in an input file that does not change the problem (optional metadata such as
    FCLIB ``info/description``) could not be read as stored, and was read with a stated change
    (undecodable bytes replaced by U+FFFD) or skipped.  The message names the file, the field
    and what was done; the problem itself is read exactly.  The CLI prints each one as a
    one-line ``warning:`` on stderr."""


class InvalidArgumentError(RfverifyError, ValueError, TypeError):
    """A function or command was called with an argument of the wrong type or value (the
    ``argument`` is named).  It is both a ValueError and a TypeError so that callers catching
    either keep working."""

    def __init__(self, argument: str, problem: str, *, fix: str = ""):
        self.argument = argument
        self.problem = problem
        self.fix = fix
        super().__init__(_compose(None, argument, problem, fix))


class OutputPathError(RfverifyError, OSError):
    """An output path cannot (or must not) be written: it is an input of the same command, not
    a regular file, in a missing or read-only directory, ...  ``option`` names the CLI option
    or API argument that gave it."""

    def __init__(self, path, problem: str, *, option: str = "--out", fix: str = ""):
        self.path = str(path)
        self.option = option
        self.problem = problem
        self.fix = fix
        super().__init__(_compose(self.path if self.path else "''", option, problem, fix))

    def __str__(self) -> str:
        return self.args[0]


class BenchInputError(RfverifyError):
    """Bad benchmark input: no problems found, an unknown method, a bad, busy or damaged run
    directory, an unusable record (:class:`rfverify.bench.records.RecordError`).  The message
    names the file or option, what is wrong and the fix."""


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


# ---------------------------------------------------------------------- argument checks
def require_positive_number(value, argument: str, *, finite: bool = True) -> float:
    """A real number > 0 (finite unless ``finite=False``): not a string, not a bool."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidArgumentError(argument, f"expected a number, got {type(value).__name__} {value!r}",
                                   fix=f"pass a float, e.g. {argument}=1e-10")
    val = float(value)
    if math.isnan(val) or not val > 0 or (finite and math.isinf(val)):
        raise InvalidArgumentError(argument, f"is {val!r}, expected a {'finite ' if finite else ''}number > 0",
                                   fix=f"pass a positive{' finite' if finite else ''} number, e.g. {argument}=1e-10")
    return val


def require_time_limit(value) -> float | None:
    """A time limit in seconds: None (no limit) or a real number > 0 (not a bool, not NaN).  The
    one check of every entry point's ``time_limit`` (:class:`rfverify.Settings`, hence
    :func:`rfverify.solve` and :func:`rfverify.diagnose`; :func:`rfverify.solve_to_digits`,
    :func:`rfverify.certify`)."""
    if value is not None and not (isinstance(value, numbers.Real) and not isinstance(value, bool) and value > 0):
        raise InvalidArgumentError("time_limit", f"must be a number of seconds > 0, got {value!r}",
                                   fix="pass e.g. time_limit=60, or None for no limit")
    return value


def require_positive_int(value, argument: str) -> int:
    """An integer ≥ 1 (numpy integers accepted; bools, floats and strings refused)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InvalidArgumentError(argument, f"expected an integer, got {type(value).__name__} {value!r}",
                                   fix=f"pass a whole number ≥ 1, e.g. {argument}=100")
    if int(value) < 1:
        raise InvalidArgumentError(argument, f"is {int(value)}, expected an integer ≥ 1",
                                   fix=f"pass a whole number ≥ 1, e.g. {argument}=100")
    return int(value)
