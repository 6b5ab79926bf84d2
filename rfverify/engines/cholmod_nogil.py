"""CHOLMOD through :mod:`ctypes`, with a ``cholmod_common`` of rfverify's own: the symbolic
analysis, the numeric factorisation and the solves, all without the GIL.

Two reasons not to call cvxopt's ``cholmod.symbolic``/``numeric``/``solve``:

* they hold Python's GIL for the whole call (0.2–0.3 s per factorisation at 10⁴ contacts,
  minutes at 10⁵), so no other thread of the process runs meanwhile; a foreign call through
  ctypes releases it: the k-digit path prepares its double-double phase on the second core while
  the double solve factors (:mod:`rfverify.verify.digits`);
* they take their options from cvxopt's module-global ``cvxopt.cholmod.options`` (a user's
  ``{"postorder": False}`` or ``{"nmethods": 1}`` changes the ordering, hence every answer bit
  for bit), and setting them around a call makes rfverify's settings visible to the user's
  other threads.  rfverify neither reads nor writes that dictionary.

Same library (the libcholmod cvxopt loaded), the same calls cvxopt makes
(``cholmod_l_analyze_p``, ``cholmod_l_factorize``, ``cholmod_l_solve`` on a packed, sorted lower
triangle) and the options cvxopt applies with an empty ``options`` dictionary (CHOLMOD's
defaults with ``print`` = 0 and ``supernodal`` = 2): the same factor and the same solves bit for
bit as cvxopt's own calls under its default options (tests/test_cholmod_nogil.py).  Each
:class:`Cholmod` owns its ``cholmod_common`` (workspace and options; CHOLMOD is thread-safe across
separate ones) and its factor.

:func:`session` returns None — and the engines fall back to QDLDL — wherever anything is not as
expected: no libcholmod among the process's mapped files nor in cvxopt's package, or a
``cholmod_common`` whose leading fields, after ``cholmod_l_start``, do not hold CHOLMOD's
documented defaults at the offsets of CHOLMOD 3–5.
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

INTERRUPTIBLE_MIN_ENTRIES = 1_000_000
"""A numeric factorisation whose L has at least this many entries (about 0.05 s and up), called
from the main thread, runs on a helper thread while the main thread waits in
:data:`WAIT_SECONDS` slices, so that a Ctrl-C is raised at once instead of after the
factorisation (seconds at 10⁴ contacts, half a minute at 10⁵).  CHOLMOD cannot be stopped: the
factorisation finishes on its thread, which keeps the factor alive until then, and the factor
refuses every other call meanwhile.  The thread is not a daemon: the process ends after it (at
exit the BLAS libraries are torn down, and a factorisation still running in them crashes it),
and the command line says so while it waits (:func:`left_running`)."""

WAIT_SECONDS = 0.1

_left_running: set[threading.Thread] = set()  # factorisations a Ctrl-C left running


def left_running() -> list[threading.Thread]:
    """The helper threads of factorisations that a Ctrl-C left running and that have not ended
    yet (join them before the process exits)."""
    ended = {t for t in list(_left_running) if not t.is_alive()}
    _left_running.difference_update(ended)
    return list(_left_running)


class _Dense(ctypes.Structure):
    """``cholmod_dense`` (unchanged since CHOLMOD 1)."""

    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("d", ctypes.c_size_t), ("x", ctypes.c_void_p), ("z", ctypes.c_void_p), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int)]


class _Sparse(ctypes.Structure):
    """``cholmod_sparse`` (unchanged since CHOLMOD 1)."""

    _fields_ = [("nrow", ctypes.c_size_t), ("ncol", ctypes.c_size_t), ("nzmax", ctypes.c_size_t),
                ("p", ctypes.c_void_p), ("i", ctypes.c_void_p), ("nz", ctypes.c_void_p), ("x", ctypes.c_void_p),
                ("z", ctypes.c_void_p), ("stype", ctypes.c_int), ("itype", ctypes.c_int), ("xtype", ctypes.c_int),
                ("dtype", ctypes.c_int), ("sorted", ctypes.c_int), ("packed", ctypes.c_int)]


_FUNCTIONS = {
    "cholmod_l_start": ([ctypes.c_void_p], ctypes.c_int),
    "cholmod_l_finish": ([ctypes.c_void_p], ctypes.c_int),
    "cholmod_l_analyze_p": ([ctypes.POINTER(_Sparse), ctypes.c_void_p, ctypes.c_void_p, ctypes.c_size_t,
                             ctypes.c_void_p], ctypes.c_void_p),
    "cholmod_l_factorize": ([ctypes.POINTER(_Sparse), ctypes.c_void_p, ctypes.c_void_p], ctypes.c_int),
    "cholmod_l_solve": ([ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(_Dense), ctypes.c_void_p], ctypes.c_void_p),
    "cholmod_l_free_dense": ([ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p], ctypes.c_int),
    "cholmod_l_free_factor": ([ctypes.POINTER(ctypes.c_void_p), ctypes.c_void_p], ctypes.c_int),
}
"""The CHOLMOD functions called here, with their C signatures (CHOLMOD 3–5, SuiteSparse_long
indices): the same ones cvxopt's cholmod module calls."""
_CHOLMOD_A = 0  # cholmod_solve's sys for A x = b

