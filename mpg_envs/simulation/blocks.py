"""The "blocks" object set: eight VPG-like wooden blocks generated with ``trimesh``.

Cube, long box, flat box, tall box, cylinder, disc, triangular prism and an arch (a box
minus a cylinder, the only concave one, split into convex parts by ``coacd``). The seed
jitters every dimension by up to +-10 %. Geometry is cached on disk
(:mod:`mpg_envs.simulation.geometry_cache`).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os

import numpy as np
import trimesh

from mpg_envs.simulation.assets import (
    DEFAULT_FRICTION,
    TABLEAU_10,
    WOOD_DENSITY,
    ObjectAsset,
    Part,
    check_seed,
    convex_part,
    make_asset,
)
from mpg_envs.simulation.geometry_cache import cached_parts, resolve_cache_dir
from mpg_envs.simulation.meshes import CoacdParams, decompose

BLOCKS_JITTER = 0.1
"""Relative jitter of every block dimension (uniform in [1 - j, 1 + j])."""

CYLINDER_SECTIONS = 32
"""Facets around generated cylinders (discs, cylinders, the arch's tunnel)."""

BLOCK_SHAPES: tuple[tuple[str, str, tuple[tuple[str, float], ...]], ...] = (
    # (name, kind, nominal parameters in metres). Nominal sizes are chosen so that any jitter
    # keeps every extent in [2.5, 10] cm and the two smallest extents <= 6 cm (some horizontal
    # width fits the 85 mm opening with margin in any resting pose).
    ("cube", "box_cube", (("size", 0.05),)),
    ("long_box", "box", (("x", 0.09), ("y", 0.035), ("z", 0.035))),
    ("flat_box", "box", (("x", 0.08), ("y", 0.05), ("z", 0.028))),
    ("tall_box", "box", (("x", 0.04), ("y", 0.04), ("z", 0.09))),
    ("cylinder", "cylinder", (("diameter", 0.045), ("height", 0.06))),
    ("disc", "cylinder", (("diameter", 0.054), ("height", 0.028))),
    # A right-angled triangle (as VPG's) extruded only 4.5 cm: the fingers close across the
    # extrusion, on the two vertical triangular faces. Closed across the sloped faces instead
    # (the old 8 cm extrusion), the wedge squeezes out of the pads (30% success).
    ("triangular_prism", "prism", (("length", 0.045), ("base", 0.08), ("height", 0.04))),
    # As VPG's arch (tunnel radius a quarter of the length, height half of it): a 2.5 cm
    # bridge. With a 4.5 cm height and a 0.3 x length tunnel (a 2 cm bridge) the closing
    # fingertips slid into the tunnel and lifted the arch from inside (92% success).
    ("arch", "arch", (("length", 0.08), ("depth", 0.045), ("height", 0.05))),
)
"""The "blocks" set, in colour order (object ``i`` gets ``TABLEAU_10[i]``)."""

ARCH_TUNNEL_RATIO = 0.25
"""Arch tunnel radius as a fraction of the arch length: leaves legs of 0.25 x length."""


def blocks_object_set(
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
) -> list[ObjectAsset]:
    """The "blocks" object set: eight VPG-like wooden blocks.

    Names, in order (object ``i`` has colour ``TABLEAU_10[i]``): ``cube``, ``long_box``,
    ``flat_box``, ``tall_box``, ``cylinder``, ``disc``, ``triangular_prism``, ``arch``.
    ``seed`` jitters every dimension independently by up to +-10 % (the cube stays a cube)
    and seeds coacd for the arch. Every extent is within 2.5-10 cm and the two smallest
    extents are <= 6 cm, so a 2F-85 can grasp each block from the top whichever face it
    rests on. Mass is ``density * volume`` clamped to :data:`MASS_RANGE`.

    Args:
        seed: non-negative integer.
        cache_dir: folder for the geometry cache; ``None`` uses :func:`default_cache_dir`.
        density: kg/m^3.
        friction: sliding friction of every block.
        coacd_params: decomposition settings for the arch (default :class:`CoacdParams`).
    """
    seed = check_seed(seed)
    params = coacd_params or CoacdParams()
    folder = resolve_cache_dir(cache_dir)
    assets = []
    for index, (name, kind, nominal) in enumerate(BLOCK_SHAPES):
        dims = _jitter_dims(nominal, seed, index)
        key_data = {"kind": kind, "dims": dims, "seed": seed, "coacd": dataclasses.asdict(params)}
        if kind == "arch":
            key_data["tunnel_ratio"] = ARCH_TUNNEL_RATIO
        parts, com = cached_parts(folder, f"blocks-{name}", key_data, functools.partial(_make_block, kind, dims, seed, params))
        assets.append(make_asset(name, parts, TABLEAU_10[index % len(TABLEAU_10)], density, None, friction, "blocks", com))
    return assets


def _jitter_dims(nominal: tuple[tuple[str, float], ...], seed: int, index: int) -> dict[str, float]:
    """Jittered dimensions; each object has its own random stream so objects are independent."""
    rng = np.random.default_rng([seed, index])
    factors = rng.uniform(1.0 - BLOCKS_JITTER, 1.0 + BLOCKS_JITTER, size=len(nominal))
    # Rounded to 0.1 mm: readable sizes and an exact, stable cache key.
    return {k: round(v * float(f), 4) for (k, v), f in zip(nominal, factors)}


def _make_block(kind: str, dims: dict[str, float], seed: int, params: CoacdParams) -> list[Part]:
    """Convex parts of one block, in its canonical frame (z up), not yet centred."""
    if kind == "box_cube":
        s = dims["size"]
        return [convex_part(trimesh.creation.box(extents=(s, s, s)).vertices)]
    if kind == "box":
        return [convex_part(trimesh.creation.box(extents=(dims["x"], dims["y"], dims["z"])).vertices)]
    if kind == "cylinder":
        cyl = trimesh.creation.cylinder(radius=dims["diameter"] / 2, height=dims["height"], sections=CYLINDER_SECTIONS)
        return [convex_part(cyl.vertices)]
    if kind == "prism":
        # Isosceles triangle in the y-z plane (base on z = 0), extruded along x.
        half_l, half_b, h = dims["length"] / 2, dims["base"] / 2, dims["height"]
        section = [(-half_b, 0.0), (half_b, 0.0), (0.0, h)]
        return [convex_part(np.array([(x, y, z) for x in (-half_l, half_l) for y, z in section]))]
    if kind == "arch":
        length, depth, height = dims["length"], dims["depth"], dims["height"]
        box = trimesh.creation.box(extents=(length, depth, height))
        radius = ARCH_TUNNEL_RATIO * length
        # The tunnel: a cylinder along y, longer than the box so the boolean cuts clean through.
        tunnel = trimesh.creation.cylinder(radius=radius, height=1.5 * depth, sections=CYLINDER_SECTIONS)
        tunnel.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (1.0, 0.0, 0.0)))
        tunnel.apply_translation((0.0, 0.0, -height / 2))
        arch = box.difference(tunnel, engine="manifold")
        return decompose(arch, seed, params, preprocess=False)
    raise ValueError(f"unknown block kind {kind!r}")
