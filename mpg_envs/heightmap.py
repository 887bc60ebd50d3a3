"""Top-down heightmaps of the workspace: ray casting (no OpenGL), RGB-D back-projection,
fusion, and target footprint masks.

All heightmaps follow :mod:`mpg_envs.workspace`: pixel ``(row, col)`` covers world
``y`` (rows) and ``x`` (columns), ``row = floor((y - y_min) / res)``,
``col = floor((x - x_min) / res)``; a pixel is represented by its centre
(:meth:`Workspace.pixel_centers`). Heights are metres above the table top
(``z - workspace.z_min``) and always lie in ``[0, z_max - z_min]`` (``[0, 0.4]`` for the
default workspace, the range of the ``depth`` observation space): anything below the table
(holes, the floor, sensor noise) reads 0, and the ray-cast path clips the physically
implausible heights above ``z_max`` to ``z_max``.

The default observation path, :class:`RaycastHeightmapper`, needs no OpenGL: it casts one
ray per pixel centre with ``mujoco.mj_multiRay`` and sees only the geom groups of the table
(0) and the objects (1), so the robot (groups 2 and 3) is invisible. The camera path
(:mod:`mpg_envs.camera`) renders RGB-D images and goes through :func:`heightmap_from_rgbd`,
which a real RGB-D camera can use as well.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import mujoco
import numpy as np

from mpg_envs.workspace import Workspace

VISIBLE_GEOM_GROUPS: tuple[int, ...] = (0, 1)
"""Geom groups seen by the heightmaps: the table (0) and the objects (1)."""

DEFAULT_SOURCE_HEIGHT = 1000.0
"""Height (m) above the table of the common origin of all rays of
:class:`RaycastHeightmapper`: every ray is within 3.2e-4 rad of vertical."""

_CIRCLE_SEGMENTS = 32
"""Polygon resolution used for round primitives (sphere, capsule, cylinder)."""


# ----------------------------------------------------------------------------------------
# Heightmap container and small pure helpers
# ----------------------------------------------------------------------------------------


@dataclass
class Heightmaps:
    """Colour and depth heightmaps of one workspace view.

    Attributes:
        color: ``(H, W, 3)`` uint8 RGB colour of the highest surface at each pixel.
        depth: ``(H, W)`` float32 height of that surface in metres above the table, in
            ``[0, z_max - z_min]``; pixels where nothing was seen read 0.
        geom_id: ``(H, W)`` int32 id of the geom hit at each pixel (-1 for none); only the
            ray-cast path knows it, the RGB-D path leaves it ``None``.
    """

    color: np.ndarray
    depth: np.ndarray
    geom_id: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.depth.ndim != 2 or self.depth.dtype != np.float32:
            raise ValueError(
                f"depth must be a (H, W) float32 array, got {self.depth.shape} {self.depth.dtype}"
            )
        if self.color.shape != self.depth.shape + (3,) or self.color.dtype != np.uint8:
            raise ValueError(
                f"color must be a {self.depth.shape + (3,)} uint8 array matching depth, "
                f"got {self.color.shape} {self.color.dtype}"
            )
        if self.geom_id is not None and (
            self.geom_id.shape != self.depth.shape or self.geom_id.dtype != np.int32
        ):
            raise ValueError(
                f"geom_id must be a {self.depth.shape} int32 array matching depth, "
                f"got {self.geom_id.shape} {self.geom_id.dtype}"
            )

    @property
    def shape(self) -> tuple[int, int]:
        """Heightmap shape ``(rows, cols)``."""
        return self.depth.shape  # type: ignore[return-value]


def geomgroup_mask(groups: Sequence[int] = VISIBLE_GEOM_GROUPS) -> np.ndarray:
    """The ``mjNGROUP``-long uint8 visibility vector (as ``MjvOption.geomgroup`` and
    ``mj_ray`` take it) that shows exactly the given geom groups."""
    mask = np.zeros(mujoco.mjNGROUP, dtype=np.uint8)
    for group in groups:
        if not 0 <= int(group) < mujoco.mjNGROUP:
            raise ValueError(f"geom group must be in 0..{mujoco.mjNGROUP - 1}, got {group!r}")
        mask[int(group)] = 1
    return mask


def geom_colors(model: mujoco.MjModel) -> np.ndarray:
    """``(ngeom, 3)`` uint8 RGB colour of every geom, as MuJoCo's renderer picks it.

    The geom's own ``rgba`` wins unless the geom has a material and its ``rgba`` is left at
    the default ``(0.5, 0.5, 0.5, 1)``, in which case the material's ``rgba`` is used.
    Textures and lighting are ignored (flat colour); alpha is dropped.
    """
    rgba = model.geom_rgba.astype(np.float32).copy()
    matid = model.geom_matid
    # MuJoCo keeps float32 colours, so the default is an exact comparison.
    is_default = np.all(model.geom_rgba == np.float32([0.5, 0.5, 0.5, 1.0]), axis=1)
    use_material = (matid >= 0) & is_default
    rgba[use_material] = model.mat_rgba[matid[use_material]]
    return np.round(np.clip(rgba[:, :3], 0.0, 1.0) * 255.0).astype(np.uint8)


def heights_from_world_z(z: np.ndarray, workspace: Workspace) -> np.ndarray:
    """World ``z`` -> float32 heights above the table clipped to ``[0, z_max - z_min]``."""
    return np.clip(np.asarray(z) - workspace.z_min, 0.0, workspace.z_max - workspace.z_min).astype(np.float32)


def world_to_pixel_coords(workspace: Workspace, xy: np.ndarray) -> np.ndarray:
    """Continuous pixel coordinates ``(col, row)`` of world points ``(..., 2)``.

    Integer values are pixel centres, so pixel ``(row, col)`` spans ``[col - 0.5,
    col + 0.5) x [row - 0.5, row + 0.5)``; ``floor(coord + 0.5)`` is the pixel index of
    :func:`mpg_envs.workspace.world_to_pixel`.
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


