"""Argument checks and power-of-two scaling of the Jordan-algebra operations (see
:mod:`rfverify.jordan`)."""

from __future__ import annotations

import numpy as np

from ..errors import ConeDomainError


# --------------------------------------------------------------------------------------------
# argument checks and power-of-two scaling
# --------------------------------------------------------------------------------------------


def _prepare(op, names, *args):
    """Validate and convert the arguments of a public function: returns (single, [2-D arrays
    of the common dtype]).  Non-finite entries raise ConeDomainError(op) here."""
    arrs = []
    for name, a in zip(names, args):
        a = np.asarray(a)
        if a.dtype.kind not in "biuf":
            raise TypeError(
                f"{op}: argument '{name}' must be a real numeric array, got dtype {a.dtype}"
            )
        if a.ndim not in (1, 2) or a.shape[-1] < 1:
            raise ValueError(
                f"{op}: argument '{name}' must have shape (k,) or (N, k) with k >= 1, "
                f"got shape {a.shape}"
            )
        arrs.append(a)
    dtype = np.result_type(*arrs, np.float64)
    ks = {a.shape[-1] for a in arrs}
    if len(ks) > 1:
        raise ValueError(
            f"{op}: arguments have different cone dimensions "
            + ", ".join(f"{n}: k={a.shape[-1]}" for n, a in zip(names, arrs))
        )
    single = all(a.ndim == 1 for a in arrs)
    out = []
    for name, a in zip(names, arrs):
        a2 = np.asarray(a, dtype=dtype).reshape(-1, a.shape[-1])
        _require_finite(op, name, a2, a.ndim == 1)
        out.append(a2)
    if len(out) > 1:
        try:
            out = list(np.broadcast_arrays(*out))
        except ValueError:
            raise ValueError(
                f"{op}: batch sizes do not match: "
                + ", ".join(f"{n}: {np.shape(a)}" for n, a in zip(names, arrs))
            ) from None
    return single, out


def _require_finite(op, name, x, single):
    if np.isfinite(x).all():
        return
    i = int(np.argmin(np.isfinite(x).all(axis=1)))
    val = x[i][~np.isfinite(x[i])][0]
    raise ConeDomainError(
        op,
        f"argument '{name}' contains a non-finite entry ({val}); the operation is undefined — "
        "check where the NaN/Inf was produced upstream",
        cone=_cone_index(i, single),
        value=float(val),
    )


def _out(a, single):
    return a[0] if single else a


def _cone_index(i, single):
    return None if single else int(i)


def _raise_first(op, bad, single, describe):
    """ConeDomainError(op) at the first row where ``bad`` holds; ``describe(i)`` returns the
    message and the offending value for row i."""
    if bad.any():
        i = int(np.argmax(bad))
        text, value = describe(i)
        raise ConeDomainError(op, text, cone=_cone_index(i, single), value=value)


def _check_nan_free(op, out, single, scale=True):
    """out, or ConeDomainError(op) at the first row holding a NaN.  With ``scale=False`` the
    inputs were shown moderate() and passed the domain checks, so every intermediate of the
    kernels is finite and there is nothing to look for."""
    if not scale:
        return out
    bad = np.isnan(out)
    if bad.any():
        i = int(np.argmax(bad.reshape(bad.shape[0], -1).any(axis=1)))
        raise ConeDomainError(
            op,
            "the result is not representable in this dtype (intermediate overflow); "
            "rescale the data",
            cone=_cone_index(i, single),
            value=float("nan"),
        )
    return out


_BOUNDS = {}


def _bounds(dtype):
    """(T, 2^T, 2^-T) with T = maxexp/8 of the dtype; the powers as float64 numbers (inf and 0
    where float64 cannot hold them)."""
    b = _BOUNDS.get(dtype)
    if b is None:
        t = np.finfo(dtype).maxexp // 8
        b = _BOUNDS[dtype] = (t, np.ldexp(1.0, t) if t < 1024 else np.inf,
                              np.ldexp(1.0, -t) if t < 1074 else 0.0)
    return b


def moderate(*arrays) -> bool:
    """True when provably no row of the arrays needs rescaling: every nonzero |entry| lies in
    [2^-T, 2^T], hence so does every row's maximum (the criterion of :func:`_scaled`), and
    every entry is finite.  Row operations may then be called with ``scale=False``: products
    of up to four such numbers stay finite and normal, so once the domain checks pass no
    kernel can produce a NaN.

    Checked on the float64 image, which costs a fifth of longdouble arithmetic; False where
    that image cannot tell (NaN, Inf, entries beyond float64's range or flushed to 0 by the
    cast), and the row operations then look row by row.
    """
    for x in arrays:
        if x.size == 0:
            continue
        _, hi, lo = _bounds(x.dtype)
        if x.dtype == np.float64:
            mag = np.abs(x)
        else:
            with np.errstate(over="ignore"):
                mag = np.abs(x.astype(np.float64))
        top = mag.max()
        if not (top <= hi and top < np.inf):  # also catches NaN
            return False
        if lo > 0:
            small = mag < lo
            if small.any() and (small & (mag > 0)).any():
                return False
        elif mag.min() == 0 and x[mag == 0].any():
            return False  # longdouble entries below float64's range, flushed to 0 by the cast
    return True


def _scale_exponents(x):
    """Per-row exponent e (a multiple of 4) with x·2^-e of moderate size.

    Rows whose largest entry lies in [2^-T, 2^T] are left alone (e = 0): there products of up
    to four numbers of the row's magnitude (det·y, Q_x y, ...) can neither overflow nor reach
    the subnormal range, and leaving such rows untouched keeps ordinary results bit-for-bit
    equal to the textbook formulas.  Other rows are brought to max|x̂_i| in [2^-4, 1).  A
    multiple of 4 makes 2^(e/2) and 2^(e/4) exact, which sqrt and the NT scaling need.
    """
    m = np.max(np.abs(x), axis=-1)
    t = _bounds(x.dtype)[0]
    _, e = np.frexp(m)
    e = -((-e.astype(np.int64)) // 4) * 4
    extreme = (m > 0) & ((m > np.ldexp(np.ones_like(m), t)) | (m < np.ldexp(np.ones_like(m), -t)))
    return np.where(extreme, e, 0)


def _scaled(x, op, name, single, scale=True):
    """(x̂, e) with x = x̂·2^e row by row; e = 0 (a scalar) when no row needs rescaling, which
    ``scale=False`` asserts (the caller has checked :func:`moderate`).  Non-finite entries
    raise ConeDomainError(op) naming the argument."""
    if not scale or moderate(x):
        return x, 0
    _require_finite(op, name, x, single)
    e = _scale_exponents(x)
    if not e.any():
        return x, 0
    return np.ldexp(x, -e[:, None]), e


def _shift(a, e):
    """a·2^e row by row (exact barring over/underflow); e = 0 (no row rescaled) leaves a
    untouched."""
    if not isinstance(e, np.ndarray):
        return a
    return np.ldexp(a, e.reshape(e.shape + (1,) * (a.ndim - 1)))


def _take(e, rows):
    return e[rows] if isinstance(e, np.ndarray) else e


def _at(a, e, i):
    """a[i]·2^e[i] as a Python float (the unscaled value, for messages)."""
    return float(np.ldexp(a[i], _take(e, i)))
