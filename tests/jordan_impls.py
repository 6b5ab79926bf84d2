r"""The two implementations of DESIGN §3 behind one small interface, so that each identity is
written once and run against both (tests/test_jordan.py) and the two can be compared
(tests/test_reference_jordan.py).

* :class:`Production` — :mod:`rfverify.jordan` in float64 or ``numpy.longdouble``, called on a
  batch of cones (an ``(n, k)`` array: the vectorised path the solver uses).
* :class:`Reference` — :mod:`reference.jordan` in a private mpmath context of 50 or 30 digits,
  one cone at a time (a batch is a list of cones).

Both take the same cases: a tuple of :class:`Drawn` vectors (hypothesis, :func:`cases`) or of
:class:`Pin` arrays (pinned hard cases), which each implementation turns into its own inputs
(:meth:`Impl.inputs`); results are read back with :meth:`Impl.out`, which also asserts that they
are numbers of the implementation (the dtype under test, or the private context).

How the tolerances are built
----------------------------
``u`` is the unit of the arithmetic under test: ``numpy.finfo(dtype).eps`` for the production
code, ``ctx.eps = 2^(1-prec)`` for the reference (``2.7e-51`` at 50 digits, ``2.0e-30`` at 30).
``k`` is the cone dimension; for a vector ``x``, ``S(x) = |x0| + ‖x̄‖ = max|λi(x)|`` is its scale
and, for ``x ∈ int L``, ``κ(x) = λ1/λ2`` its conditioning (``cond(Q_x) = κ²``).  Every bound has
the form ``C·(k+2)^j·u·(conditioning)·(scale)``; the docstring of each test states it and gives
the forward-error argument.  The facts used throughout:

* ``‖x̄‖`` has relative error ``O(k u)`` (``≤ 1.5u`` in the reference: exact sum of exact
  squares, one rounding, a correctly rounded sqrt), so ``λ1`` has relative error ``O(k u)`` and
  ``λ2 = x0 − ‖x̄‖`` absolute error ``O(k u S)``, i.e. relative error ``O(k u κ)`` — ``κ`` is the
  condition number of ``λ2`` itself, so this is what a backward-stable code delivers.
* a sum of ``k`` products of entries bounded by ``a`` and ``b`` has error ``≤ k u a b``.
* results below a dtype's subnormal range underflow: :func:`check` adds an absolute floor of
  16 subnormal quanta of the dtype (none for mpmath, whose exponents are unbounded).

**Checking arithmetic** is a separate context ``HI`` with 140 digits, into which every float64,
longdouble and ≤ 140-digit value converts exactly; residuals and oracles (textbook formulas:
the exact ``x0² − ‖x̄‖²``, ``2Arw(x)² − Arw(x²)``, matrix products) are evaluated there, so the
checking side adds nothing measurable (``1e-140``) to the errors being bounded.

**Inputs** are float64 vectors with ``k ∈ {1, 2, 3, 5}``: interior points with ``λ1 = 10^s``,
``λ2/λ1 = 10^r`` and a random direction (an all-zero direction gives ``x̄ = 0``), or arbitrary
vectors of size ``10^s``.  The ranges are the implementation's, so that every bound means
something in its precision: production ``s ∈ [−3, 3]``, ``r ∈ [−6, 0]``, batches of 1–4 cones;
reference ``s ∈ [−100, 100]``, ``r ∈ [−12, 0]``, one cone (tests widen or narrow them where
their docstring says).  Longdouble inputs are jittered at the 2^-60 level so they carry bits
below float64 precision (a computation that silently went through float64 then shows up); the
reference converts its inputs exactly.  The known-hard cases (``λ2 → 0`` at relative distance
1e-12 and eps, ``λ2 ~ 1e-300``, ``x̄ = 0``, scales 1e±150 (1e±100 for the reference: its range),
subnormal ``x̄``) are pinned with ``@example`` and run against every implementation.

The constants ``C`` are small (1–8), calibrated on instrumented runs (``JORDAN_RATIOS=1`` and
``-s`` print the worst ``error/bound`` of every check): see the worst ratios quoted in
tests/test_jordan.py.  A formula error shows up as an O(1) relative error, many orders of
magnitude above these bounds.
"""

from __future__ import annotations

import math
import os
from typing import NamedTuple

