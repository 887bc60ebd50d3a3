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


@pytest.mark.parametrize(
    ("name", "who"), [("pixel-heuristic", "the pixel heuristic"), ("shipped", "an MPGNet checkpoint")]
)
def test_mask_policies_refuse_an_exemplar_env_clearly(exemplar_env, name, who):
    with pytest.raises(
        ValueError,
        match=f"{who} needs the target's mask in the observation; .*target_spec='exemplar'",
    ):
        make_policy(name, exemplar_env)


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