# ----------------------------------------------------------------------------------------
# Geom geometry: world vertices and footprints
# ----------------------------------------------------------------------------------------


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


# ----------------------------------------------------------------------------------------
# Ray casting without OpenGL
# ----------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=8)
def _ray_directions(workspace: Workspace, source_height: float) -> tuple[np.ndarray, np.ndarray]:
    """Ray origin ``(3,)`` and ``(H*W, 3)`` directions from it to every pixel centre on the
    table plane, row-major. ``dist`` returned by ``mj_multiRay`` is in units of these
    (non-unit) vectors: ``hit = origin + dist * direction``, so ``dist == 1`` on the table."""
    centre = workspace.center
    origin = np.array([centre[0], centre[1], workspace.z_min + source_height])
    gx, gy = workspace.pixel_centers()
    dirs = np.stack([gx - origin[0], gy - origin[1], np.full_like(gx, workspace.z_min - origin[2])], -1)
    dirs = dirs.reshape(-1, 3)
    origin.setflags(write=False)
    dirs.setflags(write=False)
    return origin, dirs


def _default_threads() -> int:
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        available = os.cpu_count() or 1
    return max(1, min(2, available))


class RaycastHeightmapper:
    """Colour/depth heightmaps by ray casting (``mujoco.mj_multiRay``), no OpenGL needed.

    One ray per pixel, all from a common origin ``source_height`` metres above the
    workspace centre, each aimed at its pixel centre on the table plane. Rays from that far
    up are nearly parallel: a surface at height ``h`` is sampled ``h * r / source_height``
    away from the pixel centre, ``r`` being the pixel's distance from the workspace centre
    (at most 0.32 m): 0.016 mm for a 5 cm object at the corner with the default 1000 m.
    That keeps the heightmap consistent with :func:`footprint_mask` (pixel-centre
    sampling) at object edges: on a 30-object scene, 5 edge pixels of ~16000 disagree at
    1000 m, against 23 at 100 m and 58 at 50 m. The heights stay exact in float64 (error
    ~1e-13 m). Only geom groups ``geom_groups`` (table and objects) are
    hit; the robot's groups 2 and 3 are invisible. Geoms with alpha 0 are skipped by
    MuJoCo's ray caster. A pixel whose ray hits nothing reads height 0 and
    ``background_color``.

    The rays are split over ``num_threads`` threads (``mj_multiRay`` releases the GIL);
    each ray is independent, so the result is identical for any thread count. Extra
    threads work on private copies of ``data`` (``mj_copyData``); ``data`` is never
    modified.

    Bound to one compiled model: build a new one when the model is recompiled
    (construction is cheap; the ray directions are cached per workspace). One instance
    must not be called from several threads at once (it reuses its scratch data).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        workspace: Workspace | None = None,
        *,
        geom_groups: Sequence[int] = VISIBLE_GEOM_GROUPS,
        background_color: Sequence[int] | None = None,
        source_height: float = DEFAULT_SOURCE_HEIGHT,
        num_threads: int | None = None,
    ) -> None:
        """
        Args:
            model: the compiled model whose ``MjData`` will be passed to :meth:`heightmaps`.
            workspace: the heightmap grid; the default :class:`Workspace` if ``None``.
            geom_groups: geom groups the rays can hit.
            background_color: RGB of pixels no ray hits; by default the colour of the
                largest (by bounding radius) geom of the lowest visible group, the table.
            source_height: height (m) of the common ray origin above the table; must be
                well above ``workspace.z_max``.
            num_threads: threads sharing the rays; default ``min(2, available CPUs)``.
        """
        self.model = model
        self.workspace = workspace if workspace is not None else Workspace()
        if not source_height > 10.0 * (self.workspace.z_max - self.workspace.z_min):
            raise ValueError(
                f"source_height must be far above the workspace (> 10 x its height, "
                f"{10.0 * (self.workspace.z_max - self.workspace.z_min):g} m) so rays are "
                f"nearly parallel, got {source_height!r}"
            )
        self.source_height = float(source_height)
        self.geomgroup = geomgroup_mask(geom_groups)
        self.num_threads = _default_threads() if num_threads is None else int(num_threads)
        if self.num_threads < 1:
            raise ValueError(f"num_threads must be >= 1, got {num_threads!r}")

        colors = geom_colors(model)
        if background_color is None:
            background = self._table_color(model, colors, geom_groups)
        else:
            background = np.asarray(background_color)
            if background.shape != (3,) or np.any(background < 0) or np.any(background > 255):
                raise ValueError(f"background_color must be 3 values in 0..255, got {background_color!r}")
        # The extra last row is the colour of geom id -1 (no hit): plain indexing does it.
        self._palette = np.concatenate([colors, background.astype(np.uint8)[None]])

        self._origin, dirs = _ray_directions(self.workspace, self.source_height)
        self._num_rays = dirs.shape[0]
        # Thread k takes image rows k, k + n, k + 2n, ...: clutter is often bunched in one
        # part of the workspace, and interleaved rows share it evenly.
        row_of_ray = np.arange(self._num_rays) // self.workspace.shape[1]
        self._ray_ids = [np.flatnonzero(row_of_ray % self.num_threads == k) for k in range(self.num_threads)]
        # Writable contiguous copies, so the binding can pass them to C without copying.
        self._vec = [dirs[ids].reshape(-1).copy() for ids in self._ray_ids]
        self._vec_z = dirs[:, 2].copy()
        self._scratch = [mujoco.MjData(model) for _ in range(self.num_threads - 1)]
        self._pool = ThreadPoolExecutor(self.num_threads - 1) if self.num_threads > 1 else None

    @staticmethod
    def _table_color(model: mujoco.MjModel, colors: np.ndarray, groups: Sequence[int]) -> np.ndarray:
        for group in sorted(int(g) for g in groups):
            ids = np.flatnonzero(model.geom_group == group)
            if ids.size:
                return colors[ids[np.argmax(model.geom_rbound[ids])]]
        return np.zeros(3, dtype=np.uint8)

    def cast(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Raw ray results: ``(geom_id, world_z)``, both of heightmap shape; ``geom_id`` is
        -1 and ``world_z`` is NaN where the ray hits nothing."""
        if data.geom_xpos.shape[0] != self.model.ngeom:
            raise ValueError(
                f"data belongs to a model with {data.geom_xpos.shape[0]} geoms, this "
                f"heightmapper's model has {self.model.ngeom}: build a new RaycastHeightmapper"
            )
        geom_id = np.empty(self._num_rays, dtype=np.int32)
        dist = np.empty(self._num_rays, dtype=np.float64)
        # Cutoff is compared with geom distances from the origin (metres), not with dist.
        cutoff = float(mujoco.mjMAXVAL)

        def run(k: int, d: mujoco.MjData) -> None:
            ids = self._ray_ids[k]
            ids_geom = np.empty(ids.size, dtype=np.int32)
            ids_dist = np.empty(ids.size, dtype=np.float64)
            mujoco.mj_multiRay(
                self.model,
                d,
                self._origin,
                self._vec[k],
                self.geomgroup,
                1,
                -1,
                ids_geom,
                ids_dist,
                None,
                ids.size,
                cutoff,
            )
            geom_id[ids] = ids_geom
            dist[ids] = ids_dist

        # Copy before any ray uses data's stack: mj_copyData refuses a busy stack.
        for scratch in self._scratch:
            mujoco.mj_copyData(scratch, self.model, data)
        futures = (
            [self._pool.submit(run, k, self._scratch[k - 1]) for k in range(1, self.num_threads)]
            if self._pool
            else []
        )
        run(0, data)
        for future in futures:
            future.result()
        hit = geom_id >= 0
        world_z = np.where(hit, self._origin[2] + dist * self._vec_z, np.nan)
        return geom_id.reshape(self.workspace.shape), world_z.reshape(self.workspace.shape)

    def heightmaps(self, data: mujoco.MjData) -> Heightmaps:
        """Heightmaps of the current state (``data`` after ``mj_forward`` or a step)."""
        geom_id, world_z = self.cast(data)
        depth = heights_from_world_z(np.nan_to_num(world_z, nan=self.workspace.z_min), self.workspace)
        return Heightmaps(color=self._palette[geom_id], depth=depth, geom_id=geom_id)

    def __call__(self, data: mujoco.MjData) -> Heightmaps:
        """Same as :meth:`heightmaps`."""
        return self.heightmaps(data)

    def close(self) -> None:
        """Stop the worker threads (idempotent)."""
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def __enter__(self) -> RaycastHeightmapper:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        pool = getattr(self, "_pool", None)
        if pool is not None:
            pool.shutdown(wait=False)


