"""RGB-D back-projection onto the heightmap grid and fusion of views, without OpenGL.

Every expected pixel index below is worked out by hand from the ENV.md convention
``row = floor((y + 0.224) / 0.002)``, ``col = floor((x - 0.276) / 0.002)``.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from mpg_envs.grid.workspace import Workspace, world_to_pixel
from mpg_envs.perception.heightmap import Heightmaps
from mpg_envs.perception.rgbd import fuse_heightmaps, heightmap_from_rgbd

WS = Workspace()


def down_pose(x: float, y: float, z: float) -> np.ndarray:
    """OpenCV camera at (x, y, z) looking straight down: image right = world +x, image
    down = world -y, optical axis = world -z."""
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])
    pose[:3, 3] = [x, y, z]
    return pose


def pinhole(f: float, width: int, height: int) -> np.ndarray:
    return np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])


def pixel_squares() -> tuple[np.ndarray, ...]:
    gx, gy = WS.pixel_centers()
    half = WS.resolution / 2
    return gx - half, gx + half, gy - half, gy + half


def test_flat_plane_from_straight_down_camera():
    width, height, f, cam_z, plane_z = 120, 100, 500.0, 0.5, 0.03
    depth = np.full((height, width), cam_z - plane_z, dtype=np.float32)
    color = np.zeros((height, width, 3), dtype=np.uint8)
    color[:, :60] = [255, 0, 0]  # image left half (world x < 0.5) red
    color[:, 60:] = [0, 0, 255]  # right half blue
    maps = heightmap_from_rgbd(
        color, depth, pinhole(f, width, height), down_pose(0.5, 0.0, cam_z), WS, background_color=(7, 7, 7)
    )
    assert maps.geom_id is None

    # The imaged rectangle: u in [0, 119] -> x = 0.5 + (u - 59.5) / 500 * 0.47 (1 sample
    # per 0.94 mm), likewise v -> y = -(v - 49.5) / 500 * 0.47.
    x_lo, x_hi = 0.5 - 59.5 / f * 0.47, 0.5 + 59.5 / f * 0.47
    y_lo, y_hi = -49.5 / f * 0.47, 49.5 / f * 0.47
    px0, px1, py0, py1 = pixel_squares()
    in_view = (px0 >= x_lo) & (px1 <= x_hi) & (py0 >= y_lo) & (py1 <= y_hi)
    out_view = (px1 < x_lo) | (px0 > x_hi) | (py1 < y_lo) | (py0 > y_hi)
    assert in_view.sum() > 2000
    np.testing.assert_allclose(maps.depth[in_view], plane_z, atol=1e-6)
    assert np.all(maps.depth[out_view] == 0.0)
    assert np.all(maps.color[out_view] == 7)
    # Red left of x = 0.5 (cols <= 111), blue right of it (cols >= 112).
    cols = np.broadcast_to(np.arange(224), (224, 224))
    assert np.all(maps.color[in_view & (cols <= 111)] == [255, 0, 0])
    assert np.all(maps.color[in_view & (cols >= 112)] == [0, 0, 255])

    again = heightmap_from_rgbd(
        color, depth, pinhole(f, width, height), down_pose(0.5, 0.0, cam_z), WS, background_color=(7, 7, 7)
    )
    np.testing.assert_array_equal(maps.depth, again.depth)
    np.testing.assert_array_equal(maps.color, again.color)


def test_points_outside_workspace_are_dropped():
    # Camera over the +x edge: the image spans x = 0.73 +- 59.5 / 500 * 0.5, i.e.
    # [0.6705, 0.7895]; x > 0.724 is outside.
    width, height, f = 120, 100, 500.0
    depth = np.full((height, width), 0.5, dtype=np.float32)
    color = np.full((height, width, 3), 200, dtype=np.uint8)
    maps = heightmap_from_rgbd(color, depth, pinhole(f, width, height), down_pose(0.73, 0.0, 0.5), WS)
    filled_cols = np.flatnonzero((maps.color != 0).any(axis=2).any(axis=0))
    # Nothing wrapped round into low columns; the last column (x in [0.722, 0.724)) is used.
    assert filled_cols.min() == math.floor((0.6705 - 0.276) / 0.002) == 197
    assert filled_cols.max() == 223

    # Above z_max: dropped; below the table: kept at height 0 with its colour.
    one = np.full((1, 2), 0.0, dtype=np.float32)
    one[0, 0] = 0.05  # z = 0.45 > 0.4
    one[0, 1] = 0.52  # z = -0.02
    rgb = np.array([[[10, 20, 30], [40, 50, 60]]], dtype=np.uint8)
    maps = heightmap_from_rgbd(rgb, one, pinhole(1e4, 2, 1), down_pose(0.5011, 0.0011, 0.5), WS)
    r, c = world_to_pixel(WS, 0.5011, 0.0011)
    assert np.count_nonzero(maps.color.any(axis=2)) == 1
    assert maps.depth[r, c] == 0.0
    np.testing.assert_array_equal(maps.color[r, c], [40, 50, 60])


def test_invalid_depth_is_ignored():
    width, height, f = 120, 100, 500.0
    depth = np.full((height, width), 0.47, dtype=np.float32)
    depth[:, :30] = np.nan
    depth[:, 30:60] = np.inf
    depth[:50, 60:90] = 0.0
    depth[50:, 60:90] = -1.0
    color = np.full((height, width, 3), 99, dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        maps = heightmap_from_rgbd(color, depth, pinhole(f, width, height), down_pose(0.5, 0.0, 0.5), WS)
    # Only u in [90, 119] is valid: x from 0.5 + 30.5 / 500 * 0.47 = 0.5287 on.
    cols = np.flatnonzero(maps.depth.any(axis=0))
    assert cols.min() == math.floor((0.5 + 30.5 / f * 0.47 - 0.276) / 0.002)
    np.testing.assert_allclose(maps.depth[maps.depth > 0], 0.03, atol=1e-6)


def test_highest_point_wins_each_pixel():
    # Two image pixels 0.1 mm apart fall in the same heightmap pixel.
    intrinsics, pose = pinhole(1e4, 2, 1), down_pose(0.5011, 0.0011, 1.0)
    rgb = np.array([[[255, 0, 0], [0, 255, 0]]], dtype=np.uint8)
    r, c = world_to_pixel(WS, 0.5011, 0.0011)
    for depths, winner in (([0.98, 0.99], 0), ([0.99, 0.98], 1), ([0.98, 0.98], 1)):
        maps = heightmap_from_rgbd(rgb, np.array([depths], dtype=np.float32), intrinsics, pose, WS)
        assert maps.depth[r, c] == pytest.approx(0.02, abs=1e-6)
        np.testing.assert_array_equal(maps.color[r, c], rgb[0, winner])
        assert np.count_nonzero(maps.depth) == 1


def test_rgbd_input_errors_name_the_problem():
    color = np.zeros((4, 5, 3), dtype=np.uint8)
    depth = np.ones((4, 5), dtype=np.float32)
    k, pose = pinhole(100.0, 5, 4), down_pose(0.5, 0.0, 1.0)
    with pytest.raises(ValueError, match="color"):
        heightmap_from_rgbd(color[:, :4], depth, k, pose)
    with pytest.raises(TypeError, match="color"):
        heightmap_from_rgbd(color.astype(np.float32), depth, k, pose)
    with pytest.raises(TypeError, match="depth_scale"):
        heightmap_from_rgbd(color, depth.astype(np.uint16), k, pose)
    with pytest.raises(ValueError, match="depth"):
        heightmap_from_rgbd(color, depth[None], k, pose)
    with pytest.raises(ValueError, match="intrinsics"):
        heightmap_from_rgbd(color, depth, k[:2], pose)
    with pytest.raises(ValueError, match="cam_pose"):
        heightmap_from_rgbd(color, depth, k, pose[:3])
    bad = pose.copy()
    bad[:3, :3] *= 2
    with pytest.raises(ValueError, match="rigid"):
        heightmap_from_rgbd(color, depth, k, bad)


def test_fuse_takes_per_pixel_max():
    shape = (2, 3)
    a = Heightmaps(
        color=np.full(shape + (3,), 1, np.uint8),
        depth=np.array([[0.1, 0.0, 0.3], [0.2, 0.2, 0.0]], np.float32),
        geom_id=np.full(shape, 1, np.int32),
    )
    b = Heightmaps(
        color=np.full(shape + (3,), 2, np.uint8),
        depth=np.array([[0.2, 0.0, 0.1], [0.2, 0.3, 0.0]], np.float32),
        geom_id=np.full(shape, 2, np.int32),
    )
    fused = fuse_heightmaps([a, b])
    np.testing.assert_array_equal(fused.depth, np.array([[0.2, 0.0, 0.3], [0.2, 0.3, 0.0]], np.float32))
    np.testing.assert_array_equal(fused.color[..., 0], [[2, 1, 1], [1, 2, 1]])  # ties -> first map
    np.testing.assert_array_equal(fused.geom_id, [[2, 1, 1], [1, 2, 1]])
    assert fuse_heightmaps([a, Heightmaps(color=b.color, depth=b.depth)]).geom_id is None
    with pytest.raises(ValueError, match="at least one"):
        fuse_heightmaps([])
    small = Heightmaps(color=np.zeros((1, 1, 3), np.uint8), depth=np.zeros((1, 1), np.float32))
    with pytest.raises(ValueError, match="same shape"):
        fuse_heightmaps([a, small])
    with pytest.raises(ValueError, match="float32"):
        Heightmaps(color=a.color, depth=a.depth.astype(np.float64))
