"""Procedural object sets: seeded sets of shapes from the families of :mod:`~mpg_envs.simulation.family_shapes`.

``family_object_set("superquadrics", seed)`` is a set of :data:`FAMILY_SET_SIZE` shapes of
one family; ``family_object_set("procedural", seed)`` mixes every family (shape ``i`` is of
family ``FAMILY_NAMES[i % 5]``, its ``i // 5``-th shape, so the mix holds the first shapes of
each family's set of the same seed under the same names). The env takes them by name
(``object_set="superquadrics"``, the set's seed is ``EnvConfig.object_set_seed``).

The set's seed says what it is for (:data:`FAMILY_SEED_RANGES`): training sets use seeds below
500000 (the env's default, 0, is one), held-out test sets 500000-699999 and tuning sets
700000-999999, as the env seeds of evaluations do. Shapes are drawn independently from the
stream ``[seed, family, index]``: the same seed gives the same shapes, bit for bit, and sets
of different seeds share no draws.

Geometry is cached on disk like the blocks' (:mod:`mpg_envs.simulation.geometry_cache`),
keyed by the family, the drawn parameters and :data:`FAMILY_VERSION`; mass is
``density * volume`` clamped to :data:`~mpg_envs.simulation.assets.MASS_RANGE`, as the blocks'.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from mpg_envs.simulation.assets import DEFAULT_FRICTION, TABLEAU_10, WOOD_DENSITY, ObjectAsset, check_seed, make_asset
from mpg_envs.simulation.family_shapes import FAMILY_LABELS, FAMILY_NAMES, build_shape, check_family, draw_shape
from mpg_envs.simulation.geometry_cache import cached_parts, resolve_cache_dir

PROCEDURAL = "procedural"
"""The name of the set that mixes every family."""

PROCEDURAL_SETS: tuple[str, ...] = (*FAMILY_NAMES, PROCEDURAL)
"""Every name :func:`family_object_set` (and the env's ``object_set``) takes."""

FAMILY_SET_SIZE = 20
"""Shapes in one set (the mix: four of each family)."""

FAMILY_VERSION = 1
"""Part of every cache key: bump when a family's shapes change for the same parameters."""

FAMILY_SEED_RANGES: dict[str, range] = {
    "train": range(0, 500_000),
    "test": range(500_000, 700_000),
    "tuning": range(700_000, 1_000_000),
}
"""What a set's seed is for: training sets, held-out test sets (as Table I's env seeds, from
500000) and tuning sets (as the tuning env seeds, from 700000). Seeds from 1000000 are not
assigned."""


def seed_split(seed: int) -> str:
    """``"train"``, ``"test"`` or ``"tuning"``: the split of :data:`FAMILY_SEED_RANGES` that an
    object-set seed belongs to; ValueError for a seed outside them."""
    seed = check_seed(seed)
    for split, seeds in FAMILY_SEED_RANGES.items():
        if seed in seeds:
            return split
    raise ValueError(
        f"object-set seed {seed} lies in no split; valid: "
        f"{', '.join(f'{k} {v.start}-{v.stop - 1}' for k, v in FAMILY_SEED_RANGES.items())}"
    )


def family_object_set(
    name: str,
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    size: int = FAMILY_SET_SIZE,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
) -> list[ObjectAsset]:
    """A procedural object set: ``size`` shapes of family ``name``, or of every family for
    ``"procedural"``.

    Object ``i`` is named ``f"{label}-{k:02d}"`` (``superquadric-00``, ``bent-03``; ``k`` its
    index in its family's set), has colour ``TABLEAU_10[i % 10]`` and its family as ``source``.

    Args:
        name: one of :data:`PROCEDURAL_SETS`.
        seed: the set's seed (see :data:`FAMILY_SEED_RANGES` for the splits).
        cache_dir: folder for the geometry cache; ``None`` uses the default cache.
        size: number of shapes, >= 1.
        density: kg/m^3.
        friction: sliding friction of every object.

    Raises:
        ValueError: an unknown name (lists the valid ones), a negative seed or size < 1.
    """
    seed = check_seed(seed)
    if name not in PROCEDURAL_SETS:
        raise ValueError(f"unknown procedural object set {name!r}; valid: {list(PROCEDURAL_SETS)}")
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise ValueError(f"size must be a positive integer, got {size!r}")
    members = (
        [(FAMILY_NAMES[i % len(FAMILY_NAMES)], i // len(FAMILY_NAMES)) for i in range(size)]
        if name == PROCEDURAL
        else [(name, i) for i in range(size)]
    )
    folder = resolve_cache_dir(cache_dir)
    return [
        _shape_asset(family, seed, index, TABLEAU_10[i % len(TABLEAU_10)], folder, density, friction)
        for i, (family, index) in enumerate(members)
    ]


def family_asset(
    family: str,
    name: str,
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
) -> ObjectAsset:
    """One shape of a family's set by its object name (``"superquadric-03"``), whatever the
    size of the set it came from; its colour is the set's (``TABLEAU_10[index % 10]``).
    A scene file that names a procedural object loads it this way.

    Raises:
        ValueError: an unknown family, or a name that is not one of the family's objects.
    """
    check_family(family)
    match = re.fullmatch(rf"{re.escape(FAMILY_LABELS[family])}-(\d+)", name)
    if match is None:
        raise ValueError(f"{name!r} is not a {family} object name (expected {FAMILY_LABELS[family]}-<index>)")
    index = int(match.group(1))
    rgba = TABLEAU_10[index % len(TABLEAU_10)]
    return _shape_asset(family, check_seed(seed), index, rgba, resolve_cache_dir(cache_dir), density, friction)


def _shape_asset(
    family: str, seed: int, index: int, rgba: tuple[float, float, float, float], folder: Path, density: float, friction: float
) -> ObjectAsset:
    """Shape ``index`` of ``family``'s set ``seed`` as an asset, its parts from the cache."""
    params = draw_shape(family, seed, index)
    key = {"kind": "procedural", "family": family, "params": params, "version": FAMILY_VERSION}
    label = f"{FAMILY_LABELS[family]}-{index:02d}"
    parts, com = cached_parts(folder, f"{family}-{label}", key, lambda: build_shape(family, params))
    return make_asset(label, parts, rgba, density, None, friction, family, com)
