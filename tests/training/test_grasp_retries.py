"""``grasp_retries``: after K grasps in a row that did not take the target, a network policy
pushes once, then may grasp again."""

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.acting.decision import Decision
from mpg_agents.evaluation.policy_zoo import make_policy, shipped_checkpoint
from mpg_envs.grid.actions import decode_action
from mpg_envs.scenes.arranged import arrangement_scene
from mpg_envs.scenes.arrangement_draw import draw_arrangement

GRASP_NET = str(shipped_checkpoint().parent / "stage2_grasp_small.safetensors")
# The shipped config trained on clean heightmaps (training seed 1): exported without grasp retries.
CLEAN_NET = str(Path(__file__).resolve().parents[2] / "benchmarks" / "checkpoints" / "uncover_s1.safetensors")


class ScriptedAgent:
    """Stands in for the network: grasps unless told which primitive to use, and records that."""

    def __init__(self):
        self.asked: list[str | None] = []

    def decide(self, obs, primitive=None, forbidden=None):
        self.asked.append(primitive)
        chosen = primitive or "grasp"
        return Decision(0, chosen, 0, 0, 0, 0.0, 0.0, {})


@pytest.fixture(scope="module")
def env():
    env = gym.make("MPG-Occluded-v0", num_objects=5)
    yield env
    env.close()


def test_k_failed_grasps_then_one_push_then_grasps_again(env):
    policy = make_policy("shipped", env, grasp_retries=2)
    assert policy.name.endswith("[push after 2 failed grasps]")
    policy.policy = ScriptedAgent()
    obs = env.observation_space.sample()
    for _ in range(7):
        policy.act(obs)
    assert policy.policy.asked == [None, None, "push", None, None, "push", None]
    policy.reset()  # a new episode starts the count again
    policy.act(obs)
    assert policy.policy.asked[-1] is None


def test_the_shipped_net_pushes_after_three_failed_grasps_by_its_header(env):
    policy = make_policy("shipped", env)
    assert policy.grasp_retries == 3 and policy.name.endswith("[push after 3 failed grasps]")
    policy.policy = ScriptedAgent()
    obs = env.observation_space.sample()
    for _ in range(5):
        policy.act(obs)
    assert policy.policy.asked == [None, None, None, "push", None]


def test_grasp_retries_is_off_by_default_refused_when_not_positive_and_idle_for_a_grasp_only_net(env):
    policy = make_policy(CLEAN_NET, env)  # its header has no grasp_retries
    assert policy.grasp_retries is None
    policy.policy = ScriptedAgent()
    obs = env.observation_space.sample()
    for _ in range(5):
        policy.act(obs)
    assert policy.policy.asked == [None] * 5
    for bad in (-1, True, 1.5):
        with pytest.raises(ValueError, match="grasp_retries"):
            make_policy("shipped", env, grasp_retries=bad)
    assert make_policy("shipped", env, grasp_retries=0).grasp_retries is None
    grasp_only = make_policy(GRASP_NET, gym.make("MPG-Stage2-v0"), grasp_retries=1)
    assert grasp_only.grasp_retries is None and "failed grasps" not in grasp_only.name


def test_an_exported_checkpoint_carries_its_default_and_a_policy_may_turn_it_off(env, tmp_path):
    from mpg_agents.acting.weights import read_checkpoint_header
    from mpg_agents.cli import export_main

    dst = tmp_path / "copy.safetensors"
    assert export_main([str(shipped_checkpoint()), str(dst), "--grasp-retries", "2"]) == 0
    assert read_checkpoint_header(dst)["extra"]["grasp_retries"] == 2
    assert make_policy(str(dst), env).grasp_retries == 2
    assert make_policy(str(dst), env, grasp_retries=0).grasp_retries is None
    assert make_policy(str(dst), env, grasp_retries=3).grasp_retries == 3
    assert export_main([str(shipped_checkpoint()), str(tmp_path / "bad.safetensors"), "--grasp-retries", "-1"]) != 0


def test_in_a_closed_ring_the_shipped_net_pushes_after_two_failed_grasps(env):
    """The drawn tuning scene ring-700027: a cube in a closed ring of six round blocks, where
    the shipped config trained on clean heightmaps (training seed 1), without grasp retries,
    grasps ten times in a row to the motion cap."""
    arrangement = draw_arrangement(700027)
    assert arrangement.name == "ring-700027"
    obs, _ = env.reset(seed=0, options={"scene": arrangement_scene(arrangement)})
    policy = make_policy("shipped", env, grasp_retries=2)
    primitives = env.unwrapped.primitives
    done, taken = False, []
    while not done and len(taken) < 3:
        action = policy.act(obs)
        taken.append(decode_action(primitives, action).primitive)
        obs, _, terminated, truncated, _ = env.step(action)
        done = terminated or truncated
    assert taken == ["grasp", "grasp", "push"]
    assert np.isfinite(obs["depth"]).all()
