"""Q*_g calibration (mpg_agents.acting.grasp_threshold) and mpg-calibrate."""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass

import pytest

from mpg_envs.scenes.generators import InvalidSceneError

from mpg_agents.cli import calibrate_main
from mpg_agents.acting.grasp_threshold import Calibration, calibrate_q_star, estimate_q_star, write_calibration
from mpg_agents.acting.seeds import episode_seed


@dataclass
class Decision:
    action: int
    q_value: float


class ScriptedPolicy:
    """A grasp net whose k-th grasp has Q ``qs[k]``."""

    usable_primitives = ("grasp",)
    branches = ("grasp",)

    def __init__(self, qs):
        self.qs = list(qs)
        self.asked: list[str] = []

    def decide(self, obs, primitive):
        self.asked.append(primitive)
        return Decision(action=len(self.asked) - 1, q_value=self.qs[len(self.asked) - 1])


class ScriptedEnv:
    """Episodes of scripted grasp outcomes: ``episodes[k]`` lists whether each grasp took the target."""

    def __init__(self, episodes):
        self.episodes = episodes
        self.seeds: list[int] = []
        self.k = -1

    def reset(self, seed):
        self.seeds.append(seed)
        self.k += 1
        self.step_in_episode = 0
        return {}, {}

    def step(self, action):
        outcomes = self.episodes[self.k]
        taken = outcomes[self.step_in_episode]
        self.step_in_episode += 1
        return {}, 0.0, taken, self.step_in_episode == len(outcomes), {"target_grasped": taken}


def test_q_star_is_the_quantile_of_the_target_grasps_q_on_calibration_seeds():
    # Episode 0: miss (Q 5), take (Q 0.2). Episode 1: take (Q 0.6). Episode 2: miss, miss (the cap).
    env = ScriptedEnv([[False, True], [True], [False, False]])
    policy = ScriptedPolicy([5.0, 0.2, 0.6, 9.0, 9.0])
    seen = []
    result = calibrate_q_star(policy, env, 3, seed=4, quantile=0.5, on_episode=lambda *a: seen.append(a))
    assert result == Calibration(q_star=pytest.approx(0.4), quantile=0.5, episodes=3, grasps=5, target_grasp_q=(0.2, 0.6))
    assert env.seeds == [episode_seed(4, k, calibration=True) for k in range(3)]
    assert policy.asked == ["grasp"] * 5
    assert seen == [(0, 2, 1), (1, 3, 2), (2, 5, 2)]
    low = calibrate_q_star(ScriptedPolicy([5.0, 0.2, 0.6]), ScriptedEnv([[False, True], [True]]), 2, seed=4, quantile=0.0)
    assert low.q_star == pytest.approx(0.2)


class SceneFailsOnce(ScriptedEnv):
    """A ScriptedEnv whose second calibration seed gives no valid scene."""

    def reset(self, seed):
        if seed == episode_seed(0, 1, calibration=True):
            raise InvalidSceneError(f"seed {seed}")
        return super().reset(seed)


def test_a_calibration_seed_without_a_scene_passes_to_the_next_and_is_reported():
    env, skipped = SceneFailsOnce([[True], [True]]), []
    result = calibrate_q_star(ScriptedPolicy([0.2, 0.6]), env, 2, seed=0, on_skip=lambda k, e: skipped.append(k))
    assert result.episodes == 2 and result.target_grasp_q == (0.2, 0.6)
    assert env.seeds == [episode_seed(0, 0, calibration=True), episode_seed(0, 2, calibration=True)]
    assert skipped == [1]


def test_an_infinite_q_is_not_a_calibration_value():
    result = calibrate_q_star(ScriptedPolicy([float("-inf"), 0.3]), ScriptedEnv([[True], [True]]), 2, seed=0)
    assert result.target_grasp_q == (0.3,) and result.q_star == pytest.approx(0.3)


@pytest.mark.parametrize(
    "policy, episodes, quantile, error, message",
    [
        (ScriptedPolicy([1.0]), 1, 1.5, ValueError, r"quantile must be in \[0, 1\], got 1.5"),
        (ScriptedPolicy([1.0]), 0, 0.5, ValueError, "at least one episode, got 0"),
        (ScriptedPolicy([1.0]), 1, 0.5, RuntimeError, r"no grasp took the target in 1 calibration episodes \(1 grasps\)"),
    ],
)
def test_calibration_rejects_what_it_cannot_measure(policy, episodes, quantile, error, message):
    with pytest.raises(error, match=message):
        calibrate_q_star(policy, ScriptedEnv([[False]]), episodes, seed=0, quantile=quantile)


