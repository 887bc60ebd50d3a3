"""Top-down heightmaps of the workspace by ray casting (no OpenGL).

RGB-D back-projection and fusion of camera views live in :mod:`mpg_envs.perception.rgbd`; the target
footprint mask in :mod:`mpg_envs.perception.footprint`.

All heightmaps follow :mod:`mpg_envs.grid.workspace`: pixel ``(row, col)`` covers world
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
(:mod:`mpg_envs.perception.camera`) renders RGB-D images and goes through
:func:`mpg_envs.perception.rgbd.heightmap_from_rgbd`, which a real RGB-D camera can use as well.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.ray_culling import pixels_under_boxes, world_boxes
from mpg_envs.threads import num_threads, requested_threads

VISIBLE_GEOM_GROUPS: tuple[int, ...] = (0, 1)
"""Geom groups seen by the heightmaps: the table (0) and the objects (1)."""

_STATIC_CASTS: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
"""The rays' results against the static geoms alone, per layout of those geoms (a few kept)."""

DEFAULT_SOURCE_HEIGHT = 1000.0
"""Height (m) above the table of the common origin of all rays of
:class:`RaycastHeightmapper`: every ray is within 3.2e-4 rad of vertical."""


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
            raise ValueError(f"depth must be a (H, W) float32 array, got {self.depth.shape} {self.depth.dtype}")
        if self.color.shape != self.depth.shape + (3,) or self.color.dtype != np.uint8:
            raise ValueError(
                f"color must be a {self.depth.shape + (3,)} uint8 array matching depth, "
                f"got {self.color.shape} {self.color.dtype}"
            )
        if self.geom_id is not None and (self.geom_id.shape != self.depth.shape or self.geom_id.dtype != np.int32):
            raise ValueError(
                f"geom_id must be a {self.depth.shape} int32 array matching depth, "
                f"got {self.geom_id.shape} {self.geom_id.dtype}"
            )

    @property
    def shape(self) -> tuple[int, int]:
        """Heightmap shape ``(rows, cols)``."""
        return self.depth.shape


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
    is_default = np.all(model.geom_rgba == np.array([0.5, 0.5, 0.5, 1.0], dtype=np.float32), axis=1)
    use_material = (matid >= 0) & is_default
    rgba[use_material] = model.mat_rgba[matid[use_material]]
    return np.round(np.clip(rgba[:, :3], 0.0, 1.0) * 255.0).astype(np.uint8)


def heights_from_world_z(z: np.ndarray, workspace: Workspace) -> np.ndarray:
    """World ``z`` -> float32 heights above the table clipped to ``[0, z_max - z_min]``."""
    return np.clip(np.asarray(z) - workspace.z_min, 0.0, workspace.z_max - workspace.z_min).astype(np.float32)


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
    """Up to 2, fewer when the cores are busy or a worker asked for one thread
    (``MPG_NUM_THREADS`` / ``OMP_NUM_THREADS``, as ``mpg_envs.threads.worker_init`` sets),
    and 1 in a ``multiprocessing`` child (an ``AsyncVectorEnv``/``SubprocVecEnv`` worker)
    unless those variables ask for more: two workers with 2 ray-cast threads each would
    fight over 2 cores."""
    explicit = requested_threads() is not None or os.environ.get("OMP_NUM_THREADS", "").strip()
    if multiprocessing.parent_process() is not None and not explicit:
        return 1
    return max(1, min(2, num_threads()))