import mpmath
import numpy as np
import pytest
from hypothesis import assume, example
from hypothesis import strategies as st

from reference import jordan as R
from rfverify import jordan as J
from rfverify.errors import ConeDomainError

LD = np.longdouble
KS = (1, 2, 3, 5)
KS_FRAME = (2, 3, 5)
HI = R.context(140)  # checking arithmetic: every value under test converts exactly
_HI_MPF = type(HI.mpf(1))
MAX_BATCH = 4


# ------------------------------------------------------------------------------------------
# checking arithmetic (all in HI)
# ------------------------------------------------------------------------------------------

_WORST: dict[str, float] = {}


@pytest.fixture(scope="module", autouse=True)
def report_worst_ratios():
    """With JORDAN_RATIOS=1 (and -s), print the worst error/bound of every check of the module
    (an autouse fixture wherever it is imported)."""
    yield
    if os.environ.get("JORDAN_RATIOS"):
        print("\nworst error/bound ratios:")
        for what, r in sorted(_WORST.items(), key=lambda t: -t[1]):
            print(f"  {r:9.3g}  {what}")
    _WORST.clear()


def H(v):
    """To the checking context (exact for float64, longdouble and every mpf of <= 140 digits);
    ±inf (α = inf, cond = inf, an overflowed float) maps to ±HI.inf.  Arrays and lists keep
    their nesting (a batch becomes a list of cones)."""
    t = type(v)
    if t is _HI_MPF:  # the helpers below pass their results around: no work then
        return v
    if t is list or t is tuple:
        return [x if type(x) is _HI_MPF else H(x) for x in v]
    if t is float or t is np.float64:  # exact, and fast: the bulk of the production's numbers
        if v != v:
            raise ValueError("NaN where a number was expected")
        return HI.mpf(float(v))
    if hasattr(v, "_mpf_") and v._mpf_[3] <= HI.prec:  # an mpf of at most 140 digits: exact
        return HI.make_mpf(v._mpf_)
    if t is np.ndarray:
        if v.ndim == 0:
            return H(v[()])
        return H(v.tolist()) if v.dtype == np.float64 else [H(x) for x in v]
    if (hasattr(v, "_mpf_") and mpmath.isinf(v)) or (isinstance(v, (float, np.floating)) and np.isinf(v)):
        return HI.inf if v > 0 else -HI.inf
    return R.to_ctx(HI, v)


def o_norm(x):
    x = H(x)
    return HI.sqrt(HI.fsum(x[1:], squared=True)) if len(x) > 1 else HI.zero


def o_lams(x):
    x = H(x)
    n = o_norm(x)
    return x[0] + n, x[0] - n


def o_det(x):
    """Exact x0² − ‖x̄‖² (for k = 1: x0²): exact squares, exact sum, one rounding in HI."""
    x = H(x)
    if len(x) == 1:
        return x[0] * x[0]
    return HI.fsum([x[0] * x[0]] + [-(v * v) for v in x[1:]])


def o_inverse(x):
    """Exact R x / det x (k = 1: 1/x0)."""
    x = H(x)
    if len(x) == 1:
        return [1 / x[0]]
    d = o_det(x)
    return [x[0] / d] + [-v / d for v in x[1:]]


def scale(x):
    x = H(x)
    return abs(x[0]) + o_norm(x)


def kappa(x):
    l1, l2 = o_lams(x)
    return l1 / l2 if l2 > 0 else HI.inf


def o_product(x, y):
    x, y = H(x), H(y)
    return [HI.fdot(x, y)] + [HI.fdot(((x[0], b), (y[0], a))) for a, b in zip(x[1:], y[1:])]


def o_arrow(x):
    x = H(x)
    k = len(x)
    rows = [list(x)]
    for i in range(1, k):
        row = [HI.zero] * k
        row[0], row[i] = x[i], x[0]
        rows.append(row)
    return rows


def matmul(a, b):
    a, b = H(a), H(b)
    cols = list(zip(*b))
    return [[HI.fdot(r, c) for c in cols] for r in a]


def matvec(a, v):
    a, v = H(a), H(v)
    return [HI.fdot(r, v) for r in a]


