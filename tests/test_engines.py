"""The contract of the float64 factorisation engines (rfverify.engines.factor): every engine
factors the matrix it is handed and solves with it to float64 accuracy, factors again on the
same pattern, counts only the factorisations that succeeded, and refuses a matrix it cannot
factor by raising, never by returning a wrong answer."""

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings, strategies as st

from rfverify.engines.factor import CholmodEngine, QDLDLEngine, SuperLUEngine

from conftest import block_cvxopt


def quasidefinite(rng, n_pos, n_neg, density=0.3):
    """[[P, B], [Bᵀ, −N]] with P, N positive definite: quasi-definite, n_neg negative eigenvalues."""
    def spd(n):
        A = sp.random(n, n, density=density, random_state=rng)
        return (A @ A.T + sp.identity(n)).tocsc()
    B = sp.random(n_pos, n_neg, density=density, random_state=rng)
    return sp.bmat([[spd(n_pos), B], [B.T, -spd(n_neg)]], format="csc")


def spd_matrix(rng, n, density=0.3):
    A = sp.random(n, n, density=density, random_state=rng)
    return (A @ A.T + 0.5 * sp.identity(n)).tocsc()


def same_pattern(K, rng):
    """K's pattern with new values of the same matrix class (scaled diagonal blocks)."""
    K2 = K.copy()
    K2.data = K.data * rng.uniform(0.5, 2.0) if K2.nnz else K2.data
    return K2


def relative_residual(K, x, b):
    return np.abs(K @ x - b).max() / (abs(K).sum(axis=1).max() * np.abs(x).max() + np.abs(b).max())


ENGINES = {
    "qdldl": (QDLDLEngine, lambda rng, n: quasidefinite(rng, n, max(1, n // 2)), lambda K: sp.triu(K, format="csc")),
    "superlu": (SuperLUEngine, lambda rng, n: (sp.random(n, n, density=0.3, random_state=rng)
                                               + 3 * sp.identity(n)).tocsc(), lambda K: K),
    "cholmod": (CholmodEngine, spd_matrix, lambda K: sp.tril(K, format="csc")),
}


@pytest.mark.parametrize("name", list(ENGINES))
@settings(max_examples=15, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 2**32 - 1))
def test_an_engine_solves_what_it_factored_and_refactors_on_the_same_pattern(name, n, seed):
    cls, build, stored = ENGINES[name]
    rng = np.random.default_rng(seed)
    engine = cls()
    K = build(rng, n)
    N = K.shape[0]
    for round_ in range(2):
        engine.factor(stored(K))
        assert engine.factorisations == round_ + 1
        b = rng.standard_normal(N)
        x = engine.solve(b)
        assert x.shape == (N,) and x.dtype == np.float64
        assert relative_residual(K, x, b) < 1e-12
        K = same_pattern(K, rng)


def test_qdldl_pivots_are_the_inertia_and_a_refused_factorisation_is_not_counted():
    rng = np.random.default_rng(5)
    K = quasidefinite(rng, 6, 4)
    engine = QDLDLEngine()
    engine.factor(sp.triu(K, format="csc"))
    D = engine.pivots()
    assert np.count_nonzero(D < 0) == 4 and np.count_nonzero(D > 0) == 6  # Sylvester
    zero = sp.triu(K, format="csc").copy()
    zero.data[:] = 0.0
    fresh = QDLDLEngine()
    with pytest.raises(RuntimeError):  # a first factorisation with a zero pivot is refused
        fresh.factor(zero)
    assert fresh.factorisations == 0
    fresh.factor(sp.triu(K, format="csc"))  # and leaves no broken analysis behind
    b = rng.standard_normal(10)
    assert relative_residual(K, fresh.solve(b), b) < 1e-12
    assert fresh.factorisations == 1


def test_qdldl_update_with_a_zero_pivot_shows_in_the_pivots():
    """qdldl's update does not raise on a zero pivot (the limit QDLDLEngine documents): the
    pivots must show it, since that is what the forms' inertia check reads."""
    K = sp.triu(sp.csc_matrix(np.array([[2.0, 1.0], [1.0, -3.0]])), format="csc")
    engine = QDLDLEngine()
    engine.factor(K)
    zero = K.copy()
    zero.data[:] = 0.0
    try:
        engine.factor(zero)
    except RuntimeError:
        return  # a later qdldl that reports it: the contract holds outright
    D = engine.pivots()
    assert not (np.all(np.isfinite(D)) and np.all(D != 0))


def test_superlu_refuses_a_singular_matrix_and_keeps_no_stale_factor():
    engine = SuperLUEngine()
    engine.factor(sp.identity(3, format="csc") * 2.0)
    with pytest.raises(RuntimeError):
        engine.factor(sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 4.0, 0.0], [0.0, 0.0, 1.0]])))
    assert engine.factorisations == 1
    with pytest.raises(AttributeError):  # the old factor is gone: no answer from a matrix not asked about
        engine.solve(np.ones(3))


