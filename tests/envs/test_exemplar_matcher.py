"""The matching heuristic (mpg_envs.policies.exemplar_matcher): its pure parts by hand, and on
exemplar envs."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.perception.exemplar_match import (
    MatchSettings,
    colour_gap,
    colour_match,
    find_blobs,
    height_steps,
    heights,
    lab_colours,
    object_extents,
    pose_fit,
    pose_table,
    query_model,
    shape_score,
)
from mpg_envs.policies.exemplar_matcher import ExemplarMatcher, free_grasp
from mpg_envs.policies.policy import Policy

RES = 0.002


def box_image(rows: slice, cols: slice, shape=(40, 40)) -> np.ndarray:
    image = np.zeros(shape, dtype=bool)
    image[rows, cols] = True
    return image


def test_extents_of_a_drawn_rectangle_are_its_sides_and_height():
    # 10 x 25 pixels of 2 mm: a 2 cm x 5 cm footprint, 3 cm high.
    extents = object_extents(box_image(slice(5, 15), slice(5, 30)), 0.03, RES)
    assert extents == pytest.approx([0.02, 0.03, 0.05])


def test_shape_score_by_hand():
    extents = np.array([0.03, 0.05, 0.07])
    config = MatchSettings()
    assert shape_score(0.03, np.array([0.07, 0.05]), extents, config) == pytest.approx(1.0)  # lying flat
    assert shape_score(0.07, np.array([0.05, 0.03]), extents, config) == pytest.approx(1.0)  # standing on its end
    # Half of the footprint shows: the cover halves the score; judged partial, it does not count.
    assert shape_score(0.03, np.array([0.07, 0.025]), extents, config) == pytest.approx(0.5)
    assert shape_score(0.03, np.array([0.07, 0.025]), extents, config, partial=True) == pytest.approx(1.0)
    # One extent_tolerance too long: the fit is exp(-1/2); one height_sigma off: likewise.
    assert shape_score(0.03, np.array([0.07 + config.extent_tolerance, 0.05]), extents, config) == pytest.approx(
        math.exp(-0.5)
    )
    # (Standing the 5 cm extent up instead: 2.3 sigma off, and 5 cm of footprint on a 3 cm side.)
    assert shape_score(0.03 + config.height_sigma, np.array([0.07, 0.05]), extents, config) == pytest.approx(math.exp(-0.5))
    # A disc of 5.3 cm lying flat is no 3 x 5 x 7 cm box: too wide for the 5 cm side.
    assert shape_score(0.028, np.array([0.053, 0.053]), extents, config) < 0.75


def test_height_steps_mark_both_sides_of_a_step():
    up = np.zeros((5, 6), np.float32)
    up[:, 3:] = 0.03
    steps = height_steps(up, 0.006)
    assert steps[:, 2].all() and steps[:, 3].all() and not steps[:, [0, 1, 4, 5]].any()


def test_colour_match_and_the_table_level():
    color = np.zeros((4, 4, 3), np.uint8)
    color[:2] = (225, 87, 89)  # red
    color[2:] = (242, 142, 43)  # orange
    reference, _ = query_model(color, np.pad(np.full((2, 4), 0.05, np.float32), ((0, 2), (0, 0))), RES)
    assert colour_match(color, reference, 14.0).tolist() == [[True] * 4] * 2 + [[False] * 4] * 2
    depth = np.full((10, 10), 0.005, np.float32)  # a camera's table, 5 mm up
    depth[:3, :3] = 0.035
    assert heights(depth)[0, 0] == pytest.approx(0.03) and heights(depth)[9, 9] == 0


def test_colour_gap_by_hand_and_blobs_from_what_a_caller_worked_out_are_the_same():
    lab = np.array([[[50.0, 128.0, 128.0], [53.0, 132.0, 128.0]]], np.float32)
    assert colour_gap(lab, np.array([50.0, 128.0, 128.0])).tolist() == [[0.0, 5.0]]  # a 3-4-5 triangle
    rng = np.random.default_rng(3)
    color = np.full((60, 60, 3), 90, np.uint8)
    depth = np.zeros((60, 60), np.float32)
    for rows, cols, height in (
        (slice(5, 15), slice(5, 30), 0.03),
        (slice(30, 50), slice(30, 40), 0.05),
        (slice(40, 58), slice(2, 12), 0.03),
    ):
        color[rows, cols] = (89, 161, 79)
        depth[rows, cols] = height
    color[8:11, 8:12] = (225, 87, 89)  # another colour on the first box
    depth[8:11, 8:12] = 0.045
    depth += rng.uniform(0, 0.001, depth.shape).astype(np.float32)
    query_color, query_depth = np.full((60, 60, 3), 90, np.uint8), np.zeros((60, 60), np.float32)
    query_color[20:30, 20:45], query_depth[20:30, 20:45] = (89, 161, 79), 0.03
    model = query_model(query_color, query_depth, RES)
    plain = find_blobs(color, depth, query_color, query_depth, RES)
    given = find_blobs(color, depth, np.zeros(0), np.zeros(0), RES, model=model, gap=colour_gap(lab_colours(color), model[0]))
    assert len(plain) == 3 and len(given) == len(plain)
    for a, b in zip(plain, given):
        assert np.array_equal(a.pixels, b.pixels) and (a.score, a.covered, a.height, a.top) == (
            b.score,
            b.covered,
            b.height,
            b.top,
        )
    assert plain[0].score > 0.9 and not plain[0].covered  # the unmarked 10 x 25 box of 3 cm


def test_the_poses_of_a_box_seen_from_above_by_hand():
    table = pose_table([0.03, 0.05, 0.075])
    assert table.shape == (6 * 10 * 10, 3)  # extents to axes, then 10 x 10 tilts
    assert any(np.allclose(row, [0.05, 0.03, 0.075]) for row in table)  # standing on its smallest face
    assert any(np.allclose(row, [0.075, 0.05, 0.03]) for row in table)  # lying flat
    cube = pose_table([0.05, 0.05, 0.05])
    half_turn = 0.05 * math.sqrt(2)  # tilted 45 degrees about one axis: an edge up, two faces seen
    assert any(np.allclose(row, [half_turn, 0.05, half_turn]) for row in cube)
    assert cube[:, 1].min() == pytest.approx(0.05) and cube[:, 2].min() == pytest.approx(0.05)  # never thinner, never lower
    assert pose_fit([0.075, 0.05], 0.03, table) == pytest.approx(1.0)
    assert pose_fit([0.05, 0.05], 0.05, cube, side_sigma=0.006) == pytest.approx(1.0)
    assert pose_fit([0.05, 0.05 - 0.006], 0.05, cube, side_sigma=0.006) == pytest.approx(math.exp(-0.5))  # one sigma short
    assert pose_fit([0.05, 0.05], 0.038, cube, height_sigma=0.006) == pytest.approx(math.exp(-2.0))  # two sigmas low


def test_query_model_reads_the_object():
    color = np.full((40, 40, 3), 90, np.uint8)
    depth = np.zeros((40, 40), np.float32)
    color[10:20, 5:30] = (89, 161, 79)
    depth[10:20, 5:30] = 0.03
    colour, extents = query_model(color, depth, RES)
    assert extents == pytest.approx([0.02, 0.03, 0.05])
    with pytest.raises(ValueError, match="the query shows no object above the table"):
        query_model(color, np.zeros((40, 40), np.float32), RES)


def test_free_grasp_takes_the_least_blocked_angle_and_avoids_tried_ones():
    pixels = box_image(slice(10, 20), slice(10, 20))
    blocked = np.full((16, 40, 40), 0.02, np.float32)
    blocked[3] = -0.01
    blocked[6] = 0.0
    rotation, row, col, height = free_grasp(pixels, blocked)
    assert rotation == 3 and height == pytest.approx(-0.01) and pixels[row, col]
    assert free_grasp(pixels, blocked, avoid=[3])[0] == 6  # 2, 3, 4 are taken last
    assert free_grasp(pixels, blocked, avoid=[2])[0] == 6


def test_the_matcher_needs_an_exemplar_env(make_env):
    with pytest.raises(ValueError, match="needs an exemplar .* target_spec='exemplar'"):
        ExemplarMatcher(make_env("MPG-OccludedHard-v0", wrapped=True))
    with pytest.raises(ValueError, match="target_spec='exemplar' needs a target"):
        make_env("MPG-Stage1-v0", target_spec="exemplar")


def test_the_matcher_takes_an_isolated_target_among_look_alikes(make_env):
    env = make_env("MPG-Stage2-v0", wrapped=True, target_spec="exemplar")
    matcher = ExemplarMatcher(env)
    obs, info = env.reset(seed=2)
    assert info["lookalikes"]["colour"] >= 1
    obs, reward, terminated, truncated, info = env.step(matcher.act(obs))
    assert info["target_grasped"] and matcher.last_plan["kind"] == "grasp_match"


def test_the_matcher_uncovers_a_covered_target_first(make_env):
    env = make_env("MPG-OccludedHardExemplar-v0", wrapped=True)
    matcher = ExemplarMatcher(env)
    obs, info = env.reset(seed=500000)
    action = matcher.act(obs)
    assert env.action_space.contains(action)
    assert matcher.last_plan["kind"] in ("uncover", "dig") and env.unwrapped.action_space.decode(action).primitive == "move"
    matcher.reset()
    assert matcher.last_plan is None and len(matcher.memory) == 0


def test_the_matcher_is_a_policy():
    env = gym.make("MPG-OccludedHardExemplar-v0")
    assert isinstance(ExemplarMatcher(env), Policy)
    env.close()