def o_quad_matrix(x):
    """Textbook Q_x = 2Arw(x)² − Arw(x∘x), independent of the 2xxᵀ − det(x)R formula."""
    a = o_arrow(x)
    a2 = o_arrow(o_product(x, x))
    return [[2 * p - q for p, q in zip(r1, r2)] for r1, r2 in zip(matmul(a, a), a2)]


def maxabs(v):
    return max(abs(t) for t in H(v))


def diff(a, b):
    return max(abs(p - q) for p, q in zip(H(a), H(b)))


def mdiff(a, b):
    return max(diff(r, s) for r, s in zip(a, b))


def eye(k):
    return [[HI.mpf(1) if i == j else HI.zero for j in range(k)] for i in range(k)]


def unit(k):
    return [HI.mpf(1)] + [HI.zero] * (k - 1)


def check(impl, err, bound, what):
    """Assert err <= bound + the underflow floor of ``impl`` (HI numbers); record the worst
    ratio per check and implementation."""
    err, bound = H(err), H(bound) + impl.floor
    ratio = float(err / bound) if bound else (0.0 if not err else math.inf)
    key = f"{what} [{impl.name}]"
    if ratio > _WORST.get(key, -1.0):
        _WORST[key] = ratio
    if not err <= bound:
        pytest.fail(f"{key}: error {HI.nstr(err, 5)} exceeds bound {HI.nstr(bound, 5)} "
                    f"(ratio {ratio:.3g})")


# ------------------------------------------------------------------------------------------
# inputs: drawn (hypothesis) and pinned
# ------------------------------------------------------------------------------------------

DEFAULT_RANGES = {
    "production": {"log_scale": (-3.0, 3.0), "log_rho": (-6.0, 0.0)},
    "reference": {"log_scale": (-100.0, 100.0), "log_rho": (-12.0, 0.0)},
}
BATCH = {"production": MAX_BATCH, "reference": 1}


class Drawn(NamedTuple):
    """One vector of a drawn case: per cone the unit draws (t_s, t_r, directions), turned into
    float64 values by :meth:`rows` in the ranges of an implementation's family."""

    kind: str  # "i" interior, "g" general
    k: int
    cones: tuple
    ranges: dict

    def rows(self, family):
        (s0, s1), (r0, r1) = self.ranges[family]["log_scale"], self.ranges[family]["log_rho"]
        out = []
        for t_s, t_r, dirs in self.cones[:BATCH[family]]:
            log_s = s0 + t_s * (s1 - s0)
            if self.kind == "g":
                out.append([v * 10.0 ** log_s for v in dirs])
                continue
            lam1 = 10.0 ** log_s
            lam2 = lam1 * 10.0 ** (r0 + t_r * (r1 - r0))
            x = [(lam1 + lam2) / 2] + [0.0] * (self.k - 1)
            d = np.asarray(dirs, dtype=np.float64)
            m = np.max(np.abs(d), initial=0.0)
            if m > 0:
                r = d / m
                x[1:] = ((lam1 - lam2) / 2 * (r / np.sqrt(np.sum(r * r)))).tolist()
            out.append(x)
        return np.array(out, dtype=np.float64)


def _unit_floats(no_tiny):
    """Floats in [-1, 1]; with no_tiny, values below 2^-60 in magnitude become exact zeros."""
    f = st.floats(-1.0, 1.0)
    return f.map(lambda v: v if abs(v) >= 2.0**-60 else 0.0) if no_tiny else f


@st.composite
def cases(draw, kinds, ks=KS, no_tiny=False, production=None, reference=None):
    """A tuple of :class:`Drawn` vectors of one common k and batch size: kind "i" = interior,
    "g" = general.  ``production`` / ``reference`` override that family's ranges
    (``log_scale``, ``log_rho``)."""
    ranges = {"production": {**DEFAULT_RANGES["production"], **(production or {})},
              "reference": {**DEFAULT_RANGES["reference"], **(reference or {})}}
    k = draw(st.sampled_from(ks))
    n = draw(st.integers(1, MAX_BATCH))
    unit_f = _unit_floats(no_tiny)
    out = []
    for kind in kinds:
        cones = []
        for _ in range(n):
            t_s = draw(st.floats(0.0, 1.0))
            t_r = draw(st.floats(0.0, 1.0)) if kind == "i" else None
            size = k - 1 if kind == "i" else k
            cones.append((t_s, t_r, tuple(draw(st.lists(unit_f, min_size=size, max_size=size)))))
        out.append(Drawn(kind, k, tuple(cones), ranges))
    return tuple(out)


