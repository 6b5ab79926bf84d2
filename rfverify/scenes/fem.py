"""A linear-elastic body meshed with linear tetrahedra, time-stepped by Moreau–Jean (θ = 1)
on a rigid support: the finite-element one-step problems of the ElasticBlock scene
(:class:`ElasticBlock`, at the end).

Mesh
----
A block of ``nx × ny × nz`` cubic cells of edge ``a`` on the plane z = 0, each cell split into
the six tetrahedra of the Kuhn (Freudenthal) subdivision along its (0,0,0)–(1,1,1) diagonal,
which is conforming across cells.  Optionally every node is moved by a uniform random offset
of at most ``jitter·a`` per coordinate, except that the nodes of the bottom face keep z = 0
exactly (they rest on the support with zero gap).

Dofs: 3 per node (displacement velocity, world frame), node k owns rows 3k..3k+2.  Nodes have
no rotation.

Element matrices (linear tetrahedron with vertices x_a, a = 0..3, volume V > 0, constant
shape-function gradients g_a = ∇N_a, isotropic material with Young's modulus E, Poisson
ratio ν, Lamé λ = Eν/((1+ν)(1−2ν)), shear G = E/(2(1+ν)), density ρ):

    consistent mass   M_e[a, b] = ρ V (1 + δ_ab) / 20 · I₃                      (exact)
    stiffness         K_e[a, b] = V (λ g_a g_bᵀ + G g_b g_aᵀ + G (g_a·g_b) I₃)  (= V Bᵀ D B)
    gravity load      F_e[a]    = ρ V / 4 · g   (so F = M_mass · (g, g, ..., g), exactly)

with [1 x_aᵀ] the rows of a 4×4 matrix X, (∂N_a/∂x)_a = rows 1..3 of X⁻¹ (so Σ_a g_a = 0 and
Σ_a g_a x_aᵀ = I₃).  Global matrices are sums of the element blocks.  Element stiffness
components at round-off level of their element's largest one (64 ε), and assembled sums at
round-off level of the sum of their terms' magnitudes, vanish in exact arithmetic (the
undistorted mesh has many) and are stored as zeros; the assembled matrix is then replaced by
(A + Aᵀ)/2, which is exactly symmetric (the sparse sum adds duplicates in different orders for
(i, j) and (j, i)).

Moreau–Jean, θ = 1 (linear elasticity, no damping; q = nodal displacements from the
stress-free reference configuration, small displacements: the matrices stay those of the
reference configuration), from (q_k, v_k):

    (M_mass + h² K) v⁺ = M_mass v_k + h (F − K q_k) + H r,     q_{k+1} = q_k + h v⁺

so the FCLIB problem has M = M_mass + h² K (the *iteration matrix*: sparse, non-diagonal,
SPD) and f = M_mass v_k + h (F − K q_k).  The run starts at rest and stress-free
(q_0 = v_0 = 0), so the first problem has f = h F = h M_mass (g, ..., g): the block's weight
pushing it into the support.  With steel, 25 cm cells and h = 1e-3 s (the defaults), h²K
exceeds M_mass 3e3–9e3-fold on the diagonal, so the stepping is quasi-static: the block
reaches its static sag within the first step, and velocities at the third are ~1e-7 m/s.
M's entries span 4–6 decades (the smallest are couplings that nearly cancel on the jittered
mesh).

Contacts: one per node of the bottom face, with the rigid support (no dofs).  Normal N = e_z
(from the support to the body), tangents T1, T2 = e_x, e_y rotated about N by an angle drawn
per contact from the seed (the cone does not depend on it).  H's N, T1, T2 columns hold N, T1,
T2 in the node's three rows; the rolling columns R1, R2 are zero (μr = 0: a node has no
rotation, the rolling part of the cone reduces to r_R = 0).  The gap is zero, so w = 0.

The solution, and why it is known.  With every contact sticking, u = Hᵀv = 0 means the
bottom nodes do not move: v⁺ is the solution of the *clamped* linear system M_ff v_f = f_f
(f = free dofs, bottom nodes' velocity 0), and the reactions follow from the bottom rows,
r_c = (N, T1, T2)ᵀ (M v⁺ − f)_node, r_R = 0.  If every r_c lies strictly inside its Coulomb
cone (r_N > 0, ‖r_T‖ < μ r_N), then (v⁺, u = 0, r) satisfies every optimality condition of the
convex problem, so it *is* the solution (v and u are unique because M ≻ 0; r is unique because
the N, T1, T2 columns have full column rank and μr = 0 forces r_R = 0).  The stepper computes
exactly this, checks the cone condition at every step (SceneError otherwise: raise μ), and
advances with it; no interior-point solve is involved.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .scene import G, Scene
from .stepper import SceneError

# The six tetrahedra of the Kuhn subdivision of the unit cube: vertex path (0,0,0) → +e_i →
# +e_j → (1,1,1) for each permutation (i, j, k) of the axes.  Corner index = x + 2y + 4z.
_KUHN = tuple((0, 1 << i, (1 << i) | (1 << j), 7) for i, j, _ in itertools.permutations(range(3)))


@dataclass
class Mesh:
    """Nodes and linear tetrahedra of a block.

    nodes : (N, 3)      coordinates (reference configuration)
    tets : (E, 4)       node indices, positively oriented (volume > 0)
    bottom : (nb,)      indices of the nodes on the support (z = 0), increasing
    shape : (nx, ny, nz) cells per direction
    cell : float        cell edge
    """

    nodes: np.ndarray
    tets: np.ndarray
    bottom: np.ndarray
    shape: tuple
    cell: float

    @property
    def n_nodes(self) -> int:
        return self.nodes.shape[0]


def block_mesh(nx: int, ny: int, nz: int, cell: float, jitter: float = 0.0,
               rng: np.random.Generator | None = None) -> Mesh:
    """Kuhn-subdivided block [0, nx·a] × [0, ny·a] × [0, nz·a] (a = ``cell``), nodes numbered
    x fastest, then y, then z (the bottom face first).  ``jitter`` > 0 moves each node by
    U(−jitter·a, jitter·a) per coordinate (``rng`` required), bottom nodes in x and y only.
    Raises SceneError when a tetrahedron would be inverted or nearly flat."""
    if min(nx, ny, nz) < 1:
        raise SceneError(f"block_mesh: need at least one cell per direction, got {(nx, ny, nz)}")
    ix, iy, iz = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1), indexing="ij")
    # Node (i, j, k) has index i + (nx+1)(j + (ny+1) k).
    order = np.lexsort((ix.ravel(), iy.ravel(), iz.ravel()))
    grid = np.stack((ix.ravel()[order], iy.ravel()[order], iz.ravel()[order]), axis=1)
    nodes = cell * grid.astype(float)

    def node_id(i, j, k):
        return i + (nx + 1) * (j + (ny + 1) * k)

    cx, cy, cz = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    cx, cy, cz = (c.transpose(2, 1, 0).ravel() for c in (cx, cy, cz))  # cells x fastest
    corners = np.stack([node_id(cx + (c & 1), cy + ((c >> 1) & 1), cz + ((c >> 2) & 1))
                        for c in range(8)], axis=1)
    tets = np.concatenate([corners[:, list(t)] for t in _KUHN], axis=0)
    # Interleave so that the six tetrahedra of a cell are consecutive (element order = cell order).
    tets = tets.reshape(6, -1, 4).transpose(1, 0, 2).reshape(-1, 4)
    if jitter > 0:
        if rng is None:
            raise SceneError("block_mesh: jitter needs a random generator")
        d = rng.uniform(-jitter * cell, jitter * cell, nodes.shape)
        d[grid[:, 2] == 0, 2] = 0.0
        nodes = nodes + d
    vol = tet_volumes(nodes, tets)
    flip = vol < 0
    tets[flip] = tets[flip][:, [1, 0, 2, 3]]
    vol = np.abs(vol)
    if vol.min() < 0.05 * cell ** 3 / 6:
        raise SceneError(f"block_mesh: a tetrahedron is inverted or nearly flat (volume "
                         f"{vol.min():.3g} against {cell ** 3 / 6:.3g} undistorted); fix: a lower --param jitter")
    bottom = np.flatnonzero(grid[:, 2] == 0)
    return Mesh(nodes=nodes, tets=tets, bottom=bottom, shape=(nx, ny, nz), cell=float(cell))


def tet_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Signed volumes det[x1−x0, x2−x0, x3−x0]/6 of the tetrahedra (E,)."""
    x = nodes[tets]
    return np.linalg.det(np.stack((x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]),
                                  axis=2)) / 6.0


