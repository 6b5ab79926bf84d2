"""Repeated (row, col) entries of a matrix are summed exactly (DESIGN §7.1, rfverify.io._exact).

FCLIB files (triplet, CSC and CSR storage) and Siconos ``.dat`` CSparse print-outs may store a
position several times; the matrix holds the sum.  Summed in float, in storage order, the
entries 2^53, 1, −2^53, 1 give 1; the exact sum is 2, and that is what must be read.  A group
whose exact sum is not a float64 (1 + 2^−60) is refused, naming the matrix, the position, the
number of terms and the fix, never rounded.

The problems are tiny (1 contact, 1 or 2 dofs, M diagonal, r* = 0), so the answer of the
exactly summed problem is known by hand: v = M⁻¹ f.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import h5py
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import rfverify
from rfverify.cli import main
from rfverify.errors import ProblemFileError
from rfverify.io._exact import exact_csc

BIG = 2.0**53
# (0, 0) of M stored four times: the exact sum is 2, the float sum in this order is 1.
CANCELLING = [BIG, 1.0, -BIG, 1.0]
NOT_A_FLOAT = [1.0, 2.0**-60]  # exact sum 1 + 2^-60: between two float64s

F = np.array([4.0, 0.0])  # M = diag(2, 2) read exactly: v* = M⁻¹ f = (2, 0), r* = 0
V_EXACT = np.array([2.0, 0.0])


def bits(a):
    return np.ascontiguousarray(np.asarray(a, dtype=np.float64)).view(np.uint64)


def stored(A, r, c) -> float:
    """The value stored at (r, c), with its sign bit (scipy's A[r, c] may turn −0.0 into 0.0)."""
    coo = sp.coo_matrix(A)
    (k,) = np.flatnonzero((coo.row == r) & (coo.col == c))
    return coo.data[k]


def same_matrix(A, B) -> bool:
    A, B = sp.csc_matrix(A), sp.csc_matrix(B)
    return (A.shape == B.shape and np.array_equal(A.indptr, B.indptr)
            and np.array_equal(A.indices, B.indices) and np.array_equal(bits(A.data), bits(B.data)))


# ---------------------------------------------------------------------- FCLIB files
def entries_M(m00):
    """Triplet entries of M = diag(Σ m00, 2): position (0, 0) once per value of ``m00``."""
    rows = [0] * len(m00) + [1]
    return rows, list(rows), list(m00) + [2.0]


def entries_H():
    """H (2×5): H[0, 0] = 1 (normal of the contact), H[1, 2] = 1."""
    return [0, 1], [0, 2], [1.0, 1.0]


def matrix_group(g, name, shape, rows, cols, vals, storage):
    """An FCLIB matrix group written by hand (DESIGN §7: triplet i = row, p = column)."""
    m, n = shape
    rows, cols, vals = np.asarray(rows), np.asarray(cols), np.asarray(vals, dtype=np.float64)
    if storage == "triplet":
        p, i, x, nz = cols, rows, vals, len(vals)
    else:  # compressed, keeping every repeated entry (stable: storage order within a group)
        outer, inner, nz = (cols, rows, -1) if storage == "csc" else (rows, cols, -2)
        order = np.argsort(outer, kind="stable")
        i, x = inner[order], vals[order]
        p = np.r_[0, np.cumsum(np.bincount(outer, minlength=n if storage == "csc" else m))]
    grp = g.create_group(name)
    for key, val in (("m", m), ("n", n), ("nz", nz), ("nzmax", len(x))):
        grp[key] = np.array([val], dtype=np.int32)
    grp["p"] = np.asarray(p, dtype=np.int32)
    grp["i"] = np.asarray(i, dtype=np.int32)
    grp["x"] = np.asarray(x, dtype=np.float64)


def write_problem(path, *, M, H, storage="triplet"):
    with h5py.File(path, "w") as fh:
        g = fh.create_group("fclib_global_rolling")
        matrix_group(g, "M", (2, 2), *M, storage)
        matrix_group(g, "H", (2, 5), *H, storage)
        vec = g.create_group("vectors")
        vec["f"], vec["w"] = F, np.zeros(5)
        vec["mu"], vec["mu_r"] = np.array([0.5]), np.array([0.1])
        g["spacedim"] = np.array([5], dtype=np.int32)
    return path


@pytest.mark.parametrize("storage", ["triplet", "csc", "csr"])
def test_cancelling_repeated_entries_are_summed_exactly_and_solved(tmp_path, storage):
    rows, cols, vals = entries_M(CANCELLING)
    # What a float summation in storage order reads (the bug): 1, not 2.
    assert sp.coo_matrix((vals, (rows, cols)), shape=(2, 2)).tocsc()[0, 0] == 1.0
    path = write_problem(tmp_path / f"{storage}.hdf5", M=(rows, cols, vals), H=entries_H(), storage=storage)
    p = rfverify.load(path)
    assert p.M[0, 0] == 2.0 and p.M[1, 1] == 2.0 and p.M.nnz == 2
    res = rfverify.solve(p, tol=1e-12)
    assert res.success, res.message
    np.testing.assert_allclose(res.v, V_EXACT, atol=1e-9)  # the float-summed M gives v_0 = 4
    assert np.max(np.abs(res.r)) < 1e-9


def test_repeated_entries_in_H_and_exact_zero_sums(tmp_path):
    """H[1, 2] stored as 1, 2^53, −2^53 (exact sum 1, float sum 0); an exactly cancelling
    group stays an explicit zero (as scipy's sum_duplicates leaves it), −0.0 only when every
    term is −0.0 (IEEE addition)."""
    H = ([0, 1, 1, 1, 1, 1], [0, 2, 2, 2, 4, 4], [1.0, 1.0, BIG, -BIG, 3.0, -3.0])
    M = ([0, 1, 0, 0], [0, 1, 1, 1], [2.0, 2.0, -0.0, -0.0])
    p = rfverify.load(write_problem(tmp_path / "h.hdf5", M=M, H=H))
    assert p.H[1, 2] == 1.0 and p.H.nnz == 3  # (0,0), (1,2), and the explicit zero at (1,4)
    assert stored(p.H, 1, 4) == 0.0 and not np.signbit(stored(p.H, 1, 4))
    assert p.M.nnz == 3 and stored(p.M, 0, 1) == 0.0 and np.signbit(stored(p.M, 0, 1))


@pytest.mark.parametrize("storage", ["triplet", "csc", "csr"])
def test_a_sum_that_is_not_a_float64_is_refused_naming_the_entry(tmp_path, storage):
    path = write_problem(tmp_path / "bad.hdf5", M=entries_M([2.0]),
                         H=([0, 1, 1], [0, 2, 2], [1.0, 0.1, 0.2]), storage=storage)  # 0.1 + 0.2
    with pytest.raises(ProblemFileError) as info:
        rfverify.load(path)
    msg = str(info.value)
    for text in (str(path), "/fclib_global_rolling/H/x[", "matrix H", "entry (1, 2)",
                 "2 repeated terms", "not a float64", "0.30000000000000004", "fix: store each (row, col) once"):
        assert text in msg, (text, msg)


def test_the_refusal_names_the_first_bad_entry_in_storage_order(tmp_path):
    M = ([1, 0, 0, 1], [1, 0, 0, 1], [2.0, NOT_A_FLOAT[0], NOT_A_FLOAT[1], 2.0**-60])
    path = write_problem(tmp_path / "bad.hdf5", M=M, H=entries_H())
    with pytest.raises(ProblemFileError, match=r"M/x\[0\]: matrix M: entry \(1, 1\)"):
        rfverify.load(path)


@pytest.mark.parametrize("command", ["info", "solve"])
def test_cli_refusal_is_one_line_exit_2(tmp_path, capsys, command):
    path = write_problem(tmp_path / "bad.hdf5", M=entries_M(NOT_A_FLOAT), H=entries_H())
    capsys.readouterr()
    assert main([command, str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1, err
    assert err.startswith(f"rfverify {command}: error: {path}: ") and "Traceback" not in err
    for text in ("matrix M", "entry (0, 0)", "2 repeated terms", "nearest float64 is 1.0", "fix:"):
        assert text in err, (text, err)


@pytest.mark.parametrize("storage", ["triplet", "csc", "csr"])
def test_exactly_read_matrix_is_written_back_bit_for_bit(tmp_path, capsys, storage):
    src = write_problem(tmp_path / "src.hdf5", M=entries_M(CANCELLING), H=entries_H(), storage=storage)
    p = rfverify.load(src)
    saved = tmp_path / "saved.hdf5"
    rfverify.save(p, saved)
    q = rfverify.load(saved)
    assert same_matrix(p.M, q.M) and same_matrix(p.H, q.H) and q.M[0, 0] == 2.0
    with h5py.File(saved) as fh:  # one stored entry per position now: nothing left to sum
        assert fh["fclib_global_rolling/M/x"].size == 2
    out = tmp_path / "solved.hdf5"
    assert main(["solve", str(src), "--out", str(out)]) == 0
    capsys.readouterr()
    r = rfverify.load(out)
    assert same_matrix(p.M, r.M) and same_matrix(p.H, r.H)
    np.testing.assert_allclose(r.solution.v, V_EXACT, atol=1e-9)


# ---------------------------------------------------------------------- Siconos .dat
CSPARSE = "CSparse Version 3.2.0, Sept 12, 2017.  Copyright (c) Timothy A. Davis, 2006-2016"


def dat_triplet(shape, entries):
    m, n = shape
    return ["2", str(m), str(n), "1", CSPARSE, f"triplet: {m}-by-{n}, nzmax: {len(entries)} nnz: {len(entries)}"] + [
        f"    {i} {j} : {x}" for i, j, x in entries]


def dat_csc(shape, entries):
    m, n = shape
    lines = ["2", str(m), str(n), "1", CSPARSE, f"{m}-by-{n}, nzmax: {len(entries)} nnz: {len(entries)}, 1-norm: 0"]
    k = 0
    for j in range(n):
        col = [(i, x) for i, jj, x in entries if jj == j]
        lines.append(f"    col {j} : locations {k} to {k + len(col) - 1}")
        lines += [f"      {i} : {x}" for i, x in col]
        k += len(col)
    return lines


# %g prints 1e+22 and 1 exactly (10^22 is a float64), and 1e+22 + 1 rounds back to 1e+22: the
# printed entries sum to 2 exactly, to 1 in float in this order.
DAT_M = [(0, 0, "1e+22"), (1, 1, "2"), (0, 0, "1"), (0, 0, "-1e+22"), (0, 0, "1")]
DAT_H = [(0, 0, "1"), (1, 2, "1")]


def write_dat(path, M=DAT_M, H=DAT_H, form=dat_triplet):
    lines = ["5", "1"] + form((2, 2), M) + form((2, 5), H)
    lines += ["4 0", "0 0 0 0 0", "0.5", "0.1"]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("form", [dat_triplet, dat_csc])
def test_dat_repeated_entries_are_summed_exactly(tmp_path, capsys, form):
    path = write_dat(tmp_path / "p.dat", form=form)
    p = rfverify.load(path)
    assert p.M[0, 0] == 2.0 and p.M.nnz == 2
    res = rfverify.solve(p, tol=1e-12)
    assert res.success and np.allclose(res.v, V_EXACT, atol=1e-9)
    saved = tmp_path / "p.hdf5"
    rfverify.save(p, saved)
    assert same_matrix(rfverify.load(saved).M, p.M)
    out = tmp_path / "solved.hdf5"
    assert main(["solve", str(path), "--out", str(out)]) == 0
    capsys.readouterr()
    assert same_matrix(rfverify.load(out).M, p.M)


@pytest.mark.parametrize("form", [dat_triplet, dat_csc])
def test_dat_inexact_sum_is_refused_naming_the_line(tmp_path, capsys, form):
    M = [(0, 0, "2"), (1, 1, "1"), (1, 1, "1e-30")]  # 1 + 1e-30 is no float64
    path = write_dat(tmp_path / "bad.dat", M=M, form=form)
    with pytest.raises(ProblemFileError) as info:
        rfverify.load(path)
    first = next(k for k, s in enumerate(path.read_text().splitlines(), start=1) if s.strip().endswith(": 1"))
    assert f"line {first}: " in str(info.value)
    capsys.readouterr()
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "entry (1, 1)" in err and "2 repeated terms" in err and "fix:" in err


def test_long_groups_overflow_and_non_finite_terms():
    """Groups longer than the vectorised pass (summed with Fraction directly), a group whose
    float partial sums overflow although its exact sum is a float64, and Inf terms (left to
    the problem's validation, which refuses non-finite entries)."""
    r = np.zeros(100, dtype=np.int64)
    A = exact_csc(r, r, np.r_[CANCELLING, np.full(96, 0.5)], (1, 1), matrix="M", refuse=_refuse)
    assert A[0, 0] == 50.0
    A = exact_csc(r, r, np.full(100, -0.0), (1, 1), matrix="M", refuse=_refuse)
    assert A.nnz == 1 and np.signbit(A.data[0])
    big = np.finfo(float).max
    A = exact_csc(r[:3], r[:3], [big, big, -big], (1, 1), matrix="M", refuse=_refuse)
    assert A[0, 0] == big
    with pytest.raises(ValueError, match="overflows float64"):
        exact_csc(r[:2], r[:2], [big, big], (1, 1), matrix="M", refuse=_refuse)
    A = exact_csc(r[:3], r[:3], [np.inf, 1.0, -np.inf], (1, 1), matrix="M", refuse=_refuse)
    assert np.isnan(A.data[0])


# ---------------------------------------------------------------------- property
# Terms a·2^e with |a| < 2^53: every term is a float64, and mixing magnitudes 2^52..2^53 with
# small ones makes the float sum depend on the order.
terms = st.builds(lambda a, e: float(a) * 2.0**e,
                  st.one_of(st.integers(-2**53 + 1, 2**53 - 1), st.integers(-8, 8)),
                  st.integers(-3, 3))
# A big term and its negation around small integers: the exact sum is the small ones' (a
# float64), the float sum loses those added while the big term is in (the order is shuffled).
cancelling = st.builds(lambda a, k, small: [float(a) * 2.0**k, -float(a) * 2.0**k, *small],
                       st.integers(2**52, 2**53 - 1), st.integers(1, 10),
                       st.lists(st.integers(-8, 8).map(float), min_size=1, max_size=4))
groups = st.lists(st.tuples(st.integers(0, 2), st.integers(0, 2),
                            st.one_of(st.lists(terms, min_size=1, max_size=6), cancelling)),
                  min_size=1, max_size=6)


def _expand(groups_, seed):
    rows, cols, vals, exact = [], [], [], {}
    for r, c, ts in groups_:
        for t in ts:
            rows.append(r), cols.append(c), vals.append(t)
            exact[r, c] = exact.get((r, c), Fraction(0)) + Fraction(t)
    perm = np.random.default_rng(seed).permutation(len(vals))  # any storage order
    return np.asarray(rows)[perm], np.asarray(cols)[perm], np.asarray(vals)[perm], exact


def _refuse(k, msg):
    return ValueError(msg)


@settings(max_examples=300)
@given(groups_=groups, seed=st.integers(0, 2**32 - 1))
def test_every_entry_is_the_exact_sum_or_refused(groups_, seed):
    rows, cols, vals, exact = _expand(groups_, seed)
    representable = all(Fraction(float(v)) == v for v in exact.values())
    if not representable:
        with pytest.raises(ValueError, match="repeated terms whose exact sum is not a float64"):
            exact_csc(rows, cols, vals, (3, 3), matrix="M", refuse=_refuse)
        return
    A = exact_csc(rows, cols, vals, (3, 3), matrix="M", refuse=_refuse)
    assert A.nnz == len(exact)  # one stored entry per position, zero sums kept explicit
    for (r, c), v in exact.items():
        assert Fraction(A[r, c]) == v


@settings(max_examples=40)  # one HDF5 file per example
@given(groups_=groups, seed=st.integers(0, 2**32 - 1))
def test_fclib_reader_matches_the_exact_sums(tmp_path_factory, groups_, seed):
    rows, cols, vals, exact = _expand(groups_, seed)
    path = Path(tmp_path_factory.mktemp("prop")) / "h.hdf5"
    # The groups go into columns 2..4 of H (m = 2: rows 0 and 1 only); H[0, 0] = 1 is the normal.
    keep = rows < 2
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    want = {(r, c + 2): v for (r, c), v in exact.items() if r < 2}
    write_problem(path, M=entries_M([2.0]), H=(np.r_[0, rows], np.r_[0, cols + 2], np.r_[1.0, vals]))
    if all(Fraction(float(v)) == v for v in want.values()):
        H = rfverify.load(path).H
        assert H[0, 0] == 1.0 and H.nnz == 1 + len(want)
        for (r, c), v in want.items():
            assert Fraction(H[r, c]) == v
    else:
        with pytest.raises(ProblemFileError, match="not a float64"):
            rfverify.load(path)
