"""A heightmap as cameras with a calibration error would give it (pure geometry).

A camera whose true pose is its calibrated one moved by ``offset`` and turned about its centre
by ``rotvec`` (:func:`~mpg_envs.perception.appearance.perturbed_pose`) sees a world point ``P``
and back-projects it, with the calibrated pose, to ``P' = R^T (P - c - t) + c`` (``c`` the
calibrated centre, ``t`` the offset, ``R`` the rotation): the whole scene appears moved by that
rigid motion. For 1 cm and 1 degree at the overhead camera's 0.85 m that moves the image up to
about 2.5 cm (12 pixels) against the target mask, which comes from the true state.

:func:`misregistered_heightmaps` gives a ray-cast heightmap that misregistration: each camera's
view is the heightmap looked up through its own rigid motion (nearest pixel), its heights
moved with it, and the views are fused by the highest reading, as the camera path fuses its
cameras. Occlusion between views is not modelled: it is the placement error, not the
rendering, that a policy trained on ray casts has to meet.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.heightmap import Heightmaps


def _check_poses(centres: np.ndarray, offsets: np.ndarray, rotvecs: np.ndarray) -> None:
    for name, value in (("centres", centres), ("offsets", offsets), ("rotvecs", rotvecs)):
        if value.ndim != 2 or value.shape[1] != 3 or not np.all(np.isfinite(value)):
            raise ValueError(f"{name} must be a finite (K, 3) array, got shape {value.shape}")
    if not (len(centres) == len(offsets) == len(rotvecs) >= 1):
        raise ValueError(
            "centres, offsets and rotvecs need one row per camera (at least "
            f"one), got {len(centres)}, {len(offsets)}, {len(rotvecs)}"
        )


def misregistered_heightmaps(
    maps: Heightmaps,
    workspace: Workspace,
    centres: np.ndarray,
    offsets: np.ndarray,
    rotvecs: np.ndarray,
    background_color: tuple[int, int, int] = (0, 0, 0),
) -> Heightmaps:
    """``maps`` as ``K`` cameras with these calibration errors would place them.

    Args:
        maps: a heightmap of the true state (ray cast).
        workspace: its grid.
        centres: ``(K, 3)`` calibrated camera centres, world metres.
        offsets: ``(K, 3)`` true minus calibrated position, metres.
        rotvecs: ``(K, 3)`` world-frame rotation vectors (radians) from the calibrated to the
            true orientation.
        background_color: the colour of pixels that no camera's view covers (they read height
            0 and geom -1, as the camera path's unseen pixels).

    Returns:
        The fused heightmaps: at each pixel the highest of the cameras' readings (the first
        camera on ties), with its colour and geom id.

    Raises:
        ValueError: a pose array that is not ``(K, 3)`` and finite, or ``maps`` not on the
            workspace's grid.
    """
    centres, offsets, rotvecs = (np.asarray(a, dtype=np.float64) for a in (centres, offsets, rotvecs))
    _check_poses(centres, offsets, rotvecs)
    rows, cols = workspace.shape
    if maps.depth.shape != (rows, cols):
        raise ValueError(f"maps are {maps.depth.shape}, the workspace's grid is {(rows, cols)}")
    gx, gy = workspace.pixel_centers()
    query = np.stack([gx, gy, np.full_like(gx, workspace.z_min)], axis=-1).reshape(-1, 3)
    height_cap = workspace.z_max - workspace.z_min
    best = np.full(rows * cols, -np.inf)
    source = np.full(rows * cols, -1, dtype=np.int64)
    for c, t, r in zip(centres, offsets, rotvecs):
        rot = Rotation.from_rotvec(r).as_matrix()
        # The true point each pixel shows: P = R (Q - c) + c + t, looked up at table height
        # (an object's height moves the lookup by well under a pixel at these errors).
        seen = (query - c) @ rot.T + c + t
        col = np.floor((seen[:, 0] - workspace.x_min) / workspace.resolution).astype(np.int64)
        row = np.floor((seen[:, 1] - workspace.y_min) / workspace.resolution).astype(np.int64)
        inside = (col >= 0) & (col < cols) & (row >= 0) & (row < rows)
        flat = np.where(inside, row * cols + col, 0)
        point = seen.copy()
        point[:, 2] = maps.depth.reshape(-1)[flat] + workspace.z_min
        # ... and the height it is placed at: P' = R^T (P - c - t) + c.
        height = ((point - c - t) @ rot)[:, 2] + c[2] - workspace.z_min
        keep = inside & (height <= height_cap)
        height = np.maximum(height, 0.0)
        better = keep & (height > best)
        best[better] = height[better]
        source[better] = flat[better]
    seen_any = source >= 0
    color = np.empty((rows * cols, 3), dtype=np.uint8)
    color[:] = np.asarray(background_color, dtype=np.uint8)
    color[seen_any] = maps.color.reshape(-1, 3)[source[seen_any]]
    depth = np.where(seen_any, best, 0.0).astype(np.float32)
    geom_id: np.ndarray | None = None
    if maps.geom_id is not None:
        geom_id = np.full(rows * cols, -1, dtype=np.int32)
        geom_id[seen_any] = maps.geom_id.reshape(-1)[source[seen_any]]
        geom_id = geom_id.reshape(rows, cols)
    return Heightmaps(color=color.reshape(rows, cols, 3), depth=depth.reshape(rows, cols), geom_id=geom_id)