def shape_gradients(nodes: np.ndarray, tets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(g, V): constant gradients g (E, 4, 3) of the four linear shape functions and volumes
    V (E,) (positive for positively oriented tetrahedra)."""
    x = nodes[tets]
    X = np.concatenate((np.ones((x.shape[0], 4, 1)), x), axis=2)  # rows [1, x_aᵀ]
    C = np.linalg.inv(X)  # N_a(x) = C[0, a] + C[1:, a]·x
    return np.transpose(C[:, 1:, :], (0, 2, 1)), np.linalg.det(X) / 6.0


def lame(young: float, poisson: float) -> tuple[float, float]:
    """(λ, G) of an isotropic material."""
    if not (young > 0 and -1.0 < poisson < 0.5):
        raise SceneError(f"elastic material needs young > 0 and -1 < poisson < 0.5, got "
                         f"young = {young!r}, poisson = {poisson!r}; fix: give --param young=VALUE > 0 and "
                         "--param poisson=VALUE in (-1, 0.5)")
    return (young * poisson / ((1 + poisson) * (1 - 2 * poisson)),
            young / (2 * (1 + poisson)))


def _assemble(tets: np.ndarray, blocks: np.ndarray, n_nodes: int) -> sp.csc_matrix:
    """Global (3N × 3N) matrix from element blocks (E, 4, 4, 3, 3) = [a, b, i, j]."""
    E = tets.shape[0]
    a, b, i, j = np.meshgrid(np.arange(4), np.arange(4), np.arange(3), np.arange(3), indexing="ij")
    rows = 3 * tets[:, a.ravel()] + i.ravel()
    cols = 3 * tets[:, b.ravel()] + j.ravel()
    vals = blocks.reshape(E, -1)
    keep = vals != 0.0  # structural zeros (the off-diagonal components of mass blocks)
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    shape = (3 * n_nodes, 3 * n_nodes)
    A = sp.csc_matrix((vals, (rows, cols)), shape=shape)  # duplicates summed
    # Sums that cancel exactly in exact arithmetic (the structured mesh has many) come out as
    # round-off, ~1e-16 of the terms summed: store them as the zeros they are.
    S = sp.csc_matrix((np.abs(vals), (rows, cols)), shape=shape)
    A.sort_indices()
    S.sort_indices()
    assert np.array_equal(A.indices, S.indices) and np.array_equal(A.indptr, S.indptr)
    A.data[np.abs(A.data) <= 64 * np.finfo(float).eps * S.data] = 0.0
    A.eliminate_zeros()
    # The order in which duplicates are summed is not the same for (i, j) and (j, i);
    # averaging with the transpose makes A exactly symmetric (floating-point + commutes).
    A = ((A + A.T) * 0.5).tocsc()
    A.sort_indices()
    return A


def mass_matrix(mesh: Mesh, density: float) -> sp.csc_matrix:
    """Consistent mass matrix ρ V (1 + δ_ab)/20 · I₃ per element pair of nodes (a, b)."""
    _, V = shape_gradients(mesh.nodes, mesh.tets)
    m = density * V[:, None, None] * (np.ones((4, 4)) + np.eye(4))[None] / 20.0
    blocks = m[:, :, :, None, None] * np.eye(3)[None, None, None]
    return _assemble(mesh.tets, blocks, mesh.n_nodes)


def stiffness_matrix(mesh: Mesh, young: float, poisson: float) -> sp.csc_matrix:
    """Linear-elastic stiffness V (λ g_a g_bᵀ + G g_b g_aᵀ + G (g_a·g_b) I₃) per element pair
    of nodes (a, b); each element block is symmetrised exactly before assembly."""
    lam, G = lame(young, poisson)
    g, V = shape_gradients(mesh.nodes, mesh.tets)
    outer = np.einsum("eai,ebj->eabij", g, g)  # g_a g_bᵀ
    dot = np.einsum("eai,ebi->eab", g, g)
    k = (lam * outer + G * np.swapaxes(outer, 3, 4)
         + G * dot[:, :, :, None, None] * np.eye(3)[None, None, None]) * V[:, None, None, None, None]
    k = 0.5 * (k + np.transpose(k, (0, 2, 1, 4, 3)))  # K_e[b, a] = K_e[a, b]ᵀ, bit for bit
    # Components that vanish in exact arithmetic (axis-aligned edges of the undistorted mesh)
    # come out of the inverse as round-off of the element's scale: store them as zeros.
    scale = np.abs(k).reshape(k.shape[0], -1).max(axis=1)
    k[np.abs(k) <= 64 * np.finfo(float).eps * scale[:, None, None, None, None]] = 0.0
    return _assemble(mesh.tets, k, mesh.n_nodes)


def support_contact_matrix(mesh: Mesh, angles: np.ndarray) -> tuple[sp.csc_matrix, np.ndarray]:
    """H (3N × 5nb) for one contact per bottom node, normal e_z, tangents rotated by
    ``angles`` (nb,) about e_z; rolling columns empty.  Also returns the frames (nb, 3, 3)
    whose columns are N, T1, T2."""
    nb = mesh.bottom.size
    c, s = np.cos(angles), np.sin(angles)
    F = np.zeros((nb, 3, 3))
    F[:, 2, 0] = 1.0                                   # N = e_z
    F[:, 0, 1], F[:, 1, 1] = c, s                      # T1 = (cos, sin, 0)
    F[:, 0, 2], F[:, 1, 2] = -s, c                     # T2 = N × T1 = (−sin, cos, 0)
    rows = 3 * mesh.bottom[:, None, None] + np.arange(3)[None, :, None]
    cols = 5 * np.arange(nb)[:, None, None] + np.arange(3)[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    H = sp.csc_matrix((F.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * mesh.n_nodes, 5 * nb))
    H.eliminate_zeros()  # exact zeros of axis-aligned frames are not stored
    H.sort_indices()
    return H, F


@dataclass
class ElasticStep:
    """One Moreau–Jean step of the elastic body (see :class:`ElasticMoreauJean`).

    step : int             index (0-based)
    time : float           time at the start of the step
    f : (3N,)              f = M_mass v_k + h (F − K q_k)
    v, r : ndarrays        the solution (clamped solve), r in FCLIB layout (5 per contact)
    max_ratio : float      max over contacts of ‖r_T‖ / r_N (sticking needs < μ)
    min_rN : float         smallest normal impulse (> 0: every contact closed)
    """

    step: int
    time: float
    f: np.ndarray
    v: np.ndarray
    r: np.ndarray
    max_ratio: float
    min_rN: float


@dataclass
class ElasticMoreauJean:
    """Moreau–Jean (θ = 1) stepping of a linear-elastic body whose bottom nodes rest on a rigid
    support with every contact sticking (module docstring): starts at rest in the stress-free
    reference configuration (q = 0, v = 0) when gravity is switched on.

    The iteration matrix M = M_mass + h² K and H do not change (small displacements: the
    reference configuration is kept; the support contacts stay closed with zero gap)."""

    mesh: Mesh
    M_mass: sp.csc_matrix
    K: sp.csc_matrix
    H: sp.csc_matrix
    frames: np.ndarray
    gravity: np.ndarray
    h: float
    mu: float
    q: np.ndarray = None
    v: np.ndarray = None
    time: float = 0.0
    steps_done: int = 0
    M: sp.csc_matrix = field(init=False)

    def __post_init__(self):
        m = self.M_mass.shape[0]
        self.q = np.zeros(m) if self.q is None else np.asarray(self.q, dtype=float)
        self.v = np.zeros(m) if self.v is None else np.asarray(self.v, dtype=float)
        self.M = (self.M_mass + (self.h * self.h) * self.K).tocsc()
        self.M.sort_indices()
        self.F = self.M_mass @ np.tile(np.asarray(self.gravity, dtype=float), m // 3)
        clamped = np.zeros(m, dtype=bool)
        clamped[(3 * self.mesh.bottom[:, None] + np.arange(3)).ravel()] = True
        self._free = np.flatnonzero(~clamped)
        self._bottom_dofs = (3 * self.mesh.bottom[:, None] + np.arange(3)).reshape(-1, 3)
        self._lu = splu(self.M[self._free][:, self._free].tocsc())

    def one_step_f(self) -> np.ndarray:
        return self.M_mass @ self.v + self.h * (self.F - self.K @ self.q)

    def step(self) -> ElasticStep:
        """Advance one step with the clamped solution; SceneError if a contact would not stick."""
        f = self.one_step_f()
        v = np.zeros_like(f)
        v[self._free] = self._lu.solve(f[self._free])
        load = (self.M @ v - f)[self._bottom_dofs]          # (nb, 3): H r at the bottom nodes
        rc = np.einsum("kij,ki->kj", self.frames, load)     # (N, T1, T2) per contact
        rN, rT = rc[:, 0], np.linalg.norm(rc[:, 1:], axis=1)
        if not np.all(rN > 0):
            k = int(np.argmin(rN))
            raise SceneError(f"ElasticBlock step {self.steps_done}: contact {k} would open "
                             f"(clamped normal impulse {rN[k]:.3g} <= 0); the body is not "
                             "resting on every bottom node; fix: another --seed or a lower --param jitter")
        ratio = rT / rN
        if not np.all(ratio < self.mu):
            k = int(np.argmax(ratio))
            raise SceneError(f"ElasticBlock step {self.steps_done}: contact {k} would slide "
                             f"(|r_T|/r_N = {ratio[k]:.4g} >= mu = {self.mu:g}); fix: a larger --param mu")
        r = np.zeros(5 * rc.shape[0])
        r.reshape(-1, 5)[:, :3] = rc
        rec = ElasticStep(step=self.steps_done, time=self.time, f=f, v=v, r=r,
                          max_ratio=float(ratio.max()), min_rN=float(rN.min()))
        self.q = self.q + self.h * v
        self.v = v
        self.time += self.h
        self.steps_done += 1
        return rec


def entry_range(A: sp.spmatrix) -> tuple[float, float]:
    """(smallest, largest) absolute value of the stored nonzero entries of A."""
    d = np.abs(sp.csc_matrix(A).data)
    d = d[d > 0]
    return float(d.min()), float(d.max())


__all__ = ["Mesh", "block_mesh", "tet_volumes", "shape_gradients", "lame", "mass_matrix",
           "stiffness_matrix", "support_contact_matrix", "ElasticMoreauJean", "ElasticStep",
           "entry_range"]


# ---------------------------------------------------------------------- the scene
class ElasticBlock(Scene):
    name = "ElasticBlock"
    summary = ("finite-element scene: a linear-elastic steel block (linear tetrahedra, 3 dofs "
               "per node, consistent mass) resting with zero gap on a rigid support, one "
               "contact per bottom node, w = 0, mu_r = 0; M = M_mass + h^2 K is sparse, "
               "non-diagonal, SPD; every contact sticks (u = 0, v = the clamped solve)")
    configuration = ("block of size x round(size*width_ratio) x round(size*height_ratio) cubic "
                     "cells of edge 'cell', Kuhn subdivision into 6 tetrahedra per cell, nodes "
                     "jittered by up to jitter*cell (bottom nodes stay on z = 0); tangent frames "
                     "rotated about the normal at random; starts at rest, stress-free, when "
                     "gravity is switched on; Moreau-Jean steps with the clamped solution "
                     "(checked strictly inside every friction cone); stage K dumps step "
                     "(K+1)*steps of the run")
    defaults = dict(cell=0.25, density=7850.0, young=2.1e11, poisson=0.3, h=1e-3, mu=1.0,
                    jitter=0.1, width_ratio=0.5, height_ratio=0.25)
    default_size = 8
    min_size = 1
    size_unit = "cells along the length"
    finite_element = True
    """Generated by :func:`rfverify.scenes.generate` through :class:`ElasticMoreauJean`,
    not the rigid-body :class:`World` / :class:`MoreauJean` path."""

    def cells(self, p, size) -> tuple[int, int, int]:
        """(nx, ny, nz) cells of the block at ``size`` cells along the length."""
        def rnd(x):
            return max(1, int(math.floor(x + 0.5)))
        return int(size), rnd(size * p["width_ratio"]), rnd(size * p["height_ratio"])

    def prepare(self, p, size, rng):
        for k in ("cell", "density", "young", "width_ratio", "height_ratio"):
            if not p[k] > 0:
                raise SceneError(f"{self.name}: parameter {k} = {p[k]!r} must be > 0; fix: give --param {k}=VALUE > 0")
        if not p["mu"] >= 0:
            raise SceneError(f"{self.name}: parameter mu = {p['mu']!r} must be >= 0; fix: give --param mu=VALUE >= 0")
        if not 0 <= p["jitter"] <= 0.25:
            raise SceneError(f"{self.name}: parameter jitter = {p['jitter']!r} must be in "
                             "[0, 0.25] (a fraction of the cell edge); fix: give e.g. --param jitter=0.1 "
                             "(the default)")
        lame(p["young"], p["poisson"])  # checks the material
        nx, ny, nz = self.cells(p, size)
        mesh = block_mesh(nx, ny, nz, p["cell"], p["jitter"], rng)
        angles = rng.uniform(0.0, 2 * math.pi, mesh.bottom.size)
        H, frames = support_contact_matrix(mesh, angles)
        return {"mesh": mesh, "M_mass": mass_matrix(mesh, p["density"]),
                "K": stiffness_matrix(mesh, p["young"], p["poisson"]), "H": H, "frames": frames}

    def stepper(self, base, p):
        """A fresh :class:`ElasticMoreauJean` run from rest (q = 0, v = 0)."""
        return ElasticMoreauJean(base["mesh"], base["M_mass"], base["K"], base["H"],
                                 base["frames"], gravity=np.array([0.0, 0.0, -G]), h=p["h"],
                                 mu=p["mu"])