class Pin:
    """A pinned hard case: float64 rows (cones of one k), and other rows for the reference
    where its range differs (HUGE, TINY).  Arithmetic and indexing act on both."""

    def __init__(self, rows, reference=None):
        self.production = None if rows is None else np.atleast_2d(np.asarray(rows, dtype=np.float64))
        self.reference = self.production if reference is None else np.atleast_2d(
            np.asarray(reference, dtype=np.float64))

    def rows(self, family):
        """The rows for ``family``; a pin without them does not apply there (hypothesis skips
        an explicit example whose assumption fails)."""
        rows = getattr(self, family)
        assume(rows is not None)
        return rows

    def _map(self, fn, other=None):
        def f(*a):
            return None if any(v is None for v in a) else fn(*a)
        if isinstance(other, Pin):
            return Pin(f(self.production, other.production), f(self.reference, other.reference))
        return Pin(f(self.production), f(self.reference))

    def __getitem__(self, idx):
        return self._map(lambda a: a[idx])

    def __neg__(self):
        return self._map(lambda a: -a)

    def __mul__(self, c):
        return self._map(lambda a, b=c: a * b) if not isinstance(c, Pin) else self._map(np.multiply, c)

    def __sub__(self, c):
        return self._map(lambda a, b=c: a - b) if not isinstance(c, Pin) else self._map(np.subtract, c)

    def repeat(self, n, axis=0):
        return self._map(lambda a: a.repeat(n, axis))

    def __repr__(self):
        def show(a):
            return None if a is None else a.tolist()
        if self.reference is self.production:
            return f"Pin({show(self.production)!r})"
        return f"Pin({show(self.production)!r}, reference={show(self.reference)!r})"


def families(production: Pin, reference: Pin) -> Pin:
    """The production rows of one pin with the reference rows of another (where the two suites
    pinned the same hard case at the edges of their own ranges)."""
    return Pin(production.production, reference.reference)


def reference_only(rows) -> Pin:
    """A pinned case meaningful only at the reference's precision (e.g. λ2/λ1 ~ 1e-12 in all
    three arguments of a check whose float64 bound would exceed 1)."""
    return Pin(None, reference=rows)


def pinned(*cases_, **fixed):
    """``@example(case=c, **fixed)`` for every pinned case ``c`` (a tuple of Pins)."""
    def deco(fn):
        for c in reversed(cases_):
            fn = example(case=tuple(p if isinstance(p, Pin) else Pin(p) for p in c), **fixed)(fn)
        return fn
    return deco


