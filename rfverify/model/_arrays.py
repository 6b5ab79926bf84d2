"""The arrays of a :class:`~rfverify.model.problem.Problem` as it checks and keeps them: any matrix
or vector given converted to float64 (CSC, duplicates summed, indices sorted; a flat vector),
every entry checked finite (the first offending index named), and read-only copies that
alias nothing the caller holds.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidProblemError


def _refuse_complex(name: str, x) -> None:
    """Complex data would lose its imaginary part in the float64 conversion, silently."""
    dtype = x.dtype if sp.issparse(x) or isinstance(x, np.ndarray) else np.asarray(x).dtype
    if np.issubdtype(dtype, np.complexfloating):
        raise InvalidProblemError(name, "is complex; the contact problem is real",
                                  fix="pass real data (the real part, if the imaginary part is rounding)")


def as_csc(name: str, A) -> sp.csc_matrix:
    """``A`` (dense or sparse) as a new float64 CSC matrix, duplicates summed, indices sorted."""
    _refuse_complex(name, A)
    try:
        if sp.issparse(A):
            A = sp.csc_matrix(A, dtype=np.float64, copy=True)  # never sort the caller's matrix
        else:
            arr = np.asarray(A, dtype=np.float64)
            if arr.ndim != 2:
                raise InvalidProblemError(name, f"has {arr.ndim} dimensions, expected a matrix",
                                          fix="pass a 2-D array or a scipy.sparse matrix")
            A = sp.csc_matrix(arr)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InvalidProblemError):
            raise
        raise InvalidProblemError(name, f"cannot be converted to a float64 matrix ({exc})",
                                  fix="pass numeric data") from None
    A.sum_duplicates()
    A.sort_indices()
    return A


def as_vector(name: str, x) -> np.ndarray:
    """``x`` as a new flat float64 vector (a row or column matrix is flattened)."""
    _refuse_complex(name, x)
    try:
        arr = np.array(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidProblemError(name, f"cannot be converted to a float64 vector ({exc})",
                                  fix="pass numeric data") from None
    if arr.ndim != 1:
        if arr.ndim == 2 and 1 in arr.shape:
            arr = arr.ravel()
        else:
            raise InvalidProblemError(name, f"has shape {arr.shape}, expected a 1-D vector",
                                      fix="pass a flat array")
    return arr


def check_finite_vector(name: str, x: np.ndarray):
    bad = np.flatnonzero(~np.isfinite(x))
    if bad.size:
        raise InvalidProblemError(name, f"contains a non-finite value ({float(x[bad[0]])!r}) at index "
                                        f"{bad[0]} ({bad.size} in all)",
                                  index=int(bad[0]), fix="remove NaN/Inf from the data")


def check_finite_sparse(name: str, A: sp.csc_matrix):
    bad = np.flatnonzero(~np.isfinite(A.data))
    if bad.size:
        k = int(bad[0])
        col = int(np.searchsorted(A.indptr, k, side="right") - 1)
        row = int(A.indices[k])
        raise InvalidProblemError(name, f"contains a non-finite value ({float(A.data[k])!r}) at "
                                        f"({row}, {col}) ({bad.size} in all)",
                                  index=(row, col), fix="remove NaN/Inf from the data")


def freeze(a: np.ndarray) -> np.ndarray:
    """A read-only float64 copy of ``a``."""
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def freeze_sparse(A: sp.csc_matrix) -> sp.csc_matrix:
    """A CSC copy of ``A`` whose arrays are read-only."""
    A = sp.csc_matrix(A, copy=True)
    for arr in (A.data, A.indices, A.indptr):
        arr.setflags(write=False)
    return A
