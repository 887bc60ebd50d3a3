"""Policies on envs that name the target otherwise than by its mask: the matcher by name, the
mask policies refusing exemplar envs clearly, the shipped net on the visible mask, and mpg-eval
recording what finding the target cost."""

from __future__ import annotations

import json

import gymnasium as gym
import pytest

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_agents.cli import eval_main
from mpg_agents.evaluation.policy_zoo import BUILTIN, make_policy
from mpg_envs.policies.exemplar_matcher import ExemplarMatcher


@pytest.fixture(scope="module")
def exemplar_env():
    env = gym.make("MPG-OccludedHardExemplar-v0")
    yield env
    env.close()


def test_the_matcher_is_a_builtin_policy(exemplar_env):
    assert "matcher" in BUILTIN
    assert isinstance(make_policy("matcher", exemplar_env), ExemplarMatcher)
    assert (
        make_policy("oracle", exemplar_env).name == "oracle"
        and make_policy("random", exemplar_env).name == "random"
    )


def test_the_pixel_heuristic_refuses_an_exemplar_env_clearly(exemplar_env):
    with pytest.raises(
        ValueError,
        match="the pixel heuristic needs the target's mask in the observation; .*target_spec='exemplar'",
    ):
        make_policy("pixel-heuristic", exemplar_env)


def test_a_net_on_an_exemplar_env_acts_through_the_shipped_locator_or_says_it_needs_one(exemplar_env):
    from mpg_agents.locator.finding_policy import FindingPolicy
    from mpg_agents.locator.locator import SHIPPED_LOCATOR, read_locator_header

    if SHIPPED_LOCATOR.is_file():
        policy = make_policy("shipped", exemplar_env, device="cpu")
        assert isinstance(policy, FindingPolicy)
        header = read_locator_header(SHIPPED_LOCATOR)
        assert policy.rule.to_dict() == header["rule"] and policy.locator.seen_threshold == header["seen_threshold"]
    else:
        with pytest.raises(ValueError, match="acts through a target locator, and none ships.*mpg-train-locator"):
            make_policy("shipped", exemplar_env)


def test_a_net_acts_on_an_exemplar_env_through_a_locator(exemplar_env, tmp_path):
    from mpg_agents.locator.finding_policy import FindingPolicy
    from mpg_agents.locator.locator import save_locator
    from mpg_agents.locator.net import LocatorConfig, LocatorNet

    path = tmp_path / "locator.safetensors"
    save_locator(LocatorNet(LocatorConfig(8, 8, 16)), path, 0.5, 0.5, {})
    policy = make_policy("shipped", exemplar_env, locator=path, device="cpu")
    assert isinstance(policy, FindingPolicy) and policy.name.endswith("+ locator")
    obs, _ = exemplar_env.reset(seed=500000)
    policy.reset()
    assert exemplar_env.action_space.contains(policy.act(obs))
    assert policy.last_location is not None and policy.last_location.probability.shape == obs["depth"].shape
    located = policy.located_observation(obs)
    assert set(located) == {"color", "depth", "mask", "occluded"} and located["mask"].shape == obs["depth"].shape


def test_the_shipped_net_acts_on_the_visible_mask():
    env = gym.make("MPG-OccludedHardVisible-v0")
    policy = make_policy("shipped", env, device="cpu")
    obs, _ = env.reset(seed=500000)
    assert env.action_space.contains(policy.act(obs))
    env.close()


def test_mpg_eval_records_finding_the_target(tmp_path, capsys):
    path = tmp_path / "eval.json"
    options = ["--env-option", "target_spec=exemplar", "--env-option", "max_motions=2"]
    run = ["--episodes", "1", "--seed", "500000", "--json", str(path), "--quiet"]
    argv = ["--policy", "matcher", "--env", "MPG-OccludedHard-v0", *options, *run]
    assert eval_main(argv) == 0
    data = json.loads(path.read_text())
    assert data["env_options"]["target_spec"] == "exemplar"
    record = data["records"][0]
    assert record["seed"] == 500000 and record["lookalike_grasps"] >= 0 and "first_sight" in record
    assert record["first_sight"] == 0  # the shipped scene's target shows a little at reset (18%)
    assert data["finding"]["episodes"] == 1 and "lookalike_grasps_per_episode" in data["finding"]
    assert "finding the target" in capsys.readouterr().out
