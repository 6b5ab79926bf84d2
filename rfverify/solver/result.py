"""Settings, status and result objects of the production solver."""

from __future__ import annotations

import enum
import functools
import operator
import sys
import warnings
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields, is_dataclass

import numpy as np

from ..errors import require_time_limit

ALGORITHM1_METHODS = ("jqinv", "qp2", "reduced", "reduced_factored", "noscaling", "schur")
"""Linear-system forms of Algorithm 1 (DESIGN §4): (14), (11), (15), (16), (6), and (16) with its
identity block eliminated (``schur``: factored by CHOLMOD with the optional extra ``cholmod``, else
by QDLDL)."""

AUTO_SEQUENCE = ("jqinv", "reduced", "noscaling")
"""The forms ``method="auto"`` tries in turn until one is Solved: jqinv first (fastest and most
robust on the scene collections), then the reduced and unscaled forms, which solve lifted local
problems with a singular Delassus operator where jqinv stalls (docs/DECISIONS.md)."""

AUTO_SEQUENCE_LARGE = ("schur", "jqinv", "noscaling")
"""``auto``'s forms on a problem whose factorisation is expensive (``rfverify.solver.auto_sequence``
decides): schur, the path of form (16) on the smallest matrix (CHOLMOD's speed where it is
installed), then jqinv (another path), then noscaling."""

AUTO_LAST_RESORT = ("jqinv", "paper")
"""(form, σ rule) ``auto`` tries once more after every form of its sequence stalled or broke
down, unless the caller chose a σ rule: on a MassRatio problem at mass ratio 1e8 every form
stalls under the default hybrid rule, in exact arithmetic too, and jqinv with the paper's rule is
Solved in 37 iterations (docs/DECISIONS.md, "auto's last resort")."""

AUTO_SCHUR_MIN_CONTACTS = 500
AUTO_SCHUR_MIN_FILL = 100.0
"""``auto`` starts with schur instead of jqinv on a problem of at least AUTO_SCHUR_MIN_CONTACTS
contacts whose factorisation costs at least AUTO_SCHUR_MIN_FILL per contact, measured as
Σ(column count)² of the Cholesky factor (AMD) of the body graph (``rfverify.solver.body_fill``):
fill, not size, decides which engine wins — a 2324-contact chute (8 per contact) runs 2.2× faster
with jqinv, a 576-contact lattice bed (135) 2.3× faster with schur (docs/DECISIONS.md, "Scale
(issue 27 items 2, 3, 5)").  Without CHOLMOD schur factors by QDLDL and the same thresholds gain
1.5× (576 contacts) to 4× (9675) on lattice beds, are about even on deposited piles (0.87× at 3209
contacts, 1.08× at 10 116) and cost up to 1.35× on random problems of 1000–2000 contacts
(docs/DECISIONS.md, "schur without the extra")."""

OPTIONAL_METHODS = {"siconos": ("rfverify.solver.siconos_peer", "bash benchmarks/peers/siconos/build.sh, then "
                                                                "RFVERIFY_SICONOS=<the prefix it prints>")}
"""Methods that need an optional module: name -> (module to import, how to install it).  A module
may also define ``unavailable()`` for what an import cannot tell (the Siconos peer's built driver)."""


def method_unavailable(method: str) -> str | None:
    """Why ``method`` cannot run in this environment (its optional module does not import), or
    None when it can."""
    if method not in OPTIONAL_METHODS:
        return None
    module, install = OPTIONAL_METHODS[method]
    try:
        __import__(module)
    except ImportError as exc:
        return f"{method!r} needs {module}, which does not import here ({' '.join(str(exc).split())}); fix: {install}"
    probe = getattr(sys.modules[module], "unavailable", None)
    return probe() if probe is not None else None

PORTFOLIO_METHODS = ("auto",)
"""Methods that run several Algorithm 1 forms; benches measure the forms themselves."""

