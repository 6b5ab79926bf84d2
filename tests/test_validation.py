"""Validation of problem data by :meth:`Problem.from_arrays` (DESIGN §1, §7).

Property tests take a random *valid* rigid-body problem (tests/strategies.py), corrupt one
thing, and check that an :class:`InvalidProblemError` names the right field and, where it
means something, the index of the corruption: the (row, col) of a non-finite entry of M or H,
the entry of a vector, the contact of a negative coefficient, the diagonal entry or the dof
range of a non-positive-definite body block.  Expectations are computed in the tests with
dense numpy, not with the library's helpers.
"""

from __future__ import annotations

import dataclasses
import re

import h5py
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import event, given
from hypothesis import strategies as st

from rfverify.errors import InvalidProblemError
from rfverify.io.fclib import read_fclib, write_fclib
from rfverify.model.problem import DEFAULT_MAX_ASYMMETRY, Problem, StoredSolution

try:
    from strategies import build_problem, from_arrays_kwargs, problem_arrays, problems
except ImportError:  # tests/ made a package
    from tests.strategies import build_problem, from_arrays_kwargs, problem_arrays, problems

EPS = np.finfo(float).eps
NONFINITE = st.sampled_from([np.nan, np.inf, -np.inf])


def rejected(arrays, **overrides) -> InvalidProblemError:
    """Build with ``overrides``; the build must fail with InvalidProblemError."""
    with pytest.raises(InvalidProblemError) as info:
        build_problem(arrays, **overrides)
    err = info.value
    text = str(err)
    assert text.startswith(err.field), text  # the message names the field first
    assert "fix:" in text and err.fix, text
    return err


def dense_scaled_asymmetry(D):
    """max |D_ij − D_ji| / sqrt(D_ii D_jj) over i ≠ j, and the set of (i, j) attaining it."""
    A = D - D.T
    d = np.abs(np.diag(D))
    i, j = np.nonzero(A)
    if i.size == 0:
        return 0.0, set()
    # Same rounding as the library (sqrt(d_i)·sqrt(d_j), which cannot under/overflow), so the
    # inclusive-limit test can use the exact value; scale invariance is tested separately.
    rel = np.abs(A[i, j]) / (np.sqrt(d[i]) * np.sqrt(d[j]))
    top = rel.max()
    return float(top), {(int(a), int(b)) for a, b, r in zip(i, j, rel) if r == top}


def sym_min_eig(D, dofs):
    S = 0.5 * (D + D.T)
    sub = S[np.ix_(dofs, dofs)]
    return np.linalg.eigvalsh(sub)[0], np.abs(sub).max()


# ---------------------------------------------------------------------- valid data
@given(problem_arrays())
def test_valid_problems_are_accepted(arrays):
    p = build_problem(arrays)
    meta = arrays["meta"]
    assert p.n_dofs == 6 * meta["n_bodies"] and p.n_contacts == meta["n_contacts"]
    assert p.symmetry.scaled <= DEFAULT_MAX_ASYMMETRY
    assert p.blocks.proven and np.all(p.blocks.lam_lower > 0)
    free = {6 * b + k for b in meta["free_bodies"] for k in range(6)}
    assert free <= set(p.contact_free_dofs.tolist())
    assert np.array_equal(p.mu, arrays["mu"]) and np.array_equal(p.mu_r, arrays["mu_r"])


def test_negative_zero_and_zero_coefficients_are_accepted():
    p = _one_body(mu=[-0.0], mu_r=[0.0])
    assert np.signbit(p.mu[0]) and p.mu[0] == 0.0  # kept as given, not "negative"


# ---------------------------------------------------------------------- non-finite values
@given(arrays=problem_arrays(), name=st.sampled_from(["M", "H"]), value=NONFINITE,
       kind=st.sampled_from(["dense", "coo", "csr", "csc"]), data=st.data())
