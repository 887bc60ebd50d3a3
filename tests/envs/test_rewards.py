"""Rewards on constructed outcomes and in the envs, and the occlusion and change tests they read."""

import cv2
import numpy as np
import pytest

from mpg_envs.perception.occlusion import change_detected, is_occluded
from mpg_envs.policies.oracle import OraclePolicy
from mpg_envs.tasks.rewards import RewardConfig, StepOutcome, reward_grasp_any, reward_grasp_target, reward_move, reward_push

def test_reward_equations_on_constructed_cases():
    o = StepOutcome
    assert reward_grasp_any(o("grasp", lifted=True)) == 1.0
    assert reward_grasp_any(o("grasp")) == 0.0
    assert reward_grasp_target(o("grasp", lifted=True, target_grasped=False)) == 0.0  # wrong grasp
    assert reward_grasp_target(o("grasp", lifted=True, target_grasped=True)) == 1.0
    assert reward_move(o("move", move_success=True, change_detected=True)) == 1.0
    assert reward_move(o("move", change_detected=True, grasp_q_gain=0.6)) == 0.5
    assert reward_move(o("move", change_detected=True, grasp_q_gain=0.4)) == 0.0
    assert reward_move(o("move", change_detected=False)) == -0.5
    assert reward_move(o("move", target_grasped=True, change_detected=True)) == -0.5
    # With move_needs_lift, a move whose fingers held nothing is a failed move, whatever it nudged.
    lift = RewardConfig(move_needs_lift=True)
    assert reward_move(o("move", move_success=True, change_detected=True), lift) == -0.5
    assert reward_move(o("move", change_detected=True, grasp_q_gain=0.6), lift) == -0.5
    assert reward_move(o("move", lifted=True, move_success=True, change_detected=True), lift) == 1.0
    assert reward_move(o("move", lifted=True, change_detected=True, grasp_q_gain=0.6), lift) == 0.5
    # With move_visible_gain, a move that uncovers part of the target pays as a grasp-Q gain does.
    seen = RewardConfig(move_visible_gain=0.1)
    assert reward_move(o("move", change_detected=True, visible_gain=0.1), seen) == 0.5
    assert reward_move(o("move", change_detected=True, visible_gain=0.09), seen) == 0.0
    assert reward_move(o("move", change_detected=True, visible_gain=0.5)) == 0.0  # off by default
    assert reward_move(o("move", change_detected=False, visible_gain=0.5), seen) == -0.5
    assert reward_move(o("move", move_success=True, change_detected=True, visible_gain=0.5), seen) == 1.0
    assert reward_push(o("push", change_detected=True, grasp_q_gain=0.2)) == 0.5
    assert reward_push(o("push", change_detected=True, grasp_q_gain=0.05)) == 0.0
    assert reward_push(o("push", change_detected=False, grasp_q_gain=0.9)) == -0.5
    # A push while the target is covered, paid as a move with push_uncovers (R_p otherwise).
    cover = RewardConfig(push_uncovers=True)
    assert reward_push(o("push", change_detected=True, covered_before=True, cleared=True), cover) == 1.0
    assert reward_push(o("push", change_detected=True, covered_before=True, cleared=True)) == 0.0
    assert reward_push(o("push", change_detected=True, covered_before=True, grasp_q_gain=0.2), cover) == 0.0  # R_m's 0.5 bar
    assert reward_push(o("push", change_detected=True, covered_before=True, grasp_q_gain=0.6), cover) == 0.5
    assert reward_push(o("push", change_detected=False, covered_before=True, cleared=True), cover) == -0.5
    assert reward_push(o("push", change_detected=True, grasp_q_gain=0.2), cover) == 0.5  # uncovered before: R_p


def test_reward_config_rejects_a_visible_gain_outside_0_1():
    for bad in (0.0, -0.1, 1.5, True, "0.1"):
        with pytest.raises(ValueError, match="move_visible_gain"):
            RewardConfig(move_visible_gain=bad)
    assert RewardConfig(move_visible_gain=1).move_visible_gain == 1


def test_move_that_uncovers_the_target_earns_1_in_stage3(make_env):
    env = make_env("MPG-Stage3-v0")
    _, info = env.reset(seed=0)
    oracle = OraclePolicy(env)
    for _ in range(5):
        before = info["visible_fraction"]
        obs, r, term, trunc, info = env.step(oracle.act())
        if info["visible_fraction"] is not None and before is not None:
            assert info["visible_gain"] == pytest.approx(info["visible_fraction"] - before)
        if info["move_success"]:
            assert r == 1.0 and term and info["occluded_before"] and not info["occluded"]
            assert info["visible_gain"] > 0  # the last occluder left
            return
    pytest.fail("the oracle's moves never uncovered the target")


def test_push_rewards_no_change_and_scorer_gain(make_env):
    # A scorer that likes empty space around the target: pushing a neighbour away pays.
    def scorer(obs):
        ring = cv2.dilate(obs["mask"], np.ones((31, 31), np.uint8)) & (1 - obs["mask"])
        return -float(obs["depth"][ring > 0].mean()) * 100

    env = make_env("MPG-Stage4-v0", grasp_scorer=scorer)
    obs, _ = env.reset(seed=0)
    # A push in an empty corner changes nothing.
    _, r, *_, info = env.step(env.action_space.encode("push", 0, 5, 5))
    assert not info["change_detected"] and abs(info["grasp_q_gain"]) < 0.01 and r == -0.5
    before = scorer(env.last_observation)
    oracle = OraclePolicy(env)
    primitive, *rest = env.action_space.decode(oracle.act())
    assert primitive == "push"  # the target is boxed in
    obs, r, *_, info = env.step(env.action_space.encode("push", *rest))
    assert info["change_detected"]
    assert info["grasp_q_gain"] == pytest.approx(scorer(obs) - before)
    assert r == (0.5 if info["grasp_q_gain"] > 0.1 else 0.0)


def test_occlusion_and_change_detection_on_hand_made_maps():
    depth = np.zeros((20, 20), np.float32)
    mask = np.zeros((20, 20), np.uint8)
    mask[5:15, 5:15] = 1
    depth[5:15, 5:15] = 0.03  # the target, 3 cm tall
    assert not is_occluded(depth, mask, target_top=0.03)
    depth[8:12, 8:12] = 0.06  # something on top of it
    assert is_occluded(depth, mask, target_top=0.03)
    before = np.zeros((224, 224), np.float32)
    after = before.copy()
    after[:10, :10] = 0.05  # 100 changed pixels away from the target: not enough
    tmask = np.zeros_like(before, np.uint8)
    tmask[100:110, 100:110] = 1
    assert not change_detected(before, after, tmask)
    after[95:105, 95:105] = 0.05  # 100 pixels near the target
    assert change_detected(before, after, tmask)
    assert change_detected(before, before, tmask, lifted=True)