class RaycastHeightmapper:
    """Colour/depth heightmaps by ray casting (``mujoco.mj_multiRay``), no OpenGL needed.

    One ray per pixel, all from a common origin ``source_height`` metres above the
    workspace centre, each aimed at its pixel centre on the table plane. Rays from that far
    up are nearly parallel: a surface at height ``h`` is sampled ``h * r / source_height``
    away from the pixel centre, ``r`` being the pixel's distance from the workspace centre
    (at most 0.32 m): 0.016 mm for a 5 cm object at the corner with the default 1000 m.
    That keeps the heightmap consistent with :func:`mpg_envs.perception.footprint.footprint_mask` (pixel-centre
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

    Only the rays under a moving geom's bounding box are cast
    (:mod:`mpg_envs.perception.ray_culling`); every other ray sees only the geoms welded to
    the world (the table), whose result is cast once per process and layout of those geoms
    and kept (with the moving geoms hidden for that one cast). Each ray's result is MuJoCo's
    own, so the heightmaps are the same, bit for bit, as casting every ray (:meth:`cast_all`).

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
            num_threads: threads sharing the rays; default up to 2 (see ``_default_threads``).
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

        self._origin, self._dirs = _ray_directions(self.workspace, self.source_height)
        self._num_rays = self._dirs.shape[0]
        self._vec_z = self._dirs[:, 2]
        # The largest horizontal-to-vertical ratio of the rays: how far they slant.
        self._slant = float(np.max(np.hypot(self._dirs[:, 0], self._dirs[:, 1]) / np.abs(self._dirs[:, 2])))
        visible = self.geomgroup[model.geom_group] > 0
        welded = (model.body_weldid[model.geom_bodyid] == 0) & (model.body_mocapid[model.geom_bodyid] < 0)
        self._static_geoms = np.flatnonzero(visible & welded)
        self._moving_geoms = np.flatnonzero(~welded)  # visible or not now: objects change group when removed
        self._hidden_group = int(np.flatnonzero(self.geomgroup == 0)[0])
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
        -1 and ``world_z`` is NaN where the ray hits nothing. The rays no moving geom can
        reach take the kept result of the static geoms (see the class docstring)."""
        self._check_data(data)
        moving = self._moving_geoms[self.geomgroup[self.model.geom_group[self._moving_geoms]] > 0]
        lo, hi = world_boxes(self.model.geom_aabb[moving], data.geom_xpos[moving], data.geom_xmat[moving])
        ids = np.flatnonzero(pixels_under_boxes(self.workspace, lo, hi, self._slant).ravel())
        static_id, static_dist = self._static_cast(data)
        geom_id, dist = static_id.copy(), static_dist.copy()
        geom_id[ids], dist[ids] = self._cast_rays(data, ids)
        return self._results(geom_id, dist)

    def cast_all(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`cast` with every ray cast against every visible geom (no culling, nothing
        kept): the reference :meth:`cast` equals, bit for bit."""
        self._check_data(data)
        return self._results(*self._cast_rays(data, np.arange(self._num_rays)))

    def _check_data(self, data: mujoco.MjData) -> None:
        if data.geom_xpos.shape[0] != self.model.ngeom:
            raise ValueError(
                f"data belongs to a model with {data.geom_xpos.shape[0]} geoms, this "
                f"heightmapper's model has {self.model.ngeom}: build a new RaycastHeightmapper"
            )

    def _results(self, geom_id: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        world_z = np.where(geom_id >= 0, self._origin[2] + dist * self._vec_z, np.nan)
        return geom_id.reshape(self.workspace.shape), world_z.reshape(self.workspace.shape)

    def _static_cast(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """Every ray against the static geoms alone, kept per process for their layout (ids,
        types, groups, sizes, meshes and height fields, poses, colours' alpha) and the rays."""
        m, g = self.model, self._static_geoms
        shapes = [
            m.mesh_vert[m.mesh_vertadr[k] : m.mesh_vertadr[k] + m.mesh_vertnum[k]]
            for k in m.geom_dataid[g][m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
        ]
        shapes += [
            m.mesh_face[m.mesh_faceadr[k] : m.mesh_faceadr[k] + m.mesh_facenum[k]]
            for k in m.geom_dataid[g][m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
        ]
        shapes += [
            m.hfield_data[m.hfield_adr[k] : m.hfield_adr[k] + m.hfield_nrow[k] * m.hfield_ncol[k]]
            for k in m.geom_dataid[g][m.geom_type[g] == mujoco.mjtGeom.mjGEOM_HFIELD]
        ]
        ray_setup = np.array(
            [
                self.source_height,
                *self.workspace.shape,
                self.workspace.resolution,
                self.workspace.x_min,
                self.workspace.y_min,
                self.workspace.z_min,
            ]
        )
        key = b"".join(
            np.ascontiguousarray(a).tobytes()
            for a in (g, m.geom_type[g], m.geom_group[g], m.geom_size[g], m.geom_aabb[g], m.geom_rgba[g, 3],
                      data.geom_xpos[g], data.geom_xmat[g], *shapes, self._origin, self.geomgroup, ray_setup)
        )  # fmt: skip
        kept = _STATIC_CASTS.get(key)
        if kept is None:
            groups = m.geom_group[self._moving_geoms].copy()
            m.geom_group[self._moving_geoms] = self._hidden_group
            try:
                kept = self._cast_rays(data, np.arange(self._num_rays))
            finally:
                m.geom_group[self._moving_geoms] = groups
            for a in kept:
                a.setflags(write=False)
            if len(_STATIC_CASTS) >= 8:
                _STATIC_CASTS.pop(next(iter(_STATIC_CASTS)))
            _STATIC_CASTS[key] = kept
        return kept

    def _cast_rays(self, data: mujoco.MjData, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(geom_id, dist)`` of the rays ``ids`` (MuJoCo's ``mj_multiRay``, split over the threads)."""
        geom_id = np.empty(ids.size, dtype=np.int32)
        dist = np.empty(ids.size, dtype=np.float64)
        # Cutoff is compared with geom distances from the origin (metres), not with dist.
        cutoff = float(mujoco.mjMAXVAL)
        # Thread k takes every n-th of the rays (image rows come in order): clutter is often
        # bunched in one part of the workspace, and interleaved rays share it evenly.
        parts = [np.arange(k, ids.size, self.num_threads) for k in range(self.num_threads)]

        def run(k: int, d: mujoco.MjData) -> None:
            part = parts[k]
            if part.size == 0:
                return
            vec = self._dirs[ids[part]].reshape(-1).copy()  # contiguous: passed to C without a copy
            part_geom = np.empty(part.size, dtype=np.int32)
            part_dist = np.empty(part.size, dtype=np.float64)
            mujoco.mj_multiRay(
                self.model, d, self._origin, vec, self.geomgroup, 1, -1, part_geom, part_dist, None, part.size, cutoff
            )
            geom_id[part] = part_geom
            dist[part] = part_dist

        # Copy before any ray uses data's stack: mj_copyData refuses a busy stack.
        for scratch in self._scratch:
            mujoco.mj_copyData(scratch, self.model, data)
        futures = [self._pool.submit(run, k, self._scratch[k - 1]) for k in range(1, self.num_threads)] if self._pool else []
        run(0, data)
        for future in futures:
            future.result()
        return geom_id, dist

    def heightmaps(self, data: mujoco.MjData, colors: np.ndarray | None = None) -> Heightmaps:
        """Heightmaps of the current state (``data`` after ``mj_forward`` or a step).

        ``colors``: an ``(ngeom, 3)`` uint8 colour per geom to paint instead of the base
        colours (a visual randomization's); pixels no ray hits keep ``background_color``.
        """
        geom_id, world_z = self.cast(data)
        depth = heights_from_world_z(np.nan_to_num(world_z, nan=self.workspace.z_min), self.workspace)
        palette = self._palette
        if colors is not None:
            colors = np.asarray(colors)
            if colors.shape != (self.model.ngeom, 3) or colors.dtype != np.uint8:
                raise ValueError(f"colors must be a ({self.model.ngeom}, 3) uint8 array, got {colors.shape} {colors.dtype}")
            palette = np.concatenate([colors, self._palette[-1:]])
        return Heightmaps(color=palette[geom_id], depth=depth, geom_id=geom_id)

    def __call__(self, data: mujoco.MjData, colors: np.ndarray | None = None) -> Heightmaps:
        """Same as :meth:`heightmaps`."""
        return self.heightmaps(data, colors)

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