def test_nonfinite_in_matrix_names_row_and_column(arrays, name, value, kind, data):
    A = arrays[name]
    i = data.draw(st.integers(0, A.shape[0] - 1), label="row")
    j = data.draw(st.integers(0, A.shape[1] - 1), label="col")
    if kind == "dense":
        bad = A.toarray()
        bad[i, j] = value
    else:
        # add the value as a (possibly duplicate) entry: NaN/±Inf + x keeps it non-finite
        coo = A.tocoo()
        bad = sp.coo_matrix((np.r_[coo.data, value], (np.r_[coo.row, i], np.r_[coo.col, j])),
                            shape=A.shape).asformat(kind)
    err = rejected(arrays, **{name: bad})
    assert err.field == name
    assert err.index == (i, j)
    assert f"({i}, {j})" in str(err)


@given(arrays=problem_arrays(), name=st.sampled_from(["f", "w", "mu", "mu_r"]),
       value=NONFINITE, data=st.data())
def test_nonfinite_in_vector_names_entry(arrays, name, value, data):
    vec = np.array(arrays[name])
    k = data.draw(st.integers(0, vec.size - 1), label="position")
    vec[k] = value
    err = rejected(arrays, **{name: vec})
    assert err.field == name
    assert err.index == k


@given(arrays=problem_arrays(solution=True), value=NONFINITE, data=st.data())
def test_nonfinite_in_stored_solution_is_refused(arrays, value, data):
    s = arrays["solution"]
    key = data.draw(st.sampled_from([k for k in "vur" if getattr(s, k) is not None]))
    vec = np.array(getattr(s, key))
    k = data.draw(st.integers(0, vec.size - 1))
    vec[k] = value
    err = rejected(arrays, solution=dataclasses.replace(s, **{key: vec}))
    assert err.field == f"solution.{key}"
    assert err.index == k


# ---------------------------------------------------------------------- signs
negative_values = st.one_of(st.sampled_from([-5e-324, -1e-300, -1.0, -1e300]),
                            st.floats(max_value=-5e-324, allow_nan=False, allow_infinity=False))


@given(arrays=problem_arrays(), name=st.sampled_from(["mu", "mu_r"]), value=negative_values,
       data=st.data())
def test_negative_coefficient_names_contact(arrays, name, value, data):
    vec = np.array(arrays[name])
    k = data.draw(st.integers(0, vec.size - 1), label="contact")
    later = data.draw(st.lists(st.integers(k, vec.size - 1)), label="more negatives")
    vec[later] = -1.0
    vec[k] = value
    err = rejected(arrays, **{name: vec})
    assert err.field == name
    assert err.index == k
    assert f"contact {k}" in str(err)


# ---------------------------------------------------------------------- sizes
def _resized(x, size):
    x = np.asarray(x)
    return np.r_[x, np.ones(size - x.size)] if size > x.size else x[:size].copy()


@given(arrays=problem_arrays(), name=st.sampled_from(["f", "w", "mu_r"]),
       delta=st.integers(-30, 5).filter(bool))
def test_wrong_vector_size_is_refused(arrays, name, delta):
    vec = arrays[name]
    size = max(vec.size + delta, 0)
    if size == vec.size:
        size += 1
    err = rejected(arrays, **{name: _resized(vec, size)})
    assert err.field == name
    assert str(size) in str(err)


def _resized_along(A, axis: int, delta: int, smallest: int):
    """A copy of A with its size along ``axis`` changed by ``delta`` (at least ``smallest``,
    never the original size), truncated or zero-padded."""
    size = max(A.shape[axis] + delta, smallest)
    if size == A.shape[axis]:
        size += 1
    bad = np.zeros((size, A.shape[1]) if axis == 0 else (A.shape[0], size))
    keep = min(size, A.shape[axis])
    if axis == 0:
        bad[:keep] = A[:keep]
    else:
        bad[:, :keep] = A[:, :keep]
    return bad


@given(arrays=problem_arrays(), axis=st.sampled_from([0, 1]),
       delta=st.integers(-12, 12).filter(bool))
def test_wrong_H_shape_is_refused(arrays, axis, delta):
    bad = _resized_along(arrays["H"].toarray(), axis, delta, smallest=0)
    err = rejected(arrays, H=bad)
    assert err.field == "H"
    assert str(bad.shape) in str(err)


