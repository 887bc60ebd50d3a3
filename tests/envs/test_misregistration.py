"""Heightmaps placed by cameras with a calibration error: hand-checked rigid motions."""

import numpy as np
import pytest

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.heightmap import Heightmaps
from mpg_envs.perception.misregistration import misregistered_heightmaps

WS = Workspace(x_min=0.0, x_max=0.02, y_min=0.0, y_max=0.02, z_min=0.0, z_max=0.4, resolution=0.002)  # 10 x 10
ABOVE = np.array([[0.01, 0.01, 0.85]])  # a camera over the grid's centre (a pixel corner)
ZERO = np.zeros((1, 3))


def scene() -> Heightmaps:
    rng = np.random.default_rng(0)
    depth = rng.uniform(0.0, 0.1, size=(10, 10)).astype(np.float32)
    color = rng.integers(0, 256, size=(10, 10, 3), dtype=np.uint8)
    geom = np.arange(100, dtype=np.int32).reshape(10, 10)
    return Heightmaps(color=color, depth=depth, geom_id=geom)


def test_no_error_gives_the_same_maps():
    maps = scene()
    out = misregistered_heightmaps(maps, WS, ABOVE, ZERO, ZERO)
    np.testing.assert_array_equal(out.color, maps.color)
    np.testing.assert_allclose(out.depth, maps.depth, atol=1e-7)
    np.testing.assert_array_equal(out.geom_id, maps.geom_id)


def test_a_camera_one_pixel_off_in_x_shows_the_scene_one_pixel_back():
    # The true camera sits 2 mm further along +x than calibrated: what it sees at x + 2 mm
    # is placed at x, so pixel column j shows the true column j + 1; the last column is unseen.
    maps = scene()
    out = misregistered_heightmaps(maps, WS, ABOVE, np.array([[0.002, 0.0, 0.0]]), ZERO, background_color=(1, 2, 3))
    np.testing.assert_array_equal(out.geom_id[:, :9], maps.geom_id[:, 1:])
    np.testing.assert_array_equal(out.color[:, :9], maps.color[:, 1:])
    np.testing.assert_allclose(out.depth[:, :9], maps.depth[:, 1:], atol=1e-7)
    assert (out.geom_id[:, 9] == -1).all() and (out.depth[:, 9] == 0).all() and (out.color[:, 9] == (1, 2, 3)).all()


def test_a_camera_higher_than_calibrated_places_everything_lower_down_to_the_table():
    maps = scene()
    out = misregistered_heightmaps(maps, WS, ABOVE, np.array([[0.0, 0.0, 0.01]]), ZERO)
    np.testing.assert_allclose(out.depth, np.maximum(maps.depth - 0.01, 0.0), atol=1e-7)
    np.testing.assert_array_equal(out.geom_id, maps.geom_id)


def test_a_quarter_turn_about_the_camera_turns_the_grid():
    # R = 90 degrees about z at the grid's centre: the pixel at offset (dx, dy) shows the true
    # point at (-dy, dx), i.e. out[i, j] = true[j, 9 - i].
    maps = scene()
    out = misregistered_heightmaps(maps, WS, ABOVE, ZERO, np.array([[0.0, 0.0, np.pi / 2]]))
    i, j = np.meshgrid(np.arange(10), np.arange(10), indexing="ij")
    np.testing.assert_array_equal(out.geom_id, maps.geom_id[j, 9 - i])
    np.testing.assert_allclose(out.depth, maps.depth[j, 9 - i], atol=1e-7)


def test_two_cameras_fuse_by_the_highest_reading():
    depth = np.zeros((10, 10), np.float32)
    depth[5, 5] = 0.05
    geom = np.where(depth > 0, 7, 0).astype(np.int32)
    maps = Heightmaps(color=np.zeros((10, 10, 3), np.uint8), depth=depth, geom_id=geom)
    offsets = np.array([[0.002, 0.0, 0.0], [-0.002, 0.0, 0.0]])
    out = misregistered_heightmaps(maps, WS, np.repeat(ABOVE, 2, axis=0), offsets, np.zeros((2, 3)))
    raised = np.argwhere(out.depth > 0).tolist()
    assert raised == [[5, 4], [5, 6]]  # the bump where each camera places it
    assert out.geom_id[5, 4] == out.geom_id[5, 6] == 7
    # The edge columns are each seen by one camera: nothing is left unseen.
    assert (out.geom_id >= 0).all()


def test_bad_poses_are_refused():
    maps = scene()
    with pytest.raises(ValueError, match="offsets must be a finite"):
        misregistered_heightmaps(maps, WS, ABOVE, np.array([[np.nan, 0, 0]]), ZERO)
    with pytest.raises(ValueError, match="one row per camera"):
        misregistered_heightmaps(maps, WS, ABOVE, np.zeros((2, 3)), ZERO)
    with pytest.raises(ValueError, match="grid"):
        misregistered_heightmaps(maps, Workspace(), ABOVE, ZERO, ZERO)
