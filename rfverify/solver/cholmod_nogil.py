"""CHOLMOD's numeric factorisation without the GIL.

cvxopt's ``cholmod.numeric`` holds Python's GIL for the whole factorisation (0.2–0.3 s per call at
10⁴ contacts, minutes at 10⁵), so no other thread of the process runs meanwhile.  This module
calls the very function cvxopt calls, ``cholmod_l_factorize`` of the libcholmod cvxopt loaded,
through :mod:`ctypes`, which releases the GIL during a foreign call: the k-digit path prepares its
double-double phase on the second core while the double solve factors (:mod:`rfverify.digits`).

Same library, same symbolic factor (cvxopt's capsule), the same lower triangle and the same
options (CHOLMOD's defaults with ``print`` = 0 and ``supernodal`` = 2, as cvxopt sets them): the
same factor bit for bit (tests/test_cholmod_nogil.py).  Each :class:`Factorizer` owns its
``cholmod_common`` (workspace and options; CHOLMOD is thread-safe across separate ones).

:func:`factorizer` returns None — and callers use cvxopt's call — wherever anything is not as
expected: no ``/proc/self/maps`` (not Linux), no libcholmod among the process's mapped files (a
cvxopt linked statically), or a ``cholmod_common`` whose leading fields, after
``cholmod_l_start``, do not hold CHOLMOD's documented defaults at the offsets of CHOLMOD 3–5.
"""

from __future__ import annotations

import ctypes
import struct
import threading
import weakref

import numpy as np

COMMON_BYTES = 1 << 16
"""Bytes reserved for one ``cholmod_common`` (about 3 KB in CHOLMOD 3.0.6; generous, since the
struct's size is not exported)."""

# Offsets in cholmod_common (CHOLMOD 3–5, LP64): dbound, grow0, grow1 (double), grow2,
# maxrank (size_t), supernodal_switch (double), then the ints supernodal, final_asis, …
_SUPERNODAL_OFFSET = 48
_PRINT_OFFSET = 144
_EXPECTED_DEFAULTS = ((0, "d", 0.0), (8, "d", 1.2), (16, "d", 1.2), (24, "Q", 5), (32, "Q", 8), (40, "d", 40.0),
                      (_SUPERNODAL_OFFSET, "i", 1), (80, "d", 0.8), (104, "Q", 4), (_PRINT_OFFSET, "i", 3))
_CHOLMOD_LONG, _CHOLMOD_REAL, _CHOLMOD_DOUBLE = 2, 1, 0


class _Sparse(ctypes.Structure):
    """``cholmod_sparse`` (unchanged since CHOLMOD 1)."""

    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


_lib = None
_checked = False
_lock = threading.Lock()
_waiting: list[threading.Event] = []  # set at the next GIL-free factorisation: see when_factoring


def when_factoring(event: threading.Event) -> None:
    """Set ``event`` when a GIL-free factorisation next starts in this process (at once if
    this module's call is not available here): the moment other threads can run beside it."""
    if _library() is None:
        event.set()
        return
    with _lock:
        _waiting.append(event)


def forget(event: threading.Event) -> None:
    """Stop waiting to set ``event`` (its owner no longer needs the signal)."""
    with _lock:
        if event in _waiting:
            _waiting.remove(event)


def _wake_waiting() -> None:
    with _lock:
        waiting = _waiting[:]
        _waiting.clear()
    for event in waiting:
        event.set()


def _loaded_libcholmod() -> str | None:
    """The path of the libcholmod this process has mapped (cvxopt's), or None."""
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                fields = line.split(maxsplit=5)  # address perms offset dev inode [pathname]
                path = fields[5].strip() if len(fields) == 6 else ""
                if "/libcholmod" in path:
                    return path
    except OSError:
        return None
    return None


def _library():
    global _lib, _checked
    with _lock:
        if _checked:
            return _lib
        _checked = True
        try:
            import cvxopt.cholmod  # noqa: F401  (maps cvxopt's libcholmod into the process)
        except ImportError:
            return None
        path = _loaded_libcholmod()
        if path is None:
            return None
        try:
            lib = ctypes.CDLL(path)  # the already-loaded library: dlopen returns the same handle
            for name in ("cholmod_l_start", "cholmod_l_finish", "cholmod_l_factorize"):
                getattr(lib, name)
        except (OSError, AttributeError):
            return None
        lib.cholmod_l_start.argtypes = [ctypes.c_void_p]
        lib.cholmod_l_finish.argtypes = [ctypes.c_void_p]
        lib.cholmod_l_factorize.argtypes = [ctypes.POINTER(_Sparse), ctypes.c_void_p, ctypes.c_void_p]
        lib.cholmod_l_factorize.restype = ctypes.c_int
        probe = ctypes.create_string_buffer(COMMON_BYTES)
        if not lib.cholmod_l_start(probe):
            return None
        ok = all(struct.unpack_from(fmt, probe, off)[0] == want for off, fmt, want in _EXPECTED_DEFAULTS)
        lib.cholmod_l_finish(probe)
        _lib = lib if ok else None
        return _lib