def test_cholmod_refuses_an_indefinite_matrix_with_an_arithmetic_error():
    engine = CholmodEngine()
    A = sp.csc_matrix(np.array([[1.0, 0.0], [0.0, 2.0]]))
    engine.factor(sp.tril(A, format="csc"))
    order = engine.permutation()
    assert order is not None
    with pytest.raises(ArithmeticError, match="CHOLMOD"):
        engine.factor(sp.tril(sp.csc_matrix(np.array([[1.0, 0.0], [0.0, -2.0]])), format="csc"))
    assert engine.factorisations == 1
    assert np.array_equal(engine.permutation(), order)  # the analysis's order outlives a failed factor
    engine.release()
    assert engine.permutation() is None


def test_without_cvxopt_the_cholmod_engine_says_what_to_install(monkeypatch):
    block_cvxopt(monkeypatch)
    with pytest.raises(ImportError, match=r"the schur form needs CHOLMOD from cvxopt.*pip install cvxopt"):
        CholmodEngine("the schur form")


def test_every_form_reaches_its_matrix_through_an_engine():
    """The forms own no factorisation of their own: each hands its matrix to an engine of
    rfverify.engines.factor (the issue's forms/engines split)."""
    import rfverify
    from rfverify.model.lifting import lift
    from rfverify.solver.forms import FORMS

    from rfverify.solver.cones import ProductCone

    problem = rfverify.load("bundled:cube")
    lp = lift(problem)
    expected = {"noscaling": SuperLUEngine, "schur": CholmodEngine}
    for name, form in FORMS.items():
        system = form(problem.M_sym, lp.H_t, lp.J, ProductCone(lp.n3, lp.n1))
        assert type(system.engine) is expected.get(name, QDLDLEngine), name


def test_without_cvxopt_the_schur_form_factors_by_qdldl_on_the_upper_triangle(monkeypatch):
    """The default install's schur: S is handed to QDLDL as the upper triangle QDLDL reads, and
    the solves invert the symmetric matrix that triangle stands for (that it is the right S is
    checked through the whole path: test_solver's schur tests against form (16), per engine)."""
    import rfverify
    from rfverify.model.lifting import lift
    from rfverify.solver.cones import ProductCone
    from rfverify.solver.forms import SchurSystem
    from rfverify.solver.kkt import ScalingPoint

    block_cvxopt(monkeypatch)
    problem = rfverify.load("bundled:cube")
    lp = lift(problem)
    cones = ProductCone(lp.n3, lp.n1)
    system = SchurSystem(problem.M_sym, lp.H_t, lp.J, cones)
    assert type(system.engine) is QDLDLEngine and system.engine.triangle == "upper"
    handed = []
    factor = system.engine.factor
    system.engine.factor = lambda K: (handed.append(K.copy()), factor(K))[1]
    rng = np.random.default_rng(0)
    z, s = (rng.standard_normal(lp.nz) for _ in range(2))
    for x in (z, s):
        x[0:3 * lp.n3:3] = np.hypot(x[1:3 * lp.n3:3], x[2:3 * lp.n3:3]) + 0.5  # interior of every L3 cone
        x[3 * lp.n3:] = np.abs(x[3 * lp.n3:]) + 0.5
    p, p_inv, _, _ = cones.nt_scaling(z, s)
    assert system.update(ScalingPoint(p=p, p_inv=p_inv))
    (K,) = handed
    assert sp.tril(K, k=-1).nnz == 0  # upper triangle only
    S = (K + sp.triu(K, k=1).T).toarray()
    rhs = rng.standard_normal(S.shape[0])
    np.testing.assert_allclose(S @ system.engine.solve(rhs), rhs, rtol=0, atol=1e-10 * np.abs(rhs).max())
