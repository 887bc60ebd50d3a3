"""Free space on the table (``mpg_envs.simulation.free_space``): hand-checked footprints and heights,
and the spot a moved object is put down."""

import numpy as np
import pytest
from conftest import flat_quat

from mpg_envs.simulation.free_space import clutter_height, disc_offsets, free_spot
from mpg_envs.simulation.world import World


def test_disc_offsets_are_the_pixels_within_the_radius():
    assert sorted(map(tuple, disc_offsets(0.01, 0.01).tolist())) == [(-1, 0), (0, -1), (0, 0), (0, 1), (1, 0)]
    assert disc_offsets(0.001, 0.01).tolist() == [[-1, 0], [0, -1], [0, 0], [0, 1], [1, 0]]  # rounded up to a pixel
    assert len(disc_offsets(0.02, 0.01)) == 13  # r = 2: 5 + 4 + 4 pixels


def test_clutter_height_is_the_highest_point_under_the_footprint():
    depth = np.zeros((5, 5))
    depth[0, 2], depth[2, 4], depth[1, 1] = 0.3, 0.2, 0.9
    offsets = disc_offsets(0.01, 0.01)  # the pixel and its four neighbours
    assert clutter_height(depth, 2, 3, offsets) == pytest.approx(0.2)  # (2, 4) is a neighbour; (1, 1) is not
    assert clutter_height(depth, 0, 2, offsets) == pytest.approx(0.3)
    assert clutter_height(depth, 4, 0, offsets) == 0.0
    assert clutter_height(depth, 0, 0, offsets) == 0.0  # past the edge reads the edge, nothing raised


def test_free_spot_is_the_most_open_place_clear_of_the_target(blocks):
    world = World([blocks["cube"], blocks["cube"]])
    ws = world.workspace
    centre = ((ws.x_min + ws.x_max) / 2, (ws.y_min + ws.y_max) / 2)
    world.set_object_pose(1, (0.9, 0.0, 0.1), flat_quat())  # the held one, wherever it is
    world.set_object_pose(0, (*centre, 0.025), flat_quat())
    world.forward()
    x, y = free_spot(world, 1, None, 0.02, 0.06)
    assert np.hypot(x - centre[0], y - centre[1]) > 0.1  # away from the other cube
    assert ws.x_min < x < ws.x_max and ws.y_min < y < ws.y_max
    assert free_spot(world, 1, None, 0.5, 0.06) is None  # a margin nothing in the workspace leaves
    assert free_spot(world, 1, 0, 0.02, 0.3) is None  # no open spot that far from the target either
    alone = free_spot(world, 0, None, 0.02, 0.06)  # nothing else on the table: the workspace's middle
    assert alone == pytest.approx(centre, abs=ws.resolution)
    assert np.hypot(alone[0] - centre[0], alone[1] - centre[1]) <= ws.resolution
