"""The learner's exploration: where random actions land, and the training aids."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from mpg_agents.learning.exploration import PUSH_REACH_PX, Explorer, linear_epsilon
from mpg_agents.acting.decision import Decision
from mpg_agents.network.regions import target_pixels
from mpg_envs.grid.actions import decode_action

PRIMS = ("move", "push", "grasp")


def _obs() -> dict[str, np.ndarray]:
    mask = np.zeros((224, 224), np.uint8)
    mask[100:140, 90:100] = 1  # an L-shaped target
    mask[130:140, 90:130] = 1
    depth = np.where(mask > 0, 0.03, 0.0).astype(np.float32)
    return {"color": np.zeros((224, 224, 3), np.uint8), "depth": depth, "mask": mask, "occluded": np.zeros(1, np.int8)}


def _decision(primitive: str) -> Decision:
    return Decision(0, primitive, 0, 0, 0, 1.0, math.nan, {})


def test_linear_epsilon_anneals_then_holds():
    assert linear_epsilon(0, 0.5, 0.1, 100) == 0.5
    assert math.isclose(linear_epsilon(50, 0.5, 0.1, 100), 0.3)
    assert math.isclose(linear_epsilon(500, 0.5, 0.1, 100), 0.1)


def test_exploratory_pixels_stay_where_the_primitive_can_matter():
    obs = _obs()
    rect = (100, 139, 90, 129)
    for grasp_on_target in (False, True):
        explorer = Explorer(PRIMS, np.random.default_rng(0), grasp_on_target=grasp_on_target)
        for primitive in PRIMS:
            off_target = 0
            for _ in range(200):
                choice = explorer.choose(obs, _decision(primitive), epsilon=1.0, failed_grasps_in_a_row=0)
                a = decode_action(PRIMS, choice.action)
                assert choice.chosen_by == "explore" and a.primitive == primitive
                pad = PUSH_REACH_PX if primitive == "push" else 0
                assert rect[0] - pad <= a.row <= rect[1] + pad and rect[2] - pad <= a.col <= rect[3] + pad
                off_target += int(obs["mask"][a.row, a.col] == 0)
            if primitive == "grasp" and grasp_on_target:
                assert off_target == 0
            elif primitive != "push":
                assert off_target > 0  # the rectangle's empty corner is explored too


def test_exploratory_grasps_keep_to_the_shrunk_target_like_the_network():
    obs = _obs()
    explorer = Explorer(PRIMS, np.random.default_rng(0), grasp_on_target=True, target_margin_px=-3)
    core = target_pixels(torch.from_numpy(obs["mask"][None] > 0), -3)[0].numpy()
    assert 0 < core.sum() < (obs["mask"] > 0).sum()
    for _ in range(100):
        a = decode_action(PRIMS, explorer.choose(obs, _decision("grasp"), epsilon=1.0, failed_grasps_in_a_row=0).action)
        assert core[a.row, a.col]


def test_greedy_and_heuristic_choices():
    obs = _obs()
    explorer = Explorer(PRIMS, np.random.default_rng(0), heuristic_after_failed_grasps=2)
    greedy = explorer.choose(obs, _decision("grasp"), epsilon=0.0, failed_grasps_in_a_row=1)
    assert greedy.chosen_by == "greedy" and greedy.q_value == 1.0
    forced = explorer.choose(obs, _decision("grasp"), epsilon=0.0, failed_grasps_in_a_row=2)
    a = decode_action(PRIMS, forced.action)
    assert forced.chosen_by == "heuristic" and obs["mask"][a.row, a.col] == 1


def test_a_random_primitive_is_one_the_network_has():
    obs = _obs()
    explorer = Explorer(PRIMS, np.random.default_rng(0), random_primitive=True, usable=("push", "grasp"))
    drawn = {explorer.choose(obs, _decision("grasp"), epsilon=1.0, failed_grasps_in_a_row=0).primitive for _ in range(100)}
    assert drawn == {"push", "grasp"}
    with pytest.raises(ValueError, match="usable"):
        Explorer(("grasp",), np.random.default_rng(0), usable=("push",))


def test_exploratory_moves_keep_to_the_footprints_top_like_the_network():
    obs = _obs()
    obs["depth"][130:140, 110:130] = 0.07  # an occluder over the L's foot, 4 cm above it
    explorer = Explorer(PRIMS, np.random.default_rng(0), move_band_m=0.015)
    for _ in range(100):
        a = decode_action(PRIMS, explorer.choose(obs, _decision("move"), epsilon=1.0, failed_grasps_in_a_row=0).action)
        assert 130 <= a.row < 140 and 110 <= a.col < 130


def test_exploratory_grasps_keep_to_where_the_target_shows_like_the_network():
    obs = _obs()
    obs["depth"][130:140, 110:130] = 0.07  # an occluder over the L's foot, 4 cm above it
    explorer = Explorer(PRIMS, np.random.default_rng(0), grasp_on_target=True, visible_band_m=0.01)
    seen = set()
    for _ in range(200):
        a = decode_action(PRIMS, explorer.choose(obs, _decision("grasp"), epsilon=1.0, failed_grasps_in_a_row=0).action)
        assert obs["mask"][a.row, a.col] == 1 and not (130 <= a.row < 140 and 110 <= a.col < 130)
        seen.add((a.row, a.col))
    assert len(seen) > 50
