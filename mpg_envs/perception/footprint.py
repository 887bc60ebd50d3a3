"""Footprints seen along gravity: the target mask heightmap and its pure geometry.

A footprint is the set of heightmap pixels whose centre lies under a geom (pixel-centre
sampling, exactly as :class:`~mpg_envs.perception.heightmap.RaycastHeightmapper` samples), whatever lies
on top of it. Grid conventions are :mod:`mpg_envs.grid.workspace`'s.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import cv2
import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace

_CIRCLE_SEGMENTS = 32
"""Polygon resolution used for round primitives (sphere, capsule, cylinder)."""


def world_to_pixel_coords(workspace: Workspace, xy: np.ndarray) -> np.ndarray:
    """Continuous pixel coordinates ``(col, row)`` of world points ``(..., 2)``.

    Integer values are pixel centres, so pixel ``(row, col)`` spans ``[col - 0.5,
    col + 0.5) x [row - 0.5, row + 0.5)``; ``floor(coord + 0.5)`` is the pixel index of
    :func:`mpg_envs.grid.workspace.world_to_pixel`.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if xy.shape[-1] != 2:
        raise ValueError(f"xy must have shape (..., 2), got {xy.shape}")
    col = (xy[..., 0] - workspace.x_min) / workspace.resolution - 0.5
    row = (xy[..., 1] - workspace.y_min) / workspace.resolution - 0.5
    return np.stack([col, row], axis=-1)


