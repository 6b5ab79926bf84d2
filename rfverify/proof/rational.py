"""Small exact rational linear algebra (Python Fractions), for systems of a few dozen unknowns.

Used by :mod:`.face` to find a self-stress exactly and to move a point exactly onto the face of
the cones that the self-stress forces.  Gaussian elimination over Q is exact, so "consistent",
"rank" and "null space" are statements about the data, not about rounding.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np


def as_fractions(A) -> list[list[Fraction]]:
    """A float (or Fraction) 2-D array as a list of rows of exact Fractions."""
    return [[x if isinstance(x, Fraction) else Fraction(float(x)) for x in row] for row in A]


def rref(A: list[list[Fraction]]) -> tuple[list[list[Fraction]], list[int]]:
    """Reduced row echelon form of A (exact) and its pivot columns.  Pivots are chosen by the
    largest magnitude in their column (only to keep the numbers of a particular solution small:
    the result is exact whatever the choice)."""
    rows = [list(r) for r in A]
    m = len(rows)
    n = len(rows[0]) if m else 0
    pivots: list[int] = []
    top = 0
    for col in range(n):
        if top == m:
            break
        best = max(range(top, m), key=lambda i: abs(rows[i][col]))
        if rows[best][col] == 0:
            continue
        rows[top], rows[best] = rows[best], rows[top]
        p = rows[top][col]
        rows[top] = [x / p for x in rows[top]]
        for i in range(m):
            if i != top and rows[i][col] != 0:
                f = rows[i][col]
                rows[i] = [a - f * b for a, b in zip(rows[i], rows[top])]
        pivots.append(col)
        top += 1
    return rows[:top], pivots


def null_space(A: list[list[Fraction]], n: int) -> list[list[Fraction]]:
    """An exact basis of {x ∈ Qⁿ : A x = 0} (A has n columns; an empty A gives the unit basis)."""
    if not A:
        return [[Fraction(int(i == j)) for i in range(n)] for j in range(n)]
    R, pivots = rref(A)
    free = [c for c in range(n) if c not in set(pivots)]
    basis = []
    for f in free:
        x = [Fraction(0)] * n
        x[f] = Fraction(1)
        for row, c in zip(R, pivots):
            x[c] = -row[f]
        basis.append(x)
    return basis


def particular_solution(A: list[list[Fraction]], b: list[Fraction]) -> list[Fraction] | None:
    """An exact x with A x = b (free unknowns 0), or None when the system is inconsistent."""
    n = len(A[0]) if A else 0
    R, pivots = rref([row + [bi] for row, bi in zip(A, b)])
    if n in pivots:  # a pivot in the right-hand side column: 0 = 1
        return None
    x = [Fraction(0)] * n
    for row, c in zip(R, pivots):
        x[c] = row[n]
    return x


def matvec(A: list[list[Fraction]], x: list[Fraction]) -> list[Fraction]:
    return [sum((a * xi for a, xi in zip(row, x) if a), Fraction(0)) for row in A]


def to_float(x) -> np.ndarray:
    return np.array([float(v) for v in x], dtype=np.float64)
