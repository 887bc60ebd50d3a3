"""The object type of the suite: a rigid object made of convex parts, and the mesh maths it needs.

An :class:`ObjectAsset` is a list of convex meshes in the object frame (origin at the centre
of mass of the parts, z up in the object's canonical pose) plus its colour, mass and
friction. The object sets (:mod:`mpg_envs.simulation.blocks`, :mod:`mpg_envs.simulation.meshes`) build assets with
:func:`make_asset`; :mod:`mpg_envs.simulation.bodies` adds them to a MuJoCo scene.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import trimesh

TABLEAU_10: tuple[tuple[float, float, float, float], ...] = tuple(
    (int(h[0:2], 16) / 255.0, int(h[2:4], 16) / 255.0, int(h[4:6], 16) / 255.0, 1.0)
    for h in (
        "4e79a7",  # blue
        "f28e2b",  # orange
        "e15759",  # red
        "76b7b2",  # teal
        "59a14f",  # green
        "edc948",  # yellow
        "b07aa1",  # purple
        "ff9da7",  # pink
        "9c755f",  # brown
        "bab0ac",  # grey
    )
)
"""The Tableau-10 palette (RGBA in [0, 1]), in Tableau's order."""

WOOD_DENSITY = 600.0
"""Default density (kg/m^3): the blocks are wooden."""

MASS_RANGE = (0.02, 0.3)
"""Default masses (kg) are clamped to this range so a closed 2F-85 can lift every object."""

DEFAULT_FRICTION = 0.9
"""Sliding friction of the objects. MuJoCo uses the larger of two geoms' values, so this
governs object-table and object-object contacts; the 2F-85 pads have ``priority=1``, so
pad contacts use the pads' own 0.7 whatever the object says."""

MIN_PART_VOLUME = 1e-9
"""Convex parts smaller than this (m^3, i.e. 1 mm^3) are dropped: they do not matter for
contacts and MuJoCo cannot compute a sensible inertia for them."""

Part = tuple[np.ndarray, np.ndarray]
"""One convex part: vertices (V, 3) float64 metres, faces (F, 3) int32."""


