"""The extended-precision engine (rfverify.extended): double-double arithmetic, the Jordan
kernels against the independent mpmath reference, the sparse LDLᵀ, the two Newton back ends,
and the run itself."""

from __future__ import annotations

import math

import mpmath
import numba
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rfverify
from rfverify.scenes.random_problems import random_problem
from reference import jordan as RJ
from rfverify.extended import cones as C
from rfverify.extended import dd
from rfverify.extended.contactspace import ContactSpace
from rfverify.extended.data import ExtendedData
from rfverify.extended.dofspace import DofSpace
from rfverify.extended.ldl import DDCholesky
from rfverify.extended.mixed import MixedCholesky

U_DD = 2.0 ** -104


@numba.njit
def _ops(ah, al, bh, bl):
    return dd.add(ah, al, bh, bl), dd.mul(ah, al, bh, bl), dd.div(ah, al, bh, bl), dd.sqrt(abs(ah), al if ah > 0 else -al)


def _mp(h, l):
    """hi + lo exactly (callers compare inside mpmath.workdps(60))."""
    return mpmath.mpf(float(h)) + mpmath.mpf(float(l))


nonzero = st.floats(min_value=1e-30, max_value=1e30).flatmap(lambda x: st.sampled_from([x, -x]))


@given(nonzero, nonzero, st.floats(-1, 1), st.floats(-1, 1))
@example(1.0, 3.0, 0.0, 0.0)
@example(1e30, -1e-30, 0.5, -0.5)
def test_double_double_operations_have_dd_accuracy(a, b, ta, tb):
    ah, al = dd.two_sum(a, a * 2.0 ** -60 * ta)
    bh, bl = dd.two_sum(b, b * 2.0 ** -60 * tb)
    s, p, q, r = _ops(ah, al, bh, bl)
    with mpmath.workdps(60):
        A, Bv = _mp(ah, al), _mp(bh, bl)
        assert abs(_mp(*s) - (A + Bv)) <= 4 * U_DD * (abs(A) + abs(Bv))
        assert abs(_mp(*p) - A * Bv) <= 4 * U_DD * abs(A * Bv)
        assert abs(_mp(*q) - A / Bv) <= 8 * U_DD * abs(A / Bv)
        assert abs(_mp(*r) - mpmath.sqrt(abs(A))) <= 8 * U_DD * mpmath.sqrt(abs(A))


def _interior(rng, n3, n1, spread):
    x = rng.normal(size=3 * n3 + n1)
    for c in range(n3):
        x[3 * c] = np.hypot(x[3 * c + 1], x[3 * c + 2]) * (1 + 10.0 ** rng.uniform(-spread, 0)) + 1e-300
    x[3 * n3:] = np.abs(x[3 * n3:]) + 10.0 ** rng.uniform(-spread, 0, n1)
    return x


@settings(max_examples=30)
@given(st.integers(0, 2**31), st.integers(0, 8))
@example(0, 8)
def test_jordan_kernels_agree_with_the_reference(seed, spread):
    """NT scaling, Q_{p^k} (spectral form), ∘, Jordan division and step length against
    reference.jordan at 60 digits, relative to the condition of each quantity."""
    rng = np.random.default_rng(seed)
    n3, n1 = 4, 2
    z, s, y = _interior(rng, n3, n1, spread), _interior(rng, n3, n1, spread), rng.normal(size=3 * n3 + n1)
    z[0:3] = [2.0, 0.0, 0.0]  # x̄ = 0: the spectral frame is arbitrary and must not matter
    nz = z.size
    zero = np.zeros(nz)
    ph, pl, pih, pil, lh, ll = (np.zeros(nz) for _ in range(6))
    spec = np.zeros((n3 + n1, 8))
    assert C.nt_scaling(n3, z, zero, s, zero, ph, pl, pih, pil, lh, ll, spec) == -1
    ctx = RJ.context(60)
    with mpmath.workdps(60):
        _compare_kernels(ctx, n3, n1, z, s, y, ph, pl, lh, ll, spec)
    _check_division_and_step(ctx, n3, z, s, y, spread)