@given(arrays=problem_arrays(), axis=st.sampled_from([0, 1]),
       delta=st.integers(-5, 5).filter(bool))
def test_non_square_M_is_refused(arrays, axis, delta):
    err = rejected(arrays, M=_resized_along(arrays["M"].toarray(), axis, delta, smallest=1))
    assert err.field == "M"
    assert "square" in str(err)


@given(spacedim=st.integers(-3, 40).filter(lambda s: s != 5), arrays=problem_arrays())
def test_spacedim_other_than_5_is_refused(spacedim, arrays):
    err = rejected(arrays, spacedim=spacedim)
    assert err.field == "spacedim"
    assert str(spacedim) in str(err)


def test_spacedim_in_file_is_checked(tmp_path):
    p = _one_body()
    path = tmp_path / "sd.hdf5"
    write_fclib(p, path)
    with h5py.File(path, "r+") as fh:
        del fh["fclib_global_rolling/spacedim"]
        fh["fclib_global_rolling"].create_dataset("spacedim", data=np.array([3], np.int32))
    with pytest.raises(InvalidProblemError) as info:
        read_fclib(path)
    assert info.value.field == "spacedim"


# ---------------------------------------------------------------------- symmetry of M
@given(arrays=problem_arrays(), data=st.data())
def test_asymmetry_threshold(arrays, data):
    """Plant an asymmetry in one body block; the limit is inclusive and user-settable; an
    accepted M is kept raw and M_sym = (M + Mᵀ)/2."""
    nb = arrays["meta"]["n_bodies"]
    b = data.draw(st.integers(0, nb - 1), label="body")
    i, j = data.draw(st.lists(st.integers(0, 5), min_size=2, max_size=2, unique=True),
                     label="pair")
    i, j = 6 * b + i, 6 * b + j
    D = arrays["M"].toarray()
    blk = slice(6 * b, 6 * b + 6)
    lam_min = np.linalg.eigvalsh(0.5 * (D[blk, blk] + D[blk, blk].T))[0]
    # ‖symmetrised perturbation‖₂ = delta/2 ≤ lam_min/2: the block stays positive definite.
    delta = lam_min * data.draw(st.floats(1e-6, 1.0), label="delta/lam_min")
    D[i, j] += delta
    s, where = dense_scaled_asymmetry(D)
    assert s > 0

    below = data.draw(st.one_of(st.just(float(np.nextafter(s, 0))),
                                st.floats(0.0, s, exclude_max=True)), label="limit below")
    err = rejected(arrays, M=D, max_asymmetry=below)
    assert err.field == "M"
    assert err.index in where
    assert "max_asymmetry" in str(err)

    # with the default limit: accepted exactly when s <= 1e-2
    event("above default limit" if s > DEFAULT_MAX_ASYMMETRY else "below default limit")
    if s > DEFAULT_MAX_ASYMMETRY:
        assert rejected(arrays, M=D).field == "M"

    above = data.draw(st.one_of(st.just(s), st.just(np.inf), st.floats(s, 1e300)),
                      label="limit at/above")
    p = build_problem(arrays, M=D, max_asymmetry=above)
    assert p.symmetry.scaled == s
    assert (p.symmetry.row, p.symmetry.col) in where
    np.testing.assert_array_equal(p.M.toarray(), D)  # raw, not symmetrised
    assert not np.array_equal(p.M.toarray(), p.M.toarray().T)
    np.testing.assert_array_equal(p.M_sym.toarray(), (D + D.T) / 2)


# ---------------------------------------------------------------------- definiteness
def _parse_span(index: str):
    """'block k: dofs lo..hi' → range; 'block k: c dofs from lo to hi' → (lo, hi, c)."""
    m = re.fullmatch(r"block (\d+): dofs (\d+)\.\.(\d+)", index)
    if m:
        lo, hi = int(m[2]), int(m[3])
        return lo, hi, hi - lo + 1
    m = re.fullmatch(r"block (\d+): (\d+) dofs from (\d+) to (\d+)", index)
    assert m, f"unexpected index {index!r}"
    return int(m[3]), int(m[4]), int(m[2])