@dataclass(frozen=True, eq=False)
class ObjectAsset:
    """A rigid object made of convex parts.

    ``parts`` are in the object frame, whose origin is the centre of mass of the parts
    (uniform density), so a body built from them has its centre of mass at the body origin.
    Arrays are stored read-only. Equality is identity (arrays make ``==`` ambiguous).
    """

    name: str
    parts: tuple[Part, ...]
    rgba: tuple[float, float, float, float]
    mass: float
    friction: float
    source: str
    mesh_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Where the object frame's origin (the centre of mass) lies in the source mesh's frame
    (scaled by ``scale``), so a pose given for the mesh frame (a VPG scene file) converts to
    the body's pose."""
    scale: float = 1.0
    """The factor the source mesh's coordinates were multiplied by to make this object (a
    set's scale times a fit to the gripper), so a scene file can record it and the same object
    be loaded again from ``source``; 1.0 for generated sets."""
    licence: str = ""
    """The licence of the source geometry where it comes from outside (e.g. ``"zlib"``), else ``""``."""

    def __post_init__(self) -> None:
        if not self.parts:
            raise ValueError(f"object {self.name!r}: needs at least one convex part")
        parts = []
        for i, (vertices, faces) in enumerate(self.parts):
            v = np.array(vertices, dtype=np.float64)
            f = np.array(faces, dtype=np.int32)
            if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4 or not np.all(np.isfinite(v)):
                raise ValueError(f"object {self.name!r} part {i}: vertices must be finite (V>=4, 3)")
            if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4 or f.min() < 0 or f.max() >= len(v):
                raise ValueError(f"object {self.name!r} part {i}: faces must be (F>=4, 3) vertex indices")
            v.setflags(write=False)
            f.setflags(write=False)
            parts.append((v, f))
        # Frozen dataclass: normalise through object.__setattr__ (only here, at construction).
        object.__setattr__(self, "parts", tuple(parts))
        rgba = tuple(float(c) for c in self.rgba)
        if len(rgba) != 4 or not all(0.0 <= c <= 1.0 for c in rgba):
            raise ValueError(f"object {self.name!r}: rgba must be 4 values in [0, 1], got {self.rgba}")
        object.__setattr__(self, "rgba", rgba)
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"object {self.name!r}: mass must be positive, got {self.mass}")
        if not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"object {self.name!r}: friction must be positive, got {self.friction}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"object {self.name!r}: scale must be positive, got {self.scale}")

    @property
    def num_parts(self) -> int:
        """Number of convex parts."""
        return len(self.parts)

    @property
    def vertices(self) -> np.ndarray:
        """All part vertices stacked, (sum V, 3)."""
        return np.concatenate([v for v, _ in self.parts])

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box in the object frame, [[xmin, ymin, zmin], [xmax, ymax, zmax]]."""
        v = self.vertices
        return np.stack([v.min(axis=0), v.max(axis=0)])

    @property
    def extents(self) -> np.ndarray:
        """Bounding-box size (x, y, z) in metres, in the object frame."""
        b = self.bounds
        return b[1] - b[0]

    @functools.cached_property
    def part_volumes(self) -> np.ndarray:
        """Volume (m^3) of each convex part (read-only; computed once, as every scene build reads it)."""
        volumes = np.array([mesh_volume(v, f) for v, f in self.parts])
        volumes.setflags(write=False)
        return volumes

    @property
    def volume(self) -> float:
        """Total volume (m^3): the sum of the part volumes."""
        return float(self.part_volumes.sum())


def check_seed(seed: int) -> int:
    """The seed as a plain int; ValueError unless a non-negative integer (numpy's RNG rule)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def convex_part(points: np.ndarray) -> Part:
    """Convex hull of ``points`` as (vertices float64, faces int32); ValueError if too small."""
    points = np.asarray(points, dtype=np.float64)
    try:
        hull = trimesh.convex.convex_hull(points)
    except Exception as exc:  # qhull raises on coplanar/degenerate input
        raise ValueError("degenerate convex part") from exc
    vertices = np.asarray(hull.vertices, dtype=np.float64)
    faces = np.asarray(hull.faces, dtype=np.int32)
    if len(faces) < 4 or mesh_volume(vertices, faces) < MIN_PART_VOLUME:
        raise ValueError("degenerate convex part")
    return vertices, faces


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem)."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def mesh_centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Centroid of the solid enclosed by a closed, outward-oriented triangle mesh."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    signed = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0  # tetrahedra with the origin
    return (signed[:, None] * (a + b + c) / 4.0).sum(axis=0) / signed.sum()


def centre_parts(parts: list[Part]) -> tuple[list[Part], np.ndarray]:
    """Shift parts so their joint centre of mass (uniform density) is the origin.

    Computed from the parts rather than the source mesh so that it is exactly where MuJoCo
    puts the body's centre of mass when the mass is split across the parts by volume.
    Returns the shifted parts and the centre of mass in the source frame.
    """
    volumes = np.array([mesh_volume(v, f) for v, f in parts])
    centroids = np.array([mesh_centroid(v, f) for v, f in parts])
    com = (volumes[:, None] * centroids).sum(axis=0) / volumes.sum()
    return [(v - com, f) for v, f in parts], com


def make_asset(
    name: str,
    parts: list[Part],
    rgba: tuple[float, float, float, float],
    density: float,
    mass: float | None,
    friction: float,
    source: str,
    com: np.ndarray,
    *,
    volume: float | None = None,
    scale: float = 1.0,
    licence: str = "",
) -> ObjectAsset:
    """An asset from centred parts; ``mass=None`` means ``density * volume`` within MASS_RANGE.

    ``volume`` is the solid's volume when the parts overlap (the union of a mesh's bodies);
    ``None`` means the sum of the part volumes.
    """
    if mass is None:
        if not (math.isfinite(density) and density > 0):
            raise ValueError(f"density must be positive, got {density!r}")
        if volume is None:
            volume = sum(mesh_volume(v, f) for v, f in parts)
        mass = float(np.clip(density * volume, *MASS_RANGE))
    x, y, z = (float(c) for c in com)
    offset = (x, y, z)
    return ObjectAsset(
        name=name, parts=tuple(parts), rgba=rgba, mass=mass, friction=friction, source=source,
        mesh_offset=offset, scale=float(scale), licence=licence,
    )  # fmt: skip
