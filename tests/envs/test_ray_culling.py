"""Ray culling: which heightmap rays can reach a moving geom, and a cast that uses it gives
MuJoCo's result of every ray, bit for bit.

Pixel ``(row, col)`` covers ``x in [x_min + col * res, x_min + (col + 1) * res)`` and the
same in ``y`` by row (``res = 0.002``, ``x_min = 0.276``, ``y_min = -0.224``)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpg_envs.grid.workspace import Workspace, pixel_to_world
from mpg_envs.perception.heightmap import RaycastHeightmapper
from mpg_envs.perception.ray_culling import pixels_under_boxes, world_boxes
from mpg_envs.simulation.objects import load_object_set
from mpg_envs.simulation.world import World

WS = Workspace()


def test_world_boxes_of_shifted_and_turned_boxes():
    aabb = np.array([[0.0, 0.0, 0.0, 1.0, 2.0, 3.0], [0.5, 0.0, 0.0, 1.0, 2.0, 3.0]])
    quarter_turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 degrees about z
    lo, hi = world_boxes(aabb, [[10.0, 0.0, 0.0], [0.0, 0.0, 1.0]], np.stack([np.eye(3), quarter_turn]).reshape(2, 9))
    np.testing.assert_allclose(lo, [[9.0, -2.0, -3.0], [-2.0, -0.5, -2.0]])  # the turned box: x half 2, y half 1, centre (0, 0.5)
    np.testing.assert_allclose(hi, [[11.0, 2.0, 3.0], [2.0, 1.5, 4.0]])


def test_pixels_under_a_point_box_are_its_cell_and_one_pixel_around():
    x, y = pixel_to_world(WS, 10, 20)  # the centre of pixel (10, 20)
    point = np.array([[x, y, WS.z_min]])
    mask = pixels_under_boxes(WS, point, point, slant=0.0)
    expected = np.zeros(WS.shape, bool)
    expected[9:12, 19:22] = True  # grown by one pixel: the cells meeting [c - res, c + res]
    np.testing.assert_array_equal(mask, expected)


def test_pixels_under_a_box_grow_with_the_rays_slant_at_its_height():
    x, y = pixel_to_world(WS, 10, 20)
    top = np.array([[x, y, WS.z_min + 0.1]])
    # Grown by 1 pixel + slant x 0.1 m: 1.25 pixels (centre 20.5 -> cells 19.25..21.75), then 2 pixels (18.5..22.5).
    np.testing.assert_array_equal(np.argwhere(pixels_under_boxes(WS, top, top, slant=0.005))[[0, -1]], [[9, 19], [11, 21]])
    np.testing.assert_array_equal(np.argwhere(pixels_under_boxes(WS, top, top, slant=0.02))[[0, -1]], [[8, 18], [12, 22]])


def test_no_boxes_or_boxes_off_the_workspace_mark_nothing():
    assert not pixels_under_boxes(WS, np.zeros((0, 3)), np.zeros((0, 3)), 0.0).any()
    far = np.array([[5.0, 5.0, 0.0]])
    assert not pixels_under_boxes(WS, far, far + 0.1, 0.0).any()
    edge = np.array([[WS.x_min - 0.1, WS.y_min - 0.1, 0.0]])  # a box over the corner, clipped to it
    assert pixels_under_boxes(WS, edge, edge + np.array([0.1 + 0.001, 0.1 + 0.001, 0.0]), 0.0).sum() == 2 * 2


@pytest.mark.parametrize("object_set", ["blocks", "random_urdfs_test"])
def test_the_culled_cast_is_every_rays_own_result(object_set):
    assets = load_object_set(object_set)
    rng = np.random.default_rng(3)
    world = World([assets[int(k)] for k in rng.integers(len(assets), size=8)], robot_visual=False)
    for i in range(8):
        angle = 2 * math.pi * i / 8
        world.drop_object(i, WS.center[:2] + 0.04 * np.array([math.cos(angle), math.sin(angle)]), (1.0, 0.0, 0.0, 0.0), max_steps=50)
    world.forward()
    caster = RaycastHeightmapper(world.model, num_threads=2)
    checks = []
    for change in ("piled", "one removed", "one moved"):
        if change == "one removed":
            world.remove_object(2)
        elif change == "one moved":
            world.set_object_pose(0, (WS.x_min + 0.03, WS.y_min + 0.03, 0.2), (0.0, 1.0, 0.0, 0.0))
        world.forward()
        (geom_id, z), (all_id, all_z) = caster.cast(world.data), caster.cast_all(world.data)
        np.testing.assert_array_equal(geom_id, all_id)
        np.testing.assert_array_equal(z, all_z)
        checks.append(int(np.isin(geom_id, np.concatenate(world.object_geom_ids)).sum()))
    assert min(checks) > 500  # the objects were seen each time
