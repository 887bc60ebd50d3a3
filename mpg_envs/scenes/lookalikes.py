"""The colours of an exemplar scene: one object answers the query, and neither its shape nor
its colour alone singles it out (pure, no simulator).

An exemplar episode names its target by pictures of it alone (``target_spec="exemplar"``).
Its scene is the one the same seed gives without the exemplar (the same bodies and start
poses); only the objects' colours change, each a colour of :data:`PALETTE`, by one rule
(:func:`exemplar_colours`):

1. the target takes a palette colour drawn at random;
2. every other object of the target's shape takes a palette colour drawn among the others;
3. every object of another shape takes a palette colour drawn among all of them, and when
   none of them drew the target's, one of them, drawn at random, takes it.

So no other object has both the target's shape and its colour; every other object of its
shape has another colour; and in every scene with at least one object of another shape, at
least one of them has the target's colour. An object that shares the target's colour or its
shape is a look-alike (:func:`shared_looks`): grasping one is the mis-pick an exemplar
policy risks. Two objects have the same shape when they are the same asset of the same
object set (:func:`shape_key`).
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence

import numpy as np

from mpg_envs.simulation.assets import TABLEAU_10, ObjectAsset

PALETTE: tuple[tuple[float, float, float, float], ...] = TABLEAU_10
"""The colours an exemplar scene's objects take (RGBA in [0, 1]): the Tableau-10 palette."""

LOOKS = ("colour", "shape")
"""What a look-alike may share with the target."""


def shape_key(asset: ObjectAsset) -> tuple[str, str]:
    """What makes two objects the same shape: their object set (``source``) and name."""
    return (asset.source, asset.name)


def exemplar_colours(
    shapes: Sequence[Hashable],
    target: int,
    rng: np.random.Generator,
    palette_size: int = len(PALETTE),
) -> tuple[int, ...]:
    """Palette indices of the objects of a scene whose shapes are ``shapes`` (one key per
    object, equal keys for equal shapes) and whose target is ``shapes[target]``, drawn from
    ``rng`` by the module's rule.

    Raises:
        ValueError: ``target`` is not an index of ``shapes``, or the palette has fewer than 2 colours.
    """
    n = len(shapes)
    if isinstance(target, bool) or not isinstance(target, (int, np.integer)) or not 0 <= target < n:
        raise ValueError(f"target must be an object index in 0..{n - 1}, got {target!r}")
    if palette_size < 2:
        raise ValueError(f"the palette needs at least 2 colours, got {palette_size}")
    colour = int(rng.integers(palette_size))
    others = [c for c in range(palette_size) if c != colour]
    colours = [colour] * n
    unlike = []  # objects of another shape
    for i, shape in enumerate(shapes):
        if i == target:
            continue
        if shape == shapes[target]:
            colours[i] = others[int(rng.integers(len(others)))]
        else:
            colours[i] = int(rng.integers(palette_size))
            unlike.append(i)
    if unlike and colour not in (colours[i] for i in unlike):
        colours[unlike[int(rng.integers(len(unlike)))]] = colour
    return tuple(colours)


def shared_looks(shapes: Sequence[Hashable], colours: Sequence[int], target: int, other: int) -> tuple[str, ...]:
    """What object ``other`` shares with the target (``"colour"``, ``"shape"``, in
    :data:`LOOKS` order; empty when nothing: not a look-alike)."""
    shared = []
    if colours[other] == colours[target]:
        shared.append("colour")
    if shapes[other] == shapes[target]:
        shared.append("shape")
    return tuple(shared)


def rule_breaks(shapes: Sequence[Hashable], colours: Sequence[int], target: int) -> list[str]:
    """How a scene's colours break the rule (empty when they keep it): another object of the
    target's shape and colour, or a scene with objects of another shape none of which has the
    target's colour."""
    breaks = [
        f"object {i} has the target's shape and colour"
        for i in range(len(shapes))
        if i != target and len(shared_looks(shapes, colours, target, i)) == 2
    ]
    unlike = [i for i in range(len(shapes)) if shapes[i] != shapes[target]]
    if unlike and all(colours[i] != colours[target] for i in unlike):
        breaks.append("no object of another shape has the target's colour")
    return breaks
