"""Oracle demonstrations seeding the learner's replay (``TrainConfig.demonstration_episodes``)."""

import json
from dataclasses import asdict, replace

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.acting.seeds import episode_seed
from mpg_agents.learning.demonstrations import DEMONSTRATIONS_FILE, DemoStats, collect_demonstrations
from mpg_agents.learning.env_steps import StageSteps, run_env_steps
from mpg_agents.learning.learner import Counters, Learner
from mpg_agents.learning.train_config import TrainConfig

from .tiny import TINY

# The tiny learner settings of tests/training/test_training.py.


def _recorder(calls: list):
    return lambda obs, next_obs, action, reward, terminated: calls.append((obs, next_obs, action, reward, terminated))


def test_collect_demonstrations_hands_well_formed_transitions_to_add():
    env = gym.make("MPG-Stage2-v0", num_objects=2)
    calls: list = []
    stats = collect_demonstrations(env, 2, 11, ("grasp",), _recorder(calls))
    assert isinstance(stats, DemoStats)
    # The oracle grasps an isolated target at its first, verified attempt: one step per episode.
    assert (stats.episodes, stats.kept, stats.dropped, stats.successes) == (2, 2, 0, 2) and stats.seconds > 0
    assert len(calls) == stats.kept
    for i, (obs, next_obs, action, reward, terminated) in enumerate(calls):
        assert env.observation_space.contains(obs) and env.observation_space.contains(next_obs)
        assert type(action) is int and env.action_space.contains(action)
        assert env.action_space.decode(action).primitive == "grasp"
        assert type(reward) is float and reward == 1.0  # Stage II: 1 for grasping the target
        assert terminated is True
        # episode i started from the scene of reset seed 11 + i
        first, _ = env.reset(seed=11 + i)
        assert all(np.array_equal(first[k], obs[k]) for k in obs)
    env.close()
    with pytest.raises(ValueError, match="episodes"):
        collect_demonstrations(env, -1, 0, ("grasp",), _recorder([]))


def test_transitions_of_primitives_not_kept_are_dropped_and_counted():
    env = gym.make("MPG-Stage4-v0", num_objects=4)  # push and grasp
    every: list = []
    both = collect_demonstrations(env, 2, 7, ("push", "grasp"), _recorder(every))
    primitives = [env.action_space.decode(c[2]).primitive for c in every]
    # Seed 7: the oracle pushes once, then grasps (hand-checked); a mixed case is the point.
    assert "push" in primitives and "grasp" in primitives
    assert (both.kept, both.dropped, both.successes) == (len(every), 0, 2)

    pushes: list = []
    only = collect_demonstrations(env, 2, 7, ("push",), _recorder(pushes))
    assert only.kept == primitives.count("push") and only.dropped == primitives.count("grasp")
    assert [c[2] for c in pushes] == [c[2] for c, p in zip(every, primitives) if p == "push"]
    assert [(c[3], c[4]) for c in pushes] == [(c[3], c[4]) for c, p in zip(every, primitives) if p == "push"]
    nothing: list = []
    none = collect_demonstrations(env, 2, 7, ("move",), _recorder(nothing))
    assert nothing == [] and (none.kept, none.dropped) == (0, len(every))
    env.close()


def test_a_fresh_run_starts_from_the_oracles_transitions_and_a_resumed_one_collects_none(tmp_path):
    seed = 3
    expected: list = []
    env = gym.make("MPG-Stage2-v0", num_objects=2)
    oracle = collect_demonstrations(env, 1, episode_seed(seed, 0, demonstration=True), ("grasp",), _recorder(expected))
    env.close()
    n = len(expected)
    assert n >= 1 and oracle.kept == n

    logs: list[str] = []
    cfg = TrainConfig(steps=0, seed=seed, num_objects=2, demonstration_episodes=1, **TINY)
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=logs.append)
    assert learner.replay.size() == 0  # collected when the run starts, not when the learner is built
    learner.run()
    lines = [line for line in logs if "oracle demonstrations" in line]
    assert len(lines) == 1
    assert lines[0].startswith(f"Stage2: oracle demonstrations: 1 episodes ({oracle.successes} successful), {n} transitions kept, 0 dropped, ")
    assert learner.replay.size() == n
    assert learner.replay.actions[:n, 0, 0].tolist() == [c[2] for c in expected]
    assert learner.replay.rewards[:n, 0].tolist() == [c[3] for c in expected]
    assert learner.replay.dones[:n, 0].tolist() == [float(c[4]) for c in expected]
    assert asdict(learner.counters) == asdict(Counters())  # no iteration, no episode
    assert (tmp_path / "progress.csv").read_text().splitlines()[1:] == []
    record = json.loads((tmp_path / DEMONSTRATIONS_FILE).read_text())  # the oracle's env steps, for the budget
    assert (record["episodes"], record["kept"], record["dropped"], record["env_steps"]) == (1, n, 0, n)

    # The collection saved the state: a resumed run keeps the transitions and collects none.
    resumed_logs: list[str] = []
    resumed = Learner(replace(cfg, steps=1), "MPG-Stage2-v0", tmp_path, log=resumed_logs.append, resume_anyway=True)  # more steps: a changed setting
    assert resumed.resumed and resumed.replay.size() == n
    assert resumed.replay.actions[:n, 0, 0].tolist() == [c[2] for c in expected]
    resumed.run()
    assert not any("oracle demonstrations" in line for line in resumed_logs)
    assert resumed.counters.iteration == 1 and resumed.replay.size() == n + 1
    assert run_env_steps(tmp_path) == [StageSteps(tmp_path.name, 1, n, 0)]
    rows = (tmp_path / "progress.csv").read_text().splitlines()[1:]
    assert [r.split(",")[0] for r in rows] == ["1"]  # iterations count from the first training step
    resumed.env.close()
    learner.env.close()