def _compare_kernels(ctx, n3, n1, z, s, y, ph, pl, lh, ll, spec):
    nz = z.size
    zero = np.zeros(nz)
    for c in range(n3 + n1):
        sl = slice(3 * c, 3 * c + 3) if c < n3 else slice(3 * n3 + c - n3, 3 * n3 + c - n3 + 1)
        zc, sc, yc = (RJ.to_ctx(ctx, list(a[sl])) for a in (z, s, y))
        p_ref, _, lam_ref = RJ.nt_scaling(zc, sc)
        # p and λ are determined to u·κ, κ = λ1/λ2 of z and s (their λ2 cancels)
        kappa = max(float(RJ.cond_quad(zc)), float(RJ.cond_quad(sc))) ** 0.5
        scale = float(max(abs(x) for x in lam_ref))
        tol = 1e-27 * max(float(RJ.cond_quad(p_ref)), kappa)
        assert max(abs(_mp(ph[sl][i], pl[sl][i]) - p_ref[i]) for i in range(len(zc))) <= tol * float(max(abs(x) for x in p_ref))
        assert max(abs(_mp(lh[sl][i], ll[sl][i]) - lam_ref[i]) for i in range(len(zc))) <= tol * scale
        for k in (1, -1, 2, -2):
            oh, ol, table = np.zeros(nz), np.zeros(nz), np.zeros((spec.shape[0], 6))
            C.spectral_table(n3, k, spec, table)  # what the double-double phase applies
            C.quad_spectral(n3, table, spec, y, zero, oh, ol)
            want = RJ.quad_apply(RJ.power(p_ref, k), yc)
            big = float(max(abs(x) for x in want)) + float(RJ.cond_quad(RJ.power(p_ref, k))) ** 0.5 * 1e-300
            ref_scale = max(big, float(max(abs(x) for x in yc)) * float(max(RJ.spectral_values(RJ.power(p_ref, k)))) ** 2)
            assert max(abs(_mp(oh[sl][i], ol[sl][i]) - want[i]) for i in range(len(zc))) <= 1e-28 * kappa * ref_scale


def _check_division_and_step(ctx, n3, z, s, y, spread):
    nz = z.size
    zero = np.zeros(nz)
    oh, ol = np.zeros(nz), np.zeros(nz)
    C.product(n3, z, zero, s, zero, oh, ol)
    C.arrow_solve(n3, z, zero, oh, ol, oh2 := np.zeros(nz), ol2 := np.zeros(nz))
    assert np.allclose(oh2, s, rtol=1e-12, atol=1e-12 * np.abs(s).max() * (10.0 ** spread))
    alpha = C.max_step(n3, z, zero, y, zero)
    want = min(float(RJ.step_to_boundary(RJ.to_ctx(ctx, list(z[3 * c:3 * c + 3])), RJ.to_ctx(ctx, list(y[3 * c:3 * c + 3]))))
               for c in range(n3))
    want = min([want] + [(-z[i] / y[i]) if y[i] < 0 else math.inf for i in range(3 * n3, nz)])
    assert alpha == pytest.approx(want, rel=1e-10) or (alpha == math.inf and want == math.inf)


