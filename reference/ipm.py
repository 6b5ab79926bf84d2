"""Algorithm 1 in arbitrary precision (mpmath), written independently of ``rfverify``'s numerics.

Only the problem *container* is shared with the production package (``problem.M_sym``,
``problem.H`` as scipy sparse matrices, and the vectors ``f, w, mu, mu_r``); every number is
converted exactly to the working precision and every operation — lifting, Jordan algebra,
NT scaling, step lengths, linear solves — is done here in mpmath.  scipy is used for one
thing only: a fill-reducing ordering of the sparsity *pattern*.

Linear algebra (the "suggested route" of the issue): all linear-system forms of Algorithm 1
are algebraically equivalent, so the reference solves the reduced symmetric positive definite
system in contact space

    (H̃ M⁻¹ H̃ᵀ + J Q_{p⁻²} Jᵀ) dr̃ = −(b − J Q_{p⁻¹} c) − H̃ M⁻¹ a,
    dv = M⁻¹ (a + H̃ᵀ dr̃),   dz = Q_{p⁻¹} c − Q_{p⁻²} Jᵀ dr̃,

with M⁻¹ applied block by block (M is block diagonal by bodies) and a sparse Cholesky
factorisation.  What does not change between iterations — W̃ = H̃ M⁻¹ H̃ᵀ, the block
inverses, the ordering — is built once by :class:`Solver`.  Its iterates are the
exact-arithmetic iterates of every double-precision form, up to 10^(−dps).

Precision is private: the solver works in its own ``mpmath.MPContext``; the global ``mp``
context is never modified.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import mpmath
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, reverse_cuthill_mckee

from . import jordan as J

SPACEDIM = 5


@dataclass
class ReferenceResult:
    """Result of :meth:`Solver.run` and :func:`solve`.

    ``v`` (m), ``u`` (5n), ``r`` (5n) are lists of mpf numbers of the solver's private context
    ``ctx`` (arithmetic at 2·``dps`` digits); :meth:`as_float` gives float64 roundings.
    ``status`` is ``"Solved"``, ``"MaxIterations"`` or ``"NumericalError"``; ``trace`` holds
    per-iteration floats (pinfeas, dinfeas, mu, alpha, sigma).  ``r_t`` (nk) and ``z`` (cone by
    cone) are the final lifted iterate (:attr:`iterate`).  ``time`` is in seconds: the run's,
    and for :func:`solve` the build's as well.
    """

    v: list
    u: list
    r: list
    status: str
    message: str
    nit: int
    pinfeas: object
    dinfeas: object
    mu: object
    dps: int
    ctx: object
    trace: dict = field(default_factory=dict)
    time: float = 0.0
    r_t: list = field(default_factory=list)
    z: list = field(default_factory=list)

    @property
    def success(self) -> bool:
        return self.status == "Solved"

    def as_float(self, name: str) -> np.ndarray:
        return np.array([float(x) for x in getattr(self, name)])

    @property
    def iterate(self) -> "Iterate":
        return Iterate(v=self.v, r_t=self.r_t, z=self.z)


# ---------------------------------------------------------------------- lifting (own code)
class _Lifted:
    """Lifted Lorentz-cone form with the per-contact cone reduction of DESIGN §4, in mpf."""

    def __init__(self, ctx, problem):
        self.ctx = ctx
        n = int(len(problem.mu))
        mu = [ctx.mpf(float(x)) for x in problem.mu]
        mur = [ctx.mpf(float(x)) for x in problem.mu_r]
        self.n = n
        keep, scale, cones = [], [], []  # cones: list of lists of kept-row indices
        for i in range(n):
            has_t, has_r = mu[i] > 0, mur[i] > 0
            base = len(keep)
            comps = [0] + ([1, 2] if has_t else []) + ([3, 4] if has_r else [])
            for c in comps:
                keep.append(SPACEDIM * i + c)
                scale.append(ctx.mpf(1) if c == 0 else (mu[i] if c <= 2 else mur[i]))
            pos = {c: base + k for k, c in enumerate(comps)}
            if has_t:
                cones.append([pos[0], pos[1], pos[2]])
            if has_r:
                cones.append([pos[0], pos[3], pos[4]])
            if not has_t and not has_r:
                cones.append([pos[0]])
        self.keep = keep
        self.scale = scale
        self.cones = cones  # each cone: kept rows of its components (row of its head first)
        self.nk = len(keep)

    def J(self, z_cones):
        """J z: sum the cone heads into u0, copy the rest (z given cone by cone)."""
        out = [self.ctx.mpf(0)] * self.nk
        for rows, zc in zip(self.cones, z_cones):
            for row, val in zip(rows, zc):
                out[row] += val
        return out

    def JT(self, r_t):
        """Jᵀ r̃ cone by cone: (r0, r̄; r0, ř)."""
        return [[r_t[row] for row in rows] for rows in self.cones]


# ---------------------------------------------------------------------- sparse matrices in mpf
class _SymSparse:
    """Symmetric sparse matrix as {(i, j): value} on the lower triangle (i ≥ j)."""

    def __init__(self, n):
        self.n = n
        self.entries = {}

    def add(self, i, j, val):
        if i < j:
            i, j = j, i
        key = (i, j)
        self.entries[key] = self.entries.get(key, 0) + val

    def copy(self):
        out = _SymSparse(self.n)
        out.entries = dict(self.entries)
        return out


class _Cholesky:
    """Sparse LLᵀ in mpmath with a fixed symmetric ordering (reverse Cuthill–McKee of the
    pattern, computed once); left-looking, column dictionaries."""

    def __init__(self, pattern_pairs, n):
        rows = [i for i, j in pattern_pairs] + list(range(n))
        cols = [j for i, j in pattern_pairs] + list(range(n))
        A = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)).tocsr()
        A = A + A.T
        self.perm = np.asarray(reverse_cuthill_mckee(A.tocsr(), symmetric_mode=True), dtype=np.int64)
        self.iperm = np.empty(n, dtype=np.int64)
        self.iperm[self.perm] = np.arange(n)
        self.n = n

    def factor(self, ctx, S: _SymSparse):
        n = self.n
        ip = self.iperm
        cols = [dict() for _ in range(n)]  # permuted lower-triangular columns of S
        for (i, j), val in S.entries.items():
            a, b = ip[i], ip[j]
            if a < b:
                a, b = b, a
            cols[b][a] = cols[b].get(a, 0) + val
        L = [None] * n
        row_users = [[] for _ in range(n)]  # row_users[j] = columns k < j with L[j, k] ≠ 0
        for j in range(n):
            col = dict(cols[j])
            for k in row_users[j]:
                Lk = L[k]
                ljk = Lk[j]
                for i, lik in Lk.items():
                    if i >= j:
                        col[i] = col.get(i, 0) - lik * ljk
            d = col.get(j, 0)
            if not d > 0:
                raise ArithmeticError(f"reduced system not positive definite at pivot {j} ({mpmath.nstr(mpmath.mpf(d), 6)})")
            d = ctx.sqrt(d)
            Lj = {j: d}
            for i, val in col.items():
                if i > j:
                    Lj[i] = val / d
                    row_users[i].append(j)
            L[j] = Lj
        self.L = L

    def solve(self, ctx, b):
        n = self.n
        y = [b[self.perm[i]] for i in range(n)]
        L = self.L
        for j in range(n):  # forward: L y = b
            y[j] = y[j] / L[j][j]
            yj = y[j]
            for i, lij in L[j].items():
                if i > j:
                    y[i] -= lij * yj
        for j in range(n - 1, -1, -1):  # backward: Lᵀ x = y
            s = y[j]
            for i, lij in L[j].items():
                if i > j:
                    s -= lij * y[i]
            y[j] = s / L[j][j]
        x = [None] * n
        for i in range(n):
            x[self.perm[i]] = y[i]
        return x


# ---------------------------------------------------------------------- iterates
@dataclass
class Iterate:
    """A lifted iterate of Algorithm 1 in mpf numbers of one :class:`Solver`'s context: ``v``
    (m), ``r_t`` (nk, kept components in contact order) and ``z`` (one list per cone, contact
    by contact: friction, rolling, or the normal-only ray)."""

    v: list
    r_t: list
    z: list


@dataclass(frozen=True)
class Residuals:
    """What Algorithm 1 measures at an iterate: the residual vectors ``r_d = Mv − H̃ᵀr̃ − f``
    and ``r_p = H̃v + w̃ − Jz``, the paper's ``pinfeas``, ``dinfeas``, the gap zᵀJᵀr̃ and
    ``mu`` = gap / (number of contacts)."""

    r_d: list
    r_p: list
    pinfeas: object
    dinfeas: object
    gap: object
    mu: object

    @property
    def worst(self):
        return max(self.pinfeas, self.dinfeas, self.mu)


@dataclass(frozen=True)
class Step:
    """One iteration of Algorithm 1: the next ``iterate`` and the centring ``sigma`` and step
    length ``alpha`` that produced it."""

    iterate: Iterate
    sigma: object
    alpha: object


# ---------------------------------------------------------------------- the solver
class Solver:
    """Algorithm 1 at ``dps`` significant digits on one problem.

    The constructor does everything that does not depend on the iterate, once: the exact data
    in the working precision, the lifting, the inverses of the diagonal blocks of M, the
    contact-space matrix W̃ = H̃ M⁻¹ H̃ᵀ and the fill-reducing ordering of the Cholesky
    factorisation.  :meth:`step` takes one iteration from a given iterate (lockstep diagnosis),
    :meth:`run` iterates to the tolerance from the standard start (independent mode) or from a
    given iterate (warm mode).

    Parameters
    ----------
    problem
        An object with ``M_sym`` (m×m) and ``H`` (m×5n) scipy sparse matrices and float
        vectors ``f, w, mu, mu_r`` (an :class:`rfverify.Problem`); its data are converted
        exactly to the working precision (``f`` may also hold mpmath numbers, rounded to it).
    dps : int
        Requested accuracy in decimal digits (default 50); the arithmetic runs at 2·dps digits
        in the private context ``ctx``.
    """

    def __init__(self, problem, dps: int = 50):
        t0 = time.perf_counter()
        self.dps = dps
        # Twice the requested digits: the reduced system's condition number grows like 1/μ²
        # and its solution errors accumulate in the primal residual (docs/DECISIONS.md).
        ctx = self.ctx = J.context(2 * dps)
        mpf = ctx.mpf
        lifted = self.lifted = _Lifted(ctx, problem)
        self.n, self.nk = lifted.n, lifted.nk
        m = self.m = problem.M_sym.shape[0]
        self.n_cones = len(lifted.cones)
        self._tiny = mpf(2) ** (-ctx.prec * 4)

        Mc = sp.coo_matrix(problem.M_sym)
        Hc = sp.csc_matrix(problem.H).tocoo()
        self._H_entries = [(int(i), int(j), mpf(float(x))) for i, j, x in zip(Hc.row, Hc.col, Hc.data)]
        # f may hold mpmath numbers (a right-hand side that is no float64 vector), kept to the
        # working precision; floats are converted exactly.
        self._f = [mpf(x) if isinstance(x, mpmath.mpf) else mpf(float(x)) for x in problem.f]
        self._w = [mpf(float(x)) for x in problem.w]
        # H̃ = P Hᵀ on kept components: row k of H̃ ↔ column keep[k] of H.
        col_to_kept = {c: k for k, c in enumerate(lifted.keep)}
        Ht_rows = self._Ht_rows = [dict() for _ in range(self.nk)]  # H̃[k] = {dof: value}
        for i, j, x in zip(Hc.row, Hc.col, Hc.data):
            k = col_to_kept.get(int(j))
            if k is not None and x != 0:
                Ht_rows[k][int(i)] = Ht_rows[k].get(int(i), 0) + lifted.scale[k] * mpf(float(x))
        self._w_t = [lifted.scale[k] * self._w[c] for k, c in enumerate(lifted.keep)]

        # Blocks of M (bodies): exact inverse of each block in mpmath.
        pattern = sp.coo_matrix((np.ones(Mc.nnz), (Mc.row, Mc.col)), shape=(m, m))
        n_blocks, labels = connected_components(pattern, directed=False)
        blocks = [[] for _ in range(n_blocks)]
        for dof in range(m):
            blocks[labels[dof]].append(dof)
        self._M_entries = {}
        for i, j, x in zip(Mc.row, Mc.col, Mc.data):
            self._M_entries[(int(i), int(j))] = mpf(float(x))
        self._Minv_blocks = []  # (dofs, rows of the block's inverse as lists of mpf)
        for dofs in blocks:
            B = ctx.matrix(len(dofs), len(dofs))
            for a, da in enumerate(dofs):
                for b, db in enumerate(dofs):
                    B[a, b] = self._M_entries.get((da, db), mpf(0))
            Binv = ctx.inverse(B)
            self._Minv_blocks.append((dofs, [[Binv[a, b] for b in range(len(dofs))] for a in range(len(dofs))]))

        # W̃ = H̃ M⁻¹ H̃ᵀ, block by block of M.
        W = self._W = _SymSparse(self.nk)
        rows_of_block = [dict() for _ in range(n_blocks)]  # block → {kept row: {dof: val}}
        for k, row in enumerate(Ht_rows):
            for d, val in row.items():
                rows_of_block[labels[d]].setdefault(k, {})[d] = val
        for b, (dofs, Binv) in enumerate(self._Minv_blocks):
            touching = rows_of_block[b]
            if not touching:
                continue
            pos = {d: a for a, d in enumerate(dofs)}
            # y_k = M_B⁻¹ h_k for each touching row, then W[k, l] += h_lᵀ y_k.
            ys = {}
            for k, h in touching.items():
                ys[k] = [ctx.fsum(Binv[a][pos[d]] * val for d, val in h.items()) for a in range(len(dofs))]
            keys = sorted(touching)
            for ia, k in enumerate(keys):
                for l in keys[: ia + 1]:
                    W.add(k, l, ctx.fsum(val * ys[k][pos[d]] for d, val in touching[l].items()))
        G_pairs = set()
        for rows in lifted.cones:
            for a in rows:
                for b in rows:
                    G_pairs.add((max(a, b), min(a, b)))
        self._chol = _Cholesky(sorted(set(W.entries) | G_pairs), self.nk)
        self.build_time = time.perf_counter() - t0

    # ------------------------------------------------------------------ operators
    def _M_apply(self, v):
        out = [self.ctx.mpf(0)] * self.m
        for (i, j), x in self._M_entries.items():
            out[i] += x * v[j]
        return out

    def _Minv_apply(self, x):
        ctx = self.ctx
        out = [ctx.mpf(0)] * self.m
        for dofs, Binv in self._Minv_blocks:
            for a, da in enumerate(dofs):
                row = Binv[a]
                out[da] = ctx.fsum(row[b] * x[db] for b, db in enumerate(dofs))
        return out

    def _Ht_apply(self, v):
        fsum = self.ctx.fsum
        return [fsum(val * v[d] for d, val in row.items()) for row in self._Ht_rows]

    def _HtT_apply(self, r_t):
        out = [self.ctx.mpf(0)] * self.m
        for k, row in enumerate(self._Ht_rows):
            rk = r_t[k]
            for d, val in row.items():
                out[d] += val * rk
        return out

    def _norm(self, x):
        ctx = self.ctx
        return ctx.sqrt(ctx.fsum(t * t for t in x))

    # ------------------------------------------------------------------ iterates
    def start(self) -> Iterate:
        """The standard infeasible start: v = 0, r̃_N = 1 (so Jᵀr̃ = e), z = e."""
        mpf = self.ctx.mpf
        r_t = [mpf(0)] * self.nk
        for rows in self.lifted.cones:
            r_t[rows[0]] = mpf(1)
        return Iterate(v=[mpf(0)] * self.m, r_t=r_t,
                       z=[J.identity(self.ctx, len(rows)) for rows in self.lifted.cones])

    def iterate(self, v, r_t, z) -> Iterate:
        """An iterate of another implementation in this solver's context (numbers converted
        exactly: float64, longdouble, mpf): ``v`` (m), ``r_t`` (nk) and ``z`` cone by cone in
        the layout of :class:`Iterate`.  Raises ValueError when the sizes do not match."""
        if len(v) != self.m or len(r_t) != self.nk or len(z) != self.n_cones or \
                any(len(zc) != len(rows) for zc, rows in zip(z, self.lifted.cones)):
            raise ValueError("warm_start does not match the lifted layout of this problem")
        ctx = self.ctx
        return Iterate(v=J.to_ctx(ctx, list(v)), r_t=J.to_ctx(ctx, list(r_t)),
                       z=[J.to_ctx(ctx, list(zc)) for zc in z])

    def s_cones(self, it: Iterate) -> list:
        """Jᵀr̃ cone by cone, in the order of ``it.z``."""
        return self.lifted.JT(it.r_t)

    def is_interior(self, it: Iterate) -> bool:
        """z and Jᵀr̃ strictly inside their cones (where Algorithm 1 can take a step)."""
        return all(J.spectral_values(c)[1] > 0 for c in it.z + self.s_cones(it))

    def residuals(self, it: Iterate) -> Residuals:
        lifted = self.lifted
        s = lifted.JT(it.r_t)
        Mv, HTr, Hv, Jz = self._M_apply(it.v), self._HtT_apply(it.r_t), self._Ht_apply(it.v), lifted.J(it.z)
        r_d = [a - b - c for a, b, c in zip(Mv, HTr, self._f)]
        r_p = [a + b - c for a, b, c in zip(Hv, self._w_t, Jz)]
        norm, tiny = self._norm, self._tiny
        pinf = norm(r_p) / max(norm(Jz), norm(Hv), norm(self._w_t), tiny)
        dinf = norm(r_d) / max(norm(Mv), norm(self._f), norm(HTr), tiny)
        gap = self.ctx.fsum(J.dot(zc, sc) for zc, sc in zip(it.z, s))
        return Residuals(r_d=r_d, r_p=r_p, pinfeas=pinf, dinfeas=dinf, gap=gap, mu=gap / self.n)

    # ------------------------------------------------------------------ one iteration
    def step(self, it: Iterate, gamma, sigma_rule: str = "paper", residuals: Residuals | None = None) -> Step:
        """One iteration of Algorithm 1 from the interior iterate ``it`` with step-length
        fraction ``gamma`` (α = min(1, γ·α_max)) and σ rule ``"paper"``, ``"siconos"`` or
        ``"mehrotra"`` (σ = max(0.2, min(1, (μ_a/μ)³)), the far phase of the production
        solver's ``hybrid``).
        Raises :class:`reference.jordan.ReferenceDomainError` when z or Jᵀr̃ is not interior."""
        ctx, lifted = self.ctx, self.lifted
        mpf = ctx.mpf
        res = self.residuals(it) if residuals is None else residuals
        gamma = mpf(gamma)
        z, s = it.z, lifted.JT(it.r_t)
        nt = [J.nt_scaling(zc, sc) for zc, sc in zip(z, s)]
        p = [t[0] for t in nt]
        p_inv = [t[1] for t in nt]
        lam = [t[2] for t in nt]
        p_inv2 = [J.power(pc, -2) for pc in p]
        # S = W̃ + J Q_{p⁻²} Jᵀ
        S = self._W.copy()
        for rows, q in zip(lifted.cones, p_inv2):
            Q = J.quad_matrix(q)
            for a, ra in enumerate(rows):
                for b, rb in enumerate(rows):
                    if ra >= rb:
                        S.add(ra, rb, Q[a][b])
        self._chol.factor(ctx, S)

        a_vec = [-x for x in res.r_d]
        b_vec = res.r_p
        dv_a, dr_a, dz_a = self._newton(a_vec, b_vec, [[-x for x in lc] for lc in lam], p_inv, p_inv2)
        ds_a = lifted.JT(dr_a)
        alpha_a = min([mpf(1)] + [J.step_to_boundary(zc, dc) for zc, dc in zip(z, dz_a)]
                      + [J.step_to_boundary(sc, dc) for sc, dc in zip(s, ds_a)])
        gap_a = ctx.fsum(J.dot([x + alpha_a * y for x, y in zip(zc, dzc)],
                               [x + alpha_a * y for x, y in zip(sc, dsc)])
                         for zc, dzc, sc, dsc in zip(z, dz_a, s, ds_a))
        mu, mu_a = res.mu, gap_a / self.n
        ratio = max(mu_a, mpf(0)) / mu
        if sigma_rule not in ("paper", "siconos", "mehrotra"):
            raise ValueError(f"sigma_rule = {sigma_rule!r} must be 'paper', 'siconos' or 'mehrotra'")
        if sigma_rule == "paper":
            expo = max(mpf(1), 3 * alpha_a) if mu < mpf("1e-5") else mpf(1)
            sigma = min(mpf(1), ratio ** expo)
        elif sigma_rule == "mehrotra":
            sigma = max(mpf("0.2"), min(mpf(1), ratio ** 3))
        else:
            expo = max(mpf(1), 3 * alpha_a ** 2) if mu > mpf("1e-5") else max(mpf(1), 3 * alpha_a)
            sigma = min(mpf(1), ratio ** expo) / 5
        mu_c = res.gap / self.n_cones
        c_cones = []
        for lc, pc, pic, dzc, dsc in zip(lam, p, p_inv, dz_a, ds_a):
            e = J.identity(ctx, len(lc))
            corr = J.product(J.quad_apply(pc, dzc), J.quad_apply(pic, dsc))
            ll = J.product(lc, lc)
            xi = [sigma * mu_c * ei - li - ci for ei, li, ci in zip(e, ll, corr)]
            c_cones.append(J.arrow_solve(lc, xi))
        dv, dr, dz = self._newton(a_vec, b_vec, c_cones, p_inv, p_inv2)
        ds = lifted.JT(dr)
        alpha_max = min([J.step_to_boundary(zc, dc) for zc, dc in zip(z, dz)]
                        + [J.step_to_boundary(sc, dc) for sc, dc in zip(s, ds)])
        alpha = min(mpf(1), gamma * alpha_max)
        nxt = Iterate(v=[x + alpha * y for x, y in zip(it.v, dv)],
                      r_t=[x + alpha * y for x, y in zip(it.r_t, dr)],
                      z=[[x + alpha * y for x, y in zip(zc, dzc)] for zc, dzc in zip(z, dz)])
        return Step(iterate=nxt, sigma=sigma, alpha=alpha)

    def _newton(self, a_vec, b_vec, c_cones, p_inv, p_inv2):
        """Newton direction from the factored reduced system (see the module docstring)."""
        lifted = self.lifted
        qc = [J.quad_apply(pi, cc) for pi, cc in zip(p_inv, c_cones)]
        bp = [bb - jq for bb, jq in zip(b_vec, lifted.J(qc))]
        HMa = self._Ht_apply(self._Minv_apply(a_vec))
        rhs = [-x - y for x, y in zip(bp, HMa)]
        dr = self._chol.solve(self.ctx, rhs)
        dv = self._Minv_apply([x + y for x, y in zip(a_vec, self._HtT_apply(dr))])
        dz = [[x - y for x, y in zip(qcc, J.quad_apply(q2, jt))]
              for qcc, q2, jt in zip(qc, p_inv2, lifted.JT(dr))]
        return dv, dr, dz

    # ------------------------------------------------------------------ iterate to the end
    def run(self, start=None, tol=None, max_iter: int = 200, sigma_rule: str = "paper",
            gamma0: float = 0.9) -> ReferenceResult:
        """Iterate until max(pinfeas, dinfeas, μ) ≤ ``tol`` (default 10^(−dps+10)).

        ``start`` None: independent mode, from :meth:`start`.  Otherwise warm mode from an
        :class:`Iterate` or a mapping with ``v``, ``r_t``, ``z`` (see :meth:`iterate`); a
        start that is not strictly interior is replaced by the standard start, and
        ``message`` says so.  γ starts at ``gamma0`` and then is 0.9 + 0.09·α."""
        t0 = time.perf_counter()
        ctx = self.ctx
        mpf = ctx.mpf
        tol = mpf(10) ** (-(self.dps - 10)) if tol is None else mpf(tol)
        it, note = self.start(), ""
        if start is not None:
            get = start.get if isinstance(start, dict) else lambda name: getattr(start, name)
            warm = self.iterate(get("v"), get("r_t"), get("z"))
            if self.is_interior(warm):
                it, note = warm, " (warm start)"
            else:
                note = " (warm start not interior: standard start used)"
        gamma = mpf(gamma0)
        trace = {k: [] for k in ("pinfeas", "dinfeas", "mu", "sigma", "alpha")}
        status, message = "MaxIterations", f"reached max_iter = {max_iter}"
        for k in range(max_iter + 1):
            res = self.residuals(it)
            trace["pinfeas"].append(float(res.pinfeas))
            trace["dinfeas"].append(float(res.dinfeas))
            trace["mu"].append(float(res.mu))
            if res.worst <= tol:
                status, message = "Solved", f"max(pinfeas, dinfeas, mu) = {ctx.nstr(res.worst, 3)} <= tol"
                break
            if k == max_iter:
                break
            try:
                step = self.step(it, gamma, sigma_rule, res)
            except J.ReferenceDomainError as exc:
                status, message = "NumericalError", f"iteration {k}: {exc}"
                break
            trace["sigma"].append(float(step.sigma))
            trace["alpha"].append(float(step.alpha))
            it = step.iterate
            gamma = mpf("0.9") + mpf("0.09") * step.alpha
        return self._result(it, res, status, message + note, trace, time.perf_counter() - t0)

    def _result(self, it, res, status, message, trace, seconds) -> ReferenceResult:
        """Back to the original variables: r = P r̃, u = Hᵀ v + w (exact in the context)."""
        lifted = self.lifted
        r = [self.ctx.mpf(0)] * (SPACEDIM * self.n)
        for k, c in enumerate(lifted.keep):
            r[c] = lifted.scale[k] * it.r_t[k]
        u = list(self._w)
        for i, j, x in self._H_entries:
            u[j] += x * it.v[i]
        return ReferenceResult(v=it.v, u=u, r=r, status=status, message=message,
                               nit=len(trace["pinfeas"]) - 1, pinfeas=res.pinfeas, dinfeas=res.dinfeas,
                               mu=res.mu, dps=self.dps, ctx=self.ctx, trace=trace, time=seconds,
                               r_t=it.r_t, z=it.z)


def solve(problem, dps: int = 50, tol=None, max_iter: int = 200, sigma_rule: str = "paper",
          gamma0: float = 0.9, warm_start=None) -> ReferenceResult:
    """Algorithm 1 at ``dps`` significant digits: ``Solver(problem, dps).run(...)``.

    Independent mode (the standard infeasible start) by default, warm mode when
    ``warm_start`` is given: ``{"v": (m,), "r_t": (nk,), "z": list of cone vectors}`` in the
    lifted layout of :class:`Iterate`, numbers (float64, longdouble) converted exactly; a
    point that is not strictly interior falls back to the standard start and ``message`` says
    so.  ``time`` of the result includes the build.  See :class:`Solver` for the parameters.
    """
    t0 = time.perf_counter()
    res = Solver(problem, dps).run(start=warm_start, tol=tol, max_iter=max_iter,
                                   sigma_rule=sigma_rule, gamma0=gamma0)
    res.time = time.perf_counter() - t0
    return res
