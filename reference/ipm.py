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
factorisation whose ordering is computed once.  Its iterates are the exact-arithmetic
iterates of every double-precision form, up to 10^(−dps).

Precision is private: the solver works in its own ``mpmath.MPContext``; the global ``mp``
context is never modified.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components, reverse_cuthill_mckee

from . import jordan as J

SPACEDIM = 5


@dataclass
class ReferenceResult:
    """Result of :func:`solve`.

    ``v`` (m), ``u`` (5n), ``r`` (5n) are lists of mpf numbers of the solver's private context
    ``ctx`` (arithmetic at 2·``dps`` digits); ``v_float`` etc. are float64 roundings.  ``status``
    is ``"Solved"``, ``"MaxIterations"`` or ``"NumericalError"``; ``trace`` holds per-iteration
    floats (pinfeas, dinfeas, mu, alpha, sigma).  ``r_t`` (nk) and ``z`` (cone by cone) are the
    final lifted iterate, in the layout of ``warm_start``.
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
                raise ArithmeticError(f"reduced system not positive definite at pivot {j} ({d})")
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


# ---------------------------------------------------------------------- the solver
def solve(problem, dps: int = 50, tol=None, max_iter: int = 200, sigma_rule: str = "paper",
          gamma0: float = 0.9, warm_start=None) -> ReferenceResult:
    """Algorithm 1 at ``dps`` significant digits: independent mode (the standard infeasible
    start) by default, warm mode when ``warm_start`` is given.

    Parameters
    ----------
    problem
        An object with ``M_sym`` (m×m) and ``H`` (m×5n) scipy sparse matrices and float
        vectors ``f, w, mu, mu_r`` (an :class:`rfverify.Problem`); its data are converted
        exactly to the working precision.
    dps : int
        Requested accuracy in decimal digits (default 50); the arithmetic runs at 2·dps
        digits (see the comment in the code for the measurement behind this).
    tol : number, optional
        Stop when max(pinfeas, dinfeas, μ) ≤ tol; default 10^(−dps+10).
    warm_start : dict, optional
        Continue from an iterate of another implementation (the mixed-precision path):
        ``{"v": (m,), "r_t": (nk,), "z": list of cone vectors}`` in this module's lifted layout
        (kept components in contact order; cones contact by contact: friction, rolling, or
        the normal-only ray).  Numbers (float64, longdouble) are converted exactly.  The point
        must be strictly interior (z and Jᵀr̃ in the cone interiors); otherwise the run
        falls back to the standard start and says so in ``message``.
    """
    t0 = time.perf_counter()
    # The arithmetic runs at twice the requested digits: the reduced system's condition number
    # grows like 1/μ², and errors in its solution accumulate in the primal residual.  Measured
    # on the bundled cube problem with 50-digit arithmetic: pinfeas climbed from 1e-50 to 3e-27
    # while μ went to 1e-50, so the run could not meet 1e-40.  With 2·dps digits the growth
    # (about μ^-0.45 here) stays far below the target.
    ctx = J.context(2 * dps)
    mpf = ctx.mpf
    tol = mpf(10) ** (-(dps - 10)) if tol is None else mpf(tol)
    lifted = _Lifted(ctx, problem)
    n, nk = lifted.n, lifted.nk
    m = problem.M_sym.shape[0]

    # Exact data.
    Mc = sp.coo_matrix(problem.M_sym)
    Hc = sp.csc_matrix(problem.H).tocoo()
    f = [mpf(float(x)) for x in problem.f]
    w = [mpf(float(x)) for x in problem.w]
    # H̃ = P Hᵀ on kept components: row k of H̃ ↔ column keep[k] of H.
    col_to_kept = {c: k for k, c in enumerate(lifted.keep)}
    Ht_rows = [dict() for _ in range(nk)]  # H̃[k] = {dof: value}
    for i, j, x in zip(Hc.row, Hc.col, Hc.data):
        k = col_to_kept.get(int(j))
        if k is not None and x != 0:
            Ht_rows[k][int(i)] = Ht_rows[k].get(int(i), 0) + lifted.scale[k] * mpf(float(x))
    w_t = [lifted.scale[k] * w[c] for k, c in enumerate(lifted.keep)]

    # Blocks of M (bodies): exact inverse of each block in mpmath.
    pattern = sp.coo_matrix((np.ones(Mc.nnz), (Mc.row, Mc.col)), shape=(m, m))
    n_blocks, labels = connected_components(pattern, directed=False)
    blocks = [[] for _ in range(n_blocks)]
    for dof in range(m):
        blocks[labels[dof]].append(dof)
    Mentries = {}
    for i, j, x in zip(Mc.row, Mc.col, Mc.data):
        Mentries[(int(i), int(j))] = mpf(float(x))
    Minv_blocks = []
    for dofs in blocks:
        B = ctx.matrix(len(dofs), len(dofs))
        for a, da in enumerate(dofs):
            for b, db in enumerate(dofs):
                B[a, b] = Mentries.get((da, db), mpf(0))
        Minv_blocks.append((dofs, ctx.inverse(B)))

    def M_apply(v):
        out = [mpf(0)] * m
        for (i, j), x in Mentries.items():
            out[i] += x * v[j]
        return out

    def Minv_apply(x):
        out = [mpf(0)] * m
        for dofs, Binv in Minv_blocks:
            for a, da in enumerate(dofs):
                out[da] = ctx.fsum(Binv[a, b] * x[db] for b, db in enumerate(dofs))
        return out

    def Ht_apply(v):
        return [ctx.fsum(val * v[d] for d, val in row.items()) for row in Ht_rows]

    def HtT_apply(r_t):
        out = [mpf(0)] * m
        for k, row in enumerate(Ht_rows):
            rk = r_t[k]
            for d, val in row.items():
                out[d] += val * rk
        return out

    # W̃ = H̃ M⁻¹ H̃ᵀ, block by block of M (fixed for the whole run).
    W = _SymSparse(nk)
    rows_of_block = [dict() for _ in range(n_blocks)]  # block → {kept row: {dof: val}}
    for k, row in enumerate(Ht_rows):
        for d, val in row.items():
            rows_of_block[labels[d]].setdefault(k, {})[d] = val
    for b, (dofs, Binv) in enumerate(Minv_blocks):
        touching = rows_of_block[b]
        if not touching:
            continue
        pos = {d: a for a, d in enumerate(dofs)}
        # y_k = M_B⁻¹ h_k for each touching row, then W[k, l] += h_lᵀ y_k.
        ys = {}
        for k, h in touching.items():
            ys[k] = [ctx.fsum(Binv[a, pos[d]] * val for d, val in h.items()) for a in range(len(dofs))]
        keys = sorted(touching)
        for ia, k in enumerate(keys):
            for l in keys[: ia + 1]:
                W.add(k, l, ctx.fsum(val * ys[k][pos[d]] for d, val in touching[l].items()))
    G_pairs = set()
    for rows in lifted.cones:
        for a in rows:
            for b in rows:
                G_pairs.add((max(a, b), min(a, b)))
    chol = _Cholesky(sorted(set(W.entries) | G_pairs), nk)

    # Standard infeasible start: v = 0, r̃_N = 1 (so Jᵀr̃ = e), z = e.
    v = [mpf(0)] * m
    r_t = [mpf(0)] * nk
    for rows in lifted.cones:
        r_t[rows[0]] = mpf(1)
    z = [J.identity(ctx, len(rows)) for rows in lifted.cones]
    n_cones = len(lifted.cones)
    warm_note = ""
    if warm_start is not None:
        wv, wr, wz = warm_start["v"], warm_start["r_t"], warm_start["z"]
        if len(wv) != m or len(wr) != nk or len(wz) != n_cones or \
                any(len(zc) != len(rows) for zc, rows in zip(wz, lifted.cones)):
            raise ValueError("warm_start does not match the lifted layout of this problem")
        v_w = J.to_ctx(ctx, list(wv))
        r_w = J.to_ctx(ctx, list(wr))
        z_w = [J.to_ctx(ctx, list(zc)) for zc in wz]
        s_w = [[r_w[row] for row in rows] for rows in lifted.cones]
        interior = all(J.spectral_values(c)[1] > 0 for c in z_w + s_w)
        if interior:
            v, r_t, z = v_w, r_w, z_w
            warm_note = " (warm start)"
        else:
            warm_note = " (warm start not interior: standard start used)"
    gamma = mpf(gamma0)
    trace = {k: [] for k in ("pinfeas", "dinfeas", "mu", "sigma", "alpha")}

    def norm(x):
        return ctx.sqrt(ctx.fsum(t * t for t in x))

    status, message = "MaxIterations", f"reached max_iter = {max_iter}"
    k = 0
    for k in range(max_iter + 1):
        s = lifted.JT(r_t)
        Mv, HTr, Hv, Jz = M_apply(v), HtT_apply(r_t), Ht_apply(v), lifted.J(z)
        r_d = [a - b - c for a, b, c in zip(Mv, HTr, f)]
        r_p = [a + b - c for a, b, c in zip(Hv, w_t, Jz)]
        tiny = mpf(2) ** (-ctx.prec * 4)
        pinf = norm(r_p) / max(norm(Jz), norm(Hv), norm(w_t), tiny)
        dinf = norm(r_d) / max(norm(Mv), norm(f), norm(HTr), tiny)
        gap = ctx.fsum(J.dot(zc, sc) for zc, sc in zip(z, s))
        mu = gap / n
        trace["pinfeas"].append(float(pinf))
        trace["dinfeas"].append(float(dinf))
        trace["mu"].append(float(mu))
        if max(pinf, dinf, mu) <= tol:
            status, message = "Solved", f"max(pinfeas, dinfeas, mu) = {ctx.nstr(max(pinf, dinf, mu), 3)} <= tol"
            break
        if k == max_iter:
            break
        try:
            nt = [J.nt_scaling(zc, sc) for zc, sc in zip(z, s)]
        except J.ReferenceDomainError as exc:
            status, message = "NumericalError", f"iteration {k}: {exc}"
            break
        p = [t[0] for t in nt]
        p_inv = [t[1] for t in nt]
        lam = [t[2] for t in nt]
        p_inv2 = [J.power(pc, -2) for pc in p]
        # S = W̃ + J Q_{p⁻²} Jᵀ
        S = W.copy()
        for rows, q in zip(lifted.cones, p_inv2):
            Q = J.quad_matrix(q)
            for a, ra in enumerate(rows):
                for b, rb in enumerate(rows):
                    if ra >= rb:
                        S.add(ra, rb, Q[a][b])
        chol.factor(ctx, S)

        def newton(a_vec, b_vec, c_cones):
            qc = [J.quad_apply(pi, cc) for pi, cc in zip(p_inv, c_cones)]
            bp = [bb - jq for bb, jq in zip(b_vec, lifted.J(qc))]
            Minv_a = Minv_apply(a_vec)
            HMa = Ht_apply(Minv_a)
            rhs = [-x - y for x, y in zip(bp, HMa)]
            dr = chol.solve(ctx, rhs)
            dv = Minv_apply([x + y for x, y in zip(a_vec, HtT_apply(dr))])
            JTdr = lifted.JT(dr)
            dz = [[x - y for x, y in zip(qcc, J.quad_apply(q2, jt))]
                  for qcc, q2, jt in zip(qc, p_inv2, JTdr)]
            return dv, dr, dz

        a_vec = [-x for x in r_d]
        b_vec = r_p
        dv_a, dr_a, dz_a = newton(a_vec, b_vec, [[-x for x in lc] for lc in lam])
        ds_a = lifted.JT(dr_a)
        alpha_a = min([mpf(1)] + [J.step_to_boundary(zc, dc) for zc, dc in zip(z, dz_a)]
                      + [J.step_to_boundary(sc, dc) for sc, dc in zip(s, ds_a)])
        gap_a = ctx.fsum(J.dot([x + alpha_a * y for x, y in zip(zc, dzc)],
                               [x + alpha_a * y for x, y in zip(sc, dsc)])
                         for zc, dzc, sc, dsc in zip(z, dz_a, s, ds_a))
        mu_a = gap_a / n
        ratio = max(mu_a, mpf(0)) / mu
        if sigma_rule == "paper":
            expo = max(mpf(1), 3 * alpha_a) if mu < mpf("1e-5") else mpf(1)
            sigma = min(mpf(1), ratio ** expo)
        else:
            expo = max(mpf(1), 3 * alpha_a ** 2) if mu > mpf("1e-5") else max(mpf(1), 3 * alpha_a)
            sigma = min(mpf(1), ratio ** expo) / 5
        mu_c = gap / n_cones
        c_cones = []
        for lc, pc, pic, dzc, dsc in zip(lam, p, p_inv, dz_a, ds_a):
            e = J.identity(ctx, len(lc))
            corr = J.product(J.quad_apply(pc, dzc), J.quad_apply(pic, dsc))
            ll = J.product(lc, lc)
            xi = [sigma * mu_c * ei - li - ci for ei, li, ci in zip(e, ll, corr)]
            c_cones.append(J.arrow_solve(lc, xi))
        dv, dr, dz = newton(a_vec, b_vec, c_cones)
        ds = lifted.JT(dr)
        alpha_max = min([J.step_to_boundary(zc, dc) for zc, dc in zip(z, dz)]
                        + [J.step_to_boundary(sc, dc) for sc, dc in zip(s, ds)])
        alpha = min(mpf(1), gamma * alpha_max)
        trace["sigma"].append(float(sigma))
        trace["alpha"].append(float(alpha))
        v = [x + alpha * y for x, y in zip(v, dv)]
        r_t = [x + alpha * y for x, y in zip(r_t, dr)]
        z = [[x + alpha * y for x, y in zip(zc, dzc)] for zc, dzc in zip(z, dz)]
        gamma = mpf("0.9") + mpf("0.09") * alpha

    # Back to the original variables: r = P r̃, u = Hᵀ v + w (exact in the context).
    r = [mpf(0)] * (SPACEDIM * n)
    for k_, c in enumerate(lifted.keep):
        r[c] = lifted.scale[k_] * r_t[k_]
    u = list(w)
    for i, j, x in zip(Hc.row, Hc.col, Hc.data):
        u[int(j)] += mpf(float(x)) * v[int(i)]
    return ReferenceResult(v=v, u=u, r=r, status=status, message=message + warm_note,
                           nit=len(trace["pinfeas"]) - 1, pinfeas=pinf, dinfeas=dinf, mu=mu,
                           dps=dps, ctx=ctx, trace=trace, time=time.perf_counter() - t0,
                           r_t=r_t, z=z)