# ----------------------------------------------------------------------------------------
# RGB-D back-projection and fusion
# ----------------------------------------------------------------------------------------


def _check_rgbd(color: np.ndarray, depth: np.ndarray, intrinsics: np.ndarray, cam_pose: np.ndarray) -> None:
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:
        raise ValueError(f"depth must be a (H, W) array, got shape {np.shape(depth)}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise TypeError(
            f"depth must be floating-point metres, got dtype {depth.dtype}; convert raw "
            "sensor units first (e.g. uint16 millimetres: depth.astype(np.float32) * depth_scale)"
        )
    if not isinstance(color, np.ndarray) or color.shape != depth.shape + (3,):
        raise ValueError(
            f"color must be a (H, W, 3) array matching depth {depth.shape}, got shape {np.shape(color)}"
        )
    if color.dtype != np.uint8:
        raise TypeError(f"color must be uint8 RGB, got dtype {color.dtype}")
    if intrinsics.shape != (3, 3) or not np.all(np.isfinite(intrinsics)):
        raise ValueError(f"intrinsics must be a finite 3x3 pinhole matrix K, got shape {intrinsics.shape}")
    if intrinsics[0, 0] <= 0 or intrinsics[1, 1] <= 0 or not np.allclose(intrinsics[2], [0.0, 0.0, 1.0]):
        raise ValueError(
            "intrinsics must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, "
            f"got {intrinsics.tolist()}"
        )
    if cam_pose.shape != (4, 4) or not np.all(np.isfinite(cam_pose)):
        raise ValueError(
            f"cam_pose must be a finite 4x4 camera-to-world transform, got shape {cam_pose.shape}"
        )
    rot = cam_pose[:3, :3]
    if not np.allclose(cam_pose[3], [0.0, 0.0, 0.0, 1.0]) or not np.allclose(
        rot @ rot.T, np.eye(3), atol=1e-4
    ):
        raise ValueError("cam_pose must be a rigid transform: orthonormal rotation and last row [0, 0, 0, 1]")


