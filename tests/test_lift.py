"""DDSpace.lift, the δ of the Newton driver's primal projection: Jδ = e to double-double
rounding and ‖Q_pδ‖ least among all such δ, at NT scalings up to cond(Q_p) ≈ 1e32 — checked
against an 80-digit computation of the same Q_p (from the scaling's own spectral data)."""

from __future__ import annotations

import mpmath
import numpy as np
import pytest

from rfverify.extended import ipm as X
from rfverify.extended.data import ExtendedData
from rfverify.scenes.random_problems import random_problem


def _cone_point(rng, n3, n1, small_first: bool, spread: float):
    """Interior points with a spectral decomposition (1, κ) or (κ, 1) per 3-cone, κ log-uniform
    down to ``spread``, in a random frame; z and s built with the opposite orders are a
    complementary pair whose NT point p has cond(Q_p) up to 1/spread²."""
    angles = rng.uniform(0, 2 * np.pi, n3)
    kappa = 10.0 ** rng.uniform(np.log10(spread), 0, n3)
    big, small = (kappa, np.ones(n3)) if small_first else (np.ones(n3), kappa)
    x = np.zeros(3 * n3 + n1)
    x[0:3 * n3:3] = (big + small) / 2
    x[1:3 * n3:3] = (big - small) / 2 * np.cos(angles)
    x[2:3 * n3:3] = (big - small) / 2 * np.sin(angles)
    x[3 * n3:] = 10.0 ** rng.uniform(np.log10(spread), 0, n1)
    return x, angles


def _reference_Q(spec, n3, n_cones):
    """Q_p cone by cone in mpmath from the scaling's spectral data (what quad_spectral applies):
    A·q1q1ᵀ + B·q2q2ᵀ + C·q3q3ᵀ with A = a², B = b², C = ab, q1,2 = (1, ±d)/√2, q3 = (0, −d2, d1)."""
    blocks = []
    for c in range(n_cones):
        a, b = mpmath.mpf(spec[c, 0]) + spec[c, 1], mpmath.mpf(spec[c, 2]) + spec[c, 3]
        if c >= n3:
            blocks.append(mpmath.matrix([[a * a]]))
            continue
        d1, d2 = mpmath.mpf(spec[c, 4]) + spec[c, 5], mpmath.mpf(spec[c, 6]) + spec[c, 7]
        q1 = mpmath.matrix([1, d1, d2]) / mpmath.sqrt(2)
        q2 = mpmath.matrix([1, -d1, -d2]) / mpmath.sqrt(2)
        q3 = mpmath.matrix([0, -d2, d1])
        blocks.append(a * a * q1 * q1.T + b * b * q2 * q2.T + a * b * q3 * q3.T)
    return blocks


@pytest.mark.parametrize("seed, spread", [(0, 1e-3), (1, 1e-8), (2, 1e-16)])
def test_the_lift_is_exact_in_J_and_least_in_Q_p(seed, spread):
    problem = random_problem(5, 12, seed=seed, mu_r_zero_fraction=0.25, mu_zero_fraction=0.1)
    data = ExtendedData(problem)
    space = X.DDSpace(data)
    rng = np.random.default_rng(seed)
    n3, n1 = data.n3, data.n1
    z, angles = _cone_point(rng, n3, n1, False, spread)
    s, _ = _cone_point(np.random.default_rng([seed, 7]), n3, n1, True, spread)
    sc = X.DDCones(data).scaling(X.V(z), X.V(s))
    e = X.V(rng.standard_normal(data.nk) * 10.0 ** rng.uniform(-6, 6, data.nk))
    delta = space.lift(e, sc)
    f, r = space._heads
    assert f.size >= 5, "the problem must have full contacts (a normal row shared by two heads)"

    with mpmath.workdps(80):
        exact = [mpmath.mpf(h) + lo for h, lo in zip(delta.h, delta.l)]
        J = data.lp.J.tocsr()
        worst = max(abs(sum(exact[j] for j in J.indices[J.indptr[i]:J.indptr[i + 1]])
                        - (mpmath.mpf(e.h[i]) + e.l[i])) for i in range(data.nk))
        assert worst <= 1e-30 * float(np.max(np.abs(e.h))), float(worst)  # Jδ = e

        Q = _reference_Q(sc.spec, n3, n3 + n1)

        def damage(vec, cones):  # ‖Q_p vec‖² over the given cones
            total = mpmath.mpf(0)
            for c in cones:
                k = 3 if c < n3 else 1
                start = 3 * c if c < n3 else 3 * n3 + (c - n3)
                out = Q[c] * mpmath.matrix(vec[start:start + k])
                total += sum(x * x for x in out)
            return total

        naive_worse = 0
        for fh, rh in zip(f, r):  # each full contact: the split is the minimiser of ‖Q_pδ‖
            cones = (fh // 3, rh // 3)
            got = damage(exact, cones)
            g = [mpmath.mpf(0)] * len(exact)
            g[fh], g[rh] = mpmath.mpf(-1), mpmath.mpf(1)
            # ‖Q(δ + t g)‖² = got + 2t⟨Qg, Qδ⟩ + t²‖Qg‖²: its least value over t
            gg = damage(g, cones)
            cross = (damage([x + y for x, y in zip(exact, g)], cones) - got - gg) / 2
            least = got - cross * cross / gg
            bound = least * (1 + mpmath.mpf("1e-20")) + mpmath.mpf(10) ** -60
            assert got <= bound, (float(got), float(least))
            naive = list(exact)
            naive[fh], naive[rh] = exact[fh] + exact[rh], mpmath.mpf(0)  # all of e_N to one head
            naive_worse += damage(naive, cones) > bound
        assert naive_worse >= f.size // 2, "a split without the minimisation would pass this test"


def test_a_lifting_of_another_structure_is_refused():
    """_shared_heads accepts only what the lifting builds: one 1 per column of J, at most two per
    row, shared only by heads of 3-cones."""
    import scipy.sparse as sp

    J = sp.csr_matrix(np.array([[1.0, 0, 0, 1], [0, 1, 1, 0]]))  # row 1 shared by components 1 and 2
    with pytest.raises(ValueError, match="not heads of 3-cones"):
        X._shared_heads(J, 2)
    with pytest.raises(ValueError, match="at most two"):
        X._shared_heads(sp.csr_matrix(np.ones((1, 3))), 1)
    full = np.zeros((5, 6))  # one full contact: its normal row read by both heads (0 and 3)
    full[0, 0] = full[0, 3] = full[1, 1] = full[2, 2] = full[3, 4] = full[4, 5] = 1.0
    rows, (first, second) = X._shared_heads(sp.csr_matrix(full), 2)
    assert list(rows) == [0, 1, 2, 0, 3, 4] and sorted([first[0], second[0]]) == [0, 3]