def test_sparse_ldl_solves_spd_systems_in_double_double():
    rng = np.random.default_rng(1)
    A = sp.random(120, 120, density=0.05, random_state=2)
    A = (A @ A.T + 1e-6 * sp.identity(120)).tocsc()  # condition ~1e8
    ch = DDCholesky(A)
    coo = sp.triu(A).tocoo()
    vh = np.zeros(ch.nnz_upper)
    np.add.at(vh, ch.positions(coo.row, coo.col), coo.data)
    assert ch.factor(vh, np.zeros_like(vh)) == -1
    b = rng.normal(size=120)
    xh, xl = ch.solve(b, np.zeros(120))
    with mpmath.workdps(50):
        Ad = A.toarray()
        x = [_mp(h, l) for h, l in zip(xh, xl)]
        res = max(abs(sum(mpmath.mpf(float(Ad[i, j])) * x[j] for j in np.flatnonzero(Ad[i])) - b[i]) for i in range(120))
    assert float(res) <= 1e-26 * np.abs(Ad).max() * float(max(abs(t) for t in x))
    neg = (A - 2 * sp.identity(120)).tocsc()
    coo = sp.triu(neg).tocoo()
    vh = np.zeros(ch.nnz_upper)
    np.add.at(vh, ch.positions(coo.row, coo.col), coo.data)
    assert ch.factor(vh, np.zeros_like(vh)) >= 0  # indefinite: refused, never a wrong factor


def _upper_values(ch, A):
    coo = sp.triu(A).tocoo()
    vh = np.zeros(ch.nnz_upper)
    vl = np.zeros(ch.nnz_upper)
    pos = ch.positions(coo.row, coo.col)
    for p_, x in zip(pos, coo.data):  # a few hundred entries: exact double-double sums
        vh[p_], vl[p_] = dd.add(vh[p_], vl[p_], float(x), 0.0)
    return vh, vl


def _residual_mp(A, xh, xl, b):
    """max_i |(A x − b)_i| in 60 digits, and ‖A‖∞‖x‖∞."""
    with mpmath.workdps(60):
        Ad = A.toarray()
        x = [_mp(h, l) for h, l in zip(xh, xl)]
        res = max(abs(sum(mpmath.mpf(float(Ad[i, j])) * x[j] for j in np.flatnonzero(Ad[i])) - b[i])
                  for i in range(A.shape[0]))
        return float(res), float(np.abs(Ad).sum(axis=1).max()) * float(max(abs(t) for t in x))


def test_mixed_ldl_reaches_double_double_accuracy_on_a_badly_scaled_matrix():
    """D B D with B well conditioned and D spanning 1e-12 … 1e12 (condition ~1e24, far beyond
    float64): a float64 factor refined with double-double residuals solves it to a
    double-double backward error, as the contact-space matrices of the extended phase."""
    rng = np.random.default_rng(3)
    n = 150
    B = sp.random(n, n, density=0.04, random_state=4)
    B = (B @ B.T + sp.identity(n)).tocsc()
    D = sp.diags(10.0 ** rng.uniform(-12, 12, size=n))
    A = (D @ B @ D).tocsc()
    mixed = MixedCholesky(A)
    assert mixed.factor(*_upper_values(mixed, A)) == -1
    b = rng.normal(size=n) * 10.0 ** rng.uniform(-6, 6, size=n)
    xh, xl = mixed.solve(b, np.zeros(n))
    assert mixed.precision == "mixed" and mixed.fallback_reason == ""
    assert mixed.last_backward_error <= mixed.backward_target and mixed.last_steps >= 2
    res, scale = _residual_mp(A, xh, xl, b)
    assert res <= 1e-28 * scale
    # the same answer as the double-double factorisation, to ~30 digits in D-scaled terms
    full = DDCholesky(A)
    assert full.factor(*_upper_values(full, A)) == -1
    yh, yl = full.solve(b, np.zeros(n))
    d = D.diagonal()
    assert np.max(np.abs(d * (dd.to_longdouble(xh, xl) - dd.to_longdouble(yh, yl)))) <= 1e-14 * np.max(np.abs(d * yh))



def singular_in_float64(factor, n: int):
    """(high, low) values of [[1, 1], [1, 1 + 2⁻⁶⁰]] blocks chained along the diagonal, in
    ``factor``'s value order (its ``positions``): the high part singular, the exact matrix SPD."""
    hi, lo = np.zeros(factor.nnz_upper), np.zeros(factor.nnz_upper)
    rows, cols = np.arange(0, n, 2), np.arange(1, n, 2)
    hi[factor.positions(np.arange(n), np.arange(n))] = 1.0
    lo[factor.positions(cols, cols)] = 2.0 ** -60
    hi[factor.positions(rows, cols)] = 1.0
    return hi, lo