_lib = None
_checked = False
_lock = threading.Lock()


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


def _packaged_libcholmod() -> str | None:
    """The libcholmod shipped inside cvxopt's wheel (``cvxopt.libs`` beside the package on
    Linux, ``cvxopt/.dylibs`` on macOS), where the mapped files cannot be listed; None if absent."""
    import glob
    import os

    try:
        import cvxopt
    except ImportError:
        return None
    here = os.path.dirname(cvxopt.__file__)
    for pattern in (os.path.join(here + ".libs", "libcholmod*"), os.path.join(here, ".dylibs", "libcholmod*")):
        found = sorted(glob.glob(pattern))
        if found:
            return found[0]
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
        path = _loaded_libcholmod() or _packaged_libcholmod()
        if path is None:
            return None
        try:
            lib = ctypes.CDLL(path)  # the already-loaded library: dlopen returns the same handle
            for name in _FUNCTIONS:
                getattr(lib, name)
        except (OSError, AttributeError):
            return None
        for name, (argtypes, restype) in _FUNCTIONS.items():
            getattr(lib, name).argtypes = argtypes
            getattr(lib, name).restype = restype
        probe = ctypes.create_string_buffer(COMMON_BYTES)
        if not lib.cholmod_l_start(probe):
            return None
        ok = all(struct.unpack_from(fmt, probe, off)[0] == want for off, fmt, want in _EXPECTED_DEFAULTS)
        lib.cholmod_l_finish(probe)
        _lib = lib if ok else None
        return _lib