def heightmap_from_rgbd(
    color: np.ndarray,
    depth: np.ndarray,
    intrinsics: np.ndarray,
    cam_pose: np.ndarray,
    workspace: Workspace | None = None,
    background_color: Sequence[int] = (0, 0, 0),
) -> Heightmaps:
    """Back-project an RGB-D image into colour/depth heightmaps (as a real camera would).

    Args:
        color: ``(H, W, 3)`` uint8 RGB image registered to ``depth``.
        depth: ``(H, W)`` float depth in metres along the camera's optical axis (z-depth,
            not ray length); 0, negative, NaN and inf mark invalid pixels, which are skipped.
        intrinsics: 3x3 pinhole matrix ``K`` in OpenCV convention (pixel ``(u, v)`` =
            column, row; integer coordinates are pixel centres).
        cam_pose: 4x4 camera-to-world transform of the OpenCV camera frame (x right,
            y down, z forward).
        workspace: the heightmap grid; the default :class:`Workspace` if ``None``.
        background_color: RGB of heightmap pixels that receive no point.

    Points outside the workspace footprint or above ``z_max`` are dropped; points below the
    table are kept at height 0 (so sensor noise around the table plane does not punch
    holes). Each heightmap pixel keeps its highest point and that point's colour (ties go
    to the point that comes last in row-major image order). Pixels with no point read 0.

    Raises:
        ValueError / TypeError: naming the argument with a wrong shape, dtype or value.
    """
    workspace = workspace if workspace is not None else Workspace()
    intrinsics = np.asarray(intrinsics, dtype=np.float64)
    cam_pose = np.asarray(cam_pose, dtype=np.float64)
    _check_rgbd(color, depth, intrinsics, cam_pose)
    background = np.asarray(background_color)
    if background.shape != (3,) or np.any(background < 0) or np.any(background > 255):
        raise ValueError(f"background_color must be 3 values in 0..255, got {background_color!r}")

    rows, cols = workspace.shape
    out_depth = np.zeros(rows * cols, dtype=np.float32)
    out_color = np.empty((rows * cols, 3), dtype=np.uint8)
    out_color[:] = background.astype(np.uint8)

    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    v, u = np.nonzero(valid)
    z = depth[v, u].astype(np.float64)
    # Camera-frame points: K^-1 [u, v, 1] * z (handles skew too).
    k_inv = np.linalg.inv(intrinsics)
    pix = np.stack([u, v, np.ones_like(u)], axis=0).astype(np.float64)
    cam = (k_inv @ pix) * z
    world = cam_pose[:3, :3] @ cam + cam_pose[:3, 3:4]

    # The epsilon is world_to_pixel's: a point on a pixel edge (up to float error) goes to
    # the pixel that starts there.
    col = np.floor((world[0] - workspace.x_min) / workspace.resolution + 1e-9).astype(np.int64)
    row = np.floor((world[1] - workspace.y_min) / workspace.resolution + 1e-9).astype(np.int64)
    height = world[2] - workspace.z_min
    keep = (
        (col >= 0) & (col < cols) & (row >= 0) & (row < rows) & (height <= workspace.z_max - workspace.z_min)
    )
    flat = row[keep] * cols + col[keep]
    height = np.maximum(height[keep], 0.0)
    src = np.flatnonzero(keep)
    if flat.size:
        # z-buffer: per-pixel max height (ufunc.at is fast in numpy >= 1.25), then the
        # colour of the last point (in image order) that reaches it.
        best = np.full(rows * cols, -np.inf)
        np.maximum.at(best, flat, height)
        winner = np.full(rows * cols, -1, dtype=np.int64)
        top = height == best[flat]
        np.maximum.at(winner, flat[top], src[top])
        seen = winner >= 0
        out_depth[seen] = best[seen]
        out_color[seen] = color[v[winner[seen]], u[winner[seen]]]
    return Heightmaps(color=out_color.reshape(rows, cols, 3), depth=out_depth.reshape(rows, cols))


def fuse_heightmaps(maps: Sequence[Heightmaps]) -> Heightmaps:
    """Per-pixel fusion of several views: each pixel takes the highest reading and its
    colour (and geom id when every input has one); on ties the earliest map wins."""
    maps = list(maps)
    if not maps:
        raise ValueError("fuse_heightmaps needs at least one Heightmaps")
    shape = maps[0].shape
    for i, hm in enumerate(maps):
        if hm.shape != shape:
            raise ValueError(
                f"all heightmaps must have the same shape; map 0 is {shape}, map {i} is {hm.shape}"
            )
    depths = np.stack([hm.depth for hm in maps])
    best = np.argmax(depths, axis=0)
    r, c = np.indices(shape)
    color = np.stack([hm.color for hm in maps])[best, r, c]
    geom_id = None
    if all(hm.geom_id is not None for hm in maps):
        geom_id = np.stack([hm.geom_id for hm in maps])[best, r, c]  # type: ignore[misc]
    return Heightmaps(color=color, depth=depths[best, r, c], geom_id=geom_id)