def factored_singular_in_float64(monkeypatch, factor_class, shift: float, n: int = 40):
    """A ``factor_class`` (a mixed factor of :mod:`rfverify.extended.mixed`) of the
    :func:`singular_in_float64` blocks, factored with ``mixed.SHIFTS = (shift,)`` at any size: its
    float64 factorisation fails, so ``factor`` returns -1 (asserted)."""
    from rfverify.extended import mixed as mixed_module

    monkeypatch.setattr(mixed_module, "SHIFTS", (shift,))
    monkeypatch.setattr(mixed_module, "SHIFT_MIN_ROWS", 0)
    factor = factor_class(sp.identity(n, format="csc") + sp.csc_matrix(np.eye(n, k=1) + np.eye(n, k=-1)))
    hi, lo = singular_in_float64(factor, n)
    assert factor.factor(hi, lo) == -1
    return factor


def assert_solves_singular_blocks(factor, n: int = 40):
    """``factor`` (of :func:`singular_in_float64`'s blocks) solves them exactly to double-double."""
    b = np.arange(1.0, n + 1)
    xh, xl = factor.solve(b, np.zeros(n))
    x = np.asarray(dd.to_longdouble(xh, xl), dtype=float)
    # exact solution of each block [[1,1],[1,1+δ]] x = (b0, b1): x1 = (b1 − b0)/δ, x0 = b0 − x1
    x1 = (b[1::2] - b[0::2]) * 2.0 ** 60
    assert np.allclose(x[1::2], x1, rtol=1e-12)
    assert np.allclose(x[0::2], b[0::2] - x1, rtol=1e-12)


@pytest.mark.parametrize("shift", [64.0, 0.0])
def test_mixed_ldl_shifts_or_falls_back_where_float64_cannot_see_the_matrix(monkeypatch, shift):
    """A matrix whose float64 part is singular (its definiteness is in the low words): the
    float64 factorisation fails; the shifted one preconditions conjugate gradients in
    double-double, or (no shift: it fails too) the double-double factor is used; each says why,
    and the answer is exact to double-double either way."""
    mixed = factored_singular_in_float64(monkeypatch, MixedCholesky, shift)
    if shift:
        assert mixed.precision == "mixed" and mixed.shifted_from == 1 and "pivot" in mixed.shift_reason
    else:
        assert mixed.precision == "double-double" and "pivot" in mixed.fallback_reason
    assert_solves_singular_blocks(mixed)
    assert mixed.precision == ("mixed" if shift else "double-double")


def test_mixed_ldl_is_not_fooled_by_a_zero_pivot_qdldl_does_not_report():
    """qdldl's update, unlike its first factorisation, returns normally on a zero pivot and
    leaves a factor that is not the new matrix's.  MixedCholesky does not read the pivots
    (that copies L); refinement against the double-double matrix must catch it: the answer is
    the new matrix's, from the double-double fallback."""
    n = 40
    pattern = sp.identity(n, format="csc") + sp.csc_matrix(np.eye(n, k=1) + np.eye(n, k=-1))
    mixed = MixedCholesky(pattern)
    good = sp.csc_matrix(4 * np.eye(n) + np.eye(n, k=1) + np.eye(n, k=-1))
    assert mixed.factor(*_upper_values(mixed, good)) == -1 and mixed.precision == "mixed"
    hi, lo = singular_in_float64(mixed, n)
    assert mixed.factor(hi, lo) == -1  # qdldl 0.1.9: no error, the update's zero pivot goes unreported
    b = np.arange(1.0, n + 1)
    xh, xl = mixed.solve(b, np.zeros(n))
    reason = mixed.fallback_reason  # "refinement stalled", or "zero pivot" from a qdldl that reports it
    assert mixed.precision == "double-double" and ("refinement stalled" in reason or "zero pivot" in reason)
    x1 = (b[1::2] - b[0::2]) * 2.0 ** 60  # the exact answer of the new matrix (see above)
    assert np.allclose(np.asarray(dd.to_longdouble(xh, xl)[1::2], dtype=float), x1, rtol=1e-12)