@given(arrays=problem_arrays(), data=st.data())
def test_indefinite_body_block_names_its_dofs(arrays, data):
    """Flip the sign of one eigenvalue of one body's inertia tensor."""
    nb = arrays["meta"]["n_bodies"]
    b = data.draw(st.integers(0, nb - 1), label="body")
    k = data.draw(st.integers(0, 2), label="eigenvalue")
    D = arrays["M"].toarray()
    rot = slice(6 * b + 3, 6 * b + 6)
    J = 0.5 * (D[rot, rot] + D[rot, rot].T)
    lam, V = np.linalg.eigh(J)
    lam[k] = -lam[k]
    Jbad = (V * lam) @ V.T
    D[rot, rot] = 0.5 * (Jbad + Jbad.T)
    err = rejected(arrays, M=D)
    assert err.field == "M"
    first, last = 6 * b + 3, 6 * b + 5
    event("diagonal test" if isinstance(err.index, tuple) else "block test")
    if isinstance(err.index, tuple):  # caught by the diagonal test
        j, jj = err.index
        assert j == jj and first <= j <= last and D[j, j] <= 0
    else:
        lo, hi, count = _parse_span(err.index)
        assert first <= lo <= hi <= last
        assert f"dofs {lo}..{hi}" in str(err) or f"{count} dofs from {lo} to {hi}" in str(err)
        dofs = list(range(lo, hi + 1)) if count == hi - lo + 1 else [lo, hi]
        assert len(dofs) == count
        # the named dofs are a block of the sparsity graph: no coupling to other dofs ...
        S = 0.5 * (D + D.T)
        others = np.setdiff1d(np.arange(D.shape[0]), dofs)
        assert not np.any(S[np.ix_(dofs, others)])
        # ... and that block really is not positive definite
        eig, norm = sym_min_eig(D, dofs)
        assert eig <= 8 * EPS * count * norm


@given(arrays=problem_arrays(asymmetry=False), value=st.one_of(
    st.sampled_from([0.0, -0.0, -5e-324, -1.0]), st.floats(-1e3, 0.0)), data=st.data())
def test_non_positive_diagonal_names_entry(arrays, value, data):
    D = arrays["M"].toarray()
    j = data.draw(st.integers(0, D.shape[0] - 1), label="dof")
    D[j, j] = value
    err = rejected(arrays, M=D)
    assert err.field == "M"
    assert err.index == (j, j)
    assert f"M[{j},{j}]" in str(err) and "not positive" in str(err)


# ---------------------------------------------------------------------- messages
def _one_body(**kw):
    M = np.diag([2.0, 2.0, 2.0, 0.5, 0.25, 0.125])
    args = dict(M=M, H=np.arange(1.0, 31.0).reshape(6, 5), f=np.ones(6), w=np.ones(5),
                mu=[0.5], mu_r=[0.1])
    args.update(kw)
    return Problem.from_arrays(**args)


_M = np.diag([2.0, 2.0, 2.0, 0.5, 0.25, 0.125])
_M_asym = _M.copy()
_M_asym[3, 4] = 0.2
_M_indef = _M.copy()
_M_indef[3, 4] = _M_indef[4, 3] = 1.0  # 2×2 block [[0.5, 1], [1, 0.25]]: det < 0


@pytest.mark.parametrize("field, kwargs", [
    ("M", {"M": np.ones((6, 5))}),
    ("M", {"M": np.where(np.eye(6) > 0, np.nan, 0.0)}),
    ("M", {"M": _M_asym}),
    ("M", {"M": _M_indef}),
    ("M", {"M": np.diag([2.0, 2.0, 0.0, 0.5, 0.25, 0.125])}),
    ("H", {"H": np.ones((6, 4))}),
    ("H", {"H": np.full((6, 5), np.inf)}),
    ("f", {"f": np.ones(7)}),
    ("f", {"f": [1, 1, 1, np.nan, 1, 1]}),
    ("w", {"w": np.ones(4)}),
    ("mu", {"mu": [-0.5]}),
    ("mu", {"mu": [np.nan]}),
    ("mu_r", {"mu_r": [0.1, 0.2]}),
    ("mu_r", {"mu_r": [-1e-300]}),
    ("spacedim", {"spacedim": 3}),
    ("solution.v", {"solution": StoredSolution(v=np.ones(5))}),
    ("guesses[1].r", {"guesses": (StoredSolution(), StoredSolution(r=np.ones(6)))}),
])
def test_error_message_names_field_and_fix(field, kwargs):
    with pytest.raises(InvalidProblemError) as info:
        _one_body(**kwargs)
    err = info.value
    assert err.field == field
    msg = str(err)
    assert msg.startswith(field)
    assert "; fix: " in msg and err.fix and msg.endswith(err.fix)
    assert isinstance(err, ValueError)  # callers may catch ValueError


