"""The registry of scenes: every scene :func:`rfverify.scenes.generate` can make, by name
(case-insensitive, a few aliases).  The scenes themselves: the FCLIB collections' in
:mod:`.published`, the stiff and extreme families in :mod:`.extreme`, the finite-element
ElasticBlock in :mod:`.fem`; their base class and :class:`~.scene.World` in :mod:`.scene`.
"""

from __future__ import annotations

from .extreme import AllOpen, AllSticking, Frictionless, GranularBed, Lattice, MassRatio, Millimetre, RollingExtremes
from .fem import ElasticBlock
from .published import Chute, PrimitiveSoup, SpheresPile
from .scene import Scene
from .stepper import SceneError

SCENES: dict[str, Scene] = {s.name: s for s in (
    SpheresPile(), Chute(), PrimitiveSoup(), MassRatio(), RollingExtremes(), Frictionless(),
    Lattice(), AllOpen(), AllSticking(), Millimetre(), GranularBed())}
"""All rigid-body scenes by name (the FCLIB-like ones first, then the stiff and extreme
families, then the large GranularBed): 6 dofs per body, block-diagonal M, stepped by
:class:`.stepper.MoreauJean` (GranularBed, ``step_free``: only its first step's problem is built,
with no solve)."""

FE_SCENES: dict[str, Scene] = {s.name: s for s in (ElasticBlock(),)}
"""Finite-element scenes by name: 3 dofs per node, non-diagonal M (assembled iteration
matrix), stepped by :class:`.fem.ElasticMoreauJean`.  Kept apart from :data:`SCENES`, whose
users (and tests) rely on rigid-body structure."""

ALL_SCENES: dict[str, Scene] = {**SCENES, **FE_SCENES}
"""Every scene :func:`rfverify.scenes.generate` can make (rigid-body, then finite-element)."""

ALIASES = {"spherepile": "SpheresPile", "spherespile": "SpheresPile", "soup": "PrimitiveSoup",
           "millimeter": "Millimetre"}


def resolve_scene(name: str) -> Scene:
    """The scene called ``name`` (case-insensitive; a few aliases); SceneError otherwise."""
    if isinstance(name, Scene):
        return name
    key = str(name).strip()
    table = {k.lower(): v for k, v in ALL_SCENES.items()}
    low = ALIASES.get(key.lower(), key).lower()
    if low not in table:
        raise SceneError(f"unknown scene {name!r}; scenes: {', '.join(ALL_SCENES)}; fix: use one of those names")
    return table[low]