def test_mixed_ldl_falls_back_when_refinement_stalls():
    """A condition number of 1e17 in a random basis (no scaling removes it): the float64
    factor exists (seed chosen so that no pivot fails) but refinement with it cannot converge;
    the solve is redone in double-double, and the next factorisation stays there."""
    from rfverify.proof.local import exact_psd

    n = 60
    for seed in range(4, 40):
        # Rounding Q Λ Qᵀ to float64 moves the 1e-17 eigenvalue by ~1e-16: take the first seed
        # whose stored matrix is definite in exact arithmetic (LAPACK builds differ in Q).
        rng = np.random.default_rng(seed)
        Q, _ = np.linalg.qr(rng.normal(size=(n, n)))
        A = sp.csc_matrix((Q * np.logspace(0, -17, n)) @ Q.T)
        A = ((A + A.T) / 2).tocsc()
        if exact_psd(A) == "definite" and MixedCholesky(A).factor(*_upper_values(MixedCholesky(A), A)) == -1:
            break
    mixed = MixedCholesky(A)
    assert mixed.factor(*_upper_values(mixed, A)) == -1 and mixed.precision == "mixed"
    b = rng.normal(size=n)
    xh, xl = mixed.solve(b, np.zeros(n))
    assert mixed.precision == "double-double" and "refinement stalled" in mixed.fallback_reason
    res, scale = _residual_mp(A, xh, xl, b)
    assert res <= 1e-27 * scale  # the double-double factor's answer, not the stalled one
    assert mixed.factor(*_upper_values(mixed, A)) == -1 and mixed.precision == "double-double"


@pytest.mark.parametrize("name", ["chute", "random"])
def test_both_back_ends_solve_the_same_newton_system(name):
    problem = rfverify.load(f"bundled:{name}") if name != "random" else random_problem(6, 9, seed=11)
    res = rfverify.solve(problem, tol=1e-8)
    data = ExtendedData(problem)
    z = dd.from_longdouble(res.extras["z"])
    s = data.JT.matvec(*dd.from_longdouble(res.extras["r_t"]))
    nz = data.nz
    ph, pl, pih, pil, lh, ll = (np.zeros(nz) for _ in range(6))
    spec = np.zeros((data.n3 + data.n1, 8))
    assert C.nt_scaling(data.n3, z[0], z[1], s[0], s[1], ph, pl, pih, pil, lh, ll, spec) == -1
    rng = np.random.default_rng(0)
    a = (rng.normal(size=data.m), np.zeros(data.m))
    t = (rng.normal(size=data.nk), np.zeros(data.nk))
    sols = []
    for backend in (ContactSpace(data), ContactSpace(data, mixed=False), DofSpace(data, max_local_dofs=10**6)):
        assert backend.update(ph, pl, pih, pil, spec)
        dv, dr = backend.solve(a, t)
        sols.append(dd.to_longdouble(*dv))
        # first block row in extended precision: M dv − H̃ᵀ dr̃ = a
        r1 = data.M.matvec(*dv)[0] - data.HtT.matvec(*dr)[0] - a[0]
        assert np.abs(r1).max() <= 1e-12 * np.abs(a[0]).max()
    assert np.abs(sols[0] - sols[1]).max() <= 1e-8 * np.abs(sols[0]).max()


def test_extended_run_reaches_the_double_double_floor():
    from rfverify.verify.prepare import start_from
    from rfverify.extended import ipm as X

    problem = rfverify.load("bundled:chute")
    res = rfverify.solve(problem, tol=1e-10)
    data = ExtendedData(problem)
    out = X.run(data, start_from(data, res), max_iter=14)
    mu, pinf = out.trace["mu"], out.trace["pinfeas"]
    assert mu[-1] < 1e-25 < mu[0] and pinf[-1] < 1e-29
    assert all(np.diff(np.log10(mu)) < 0)  # μ falls at every iteration


