"""The mpfr Cholesky engines of the multiple-precision tail (rfverify.extended.wide_cholesky),
through their interface alone: values stored on an OrderedPattern, factor, solve."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from rfverify.extended import wide_data
from rfverify.extended.ldl import fill_reducing_order
from rfverify.extended.wide_cholesky import DenseWideCholesky, OrderedPattern, SparseWideCholesky

BITS = 320
ENGINES = (DenseWideCholesky, SparseWideCholesky)


def _random_spd(seed: int, m: int = 40, density: float = 0.08) -> sp.csc_matrix:
    """A sparse symmetric positive definite matrix (float64 entries, exact in mpfr) whose
    entries span six orders of magnitude: strictly diagonally dominant."""
    rng = np.random.default_rng(seed)
    A = sp.random(m, m, density=density, random_state=rng, data_rvs=lambda k: rng.uniform(-1, 1, k))
    A = A + A.T
    scale = 10.0 ** rng.uniform(-3, 3, m)
    A = sp.diags(np.sqrt(scale)) @ A @ sp.diags(np.sqrt(scale))
    dominance = np.asarray(abs(A).sum(axis=1)).ravel() + scale
    A = sp.tril(A + sp.diags(dominance))
    return (A + sp.tril(A, -1).T).tocsc()  # symmetric exactly (the scaling rounds each side apart)


def _values(ordered: OrderedPattern, S: sp.spmatrix) -> np.ndarray:
    """S's values in the engines' storage convention (the lower triangle of the ordered S)."""
    coo = S.tocoo()
    slots = ordered.slots(coo.row, coo.col)
    values = wide_data.zeros(ordered.indices.size)
    values[slots[slots >= 0]] = wide_data.from_dd(coo.data[slots >= 0])
    return values


def _residual(S: sp.spmatrix, x: np.ndarray, b: np.ndarray) -> float:
    """‖S x − b‖∞ / ‖b‖∞ in the working precision, S in its own numbering."""
    coo = S.tocoo()
    Sx = wide_data.zeros(S.shape[0])
    np.add.at(Sx, coo.row, wide_data.from_dd(coo.data) * x[coo.col])
    return float(wide_data.inf_norm(Sx - b) / wide_data.inf_norm(b))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_both_engines_factor_the_same_matrix_and_solve_to_full_precision(seed):
    """Same order, same values: the dense and the sparse engine's solves agree number for
    number and solve S x = b to the working precision, in S's own numbering (the order is a
    minimum-degree one, or a random one)."""
    S = _random_spd(seed)
    m = S.shape[0]
    rng = np.random.default_rng(seed)
    for order in (fill_reducing_order(S), rng.permutation(m)):
        ordered = OrderedPattern(S, order)
        with wide_data.context(BITS):
            values = _values(ordered, S)
            b = wide_data.from_dd(rng.normal(size=m))
            solutions = []
            for engine_class in ENGINES:
                engine = engine_class(ordered)
                assert engine.factor(values.copy())
                solutions.append(engine.solve(b))
            dense, sparse = solutions
            assert all(x == y for x, y in zip(dense, sparse))
            assert _residual(S, sparse, b) <= 2.0 ** (-BITS + 40)


def test_the_cost_counts_the_factors_entries():
    """ops = Σ c_j² over the strictly lower entries per column of L: counted here on the
    dense engine's factor of values without cancellation."""
    S = _random_spd(5, m=30, density=0.15)
    ordered = OrderedPattern(S, fill_reducing_order(S))
    with wide_data.context(BITS):
        engine = DenseWideCholesky(ordered)
        assert engine.factor(_values(ordered, S))
        below = np.array([sum(1 for x in engine.L[j + 1:, j] if x != 0) for j in range(S.shape[0])])
    assert ordered.ops == float(np.sum(below.astype(np.float64) ** 2)) > 0


@pytest.mark.parametrize("engine_class", ENGINES)
@pytest.mark.parametrize("matrix", [
    [[1.0, 2.0], [2.0, 1.0]],  # positive diagonal, second pivot 1 − 4 < 0
    [[4.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]],  # second pivot exactly 0
    [[1.0, 0.0], [0.0, -1.0]],
])
def test_a_non_positive_pivot_is_refused(engine_class, matrix):
    S = sp.csc_matrix(np.array(matrix))
    ordered = OrderedPattern(S, np.arange(S.shape[0]))
    with wide_data.context(BITS):
        assert not engine_class(ordered).factor(_values(ordered, S))
        # the same engine factors the matrix made definite
        definite = (S + sp.identity(S.shape[0]) * 4.0).tocsc()
        engine = engine_class(ordered)
        assert engine.factor(_values(ordered, definite))
        b = wide_data.from_dd(np.ones(S.shape[0]))
        assert _residual(definite, engine.solve(b), b) <= 2.0 ** (-BITS + 8)