PEER_METHODS = ("clarabel", "siconos")
"""Other solvers run on the same problem (no Algorithm 1 iterates, traces or lockstep): Clarabel, and
Siconos's GRFC3D_IPM (the paper's own implementation; needs a build, see OPTIONAL_METHODS)."""

SIGMA_RULES = ("hybrid", "paper", "siconos")
"""Algorithm 1's centring rules (:attr:`Settings.sigma_rule`; :func:`rfverify.algorithm.rules.centring`)."""

METHODS = ALGORITHM1_METHODS + PORTFOLIO_METHODS + PEER_METHODS
"""Every method name rfverify accepts: the one declaration the CLI, bench and report derive from."""


class Status(str, enum.Enum):
    """The one status type of every result (Clarabel-like).  A ``str`` enum: a member equals
    its printed name (``Status.SOLVED == "Solved"``), so results compare with the names users
    read.  A solve ends ``Solved`` or in one of the others; a proof (``Certificate``,
    ``DigitsSolution``) ends ``Certified``, ``NotCertified`` or — stopped by its time limit
    short of the requested digits — ``MaxTime``."""

    SOLVED = "Solved"
    ALMOST_SOLVED = "AlmostSolved"
    MAX_ITERATIONS = "MaxIterations"
    NUMERICAL_ERROR = "NumericalError"
    INSUFFICIENT_PROGRESS = "InsufficientProgress"
    INVALID_INPUT = "InvalidInput"
    MAX_TIME = "MaxTime"
    STOPPED = "Stopped"  # by the user's callback
    CERTIFIED = "Certified"  # a proof: the requested digits are proven
    NOT_CERTIFIED = "NotCertified"  # a proof: they are not

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class Settings:
    """Settings of Algorithm 1.  Defaults are the paper's unless stated.

    Attributes
    ----------
    tol : float
        Stop when the criterion of :mod:`rfverify.model.measures` — residuals of the returned
        (v, u, r) relative to their terms and to scales from the data, which do not vanish at
        a correct solution — is at most ``tol``.  The paper's max(pinfeas, dinfeas, μ)
        (DESIGN §4) is reported beside it.
    almost_factor : float
        A run that ends otherwise but whose best iterate reached ``almost_factor·tol`` is
        ``AlmostSolved``.
    max_iter : int
    sigma_rule : {"hybrid", "paper", "siconos"}
        ``paper``: σ = min(1, (μ_a/μ)^e), e = max(1, 3α_a) when μ < 1e-5, else e = 1.
        ``siconos``: e = max(1, 3α_a²) when μ > 1e-5, else e = max(1, 3α_a), and σ/5.
        ``hybrid`` (default): Mehrotra's σ = min(1, (μ_a/μ)³), but at least 0.2, while the
        iterate's criterion is above 1e-4, then the paper's rule.  Far from the solution the
        cube cuts μ faster than the paper's e = 1 (σ ≈ 0.3–0.6 there); the floor keeps the
        path close enough to the central path that the answer's forward error at a given
        criterion is no worse than under the paper's rule (docs/DECISIONS.md, "σ rule").
    gamma0 : float
        Step-to-boundary fraction of the first iteration (paper 0.9; Siconos 0.999);
        afterwards γ = 0.9 + 0.09 α of the previous step.
    start : {"velocity_scaled", "paper", "least_squares"}
        ``paper``: v = 0, r̃ = 1 on the normal rows (Jᵀr̃ = e), z = e.  ``velocity_scaled``
        (default): the same with z = θ·e, θ = max(1, rms(w̃)), so that z starts on the scale
        of the free velocities w̃ that the primal equation H̃v + w̃ = Jz asks it to match.
        ``least_squares``: the Newton step at identity scaling from the origin (a
        least-squares point of the primal and dual equations, CVXOPT's and Clarabel's start),
        each cone part shifted by (1 + its most negative λ2)·e where it is not interior.
    longdouble_jordan : bool
        Jordan operations, NT scaling and step lengths in numpy.longdouble.
    longdouble_residuals : bool
        Residuals, right-hand sides and iterates in numpy.longdouble.
    longdouble_below : float or None
        When the ``longdouble_*`` settings take effect.  ``None``: from the first
        iteration (also when the data have entries above 2^128 in magnitude).  A number
        (default 1e-9): the run starts in float64 throughout and switches for good at the
        first iterate whose criterion is at most this, or after an iteration whose float64
        linear solve ended short of what the iteration needs: neither the inexact-Newton test
        nor the refinement target met, and some block residual above both 1e-4 of its
        right-hand side and 1e-2·tol of the size of its terms (dual and primal blocks;
        ``rfverify.solver.ipm._adequate``).  Iterations above that criterion do not need the extra
        bits, which cost about five times as much: at the default tol = 1e-10 the last one or
        two iterations run extended, at tol = 1e-8 usually none (the robustness sweep at 1e-10
        verified the same problems with 1e-9 as with 1e-6 and with None; docs/DECISIONS.md).
        ``extras["longdouble_from"]`` gives the iteration of the switch for each run (also
        under its former name ``extras["extended_from"]``).
    refine_max : int
        Maximum iterative-refinement steps per linear solve (0 disables refinement).
        Refinement also stops, keeping its best iterate, once a step reduces the backward
        error by less than 20%.
    refine_longdouble : bool
        Iterative-refinement residuals in numpy.longdouble.
    refine_tol : "adaptive", float or None
        Refinement stops once the blockwise backward error of the unreduced system is at
        most this.  ``None``: 4·eps of the refinement precision.  ``"adaptive"`` (default):
        the same target, but refinement also stops as soon as every block residual (dual,
        primal, complementarity) is at most 1e-4 of that block's right-hand side — an
        inexact Newton step, as accurate as the iteration needs (1368-contact Chute at 1e-8:
        1.49 s → 0.81 s; every problem of the DECISIONS sweep still verified at 1e-10).
    compiled_kernels : bool
        Float64 cone operations (NT scaling, Q_p, step lengths, spectral values, Jordan
        product, arrow solve) through the numba kernels of :mod:`rfverify.solver.kernels`
        (default), which give bit for bit the results of the numpy formulas in a fraction of
        the time (1368-contact chute at 1e-8: 0.28 s against 0.33 s, ~2 ms less per
        iteration).  The first use in a process pays numba's start-up once (~0.3 s, loading
        the kernels from its disk cache; a few seconds the very first time, compiling them).
        False: numpy only — the same iterates, slower per iteration, no start-up.
    static_reg : float
        Static regularisation δ (relative to the largest diagonal entry of the KKT matrix)
        added on the dr̃ diagonal with the sign that keeps the symmetric forms
        quasi-definite; refinement against the unregularised matrix removes its effect
        where it converges.
    adaptive_reg : bool
        When refinement of a predictor solve ends above 1e3·eps (of the refinement
        precision), factor the same matrix without δ and use that factorisation for the
        iteration if it has the true inertia and solves better (default).  The next
        iteration then tries the factorisation without δ first, and goes back to δ when its
        predictor solve refines badly.  Needed on problems with redundant contacts
        (hyperstatic piles, lattices), see
        :meth:`rfverify.solver.kkt.KKTSystem.refactor_unregularised`.
    stall_iterations : int
        ``InsufficientProgress`` after this many consecutive iterations in which none of
        pinfeas, dinfeas, μ that is still above ``tol`` fell below 0.9 × its own best,
        counted from the first step with α ≥ 0.5, with the bests reset there (before it, a
        badly scaled start may take several tiny but growing steps while μ grows 1e6-fold;
        ``max_iter`` bounds that phase), and afresh after a step that raised μ more than
        100-fold (:data:`rfverify.solver.termination.RESCALED`: the iterate moved to another
        scale).
    time_limit : float or None
        Seconds; the run stops with status ``MaxTime`` (returning its best iterate) at the
        first iteration that starts after it.
    verbose : bool
        Print a settings header and one row per iteration as it happens (stdout).
    reduce_cones, drop_free_bodies, split_components : bool
        Presolve reductions (DESIGN §4).  Splitting solves each connected component of the
        body–contact graph by its own run of Algorithm 1 (own step lengths); it implies that
        contact-free blocks are solved directly.
    max_components : int
        Above this many components they are solved together (one run), to bound the
        per-run overhead.
    """

    tol: float = 1e-10
    almost_factor: float = 100.0
    max_iter: int = 100
    sigma_rule: str = "hybrid"
    gamma0: float = 0.9
    start: str = "velocity_scaled"
    longdouble_jordan: bool = True
    longdouble_residuals: bool = True
    longdouble_below: float | None = 1e-9
    refine_max: int = 10
    refine_longdouble: bool = True
    refine_tol: float | str | None = "adaptive"
    compiled_kernels: bool = True
    static_reg: float = 1e-12
    adaptive_reg: bool = True
    stall_iterations: int = 8
    time_limit: float | None = None
    verbose: bool = False
    reduce_cones: bool = True
    drop_free_bodies: bool = True
    split_components: bool = True
    max_components: int = 4

    def __post_init__(self):
        from ..errors import InvalidArgumentError

        def whole(x, least):
            return isinstance(x, (int, np.integer)) and not isinstance(x, bool) and x >= least

        def real(x):
            return isinstance(x, (int, float, np.floating, np.integer)) and not isinstance(x, bool)

        checks = (
            ("tol", real(self.tol) and self.tol > 0 and np.isfinite(self.tol), "a positive finite number", "1e-10"),
            ("max_iter", whole(self.max_iter, 1), "a whole number ≥ 1", "100"),
            ("start", self.start in ("velocity_scaled", "paper", "least_squares"),
             "'velocity_scaled', 'paper' or 'least_squares'", "'velocity_scaled'"),
            ("sigma_rule", self.sigma_rule in SIGMA_RULES, "'hybrid', 'paper' or 'siconos'",
             "'hybrid'"),
            ("gamma0", real(self.gamma0) and 0 < self.gamma0 < 1, "a number in (0, 1)", "0.9"),
            ("longdouble_below", self.longdouble_below is None or (real(self.longdouble_below)
                                                                   and self.longdouble_below > 0),
             "None or a positive number", "1e-9"),
            ("refine_max", whole(self.refine_max, 0), "a whole number ≥ 0", "10"),
            ("refine_tol", self.refine_tol is None or self.refine_tol == "adaptive" or (
                real(self.refine_tol) and 0 < self.refine_tol < 1), "'adaptive', None or a number in (0, 1)",
             "'adaptive'"),
            ("stall_iterations", whole(self.stall_iterations, 1), "a whole number ≥ 1", "8"),
            ("max_components", whole(self.max_components, 1), "a whole number ≥ 1", "4"),
            ("almost_factor", real(self.almost_factor) and self.almost_factor >= 1, "a number ≥ 1", "100"),
        )
        for name, ok, must, default in checks:
            if not ok:
                raise InvalidArgumentError(name, f"is {getattr(self, name)!r}; it must be {must}",
                                           fix=f"pass e.g. {name}={default} (the default)")
        for name in ("longdouble_jordan", "longdouble_residuals", "refine_longdouble", "compiled_kernels",
                     "adaptive_reg", "verbose", "reduce_cones", "drop_free_bodies", "split_components"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InvalidArgumentError(name, f"is {getattr(self, name)!r}; it must be True or False",
                                           fix=f"pass {name}=True or {name}=False")
        require_time_limit(self.time_limit)

    def as_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def names(cls):
        return [f.name for f in fields(cls)]

    @classmethod
    def accepted(cls):
        """Every name a setting may be given by: :meth:`names` and the former names of the
        longdouble settings (:data:`RENAMED_SETTINGS`)."""
        return cls.names() + list(RENAMED_SETTINGS)


RENAMED_SETTINGS = {"extended_jordan": "longdouble_jordan", "extended_residuals": "longdouble_residuals",
                    "extended_below": "longdouble_below", "refine_extended": "refine_longdouble"}
"""Former names of the longdouble settings (before issue 50 "extended" also named the
double-double phase and :attr:`rfverify.DigitsSolution.extended`).  Still accepted, with a
DeprecationWarning, wherever a setting is given (``Settings(...)``, ``rfverify.solve(...,
extended_below=None)``, :func:`dataclasses.replace`), and readable as attributes."""


def renamed_settings(options: dict) -> dict:
    """``options`` with the former names of settings (:data:`RENAMED_SETTINGS`) given their
    current ones, each with a DeprecationWarning; a setting given under both names is refused."""
    if not any(old in options for old in RENAMED_SETTINGS):
        return options
    options = dict(options)
    for old, new in RENAMED_SETTINGS.items():
        if old in options:
            if new in options:
                raise TypeError(f"the setting {new!r} is given twice, also under its former name {old!r}")
            warnings.warn(f"the setting {old!r} is now called {new!r}", DeprecationWarning, stacklevel=3)
            options[new] = options.pop(old)
    return options


def _accepting_former_names(init):
    @functools.wraps(init)
    def __init__(self, *args, **kwargs):
        init(self, *args, **renamed_settings(kwargs))
    return __init__


Settings.__init__ = _accepting_former_names(Settings.__init__)
for _old, _new in RENAMED_SETTINGS.items():
    setattr(Settings, _old, property(lambda self, _new=_new: getattr(self, _new), doc=f"Former name of ``{_new}``."))


TRACE_FIELDS = ("iter", "criterion", "pinfeas", "dinfeas", "mu", "sigma", "alpha_aff", "alpha", "gamma",
                "min_lam2_z", "min_lam2_z_cone", "min_lam2_s", "min_lam2_s_cone", "max_cond_Qp",
                "solve_residual", "refine_steps", "step_cone", "step_side", "time")
"""Per-iteration trace columns.  ``criterion`` is rfverify's stopping measure
(:func:`rfverify.model.measures.measures`, the ``max``) of that iterate's (v, u, r) on its run's own data:
its component, without the contact-free bodies (solved apart), in the iterate's arithmetic — the
returned answer's criterion on the whole problem is ``SolveResult.criterion``;
``pinfeas``, ``dinfeas``, ``mu`` are the paper's (DESIGN §4), reported beside it.
``min_lam2_*_cone`` is the index of the cone (see
``LiftedProblem.cone_contact``/``cone_part`` for its contact); ``step_cone`` is the cone of the
lifted problem whose boundary cut that iterate's step α short and ``step_side`` its member (0:
z, the lifted velocity; 1: s = Jᵀr̃, the reaction), both −1 where the step was full or not taken
(``SolveResult.steps_held`` says the same in words); ``solve_residual`` is the
largest relative residual of the linear solves of that iteration after refinement; ``time``
is seconds since the start of the solve."""

TRACE_HEADERS = {"iter": "iter", "criterion": "criterion", "pinfeas": "pinfeas", "dinfeas": "dinfeas",
                 "mu": "mu", "sigma": "sigma", "alpha_aff": "alpha_aff", "alpha": "alpha", "gamma": "gamma",
                 "min_lam2_z": "min λ2(z)", "min_lam2_s": "min λ2(s)", "max_cond_Qp": "max cond(Qp)",
                 "solve_residual": "solve resid", "refine_steps": "refine", "time": "time [s]"}


@dataclass(frozen=True)
class IterationInfo:
    """What a ``callback`` receives once per iteration (after the step is computed):
    ``component`` (index of the independent component, 0 when solved as one), ``iteration``,
    rfverify's ``criterion`` (of the iterate on its run's data, as in the trace) and the paper's ``pinfeas``, ``dinfeas``, ``mu``, the centring
    ``sigma``, step lengths ``alpha_aff``, ``alpha``, ``min_lam2_z``/``min_lam2_s`` (smallest
    λ2 of z and Jᵀr̃), ``max_cond_Qp``, the linear ``solve_residual`` (backward error),
    ``elapsed`` seconds since the solve started, the ``method`` (linear-system form) of the
    run it belongs to — under ``method="auto"``, the form running now — and ``held_by``: the
    cone whose boundary cut the step α short, {"cone" (index in the lifted problem),
    "contact", "part" (friction / rolling / normal), "side" (velocity: z; reaction: Jᵀr̃)},
    or None for a full step; ``components``: how many independent components the problem was
    split into (numbered from 0, as in the JSON and the ``--verbose`` table)."""

    component: int
    iteration: int
    criterion: float
    pinfeas: float
    dinfeas: float
    mu: float
    sigma: float
    alpha_aff: float
    alpha: float
    min_lam2_z: float
    min_lam2_s: float
    max_cond_Qp: float
    solve_residual: float
    elapsed: float
    method: str = ""
    held_by: dict | None = None
    components: int = 1



def alias(path: str, doc: str) -> property:
    """A read-only property that is another name for the attribute ``path`` (dotted for an
    attribute of an attribute, ``"certificate.status"``), read when asked; ``doc`` its docstring."""
    return property(operator.attrgetter(path), doc=doc)


class ResultAliases(Mapping):
    """What every result (:class:`SolveResult`, :class:`rfverify.DigitsSolution`,
    :class:`rfverify.Certificate`, :class:`rfverify.verify.diagnosis.Diagnosis`) offers the same way
    (docs/RESULTS.md): ``time`` is ``timings["total"]`` in seconds, ``iterations`` (Clarabel's
    name) is ``nit``, ``solve_time`` (Clarabel's) is ``time``; ``as_dict()`` is the JSON-able dict
    the CLI prints with ``--json``.

    Every result is also a read-only mapping, as SciPy's ``OptimizeResult`` (a dict) is: its keys
    are the names of its data — its dataclass fields and its public properties, the common ones
    first (``status``, ``success``, ``message``, ``nit``, ``time``, ``timings``) and the aliases
    (``iterations``, ``solve_time``) last — so ``"status" in res``, ``res["status"]``,
    ``res.keys()``, ``res.items()``, ``dict(res)``, ``len(res)`` and ``for name in res`` work, and
    ``res[name]`` is ``getattr(res, name)``, evaluated when asked.  Methods (``as_dict``, ...) are
    not keys; attribute access stays."""

    def __getitem__(self, key):  # OptimizeResult-style access, the same on every result
        if key not in self._result_keys():
            raise KeyError(key)
        return getattr(self, key)

    def __iter__(self):
        return iter(self._result_keys())

    def __len__(self) -> int:
        return len(self._result_keys())

    def __contains__(self, key) -> bool:  # without evaluating the property, unlike Mapping's
        return key in self._result_keys()

    @classmethod
    def _result_keys(cls) -> tuple:
        """The keys of this result class, computed once per class (see the class docstring)."""
        keys = cls.__dict__.get("_keys_of_class")
        if keys is None:
            names = [f.name for f in fields(cls)] if is_dataclass(cls) else []
            for klass in cls.__mro__:
                names += [n for n, v in vars(klass).items() if isinstance(v, property)]
            names = [n for n in dict.fromkeys(names) if not n.startswith("_")]
            first = [n for n in _COMMON_KEYS if n in names]
            last = [n for n in _ALIAS_KEYS if n in names]
            keys = tuple(first + [n for n in names if n not in first and n not in last] + last)
            cls._keys_of_class = keys
        return keys

    @property
    def time(self) -> float:
        """Wall time of the call in seconds, ``timings["total"]`` (NaN when not recorded)."""
        return float(self.timings.get("total", float("nan")))

    iterations = alias("nit", "Clarabel's name for ``nit``.")
    solve_time = alias("time", "Clarabel's name for ``time`` (``timings[\"total\"]``, seconds).")


_COMMON_KEYS = ("status", "success", "message", "nit", "time", "timings")
_ALIAS_KEYS = ("iterations", "solve_time")


@dataclass
class Outcome:
    """What every run reports: status, message, iterations and the paper's measures of the
    returned iterate (DESIGN §4)."""

    status: Status
    message: str
    nit: int
    pinfeas: float
    dinfeas: float
    mu: float


@dataclass
class SolveResult(Outcome, ResultAliases):
    """Result of :func:`rfverify.solve` (scipy ``OptimizeResult``-like).

    Attributes
    ----------
    v : ndarray (m,)          velocities
    u : ndarray (5n,)         contact velocities, recomputed as Hᵀ v + w (W r + q, the
                              file's own, for a problem read from a local file)
    r : ndarray (5n,)         contact reactions, r = P r̃ (zero on components the cone forces to 0)
    status : Status
    success : bool            status is Solved
    message : str             human-readable reason (names iteration/operation/cone on errors)
    nit : int                 iterations performed
    measures : Measures       rfverify's criterion of the returned (v, u, r) (:mod:`rfverify.model.measures`):
                              Solved means ``measures.max ≤ tol``
    pinfeas, dinfeas, mu : float   the paper's measures of the returned iterate (DESIGN §4)
    trace : dict of ndarray   per-iteration columns, see TRACE_FIELDS
    timings : dict            seconds: total, factor, solve, presolve, ...
    method : str
    settings : Settings
    presolve : dict           reductions applied (cone kinds, free bodies, components)
    extras : dict             method-specific extras (e.g. Clarabel's own status)
    steps_held : list of dict each step a cone's boundary cut short (α < 1): from_iteration,
                              alpha, cone, contact, part, side (and component when split);
                              empty for the peers
    iterations, solve_time    Clarabel's names for ``nit`` and ``timings["total"]``
    """

    v: np.ndarray
    u: np.ndarray
    r: np.ndarray
    trace: dict
    timings: dict
    method: str
    settings: Settings
    presolve: dict = field(default_factory=dict)
    extras: dict = field(default_factory=dict)
    measures: object = None

    @property
    def success(self) -> bool:
        return self.status is Status.SOLVED

    @property
    def criterion(self) -> float:
        """``measures.max`` (NaN when not computed)."""
        return float("nan") if self.measures is None else self.measures.max

    @property
    def steps_held(self) -> list:
        """Each step of the run that a cone's boundary cut short (α < 1), with that cone:
        [{"from_iteration", "alpha", "cone" (lifted index), "contact", "part" (friction /
        rolling / normal), "side" (velocity: z; reaction: Jᵀr̃)}, plus "component" when the
        problem was solved as independent components]; the trace's ``step_cone`` and
        ``step_side`` in words.  Empty for the peers."""
        return list(self.extras.get("steps_held", []))

    def as_dict(self) -> dict:
        """The JSON-able summary (``rfverify solve --json`` prints it with CLI details added):
        status, success, message, method, nit, time, criterion, measures, the paper's measures,
        timings, presolve, steps_held; the vectors v, u, r as lists."""
        return {"status": str(self.status), "success": self.success, "message": self.message,
                "method": self.method, "nit": self.nit, "time": self.time, "criterion": self.criterion,
                "measures": None if self.measures is None else self.measures.as_dict(),
                "pinfeas": self.pinfeas, "dinfeas": self.dinfeas, "mu": self.mu, "timings": dict(self.timings),
                "presolve": self.presolve, "steps_held": self.steps_held,
                "v": self.v.tolist(), "u": self.u.tolist(), "r": self.r.tolist()}

    def __repr__(self) -> str:
        return (f"SolveResult(method={self.method!r}, status={self.status}, nit={self.nit}, "
                f"time={self.time:.3g} s, criterion={self.criterion:.2e}, pinfeas={self.pinfeas:.2e}, "
                f"dinfeas={self.dinfeas:.2e}, mu={self.mu:.2e})")