A = np.array
NEAR12 = Pin([[1.0, 1.0 - 1e-12, 0.0], [1.0, 0.0, -(1.0 - 1e-12)]])  # λ2/λ1 ≈ 5e-13
NEAR12_K5 = Pin([[2.0, 1.2 * (1 - 1e-12), 0.0, -1.6 * (1 - 1e-12), 0.0]])
NEAREPS = Pin([[1.0 + 2.0**-52, 1.0], [1.5 + 2.0**-52, -1.5]])  # λ2 = one ulp of float64
ABS300 = Pin([[1e-300, 5e-301, 0.0], [2e-300, 0.0, 1.999999e-300]])  # λ2 ~ 1e-300 absolute
NEAR12_TINY = Pin([[1e-300, 1e-300 * (1 - 1e-12), 0.0]])
XBAR0 = Pin([[2.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
XBAR0_K2 = Pin([[1.5, 0.0]])
K1 = Pin([[0.7], [3.0], [1e-150]])
HUGE = Pin([[1e150, 3e149, 4e149], [2e150, 0.0, 1.99e150]], reference=[[1e100, 3e99, 4e99]])
TINY = Pin(HUGE.production * 1e-300, reference=[[1e-100, 3e-101, -4e-101]])
SUBN = Pin([[1.0, 1e-310, 0.0], [2.0, 5e-324, -5e-324]])  # subnormal x̄
SUBN_TINY = Pin([[1e-300, 1e-310, 2e-310]])
MIX5 = Pin([[3.0, 0.5, -1.0, 0.25, 2.0], [1.0, 0.0, 0.0, 0.0, 0.0]])
OUT = [1.0, 2.0, 0.0]  # λ2 = −1
BOUNDARY = [5.0, 3.0, 4.0]  # λ2 = 0 exactly: ‖(3, 4)‖ = 5 without rounding


def other(x: Pin, seed=0) -> Pin:
    """A well-separated interior partner of the same shape and scale."""
    def f(a):
        y = np.zeros_like(a)
        y[:, 0] = 1.0 + 0.25 * seed
        if a.shape[1] > 1:
            y[:, 1] = 0.5
        return y * np.max(np.abs(a), axis=1, keepdims=True)
    return x._map(f)


def gen_partner(x: Pin) -> Pin:
    """An arbitrary (non-cone) partner vector of the same shape and scale."""
    def f(a):
        y = np.ones_like(a) * np.max(np.abs(a), axis=1, keepdims=True)
        y[:, 0] *= -0.5
        return y
    return x._map(f)


def cast(values, dtype):
    """float64 rows → array of dtype.  For longdouble, jitter every entry at the 2^-60 level so
    the inputs have bits below float64 precision (a silent float64 computation then shows up).
    The head is only ever enlarged and |x̄_i| by at most the same factor, so λ2 can only grow:
    interior points stay interior."""
    a = np.asarray(values, dtype=np.float64)
    if dtype is np.float64:
        return a.copy()
    x = a.astype(LD)
    h = (np.arange(x.size).reshape(x.shape) * 7919 % 997) / LD(997)
    jit = np.ldexp(LD(1), -60)
    x[..., 0] *= 1 + jit * (1 + h[..., 0])
    x[..., 1:] *= 1 + jit * (2 * h[..., 1:] - 1)
    return x


# ------------------------------------------------------------------------------------------
# the implementations
# ------------------------------------------------------------------------------------------


def public_calls(module, not_functions, binary):
    """Every public function of ``module`` as a call on (x, y): the binary ones on both, power
    as x^(−1.5), nt_scaling on (x, 2x), every other one on x alone."""
    calls = {}
    for name in sorted(set(module.__all__) - not_functions):
        f = getattr(module, name)
        if name in binary:
            calls[name] = lambda x, y, f=f: f(x, y)
        elif name == "power":
            calls[name] = lambda x, y, f=f: f(x, -1.5)
        elif name == "nt_scaling":
            calls[name] = lambda x, y, f=f: f(x, 2 * x if isinstance(x, np.ndarray) else [2 * v for v in x])
        else:
            calls[name] = lambda x, y, f=f: f(x)
    return calls


class NT(NamedTuple):
    p: object
    p_inv: object
    lam: object


class Production:
    """rfverify.jordan in one dtype, on batches of cones ((n, k) arrays)."""

    production = True
    family = "production"
    domain_error = ConeDomainError

    def __init__(self, dtype):
        self.dtype = dtype
        self.name = "longdouble" if dtype is LD else "float64"
        fi = np.finfo(dtype)
        self.u = H(fi.eps)
        self.floor = 16 * H(fi.smallest_subnormal)
        self.subnormal = H(fi.smallest_subnormal)
        self.max = H(fi.max)

    def inputs(self, case):
        return tuple(cast(v.rows(self.family), self.dtype) for v in case)

    @property
    def input_dtype(self):
        return self.dtype

    def convert(self, rows):
        """Rows of numbers exactly (no jitter): for points that must lie exactly on ∂L."""
        return np.asarray(rows, dtype=self.dtype)

    def out(self, a):
        a = np.asarray(a)
        assert a.dtype == self.dtype, (a.dtype, self.dtype)
        return H(a)

    def identity(self, k, n):
        return J.identity(k, n, self.dtype)

    spectral_values = staticmethod(J.spectral_values)
    spectral_frames = staticmethod(J.spectral_frames)
    nt_scaling = staticmethod(J.nt_scaling)
    max_step = staticmethod(J.max_step)

    @staticmethod
    def min_lambda2(x):
        return J.min_lambda2(x)[0]

    BINARY = ("jordan_product", "quad_apply", "arrow_solve", "step_to_boundary", "max_step")
    module = J
    PUBLIC = public_calls(J, {"identity", "NTScaling"}, BINARY)


class Reference:
    """reference.jordan in a private context of ``dps`` digits, one cone at a time (a batch
    is a list of cones)."""

    production = False
    family = "reference"
    domain_error = R.ReferenceDomainError

    def __init__(self, dps):
        self.dps = dps
        self.ctx = R.context(dps)
        self.name = f"reference{dps}"
        self.u = H(self.ctx.eps)
        self.floor = self.subnormal = HI.zero
        self.max = HI.inf

    input_dtype = np.float64

    def inputs(self, case):
        return tuple(self.convert(v.rows(self.family)) for v in case)

    def convert(self, rows):
        return [R.to_ctx(self.ctx, list(r)) for r in rows]

    def out(self, a):
        def own(v):
            if isinstance(v, (list, tuple)):
                return all(own(t) for t in v)
            return v.context is self.ctx
        assert own(a), "a result is not a number of the working context"
        return H(a)

    def identity(self, k, n):
        return [R.identity(self.ctx, k) for _ in range(n)]

    @staticmethod
    def spectral_values(x):
        pairs = [R.spectral_values(c) for c in x]
        return [p[0] for p in pairs], [p[1] for p in pairs]

    @staticmethod
    def spectral_frames(x):
        pairs = [R.spectral_frames(c) for c in x]
        return [p[0] for p in pairs], [p[1] for p in pairs]

    @staticmethod
    def nt_scaling(z, s):
        nts = [R.nt_scaling(a, b) for a, b in zip(z, s)]
        return NT([t[0] for t in nts], [t[1] for t in nts], [t[2] for t in nts])

    @staticmethod
    def max_step(x, dx):
        """min(1, min α): what rfverify.jordan.max_step returns, from the reference's α."""
        return min([1] + [R.step_to_boundary(a, b) for a, b in zip(x, dx)])

    @staticmethod
    def min_lambda2(x):
        return min(R.spectral_values(c)[1] for c in x)

    BINARY = ("product", "dot", "quad_apply", "arrow_solve", "step_to_boundary")
    module = R
    PUBLIC = public_calls(R, {"identity", "context", "to_ctx", "NTScaling", "ReferenceDomainError"}, BINARY)


def _each(fn):
    """A one-cone reference function mapped over a batch (a list of cones); a second batch
    argument is zipped with the first, other arguments are passed on."""
    def call(x, *args):
        if args and isinstance(args[0], list):
            return [fn(a, b, *args[1:]) for a, b in zip(x, args[0])]
        return [fn(a, *args) for a in x]
    return staticmethod(call)


# The operations both implementations have under one name: the production's batch functions as
# they are, the reference's mapped over the cones of a batch.
SHARED = ("arrow", "reflect", "det", "trace", "inverse", "sqrt", "power", "quad_apply", "quad_matrix",
          "arrow_solve", "cond_quad", "step_to_boundary")
for _name in SHARED:
    setattr(Production, _name, staticmethod(getattr(J, _name)))
    setattr(Reference, _name, _each(getattr(R, _name)))
Production.product = staticmethod(J.jordan_product)
Reference.product = _each(R.product)

F64, LDBL = Production(np.float64), Production(LD)
REF50, REF30 = Reference(50), Reference(30)
IMPLS = [F64, LDBL, REF50]
over_impls = pytest.mark.parametrize("impl", IMPLS, ids=lambda i: i.name)
over_impls_and_ref30 = pytest.mark.parametrize("impl", IMPLS + [REF30], ids=lambda i: i.name)


def cones(impl, *batches):
    """The batches' results cone by cone, in HI (checking that they are the implementation's
    numbers)."""
    return zip(*(impl.out(b) for b in batches))


def expect_domain(impl, op, fn, value=None, cone=None):
    """``fn()`` must refuse with the implementation's domain error naming ``op`` (and the
    offending ``value``; for the production code the ``cone`` index too, None for a single
    vector)."""
    with pytest.raises(impl.domain_error) as ei:
        fn()
    err = ei.value
    assert err.operation == op and str(err).startswith(op), str(err)
    if not impl.production:  # the reference's errors are ValueErrors, the production's ArithmeticErrors
        assert isinstance(err, ValueError) and str(err).startswith(op + ":")
    if value is not None:
        assert err.value == value
    if impl.production:
        assert err.cone == cone
    return err