def test_extended_run_stops_with_numerical_error_when_a_solve_fails():
    """A back end whose solve returns NaN (a double-double fallback factorisation that lost
    definiteness) ends the run as NumericalError at that iteration, not steps later."""
    from rfverify.verify.prepare import start_from
    from rfverify.extended import ipm as X

    problem = rfverify.load("bundled:chute")
    res = rfverify.solve(problem, tol=1e-10)
    data = ExtendedData(problem)

    class Failing(ContactSpace):
        def solve(self, a, t):
            return (np.full(data.m, np.nan), np.zeros(data.m)), (np.full(data.nk, np.nan), np.zeros(data.nk))

    out = X.run(data, start_from(data, res), max_iter=5, backend=Failing(data))
    assert out.status == "NumericalError" and "solve failed" in out.message and out.nit == 0


def test_dense_and_blockwise_constructions_of_W_agree():
    """W̃ = H̃M⁻¹H̃ᵀ built as one dense YᵀY (chosen for a lifted local problem: M = I, H dense)
    and block by block of M: the same pair blocks to double-double accuracy."""
    from rfverify.scenes.random_problems import random_local_problem

    data = ExtendedData(random_local_problem(30, seed=4))
    built = {}
    for dense in (None, False):
        cs = ContactSpace(data)
        cs.dense_W = dense
        cs.Mchol.factor(*cs._M_upper())
        cs._build_W()
        built[dense] = (cs.dense_W_used, cs._W)
    assert built[None][0] is True and built[False][0] is False
    (ah, al), (bh, bl) = built[None][1], built[False][1]
    scale = np.abs(bh).max()
    assert scale > 0 and np.abs((ah - bh) + (al - bl)).max() <= 1e-28 * scale
    # and a rigid-body problem keeps the block-by-block construction
    cs = ContactSpace(ExtendedData(rfverify.load("bundled:chute")))
    cs.Mchol.factor(*cs._M_upper())
    cs._build_W()
    assert cs.dense_W_used is False


def test_blockwise_W_equals_a_dense_recomputation():
    """The compiled block-by-block W̃ (one small dense Cholesky per body) against H̃ M⁻¹ H̃ᵀ
    formed densely in long double, pair block by pair block."""
    from rfverify.scenes.random_problems import random_problem

    data = ExtendedData(random_problem(12, 30, seed=8))
    cs = ContactSpace(data)
    cs.Mchol.factor(*cs._M_upper())
    cs._build_W()
    assert cs.dense_W_used is False
    H = np.zeros(data.Ht.shape, dtype=np.longdouble)
    rows = np.repeat(np.arange(data.Ht.shape[0]), np.diff(data.Ht.indptr))
    H[rows, data.Ht.indices] = data.Ht.hi.astype(np.longdouble) + data.Ht.lo
    mr, mc, mh, ml = data.M.coo()
    M = np.zeros((data.m, data.m), dtype=np.longdouble)
    M[mr, mc] = mh.astype(np.longdouble) + ml
    W = H @ np.linalg.solve(M.astype(np.float64), H.T.astype(np.float64)).astype(np.longdouble)
    Wh, Wl = cs._W
    scale = float(np.abs(W).max())
    for p, (c, d) in enumerate(zip(cs.pc, cs.pd)):
        kc, kd = data.row_count[c], data.row_count[d]
        want = W[data.row_start[c]:data.row_start[c] + kc, data.row_start[d]:data.row_start[d] + kd]
        got = Wh[p, :kc, :kd].astype(np.longdouble) + Wl[p, :kc, :kd]
        assert np.abs(got - want).max() <= 1e-12 * scale, (p, c, d)
