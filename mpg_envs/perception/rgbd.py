"""RGB-D back-projection: camera images -> colour/depth heightmaps, and fusion of views.

The camera observation path (:mod:`mpg_envs.perception.camera`) renders RGB-D images and goes through
:func:`heightmap_from_rgbd`, which a real RGB-D camera can use as well; several views are
merged with :func:`fuse_heightmaps`. Grid conventions are :mod:`mpg_envs.grid.workspace`'s and
heights are those of :class:`~mpg_envs.perception.heightmap.Heightmaps`.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence

import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.heightmap import Heightmaps


def _check_rgbd(color: np.ndarray, depth: np.ndarray, intrinsics: np.ndarray, cam_pose: np.ndarray) -> None:
    if not isinstance(depth, np.ndarray) or depth.ndim != 2:
        raise ValueError(f"depth must be a (H, W) array, got shape {np.shape(depth)}")
    if not np.issubdtype(depth.dtype, np.floating):
        raise TypeError(
            f"depth must be floating-point metres, got dtype {depth.dtype}; convert raw "
            "sensor units first (e.g. uint16 millimetres: depth.astype(np.float32) * depth_scale)"
        )
    if not isinstance(color, np.ndarray) or color.shape != depth.shape + (3,):
        raise ValueError(f"color must be a (H, W, 3) array matching depth {depth.shape}, got shape {np.shape(color)}")
    if color.dtype != np.uint8:
        raise TypeError(f"color must be uint8 RGB, got dtype {color.dtype}")
    if intrinsics.shape != (3, 3) or not np.all(np.isfinite(intrinsics)):
        raise ValueError(f"intrinsics must be a finite 3x3 pinhole matrix K, got shape {intrinsics.shape}")
    if intrinsics[0, 0] <= 0 or intrinsics[1, 1] <= 0 or not np.allclose(intrinsics[2], [0.0, 0.0, 1.0]):
        raise ValueError(
            f"intrinsics must be [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0, got {intrinsics.tolist()}"
        )
    if cam_pose.shape != (4, 4) or not np.all(np.isfinite(cam_pose)):
        raise ValueError(f"cam_pose must be a finite 4x4 camera-to-world transform, got shape {cam_pose.shape}")
    rot = cam_pose[:3, :3]
    if not np.allclose(cam_pose[3], [0.0, 0.0, 0.0, 1.0]) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-4):
        raise ValueError("cam_pose must be a rigid transform: orthonormal rotation and last row [0, 0, 0, 1]")


@functools.lru_cache(maxsize=16)
def _pixel_rays(intrinsics: bytes, rotation: bytes, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame ray (x, y, z components, each ``(H*W,)``, row-major) of every pixel per metre
    of depth along the optical axis: ``R K^-1 [u, v, 1]`` (handles skew too)."""
    k_inv = np.linalg.inv(np.frombuffer(intrinsics).reshape(3, 3))
    rot = np.frombuffer(rotation).reshape(3, 3)
    v, u = np.indices(shape, dtype=np.float64)
    pix = np.stack([u.ravel(), v.ravel(), np.ones(u.size)])
    rays = rot @ (k_inv @ pix)
    for row in rays:
        row.setflags(write=False)
    return rays[0], rays[1], rays[2]


def heightmap_from_rgbd(
    color: np.ndarray,
    depth: np.ndarray,
    intrinsics: np.ndarray,
    cam_pose: np.ndarray,
    workspace: Workspace | None = None,
    background_color: Sequence[int] = (0, 0, 0),
    segmentation: np.ndarray | None = None,
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
        segmentation: optional ``(H, W)`` integer label image registered to ``depth``
            (a simulator's geom ids, say); each heightmap pixel then carries the label of
            the point it keeps, in ``geom_id`` (-1 where no point lands).

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
    if segmentation is not None and (
        np.shape(segmentation) != depth.shape or not np.issubdtype(np.asarray(segmentation).dtype, np.integer)
    ):
        raise ValueError(
            f"segmentation must be an integer (H, W) array matching depth {depth.shape}, got {np.shape(segmentation)}"
        )
    background = np.asarray(background_color)
    if background.shape != (3,) or np.any(background < 0) or np.any(background > 255):
        raise ValueError(f"background_color must be 3 values in 0..255, got {background_color!r}")

    rows, cols = workspace.shape
    out_depth = np.zeros(rows * cols, dtype=np.float32)
    out_color = np.empty((rows * cols, 3), dtype=np.uint8)
    out_color[:] = background.astype(np.uint8)
    out_label = np.full(rows * cols, -1, dtype=np.int32)

    with np.errstate(invalid="ignore"):
        valid = (np.isfinite(depth) & (depth > 0)).reshape(-1)
    z = np.where(valid, depth.reshape(-1), 0.0).astype(np.float64)
    # World point = camera centre + z * (R K^-1 [u, v, 1]): the per-pixel rays are fixed for a
    # fixed camera, so they are computed once per (K, pose, image size).
    rays = _pixel_rays(intrinsics.tobytes(), cam_pose[:3, :3].tobytes(), depth.shape)
    x, y, height = (cam_pose[axis, 3] + z * rays[axis] for axis in range(3))

    # The epsilon is world_to_pixel's: a point on a pixel edge (up to float error) goes to
    # the pixel that starts there.
    col = np.floor((x - workspace.x_min) / workspace.resolution + 1e-9)
    row = np.floor((y - workspace.y_min) / workspace.resolution + 1e-9)
    height -= workspace.z_min
    keep = valid & (col >= 0) & (col < cols) & (row >= 0) & (row < rows) & (height <= workspace.z_max - workspace.z_min)
    idx = np.flatnonzero(keep)  # the image pixels whose points land in the workspace
    flat = (row[idx] * cols + col[idx]).astype(np.int64)
    height = np.maximum(height[idx], 0.0)
    src = np.arange(idx.size)
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
        pixel = idx[winner[seen]]  # the image pixel of each heightmap pixel's point
        out_color[seen] = color.reshape(-1, 3)[pixel]
        if segmentation is not None:
            out_label[seen] = np.asarray(segmentation).reshape(-1)[pixel]
    labels = out_label.reshape(rows, cols) if segmentation is not None else None
    return Heightmaps(color=out_color.reshape(rows, cols, 3), depth=out_depth.reshape(rows, cols), geom_id=labels)


def fuse_heightmaps(maps: Sequence[Heightmaps]) -> Heightmaps:
    """Per-pixel fusion of several views: each pixel takes the highest reading and its
    colour (and geom id when every input has one); on ties the earliest map wins."""
    maps = list(maps)
    if not maps:
        raise ValueError("fuse_heightmaps needs at least one Heightmaps")
    shape = maps[0].shape
    for i, hm in enumerate(maps):
        if hm.shape != shape:
            raise ValueError(f"all heightmaps must have the same shape; map 0 is {shape}, map {i} is {hm.shape}")
    depths = np.stack([hm.depth for hm in maps])
    best = np.argmax(depths, axis=0)
    r, c = np.indices(shape)
    color = np.stack([hm.color for hm in maps])[best, r, c]
    geom_id = None
    if all(hm.geom_id is not None for hm in maps):
        geom_id = np.stack([hm.geom_id for hm in maps])[best, r, c]  # type: ignore[misc]
    return Heightmaps(color=color, depth=depths[best, r, c], geom_id=geom_id)