def test_calibration_needs_a_grasp_branch():
    policy = ScriptedPolicy([1.0])
    policy.usable_primitives = policy.branches = ("push",)
    with pytest.raises(ValueError, match="needs a grasp branch; the net has"):
        calibrate_q_star(policy, ScriptedEnv([[True]]), 1, seed=0)


def test_calibration_json_keeps_the_stage_history_only_when_asked(tmp_path):
    path = tmp_path / "calibration.json"
    first = Calibration(0.5, 0.25, 2, 4, (0.4, 0.7))
    write_calibration(path, first, iteration=0, q_star_before=None, continue_history=False)
    record = json.loads(path.read_text())
    assert record["q_star_before"] is None and record["target_grasps"] == 2 and record["target_grasp_q"] == [0.4, 0.7]
    write_calibration(path, Calibration(0.6, 0.25, 2, 3, (0.6,)), iteration=300, q_star_before=0.5, continue_history=True)
    record = json.loads(path.read_text())
    assert [h["iteration"] for h in record["history"]] == [0, 300] and record["q_star"] == 0.6 and record["q_star_before"] == 0.5
    write_calibration(path, first, iteration=0, q_star_before=0.6, continue_history=False)  # a new stage starts afresh
    assert [h["iteration"] for h in json.loads(path.read_text())["history"]] == [0]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--policy", "shipped", "--env", "MPG-Nope-v0"], "unknown env id 'MPG-Nope-v0'"),
        (["--policy", "missing.safetensors"], "checkpoint 'missing.safetensors' does not exist"),
        (["--policy", "shipped", "--episodes", "0"], "--episodes must be >= 1, got 0"),
        (["--policy", "shipped", "--quantile", "-0.1"], r"--quantile must be in \[0, 1\], got -0.1"),
    ],
)
def test_mpg_calibrate_rejects_bad_input_in_one_line(argv, message, capsys):
    assert calibrate_main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and re.search(message, err)


def test_mpg_calibrate_measures_the_shipped_net_and_writes_every_target_grasp(tmp_path, capsys):
    path = tmp_path / "q.json"
    argv = ["--policy", "shipped", "--env", "MPG-Stage2-v0", "--episodes", "1", "--quantile", "0", "--json", str(path)]
    assert calibrate_main(argv) == 0
    record = json.loads(path.read_text())
    assert record["episodes"] == 1 and record["grasps"] >= 1 and record["env_id"] == "MPG-Stage2-v0"
    assert record["q_star"] == pytest.approx(min(record["target_grasp_q"]))
    assert f"Q*_g {record['q_star']:.4f}: quantile 0 of the Q of" in capsys.readouterr().out


def test_one_estimator_is_a_quantile_of_the_target_grasps_q():
    assert estimate_q_star([0.2, 0.6], 0.5) == pytest.approx(0.4)
    assert estimate_q_star([0.9, 0.1, 0.5], 0.0) == 0.1
    with pytest.raises(ValueError, match="at least one grasp"):
        estimate_q_star([], 0.5)
    with pytest.raises(ValueError, match=r"quantile must be in \[0, 1\]"):
        estimate_q_star([0.1], 2.0)


def test_a_calibrates_q_star_stage_estimates_from_its_own_greedy_grasps_into_its_weights(tmp_path):
    """Stage II's Q*_g: the same estimate over its last greedy grasps that took the target,
    stored in its weights header (where the next stage and the pipeline read it)."""
    from mpg_agents.learning.learner import Learner
    from mpg_agents.learning.stage_calibration import calibrate_from_own_grasps
    from mpg_agents.learning.train_config import TrainConfig
    from mpg_agents.learning.training_stages import TRAINING_STAGES
    from mpg_agents.acting.weights import read_checkpoint_header

    stage = TRAINING_STAGES[1]
    assert stage.calibrates_q_star
    tiny = dict(steps=1, batch_size=1, replay_capacity=8, net_config={"trunk_depth": 2}, torch_threads=1)
    learner = Learner(TrainConfig(**tiny), stage, tmp_path, log=lambda s: None)
    assert calibrate_from_own_grasps(learner) is None  # no greedy grasp took the target: still uncalibrated
    learner.counters.successful_grasp_q = [0.3, 0.9, 0.5]
    assert calibrate_from_own_grasps(learner) == pytest.approx(estimate_q_star([0.3, 0.9, 0.5], stage.calibration_quantile))
    assert read_checkpoint_header(tmp_path / "weights.safetensors")["q_star"] == pytest.approx(0.5)
    learner.env.close()
