"""Behaviour cloning's quarter-turn augmentation and sampled rotations, checked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from mpg_agents.imitation.augment import turn_action, turn_planes
from mpg_agents.imitation.bc_loss import sampled_rotations
from mpg_envs.grid.workspace import rotation_direction


def _flat(primitive: int, rotation: int, row: int, col: int, rotations: int = 16, size: int = 5) -> int:
    return ((primitive * rotations + rotation) * size + row) * size + col


def test_a_quarter_turn_moves_the_pixel_as_rot90_and_the_rotation_back_by_a_quarter():
    # 5 x 5 maps: np.rot90 sends (row 1, col 3) to (5 - 1 - 3, 1) = (1, 1); rotation 6 -> 6 - 4 = 2.
    assert turn_action(np.array([_flat(2, 6, 1, 3)]), np.array([1]), 16, 5).tolist() == [_flat(2, 2, 1, 1)]
    # Two turns: (1, 3) -> (1, 1) -> (3, 1); rotation 2 -> 2 - 8 = 10 (mod 16). Four turns: unchanged.
    assert turn_action(np.array([_flat(0, 2, 1, 3)]), np.array([2]), 16, 5).tolist() == [_flat(0, 10, 3, 1)]
    a = np.array([_flat(1, 15, 4, 0), _flat(0, 0, 0, 4)])
    assert turn_action(a, np.array([4, 0]), 16, 5).tolist() == a.tolist()


@pytest.mark.parametrize("rotation", range(16))
def test_the_turned_rotation_points_where_the_turned_image_sends_its_direction(rotation):
    # A direction (d_col, d_row) = (cos, sin) of rotation k; rot90's pixel map (row, col) -> (W-1-col, row)
    # sends a displacement (d_col, d_row) to (d_row, -d_col). The turned action's rotation must point there.
    size = 9
    turned = turn_action(np.array([_flat(0, rotation, 4, 4, size=size)]), np.array([1]), 16, size)[0]
    new_rotation = (turned // (size * size)) % 16
    d_col, d_row = rotation_direction(rotation)
    assert np.allclose(rotation_direction(int(new_rotation)), [d_row, -d_col], atol=1e-9)


def test_planes_turn_with_their_action_and_the_rest_is_kept():
    rng = np.random.default_rng(0)
    depth = rng.random((3, 6, 6)).astype(np.float32)
    color = rng.integers(0, 255, (3, 6, 6, 3), dtype=np.uint8)
    obs = {"depth": depth, "color": color, "occluded": np.array([[0], [1], [0]], dtype=np.int8)}
    turns = np.array([0, 1, 3])
    out = turn_planes(obs, turns)
    for b, t in enumerate(turns):
        assert np.array_equal(out["depth"][b], np.rot90(depth[b], t))
        assert np.array_equal(out["color"][b], np.rot90(color[b], t))
    assert np.array_equal(out["occluded"], obs["occluded"])
    # The value under each action's pixel is the same before and after the turn.
    actions = np.array([_flat(1, r, row, col, size=6) for r, row, col in ((3, 0, 5), (9, 2, 1), (14, 5, 4))])
    moved = turn_action(actions, turns, 16, 6)
    for b in range(3):
        row, col = divmod(int(actions[b] % 36), 6)
        row2, col2 = divmod(int(moved[b] % 36), 6)
        assert out["depth"][b, row2, col2] == depth[b, row, col]


def test_bad_turns_are_named():
    with pytest.raises(ValueError, match="divisible by 4"):
        turn_action(np.array([0]), np.array([1]), 6, 5)
    with pytest.raises(ValueError, match="one turn per action"):
        turn_action(np.array([0, 1]), np.array([1]), 16, 5)
    with pytest.raises(ValueError, match="square"):
        turn_planes({"depth": np.zeros((1, 4, 5))}, np.array([1]))


def test_sampled_rotations_hold_the_recorded_one_first_and_distinct_others():
    rng = np.random.default_rng(3)
    pixels = 4  # 2 x 2 maps, 16 rotations, 3 primitives: a flat action is primitive * 64 + rotation * 4 + pixel
    actions = np.array([2 * 64 + 7 * 4 + 3, 0 * 64 + 0 * 4 + 1])
    rotations, classes = sampled_rotations(rng, actions, 4, 16, pixels)
    assert rotations.shape == (2, 4)
    assert rotations[:, 0].tolist() == [7, 0]
    for row in rotations:
        assert len(set(row.tolist())) == 4 and row.min() >= 0 and row.max() < 16
    # With K = 4 the maps are (primitive, 4, pixel): the recorded rotation is slot 0.
    assert classes.tolist() == [2 * 4 * 4 + 3, 0 * 4 * 4 + 1]
    # K = 1 is the recorded rotation alone; K = 16 every rotation once.
    one, _ = sampled_rotations(rng, actions, 1, 16, pixels)
    assert one.tolist() == [[7], [0]]
    every, _ = sampled_rotations(rng, actions, 16, 16, pixels)
    assert sorted(every[0].tolist()) == list(range(16))
    with pytest.raises(ValueError, match=r"rotations per sample must lie in 1..16"):
        sampled_rotations(rng, actions, 17, 16, pixels)
    with pytest.raises(ValueError, match="flat action indices >= 0"):
        sampled_rotations(rng, np.array([-1]), 2, 16, pixels)