class Cholmod:
    """One sparse Cholesky factorisation through CHOLMOD, with a ``cholmod_common`` of its own
    (freed with the object): :meth:`analyse` a lower-triangle pattern, :meth:`factorize` values
    on it (again and again), :meth:`solve`.  Every call releases the GIL.  Use from one thread
    at a time."""

    def __init__(self, lib):
        self._lib = lib
        self._common = ctypes.create_string_buffer(COMMON_BYTES)
        if not lib.cholmod_l_start(self._common):
            raise MemoryError("cholmod_l_start failed")
        # cvxopt's options with an empty options dictionary: CHOLMOD's defaults, print 0, supernodal 2
        struct.pack_into("i", self._common, _PRINT_OFFSET, 0)
        struct.pack_into("i", self._common, _SUPERNODAL_OFFSET, 2)
        self._factor = ctypes.c_void_p(None)
        self._pattern = None  # (indptr, indices) of the analysed lower triangle, int64
        self._numeric = False
        self._large = False  # L has INTERRUPTIBLE_MIN_ENTRIES entries or more
        # Set while a factorisation left running by a Ctrl-C goes on, on its helper thread.
        self._running = threading.Event()
        weakref.finalize(self, _finish, lib, self._factor, self._common, self._running)

    @property
    def analysed(self) -> bool:
        return bool(self._factor.value)

    @property
    def numeric(self) -> bool:
        """True when the last :meth:`factorize` succeeded (solves are possible)."""
        return self._numeric

    def analyse(self, indptr: np.ndarray, indices: np.ndarray, perm: np.ndarray | None = None) -> bool:
        """Symbolic analysis of the lower triangle with this pattern (CSC, int64, sorted): AMD,
        or — given ``perm`` — the better of ``perm`` and AMD (CHOLMOD's choice with its default
        ``nmethods``).  Returns False when CHOLMOD reports an error (out of memory)."""
        self._idle("analyse")
        self.release()
        n = indptr.size - 1
        indptr, indices = _int64(indptr), _int64(indices)
        values = np.zeros(indices.size)  # the analysis reads the pattern only
        A = _Sparse(n, n, indices.size, indptr.ctypes.data, indices.ctypes.data, None, values.ctypes.data, None,
                    -1, _CHOLMOD_LONG, _CHOLMOD_REAL, _CHOLMOD_DOUBLE, 1, 1)
        p = None if perm is None else _int64(perm)
        L = self._lib.cholmod_l_analyze_p(ctypes.byref(A), None if p is None else p.ctypes.data, None, 0,
                                          self._common)
        if not L:
            return False
        self._factor.value = L
        self._pattern = (indptr, indices)
        counts = self.counts()
        self._large = counts is not None and int(counts[1].sum()) >= INTERRUPTIBLE_MIN_ENTRIES
        return True

    def factorize(self, values: np.ndarray) -> int | None:
        """Numeric factorisation of the analysed pattern with ``values`` (float64, one per stored
        entry).  Returns the column CHOLMOD stopped at (the order n when the matrix is positive
        definite), or None when CHOLMOD reports an error (out of memory, invalid input)."""
        self._idle("factorize")
        if not self.analysed:
            raise ValueError("factorize needs an analysed pattern (analyse first)")
        indptr, indices = self._pattern
        values = np.ascontiguousarray(values, dtype=np.float64)
        if values.size != indices.size:
            raise ValueError(f"factorize needs {indices.size} values, got {values.size}")
        n = indptr.size - 1
        A = _Sparse(n, n, values.size, indptr.ctypes.data, indices.ctypes.data, None, values.ctypes.data, None,
                    -1, _CHOLMOD_LONG, _CHOLMOD_REAL, _CHOLMOD_DOUBLE, 1, 1)
        self._numeric = False

        def factorize():
            # A points into values, indptr and indices without owning them: holding them here
            # keeps them (and self, so the factor) alive while CHOLMOD reads them, also after
            # a Ctrl-C has left this call running on its helper thread.
            _ = (values, indptr, indices)
            return self._lib.cholmod_l_factorize(ctypes.byref(A), self._factor, self._common)

        interruptible = self._large and threading.current_thread() is threading.main_thread()
        if not (self._interruptibly(factorize) if interruptible else factorize()):
            return None
        column = int(ctypes.c_size_t.from_address(self._factor.value + ctypes.sizeof(ctypes.c_size_t)).value)
        self._numeric = column >= n
        return column

    def _interruptibly(self, call):
        """``call()`` on a helper thread while this (main) thread waits; a Ctrl-C meanwhile is
        raised here at once and the call left to finish on its thread (:data:`INTERRUPTIBLE_MIN_ENTRIES`)."""
        done, failed = [], []
        finished = threading.Event()
        self._running.set()

        def work():
            try:
                done.append(call())
            except BaseException as exc:  # handed to the waiting thread
                failed.append(exc)
            finally:
                self._running.clear()
                finished.set()

        thread = threading.Thread(target=work, name="rfverify-cholmod")
        try:
            thread.start()
            while not finished.wait(WAIT_SECONDS):  # not Thread.join: see rfverify.extended.stoppable
                pass
        except BaseException:
            if thread.ident is None:  # it never started (no thread to be had): nothing runs
                self._running.clear()
            else:
                _left_running.add(thread)
            raise
        if failed:
            raise failed[0]
        return done[0]

    def _idle(self, what: str) -> None:
        if self._running.is_set():
            raise RuntimeError(f"CHOLMOD: cannot {what} while a factorisation interrupted by Ctrl-C is still "
                               "running on this factor")

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """A⁻¹ rhs with the last successful factorisation (a new float64 array)."""
        self._idle("solve")
        if not self._numeric:
            raise ValueError("solve needs a successful numeric factorisation")
        n = self._pattern[0].size - 1
        b = np.array(rhs, dtype=np.float64).reshape(-1)
        if b.size != n:
            raise ValueError(f"the right-hand side has {b.size} entries, the matrix order is {n}")
        if n == 0:
            return b
        B = _Dense(n, 1, n, n, b.ctypes.data, None, _CHOLMOD_REAL, _CHOLMOD_DOUBLE)
        X = self._lib.cholmod_l_solve(_CHOLMOD_A, self._factor, ctypes.byref(B), self._common)
        if not X:
            raise MemoryError("CHOLMOD's solve failed (out of memory)")
        try:
            x = _Dense.from_address(X)
            out = np.ctypeslib.as_array((ctypes.c_double * n).from_address(x.x)).copy()
        finally:
            self._lib.cholmod_l_free_dense(ctypes.byref(ctypes.c_void_p(X)), self._common)
        return out

    def counts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(P, column counts of L) of the analysed factor (``L->Perm``, ``L->ColCount``: int64
        arrays of the order n; the leading fields of ``cholmod_factor`` since CHOLMOD 1), or None
        before the analysis.  The counts include the diagonal: nnz(L) is their sum."""
        if not self.analysed:
            return None
        L = self._factor.value
        word = ctypes.sizeof(ctypes.c_size_t)
        n = ctypes.c_size_t.from_address(L).value
        perm_at, count_at = (ctypes.c_void_p.from_address(L + k * word).value for k in (2, 3))
        if not perm_at or not count_at:
            return None
        perm = np.ctypeslib.as_array((ctypes.c_int64 * n).from_address(perm_at)).copy()
        counts = np.ctypeslib.as_array((ctypes.c_int64 * n).from_address(count_at)).copy()
        return perm, counts

    def release(self) -> None:
        """Free the factor (and its analysis)."""
        self._idle("release")
        if self._factor.value:
            self._lib.cholmod_l_free_factor(ctypes.byref(self._factor), self._common)
            self._factor.value = None
        self._pattern = None
        self._numeric = False


def _finish(lib, factor: ctypes.c_void_p, common, running: threading.Event) -> None:
    """Free a :class:`Cholmod`'s factor, then its common (the factor needs the common to be freed);
    nothing at the interpreter's exit while a factorisation left running by a Ctrl-C still uses
    them (the process's end frees them)."""
    if running.is_set():
        return
    if factor.value:
        lib.cholmod_l_free_factor(ctypes.byref(factor), common)
    lib.cholmod_l_finish(common)


def _int64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.int64)


def available() -> bool:
    """True when CHOLMOD can be called here (see the module's docstring)."""
    return _library() is not None


def session() -> Cholmod | None:
    """A :class:`Cholmod`, or None where CHOLMOD cannot be called here (see the module's
    docstring)."""
    lib = _library()
    return None if lib is None else Cholmod(lib)
