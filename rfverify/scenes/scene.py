"""What a scene is (:class:`Scene`): configurations of bodies and obstacles, one
:class:`World` per stage of a run; and the helpers every scene shares (gravity, stage sizes,
coefficient tables).

A scene builds, once per seed, a *base configuration* by a fast geometric method (deposition,
collapse, lattice; see :mod:`.deposition`), and from it one :class:`World` per stage of the
trace: stage φ ∈ [0, 1] (φ = K/(count−1) for the K-th of ``count`` problems) holds the part of
the run reached at that time — the first spheres of a pile, the bodies already landed in a
chute, the landed part of a soup — with the velocities of bodies in motion.  The
generator (:func:`rfverify.scenes.generate`) then takes a few Moreau–Jean steps from each world
and dumps the last one's problem.

Units are SI (m, kg, s) except where a scene says otherwise (Millimetre).  μr is a length
(the rolling-resistance moment is bounded by μr·r_N), μ is dimensionless.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .geometry import Bodies, Statics

G = 9.81
"""Standard gravity used by every scene (m/s²)."""


@dataclass
class World:
    """Everything a Moreau–Jean run needs, plus notes for the problem description.

    bodies, statics        the state at the start of the stage
    gravity : (3,)         acceleration (length/time²)
    h : float              time step
    margin : float         contact detection margin (length)
    mu_table, mu_r_table   (materials × materials) coefficient tables
    notes : dict           stage facts (JSON-able) for the description
    """

    bodies: Bodies
    statics: Statics
    gravity: np.ndarray
    h: float
    margin: float
    mu_table: np.ndarray
    mu_r_table: np.ndarray
    notes: dict = field(default_factory=dict)


def stage_count(lo: float, hi: float, phi: float) -> int:
    return int(round(lo + phi * (hi - lo)))


def coefficient_table(value, n=1):
    return np.full((n, n), float(value))


def min_rule_table(levels) -> np.ndarray:
    """Coefficient of a material pair = levels[min(i, j)] (so every level occurs)."""
    k = len(levels)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    return np.asarray(levels, dtype=float)[np.minimum(i, j)]


class Scene:
    """A named scene: defaults, base configuration, stages.  Subclasses set the class
    attributes and implement :meth:`prepare` and :meth:`stage`."""

    name: str = ""
    summary: str = ""
    configuration: str = ""
    defaults: dict = {}
    default_size: int = 1
    min_size: int = 1
    size_unit: str = "bodies"
    units: str = "SI (m, kg, s)"

    def convert(self, arrays: dict) -> dict:
        """Transform the arrays of a dumped problem (identity; Millimetre changes units)."""
        return arrays

    def prepare(self, p: dict, size: int, rng: np.random.Generator):
        """Build the base configuration (expensive part, done once per seed)."""
        raise NotImplementedError

    def stage(self, base, p: dict, size: int, phi: float, rng: np.random.Generator) -> World:
        """The world at stage φ ∈ [0, 1] (1 = the full-size, last stage)."""
        raise NotImplementedError