_capsule_name = ctypes.pythonapi.PyCapsule_GetName
_capsule_name.restype = ctypes.c_char_p
_capsule_name.argtypes = [ctypes.py_object]
_capsule_pointer = ctypes.pythonapi.PyCapsule_GetPointer
_capsule_pointer.restype = ctypes.c_void_p
_capsule_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]


class Factorizer:
    """``cholmod_l_factorize`` on cvxopt's symbolic factors, the GIL released, with a
    ``cholmod_common`` of its own (freed with the object).  Use from one thread at a time."""

    def __init__(self, lib):
        self._lib = lib
        self._common = ctypes.create_string_buffer(COMMON_BYTES)
        if not lib.cholmod_l_start(self._common):
            raise MemoryError("cholmod_l_start failed")
        struct.pack_into("i", self._common, _PRINT_OFFSET, 0)  # as cvxopt: CHOLMOD prints nothing
        struct.pack_into("i", self._common, _SUPERNODAL_OFFSET, 2)
        weakref.finalize(self, lib.cholmod_l_finish, self._common)

    def factorize(self, factor, indptr: np.ndarray, indices: np.ndarray, values: np.ndarray) -> int | None:
        """Refactor cvxopt's symbolic/numeric factor ``factor`` (a "CHOLMOD FACTOR D L"
        capsule) with the lower triangle (CSC: int64 ``indptr``, sorted int64 ``indices``,
        float64 ``values``; the pattern it was analysed with).  Returns the column CHOLMOD
        stopped at (the order n when the matrix is positive definite), or None when CHOLMOD
        reports an error (out of memory, invalid input): the caller then asks cvxopt, whose
        call says which."""
        name = _capsule_name(factor)
        if name != b"CHOLMOD FACTOR D L":
            raise TypeError(f"not cvxopt's factor of a lower-triangle 'd' matrix: {name!r}")
        n = indptr.size - 1
        if not (indptr.dtype == indices.dtype == np.int64 and values.dtype == np.float64
                and indptr.flags.c_contiguous and indices.flags.c_contiguous and values.flags.c_contiguous
                and values.size == indices.size == indptr[-1]):
            raise ValueError("factorize needs contiguous int64 indptr/indices and float64 values of one size")
        L = _capsule_pointer(factor, name)
        if ctypes.c_size_t.from_address(L).value != n:  # cholmod_factor starts with n, minor
            raise ValueError("the factor is not of this order")
        A = _Sparse(n, n, values.size, indptr.ctypes.data, indices.ctypes.data, None, values.ctypes.data, None,
                    -1, _CHOLMOD_LONG, _CHOLMOD_REAL, _CHOLMOD_DOUBLE, 1, 1)
        if _waiting:
            _wake_waiting()
        if not self._lib.cholmod_l_factorize(ctypes.byref(A), L, self._common):
            return None
        return int(ctypes.c_size_t.from_address(L + ctypes.sizeof(ctypes.c_size_t)).value)


def available() -> bool:
    """True when the GIL-free call can be used here (see the module's docstring)."""
    return _library() is not None


def factorizer() -> Factorizer | None:
    """A :class:`Factorizer`, or None where the GIL-free call is not available here (see the
    module's docstring)."""
    lib = _library()
    return None if lib is None else Factorizer(lib)


def factor_counts(factor) -> tuple[np.ndarray, np.ndarray] | None:
    """(P, column counts of L) of cvxopt's analysed CHOLMOD factor ``factor``, copied from the
    factor itself (``L->Perm``, ``L->ColCount``: int64 arrays of the order n; the leading fields
    of ``cholmod_factor`` since CHOLMOD 1), or None where the GIL-free library is not in use
    here.  The counts include the diagonal: nnz(L) is their sum."""
    if _library() is None:
        return None
    name = _capsule_name(factor)
    if name not in (b"CHOLMOD FACTOR D L", b"CHOLMOD FACTOR D U"):
        raise TypeError(f"not cvxopt's factor of a 'd' matrix: {name!r}")
    L = _capsule_pointer(factor, name)
    word = ctypes.sizeof(ctypes.c_size_t)
    n = ctypes.c_size_t.from_address(L).value
    perm_at, count_at = (ctypes.c_void_p.from_address(L + k * word).value for k in (2, 3))
    if not perm_at or not count_at:
        return None
    perm = np.ctypeslib.as_array((ctypes.c_int64 * n).from_address(perm_at)).copy()
    counts = np.ctypeslib.as_array((ctypes.c_int64 * n).from_address(count_at)).copy()
    return perm, counts
