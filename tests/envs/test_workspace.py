"""Pure geometry: pixel <-> world, rotations, action encoding."""

import math

import numpy as np
import pytest

from mpg_envs.grid.actions import HEIGHTMAP_SIZE, PixelActionSpace, action_space_size, decode_action, encode_action
from mpg_envs.grid.workspace import (
    Workspace,
    check_pixel,
    pixel_to_world,
    rotation_angle,
    rotation_direction,
    world_to_pixel,
)

WS = Workspace()


def test_default_grid_is_224_at_2mm():
    assert WS.shape == (224, 224)
    assert WS.resolution == 0.002


def test_the_action_codec_reads_its_grid_side_from_the_workspace():
    assert HEIGHTMAP_SIZE == WS.shape[0] == 224 and isinstance(HEIGHTMAP_SIZE, int)
    assert action_space_size(("push", "grasp")) == 2 * 16 * 224 * 224


def test_pixel_corners_hand_checked():
    # Pixel (0, 0) covers x in [0.276, 0.278), y in [-0.224, -0.222): its centre is +1 mm.
    assert pixel_to_world(WS, 0, 0) == pytest.approx((0.277, -0.223))
    assert pixel_to_world(WS, 223, 223) == pytest.approx((0.723, 0.223))
    # Rows follow y, columns follow x.
    assert world_to_pixel(WS, 0.5, 0.0) == (112, 112)
    assert world_to_pixel(WS, 0.2771, -0.2229) == (0, 0)
    assert world_to_pixel(WS, 0.7239, -0.2229) == (0, 223)


def test_pixel_world_round_trip_every_pixel():
    rows, cols = np.mgrid[0:224, 0:224]
    for r, c in zip(rows.ravel()[::97], cols.ravel()[::97]):
        x, y = pixel_to_world(WS, int(r), int(c))
        assert world_to_pixel(WS, x, y) == (r, c)


def test_rotations_are_22_5_degrees_from_plus_x_toward_plus_y():
    assert rotation_angle(4) == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(rotation_direction(0), [1, 0], atol=1e-12)
    np.testing.assert_allclose(rotation_direction(4), [0, 1], atol=1e-12)
    np.testing.assert_allclose(rotation_direction(2), [math.sqrt(0.5)] * 2, atol=1e-12)


@pytest.mark.parametrize("bad", [-1, 224, 1.5, "3", True])
def test_bad_pixel_names_the_range(bad):
    with pytest.raises(ValueError, match=r"0\.\.223"):
        check_pixel(WS, bad, 0)


@pytest.mark.parametrize("bad", [-1, 16, 2.0])
def test_bad_rotation_names_the_range(bad):
    with pytest.raises(ValueError, match=r"0\.\.15"):
        rotation_angle(bad)


def test_action_round_trip_and_order():
    prims = ("move", "push", "grasp")
    assert action_space_size(prims) == 3 * 16 * 224 * 224
    assert encode_action(prims, "move", 0, 0, 0) == 0
    assert encode_action(prims, "move", 0, 0, 1) == 1
    assert encode_action(prims, "move", 0, 1, 0) == 224
    assert encode_action(prims, "push", 0, 0, 0) == 16 * 224 * 224
    for idx in [0, 12345, 3 * 16 * 224 * 224 - 1]:
        a = decode_action(prims, idx)
        assert encode_action(prims, *a) == idx
    assert decode_action(("push", "grasp"), np.int64(16 * 224 * 224 + 5)) == ("grasp", 0, 0, 5)


@pytest.mark.parametrize(
    "prims, action, match",
    [
        (("grasp",), 16 * 224 * 224, r"0\.\.802815"),
        (("grasp",), -1, r"0\.\.802815"),
        (("grasp",), 3.0, "integer"),
        (("grasp",), np.array([1, 2]), "single integer"),
    ],
)
def test_malformed_action_raises(prims, action, match):
    with pytest.raises(ValueError, match=match):
        decode_action(prims, action)


def test_disallowed_primitive_and_bad_lists():
    with pytest.raises(ValueError, match="not allowed"):
        encode_action(("grasp",), "push", 0, 0, 0)
    with pytest.raises(ValueError, match="subset"):
        encode_action(("poke",), "poke", 0, 0, 0)
    with pytest.raises(ValueError, match="order"):
        PixelActionSpace(("grasp", "move"))


def test_pixel_action_space_is_a_discrete():
    import gymnasium as gym

    space = PixelActionSpace(("push", "grasp"))
    assert isinstance(space, gym.spaces.Discrete) and space.n == 2 * 16 * 224 * 224
    assert space.decode(space.encode("grasp", 3, 4, 5)) == ("grasp", 3, 4, 5)