def fill_convex_hull(mask: np.ndarray, points: np.ndarray, value: int = 1) -> None:
    """Set to ``value`` every pixel of ``mask`` whose centre lies in the convex hull of
    ``points`` (``(N, 2)`` continuous pixel coordinates ``(col, row)``, centres at
    integers; boundary included).

    Pixel-centre sampling matches the ray-cast heightmap, which also samples pixel centres,
    so a mask pixel is exactly a pixel where an unoccluded object shows up. (OpenCV's
    ``fillConvexPoly`` also paints pixels that the outline merely grazes, up to half a
    pixel outside, which would make the mask about one pixel wider than the object in the
    heightmap.) Degenerate hulls (all points on a line) mark the pixels of the points.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.size == 0:
        return
    rows, cols = mask.shape[:2]
    # The hull's ordered vertices; float32 is ample for pixel coordinates.
    hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2).astype(np.float64)
    nxt = np.concatenate([hull[1:], hull[:1]])
    edges = nxt - hull
    area2 = float(np.sum(hull[:, 0] * nxt[:, 1] - nxt[:, 0] * hull[:, 1]))
    if len(hull) < 3 or abs(area2) < 1e-9:
        idx = np.floor(pts + 0.5).astype(np.int64)
        keep = (idx[:, 0] >= 0) & (idx[:, 0] < cols) & (idx[:, 1] >= 0) & (idx[:, 1] < rows)
        mask[idx[keep, 1], idx[keep, 0]] = value
        return
    c0 = max(math.ceil(hull[:, 0].min() - 1e-9), 0)
    c1 = min(math.floor(hull[:, 0].max() + 1e-9), cols - 1)
    r0 = max(math.ceil(hull[:, 1].min() - 1e-9), 0)
    r1 = min(math.floor(hull[:, 1].max() + 1e-9), rows - 1)
    if c1 < c0 or r1 < r0:
        return
    cc = np.arange(c0, c1 + 1, dtype=np.float64)[None, None, :]
    rr = np.arange(r0, r1 + 1, dtype=np.float64)[None, :, None]
    ex, ey = edges[:, 0, None, None], edges[:, 1, None, None]
    hx, hy = hull[:, 0, None, None], hull[:, 1, None, None]
    # Inside a convex polygon = on the inner side of every edge; the sign of the doubled
    # area gives the winding, so either orientation works. The tiny tolerance keeps
    # centres lying exactly on an edge.
    cross = (ex * (rr - hy) - ey * (cc - hx)) * math.copysign(1.0, area2)
    tol = -1e-9 * np.hypot(ex, ey)
    inside = np.all(cross >= tol, axis=0)
    mask[r0 : r1 + 1, c0 : c1 + 1][inside] = value


def _circle(n: int = _CIRCLE_SEGMENTS) -> np.ndarray:
    """``(n, 2)`` vertices of a regular polygon circumscribing the unit circle, so that
    hulls built from it contain the true round shape."""
    angles = (np.arange(n) + 0.5) * (2.0 * math.pi / n)
    return np.stack([np.cos(angles), np.sin(angles)], axis=1) / math.cos(math.pi / n)


def geom_world_vertices(model: mujoco.MjModel, data: mujoco.MjData, geom_id: int) -> np.ndarray:
    """``(N, 3)`` world points whose convex hull is (or tightly contains) the geom.

    Uses ``data.geom_xpos`` / ``data.geom_xmat``, so call after ``mj_forward`` /
    ``mj_kinematics``. Mesh geoms give their mesh vertices: MuJoCo collides a mesh geom as
    the convex hull of these vertices, so the hull is the exact collision shape (unless
    the model caps hull vertices with ``maxhullvert``). Boxes give their 8 corners (exact).
    Spheres, capsules and cylinders give circumscribed polygons (32 segments) of their
    round outlines: the silhouette seen along gravity and the highest point are exact to
    within 0.5 % of the radius, never smaller than the true shape. Spheres and capsules also
    give their topmost and bottommost points, so ``max(z)`` is their exact highest point.
    Ellipsoids give a surface sampling (slightly inside the true shape).

    Raises:
        ValueError: for an out-of-range id, or for planes, height fields and SDF geoms
            (unbounded or not vertex-based).
    """
    if not 0 <= int(geom_id) < model.ngeom:
        raise ValueError(f"geom_id must be in 0..{model.ngeom - 1}, got {geom_id!r}")
    g = int(geom_id)
    pos = data.geom_xpos[g].copy()
    rot = data.geom_xmat[g].reshape(3, 3)
    size = model.geom_size[g]
    gtype = int(model.geom_type[g])
    if gtype == mujoco.mjtGeom.mjGEOM_MESH:
        mesh = int(model.geom_dataid[g])
        start, count = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
        local = model.mesh_vert[start : start + count].astype(np.float64)
        return pos + local @ rot.T
    if gtype == mujoco.mjtGeom.mjGEOM_BOX:
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        return pos + (signs * size[:3]) @ rot.T
    if gtype == mujoco.mjtGeom.mjGEOM_CYLINDER:
        ring = np.c_[_circle() * size[0], np.zeros(_CIRCLE_SEGMENTS)]
        local = np.concatenate([ring + [0.0, 0.0, -size[1]], ring + [0.0, 0.0, size[1]]])
        return pos + local @ rot.T
    if gtype in (mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE):
        radius = size[0]
        if gtype == mujoco.mjtGeom.mjGEOM_SPHERE:
            centres = pos[None]
        else:
            axis = rot[:, 2] * size[1]
            centres = np.stack([pos - axis, pos + axis])
        # The silhouette of a ball along gravity is its horizontal great circle (world frame).
        ring = np.c_[_circle() * radius, np.zeros(_CIRCLE_SEGMENTS)]
        poles = np.array([[0.0, 0.0, radius], [0.0, 0.0, -radius]])
        local = np.concatenate([ring, poles])
        return (centres[:, None, :] + local[None]).reshape(-1, 3)
    if gtype == mujoco.mjtGeom.mjGEOM_ELLIPSOID:
        lat = np.linspace(0.0, math.pi, 9)
        lon = np.linspace(0.0, 2.0 * math.pi, 24, endpoint=False)
        la, lo = np.meshgrid(lat, lon)
        unit = np.stack([np.sin(la) * np.cos(lo), np.sin(la) * np.sin(lo), np.cos(la)], -1).reshape(-1, 3)
        return pos + (unit * size[:3]) @ rot.T
    raise ValueError(
        f"geom {g} has type {mujoco.mjtGeom(gtype).name}, which has no bounded vertex set; "
        "supported: mesh, box, sphere, capsule, cylinder, ellipsoid"
    )


def footprint_mask(
    workspace: Workspace,
    model: mujoco.MjModel,
    data: mujoco.MjData,
    geom_ids: Sequence[int] | np.ndarray,
) -> np.ndarray:
    """``(H, W)`` uint8 mask (0/1) of the area the given geoms occupy seen along gravity.

    This is the paper's target mask heightmap: the target's whole footprint, also where
    other objects lie on top of it. Each geom is convex as MuJoCo collides it (a mesh geom
    is the convex hull of its vertices; objects are built from convex parts), so its
    footprint is the 2-D convex hull of its projected vertices
    (:func:`geom_world_vertices`), filled with pixel-centre sampling
    (:func:`fill_convex_hull`) like the ray-cast heightmap. Parts outside the workspace are
    cut off at the grid border.
    """
    mask = np.zeros(workspace.shape, dtype=np.uint8)
    for geom_id in np.asarray(geom_ids, dtype=np.int64).reshape(-1):
        verts = geom_world_vertices(model, data, int(geom_id))
        fill_convex_hull(mask, world_to_pixel_coords(workspace, verts[:, :2]))
    return mask
