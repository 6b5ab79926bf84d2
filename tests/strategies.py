"""Hypothesis strategies for random *valid* global rolling-friction problems.

The problems look like the one-step problems of a rigid-body simulation (FCLIB Chute,
SpheresPile): ``nb`` bodies with 6 dofs each (translation 6b..6b+2, rotation 6b+3..6b+5),
so M is block diagonal with a ``mass·I3`` block and a random symmetric positive definite
3×3 inertia block per body (optionally with a tiny asymmetry, well below the default
``max_asymmetry``, like the rounding of the Siconos Chute file); ``n`` contacts each touch one
or two bodies, so the 5 columns of contact i in H are nonzero only in the rows of those bodies;
some bodies touch no contact at all.  Friction coefficients include exact zeros.

Two entry points:

``problem_arrays(...)``  a dict of the keyword arguments of :meth:`Problem.from_arrays`
                         (``M``, ``H`` as scipy CSC, vectors as float64 arrays, texts,
                         ``solution``, ``guesses``) plus ``"meta"`` describing the layout
                         (bodies, contacts, which bodies are contact-free, ...).
``problems(...)``        the validated :class:`~rfverify.model.problem.Problem` built from it.

Design note (speed): hypothesis draws the *structure* (sizes, which bodies each contact
touches, flags, texts) and a seed; the bulk floating-point values come from a numpy
generator with that seed.  Drawing every entry through hypothesis cost ~25 ms per example,
too slow for 300 examples per test in CI; this costs well under 1 ms.  Special values
(exact zeros, ±0.0, subnormals, 1e±300, ±max) are planted on purpose, not left to chance.

Sizes are small (≤ 8 bodies, ≤ 6 contacts).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from hypothesis import strategies as st

from rfverify.model.problem import DEFAULT_MAX_ASYMMETRY, Problem, StoredSolution

DOFS_PER_BODY = 6
SPACEDIM = 5
MAX_BODIES = 8
MAX_CONTACTS = 6

# Largest scaled asymmetry |M_ij − M_ji| / sqrt(M_ii M_jj) the strategy plants: 40 % of the
# default limit, so every generated problem is accepted with the default settings.
MAX_PLANTED_ASYMMETRY = 0.4 * DEFAULT_MAX_ASYMMETRY

# Values that stress bit-exact storage: signed zeros, subnormals, the ends of the range.
EXTREME_VALUES = np.array([
    0.0, -0.0, 5e-324, -5e-324, 2.225073858507201e-308, -2.225073858507201e-308,
    2.2250738585072014e-308, 1e-300, -1e-300, 1e300, -1e300,
    1.7976931348623157e308, -1.7976931348623157e308, 1.0, -1.0,
])
NONNEGATIVE_EXTREME_VALUES = EXTREME_VALUES[~(EXTREME_VALUES < 0)]  # keeps -0.0

# Text of the FCLIB info strings: any Unicode except lone surrogates (not encodable in UTF-8,
# so not representable in a file at all) and NUL (HDF5 strings are NUL-padded C strings).
info_text = st.text(
    alphabet=st.characters(exclude_categories=("Cs",), exclude_characters="\x00"),
    max_size=40,
)

seeds = st.integers(0, 2**32 - 1)


# ---------------------------------------------------------------------- value generators
def moderate_values(rng, size, bound=1e3, zero_fraction=0.15):
    """Uniform in [-bound, bound] with a fraction of exact zeros."""
    x = rng.uniform(-bound, bound, size)
    x[rng.random(size) < zero_fraction] = 0.0
    return x


def extreme_values(rng, size, nonnegative=False):
    """Random finite doubles over the whole range: random bit patterns (every exponent,
    both signs, subnormals), and about a third of the entries taken from EXTREME_VALUES."""
    bits = rng.integers(0, 2**64, size, dtype=np.uint64, endpoint=False)
    x = bits.view(np.float64).copy()
    x[~np.isfinite(x)] = 0.0
    pool = NONNEGATIVE_EXTREME_VALUES if nonnegative else EXTREME_VALUES
    pick = rng.random(size) < 0.35
    x[pick] = pool[rng.integers(0, pool.size, int(pick.sum()))]
    if nonnegative:
        neg = x < 0
        x[neg] = -x[neg]  # -0.0 is not < 0 and stays: it is a valid (non-negative) μ
    return x


def friction_values(rng, size, bound, zero_fraction=0.3):
    """μ or μr: uniform in [0, bound] with exact zeros (common in real files)."""
    x = rng.uniform(0.0, bound, size)
    x[rng.random(size) < zero_fraction] = 0.0
    return x


def random_rotation(rng):
    """A uniformly random rotation matrix (from a normalised Gaussian quaternion)."""
    a, b, c, d = rng.standard_normal(4)
    n = np.sqrt(a * a + b * b + c * c + d * d)
    a, b, c, d = a / n, b / n, c / n, d / n
    return np.array([
        [a * a + b * b - c * c - d * d, 2 * (b * c - a * d), 2 * (b * d + a * c)],
        [2 * (b * c + a * d), a * a - b * b + c * c - d * d, 2 * (c * d - a * b)],
        [2 * (b * d - a * c), 2 * (c * d + a * b), a * a - b * b - c * c + d * d],
    ])


def body_block(rng, *, asymmetric=False, sphere=False):
    """The 6×6 mass-matrix block of one rigid body and its parameters.

    ``[[m I3, 0], [0, J]]`` with mass m in [1e-2, 1e2] (log-uniform) and J = R diag(λ) Rᵀ,
    λ in [0.01 m, m] (a sphere-like body has R = I, a diagonal J).  With ``asymmetric`` an
    antisymmetric perturbation of scaled size ≤ MAX_PLANTED_ASYMMETRY is added to the
    off-diagonal of J, so the symmetrised block is unchanged up to rounding.
    """
    mass = 10.0 ** rng.uniform(-2, 2)
    lam = mass * 10.0 ** rng.uniform(-2, 0, 3)
    R = np.eye(3) if sphere else random_rotation(rng)
    J = (R * lam) @ R.T
    J = 0.5 * (J + J.T)  # exactly symmetric before any planted asymmetry
    planted = 0.0
    if asymmetric:
        t = rng.uniform(-1.0, 1.0, 3) * (MAX_PLANTED_ASYMMETRY / 2)
        for k, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
            e = t[k] * np.sqrt(J[i, i] * J[j, j])
            J[i, j] += e
            J[j, i] -= e
        planted = 2 * float(np.max(np.abs(t)))
    B = np.zeros((6, 6))
    B[:3, :3] = mass * np.eye(3)
    B[3:, 3:] = J
    return {"block": B, "mass": mass, "inertia_eigenvalues": lam, "rotation": R,
            "planted_asymmetry": planted}


# ---------------------------------------------------------------------- strategies
@st.composite
def stored_solutions(draw, m, n, extreme=False):
    """A StoredSolution whose v, u, r are each present or absent (at least one present)."""
    mask = draw(st.integers(1, 7))  # bit k: vector k of (v, u, r) is present
    present = [bool(mask & 1), bool(mask & 2), bool(mask & 4)]
    rng = np.random.default_rng(draw(seeds))
    gen = (lambda k: extreme_values(rng, k)) if extreme else (lambda k: moderate_values(rng, k))
    vals = {}
    for key, size, keep in (("v", m, present[0]), ("u", SPACEDIM * n, present[1]),
                            ("r", SPACEDIM * n, present[2])):
        vals[key] = gen(size) if keep else None
    return StoredSolution(**vals)


@st.composite
def problem_arrays(draw, *, max_bodies=MAX_BODIES, max_contacts=MAX_CONTACTS,
                   asymmetry=None, extreme=False, solution=None, max_guesses=2,
                   explicit_zeros=None, min_bodies=1):
    """Keyword arguments of :meth:`Problem.from_arrays` for a random valid rigid-body problem.

    Parameters
    ----------
    asymmetry : bool or None
        Plant a tiny asymmetry (below the default limit) in some inertia blocks (True), in
        none (False), or let hypothesis choose (None).
    extreme : bool
        Draw f, w, H, mu, mu_r, solution and guesses from the whole finite double range
        (±0.0, subnormals, 1e±300, ±max) and scale M by an exact power of two in
        2^-1000 … 2^1000.  M is then exactly symmetric when the scale is beyond 2^±400:
        the library's asymmetry measure is not usable there (reported bug, see
        test_validation.py::test_asymmetry_measure_is_scale_invariant).
    solution : bool or None
        Force a stored solution (True), none (False) or let hypothesis choose (None).
    explicit_zeros : bool or None
        Keep explicitly stored zeros (``0.0``/``-0.0``) inside the contact blocks of H.

    The returned dict has an extra key ``"meta"``: ``n_bodies``, ``n_contacts``,
    ``contact_bodies`` (tuple of body tuples per contact), ``free_bodies``, ``bodies``
    (per-body parameters from :func:`body_block`), ``m_scale``, ``planted_asymmetry``.
    """
    nb = draw(st.integers(min_bodies, max_bodies))
    n = draw(st.integers(1, max_contacts))
    order = draw(st.permutations(range(nb)))
    n_free = draw(st.integers(0, min(2, nb - 1)))
    touchable = sorted(order[n_free:])
    contact_bodies = tuple(
        tuple(draw(st.lists(st.sampled_from(touchable), min_size=1, max_size=2, unique=True)))
        for _ in range(n))
    if asymmetry is None:
        asymmetry = draw(st.booleans())
    exponent = (draw(st.one_of(st.sampled_from([-1000, -600, 0, 600, 1000]),
                               st.integers(-1000, 1000))) if extreme else 0)
    keep_zeros = draw(st.booleans()) if explicit_zeros is None else explicit_zeros
    has_solution = draw(st.booleans()) if solution is None else solution
    stored = draw(stored_solutions(DOFS_PER_BODY * nb, n, extreme)) if has_solution else None
    guesses = tuple(draw(st.lists(stored_solutions(DOFS_PER_BODY * nb, n, extreme),
                                  max_size=max_guesses)))
    texts = {k: draw(info_text) for k in ("title", "description", "math_info")}
    rng = np.random.default_rng(draw(seeds))

    # ---- M: block diagonal, one 6×6 block per body
    asym_ok = asymmetry and abs(exponent) <= 400
    bodies = [body_block(rng, asymmetric=asym_ok and rng.random() < 0.7,
                         sphere=rng.random() < 0.2) for _ in range(nb)]
    m = DOFS_PER_BODY * nb
    Md = np.zeros((m, m))
    for b, body in enumerate(bodies):
        Md[6 * b:6 * b + 6, 6 * b:6 * b + 6] = body["block"]
    m_scale = 2.0 ** exponent
    Md = Md * m_scale  # exact unless an entry becomes subnormal, which is still valid data
    M = sp.csc_matrix(Md)
    M.sort_indices()

    # ---- H: contact c has nonzeros only in the rows of the bodies it touches
    rows, cols, vals = [], [], []
    for c, touched in enumerate(contact_bodies):
        for b in touched:
            if extreme:
                blk = extreme_values(rng, 30).reshape(6, 5)
            else:
                blk = moderate_values(rng, 30, bound=2.0, zero_fraction=0.05).reshape(6, 5)
                # Translational rows carry no rolling resistance (as in real rigid-body H).
                blk[:3, 3:] = 0.0
            rr, cc = np.meshgrid(np.arange(6 * b, 6 * b + 6), np.arange(5 * c, 5 * c + 5),
                                 indexing="ij")
            rows.append(rr.ravel())
            cols.append(cc.ravel())
            vals.append(blk.ravel())
    rows, cols, vals = np.concatenate(rows), np.concatenate(cols), np.concatenate(vals)
    if not keep_zeros:
        nz = vals != 0
        rows, cols, vals = rows[nz], cols[nz], vals[nz]
    # The bodies of one contact are distinct, so no (row, col) pair repeats: nothing summed.
    H = sp.csc_matrix((vals, (rows, cols)), shape=(m, SPACEDIM * n))
    H.sort_indices()

    # ---- vectors
    if extreme:
        f = extreme_values(rng, m)
        w = extreme_values(rng, SPACEDIM * n)
        mu = extreme_values(rng, n, nonnegative=True)
        mu_r = extreme_values(rng, n, nonnegative=True)
    else:
        f = moderate_values(rng, m)
        w = moderate_values(rng, SPACEDIM * n)
        mu = friction_values(rng, n, 2.0)
        mu_r = friction_values(rng, n, 0.5)

    touched_bodies = {b for cb in contact_bodies for b in cb}
    meta = {
        "n_bodies": nb,
        "n_contacts": n,
        "contact_bodies": contact_bodies,
        "free_bodies": tuple(b for b in range(nb) if b not in touched_bodies),
        "bodies": bodies,
        "m_scale": m_scale,
        "planted_asymmetry": max(body["planted_asymmetry"] for body in bodies),
    }
    return {"M": M, "H": H, "f": f, "w": w, "mu": mu, "mu_r": mu_r, **texts,
            "solution": stored, "guesses": guesses, "meta": meta}


def from_arrays_kwargs(arrays: dict) -> dict:
    """The dict of :func:`problem_arrays` without its ``"meta"`` entry."""
    return {k: v for k, v in arrays.items() if k != "meta"}


def build_problem(arrays: dict, **overrides) -> Problem:
    """``Problem.from_arrays`` on a dict from :func:`problem_arrays` (``overrides`` replace
    entries or add keyword arguments such as ``max_asymmetry``)."""
    kwargs = from_arrays_kwargs(arrays)
    kwargs.update(overrides)
    return Problem.from_arrays(**kwargs)


def problems(**kwargs):
    """Validated :class:`Problem` instances (same parameters as :func:`problem_arrays`)."""
    return problem_arrays(**kwargs).map(build_problem)
