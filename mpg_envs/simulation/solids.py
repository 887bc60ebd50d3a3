"""Solids as unions of disjoint convex parts: the pure geometry of the procedural families.

Every builder returns convex parts (:data:`~mpg_envs.simulation.assets.Part`) whose interiors
do not overlap and which meet face to face, so their union is one closed solid whose volume
is the sum of the parts' volumes; MuJoCo's per-part convex inertia, with the mass split by
volume, is then the solid's own inertia. No convex decomposition is needed (nothing to
approximate, nothing that can crash). :func:`union_mesh` merges the parts into one
watertight mesh to check that.

All lengths are metres; shapes are built in their canonical frame, z up.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import trimesh

from mpg_envs.simulation.assets import Part, convex_part
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange


def superquadric_points(
    semi_axes: Sequence[float], exponents: Sequence[float], rings: int = 25, sectors: int = 48
) -> np.ndarray:
    """Surface points of the superquadric ``(|x/a|^r + |y/b|^r)^(t/r) + |z/c|^t = 1``.

    ``semi_axes`` is ``(a, b, c)``; ``exponents`` is ``(r, t)``: 2 and 2 give an ellipsoid,
    large values a box, 1 an octahedron; the solid is convex for ``r, t >= 1``. Points lie on
    a ``rings x sectors`` latitude-longitude grid plus the two poles.
    """
    a, b, c = (float(x) for x in semi_axes)
    r, t = (float(x) for x in exponents)
    if min(a, b, c) <= 0 or r < 1 or t < 1:
        raise ValueError(f"superquadric needs positive semi-axes and exponents >= 1, got {semi_axes}, {exponents}")
    eta = np.linspace(-math.pi / 2, math.pi / 2, rings + 2)[1:-1]
    omega = np.linspace(-math.pi, math.pi, sectors, endpoint=False)
    eta, omega = np.meshgrid(eta, omega, indexing="ij")

    def signed_power(x: np.ndarray, p: float) -> np.ndarray:
        return np.sign(x) * np.abs(x) ** p

    ce, se = signed_power(np.cos(eta), 2 / t), signed_power(np.sin(eta), 2 / t)
    co, so = signed_power(np.cos(omega), 2 / r), signed_power(np.sin(omega), 2 / r)
    body = np.stack([a * ce * co, b * ce * so, c * se], axis=-1).reshape(-1, 3)
    return np.concatenate([body, [(0.0, 0.0, -c), (0.0, 0.0, c)]])


def superquadric_volume(semi_axes: Sequence[float], exponents: Sequence[float]) -> float:
    """Exact volume of the superquadric of :func:`superquadric_points` (Jaklic et al. 2000:
    ``2abc e1 e2 B(e1/2 + 1, e1) B(e2/2, e2/2)`` with ``e1 = 2/t``, ``e2 = 2/r``)."""
    a, b, c = (float(x) for x in semi_axes)
    r, t = (float(x) for x in exponents)
    e1, e2 = 2.0 / t, 2.0 / r

    def beta(x: float, y: float) -> float:
        return math.exp(math.lgamma(x) + math.lgamma(y) - math.lgamma(x + y))

    return 2.0 * a * b * c * e1 * e2 * beta(e1 / 2 + 1, e1) * beta(e2 / 2, e2 / 2)


def superquadric_part(semi_axes: Sequence[float], exponents: Sequence[float]) -> list[Part]:
    """A convex superquadric (``r, t >= 1``) as one part: the hull of its surface points."""
    return [convex_part(superquadric_points(semi_axes, exponents))]


def star_polygon_pieces(polygon: np.ndarray) -> list[np.ndarray]:
    """Split a polygon that is star-shaped about the origin into convex pieces.

    ``polygon`` is ``(N, 2)``, counter-clockwise, every vertex seen from the origin (angles
    strictly increasing). The pieces are fans of consecutive vertices around the origin, each
    grown while it stays convex: they tile the polygon exactly and do not overlap.
    """
    poly = np.asarray(polygon, dtype=np.float64)
    if poly.ndim != 2 or poly.shape[1] != 2 or len(poly) < 3:
        raise ValueError(f"polygon must be (N>=3, 2), got shape {poly.shape}")
    angles = np.unwrap(np.arctan2(poly[:, 1], poly[:, 0]))
    if not (np.all(np.diff(angles) > 0) and angles[-1] - angles[0] < 2 * math.pi):
        raise ValueError("polygon must be star-shaped about the origin, counter-clockwise")
    n = len(poly)
    origin = np.zeros(2)
    pieces, start = [], 0
    while start < n:
        end = start + 1  # the fan (origin, v[start], ..., v[end]); one triangle is always convex
        while end < n and _convex([origin, *(poly[k % n] for k in range(start, end + 2))]):
            end += 1
        pieces.append(np.array([origin, *(poly[k % n] for k in range(start, end + 1))]))
        start = end
    return pieces


def _convex(points: Sequence[np.ndarray]) -> bool:
    """Whether a closed polygon (counter-clockwise) is strictly convex."""
    p = np.asarray(points)
    d = np.roll(p, -1, axis=0) - p
    cross = d[:, 0] * np.roll(d, -1, axis=0)[:, 1] - d[:, 1] * np.roll(d, -1, axis=0)[:, 0]
    return bool(np.all(cross > 1e-12))


def extrude_pieces(pieces: Sequence[np.ndarray], height: float) -> list[Part]:
    """Convex 2-D pieces extruded from ``z = 0`` to ``z = height``, one part each."""
    if not height > 0:
        raise ValueError(f"extrusion height must be > 0, got {height}")
    parts = []
    for piece in pieces:
        piece = np.asarray(piece, dtype=np.float64)
        bottom = np.column_stack([piece, np.zeros(len(piece))])
        top = np.column_stack([piece, np.full(len(piece), height)])
        parts.append(convex_part(np.concatenate([bottom, top])))
    return parts


def sweep_pieces(path: np.ndarray, section: np.ndarray) -> list[Part]:
    """A bar bent along a planar path: a convex cross-section swept along a polyline.

    ``path`` is ``(K >= 2, 2)`` points in the x-y plane; ``section`` is ``(M >= 3, 2)`` points
    ``(u, z)`` of a convex cross-section, ``u`` across the path (to its left) and ``z`` up.
    Segments meet at mitre joints (the cross-section stretched along each corner's bisector),
    so segment ``k`` is the convex hull of its two end sections, and neighbours share a face.

    Raises:
        ValueError: a corner of 150 degrees or more, or a segment too short for its mitres
            (the pieces would overlap).
    """
    path = np.asarray(path, dtype=np.float64)
    section = np.asarray(section, dtype=np.float64)
    if section.ndim != 2 or section.shape[1] != 2 or len(section) < 3:
        raise ValueError(f"section must be (M>=3, 2), got shape {section.shape}")
    mitres = sweep_mitres(path, float(np.abs(section[:, 0]).max()))
    parts = []
    for k in range(len(path) - 1):
        ends = [np.column_stack([path[j] + section[:, :1] * mitres[j], section[:, 1]]) for j in (k, k + 1)]
        parts.append(convex_part(np.concatenate(ends)))
    return parts


def sweep_mitres(path: np.ndarray, half_width: float) -> np.ndarray:
    """``(K, 2)`` in-plane directions of the sections of :func:`sweep_pieces` at each path
    point: the ends' normals, and at the corners the bisector stretched by ``1 / cos(turn / 2)``.

    Raises:
        ValueError: a path that is not ``(K >= 2, 2)``, a zero-length segment, a corner of 150
            degrees or more, or a segment too short for the mitres of a bar ``2 * half_width``
            wide (the pieces would overlap).
    """
    path = np.asarray(path, dtype=np.float64)
    if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
        raise ValueError(f"path must be (K>=2, 2), got shape {path.shape}")
    seg = np.diff(path, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    if np.any(lengths <= 0):
        raise ValueError("path has a zero-length segment")
    tangents = seg / lengths[:, None]
    normals = np.column_stack([-tangents[:, 1], tangents[:, 0]])  # left of the path
    mitres = [normals[0]]
    for k in range(1, len(path) - 1):
        mean = normals[k - 1] + normals[k]
        cos_half_squared = float(np.dot(normals[k - 1], normals[k]) + 1.0) / 2.0
        if cos_half_squared < math.cos(math.radians(75)) ** 2:
            raise ValueError(f"path corner {k} turns 150 degrees or more")
        mitres.append(mean / np.dot(mean, normals[k]))  # normal component 1, length 1 / cos
    mitres.append(normals[-1])
    for k in range(len(seg)):
        # Each end's mitre shifts the bar's edges along the segment by up to half_width * tan.
        shift = sum(abs(float(np.dot(mitres[j], tangents[k]))) for j in (k, k + 1)) * half_width
        if shift >= lengths[k]:
            raise ValueError(f"path segment {k} is too short for its corners")
    return np.array(mitres)


def ring_pieces(inner: float, outer: float, z0: float, z1: float, sections: int = 16) -> list[Part]:
    """A ring (polygonal annulus) between heights ``z0`` and ``z1``: ``sections`` wedges."""
    if not 0 < inner < outer or not z1 > z0 or sections < 3:
        raise ValueError(f"ring needs 0 < inner < outer, z1 > z0, >= 3 sections; got {inner}, {outer}, {z0}, {z1}, {sections}")
    angles = np.linspace(0.0, 2 * math.pi, sections, endpoint=False)
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    parts = []
    for k in range(sections):
        corners = [ring[k] * inner, ring[k] * outer, ring[(k + 1) % sections] * outer, ring[(k + 1) % sections] * inner]
        parts.append(convex_part(np.array([(x, y, z) for x, y in corners for z in (z0, z1)])))
    return parts


def regular_polygon(radius: float, sides: int, scale: Sequence[float] = (1.0, 1.0)) -> np.ndarray:
    """``(sides, 2)`` counter-clockwise vertices of a regular polygon, axes scaled by ``scale``."""
    angles = np.linspace(0.0, 2 * math.pi, sides, endpoint=False)
    return np.column_stack([radius * scale[0] * np.cos(angles), radius * scale[1] * np.sin(angles)])


def box_part(lo: Sequence[float], hi: Sequence[float]) -> Part:
    """The axis-aligned box between corners ``lo`` and ``hi``."""
    a, b = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    return convex_part(np.array([[x, y, z] for x in (a[0], b[0]) for y in (a[1], b[1]) for z in (a[2], b[2])]))


def axis_fit_factors(extents: Sequence[float] | np.ndarray, extent_range: ExtentRange = BLOCKS_EXTENTS) -> np.ndarray:
    """Per-axis factors that bring ``extents`` into ``extent_range`` (the blocks' by default).

    Each extent is clamped to ``[min_extent, max_extent]`` and then the two smallest to at most
    ``max_two_smallest``; the factor is the new extent over the old. Extents already in range
    keep factor 1, so a shape drawn inside the range is left exactly as drawn. (A generated
    shape may be stretched per axis; an outside mesh is scaled uniformly:
    :func:`mpg_envs.simulation.gripper_fit.fit_scale`.)
    """
    ext = np.asarray(extents, dtype=np.float64)
    if ext.shape != (3,) or not np.all(ext > 0):
        raise ValueError(f"extents must be 3 positive lengths, got {extents}")
    target = np.clip(ext, extent_range.min_extent, extent_range.max_extent)
    two_smallest = np.argsort(target, kind="stable")[:2]
    target[two_smallest] = np.minimum(target[two_smallest], extent_range.max_two_smallest)
    return target / ext


def scale_parts(parts: Sequence[Part], factors: Sequence[float] | np.ndarray) -> list[Part]:
    """Parts scaled about the origin per axis (convex parts stay convex and disjoint)."""
    f = np.asarray(factors, dtype=np.float64)
    return [convex_part(v * f) for v, _ in parts]


def parts_extents(parts: Sequence[Part]) -> np.ndarray:
    """Bounding-box size (x, y, z) of the parts together."""
    v = np.concatenate([p[0] for p in parts])
    return v.max(axis=0) - v.min(axis=0)


def union_mesh(parts: Sequence[Part]) -> trimesh.Trimesh:
    """The parts merged into one mesh by a boolean union (manifold3d): watertight, and with
    the parts' summed volume when they do not overlap."""
    meshes = [trimesh.Trimesh(v, f, process=True) for v, f in parts]
    if len(meshes) == 1:
        return meshes[0]
    return trimesh.boolean.union(meshes, engine="manifold")