def test_not_positive_definite_message_names_block_dofs():
    with pytest.raises(InvalidProblemError) as info:
        _one_body(M=_M_indef)
    assert info.value.field == "M"
    assert "dofs 3..4" in str(info.value) and info.value.index.endswith("dofs 3..4")


# ---------------------------------------------------------------------- immutability
@given(arrays=problem_arrays())
def test_problem_arrays_are_read_only_copies(arrays):
    p = build_problem(arrays)
    for name in ("f", "w", "mu", "mu_r"):
        arr = getattr(p, name)
        with pytest.raises(ValueError):
            arr[0] = 1.0
    for name in ("M", "H", "M_sym"):
        A = getattr(p, name)
        for part in ("data", "indices", "indptr"):
            with pytest.raises(ValueError):
                getattr(A, part)[0] = 1
    with pytest.raises(ValueError):
        p.M[0, 0] = 1.0  # scipy writes into the read-only data
    with pytest.raises(dataclasses.FrozenInstanceError):
        p.f = np.zeros(p.n_dofs)
    # the problem does not alias the caller's arrays
    before_f, before_M = p.f.copy(), p.M.data.copy()
    arrays["f"][:] = 12345.0
    arrays["M"].data[:] = 12345.0
    np.testing.assert_array_equal(p.f, before_f)
    np.testing.assert_array_equal(p.M.data, before_M)


# ------------------------------------------------- regressions (bugs these tests found)
def test_stored_solution_arrays_are_read_only_copies():
    v = np.zeros(6)
    p = _one_body(solution=StoredSolution(v=v, r=[0, 0, 0, 0, 0]),
                  guesses=(StoredSolution(u=np.ones(5)),))
    v[0] = 99.0
    assert p.solution.v[0] == 0.0  # not aliased
    assert isinstance(p.solution.r, np.ndarray) and p.solution.r.dtype == np.float64
    for arr in (p.solution.v, p.guesses[0].u):
        with pytest.raises(ValueError):
            arr[0] = 1.0


def _scaled_one_body_asym(scale, asym):
    M = np.diag([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    M[3, 4] = 0.25 + asym / 2
    M[4, 3] = 0.25 - asym / 2
    return M * scale


@pytest.mark.parametrize("exponent", [-600, 600])
def test_asymmetry_measure_is_scale_invariant(exponent):
    """The scaled asymmetry is documented as invariant under a change of units."""
    ref = _one_body(M=_scaled_one_body_asym(1.0, 2e-3)).symmetry.scaled
    p = _one_body(M=_scaled_one_body_asym(2.0 ** exponent, 2e-3))
    assert p.symmetry.scaled == pytest.approx(ref, rel=1e-12)


@pytest.mark.parametrize("exponent", [
    -600, -100, 0, 100, 600,
])
def test_large_asymmetry_refused_at_any_scale(exponent):
    with pytest.raises(InvalidProblemError) as info:
        _one_body(M=_scaled_one_body_asym(2.0 ** exponent, 0.5))
    assert info.value.field == "M" and "symmetric" in str(info.value)


def test_zero_diagonal_with_tiny_asymmetry_is_reported_as_diagonal():
    M = _scaled_one_body_asym(1.0, 1e-12)
    M[3, 3] = 0.0
    with pytest.raises(InvalidProblemError) as info:
        _one_body(M=M)
    assert info.value.index == (3, 3)
    assert "not positive" in str(info.value)
