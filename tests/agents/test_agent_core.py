"""The agent core runs without Stable-Baselines3; the SB3 adapter takes mpg-train's settings."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from mpg_agents.acting.agent import MPGAgent
from mpg_agents.learning.train_config import TrainConfig
from mpg_envs.grid.actions import PixelActionSpace

from .conftest import TINY, calibrate_bn
from .fake_env import FakeMPGEnv, observation_space, random_scene

CORE = (
    "mpg_agents", "mpg_agents.acting.agent", "mpg_agents.acting.decision", "mpg_agents.acting.q_function", "mpg_agents.network.mpgnet",
    "mpg_agents.acting.coordination", "mpg_agents.acting.grasp_threshold", "mpg_agents.acting.weights", "mpg_agents.acting.discriminator",
    "mpg_agents.learning.td_step", "mpg_agents.learning.exploration", "mpg_agents.learning.train_config", "mpg_agents.evaluation.policy_zoo",
    "mpg_agents.evaluation.evaluate", "mpg_agents.cli",
)


def test_the_core_modules_do_not_import_stable_baselines3():
    code = "import importlib, sys\n" + "".join(f"importlib.import_module({m!r})\n" for m in CORE) + (
        "loaded = sorted(m for m in sys.modules if m.startswith('stable_baselines3'))\n"
        "assert not loaded, loaded\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr


def test_the_sb3_policy_decides_as_its_agent(rng):
    from mpg_agents.sb3 import MPGNetPolicy

    torch.manual_seed(0)
    policy = MPGNetPolicy(observation_space(), PixelActionSpace(("move", "push", "grasp")), lambda _: 1e-4, **TINY)
    scene = random_scene(rng, occluded=False)
    calibrate_bn(policy.q_net.mpgnet, {k: torch.as_tensor(v)[None] for k, v in scene.items()})
    agent = MPGAgent(policy.q_net, policy.coordination, policy.threshold)  # the same parts, without SB3
    for q_star in (float("-inf"), float("inf"), None):
        policy.set_q_star(q_star)
        assert agent.decide(scene).action == policy.decide(scene).action == int(policy.predict(scene, deterministic=True)[0])
    assert set(dict(policy.state_dict())) >= {"threshold.value"}  # SB3's save keeps Q*_g


def test_mpgdqn_takes_its_defaults_from_the_training_config():
    from mpg_agents.sb3 import MPGDQN, MPGNetPolicy

    config = TrainConfig()
    model = MPGDQN(MPGNetPolicy, FakeMPGEnv(("grasp",)), policy_kwargs=dict(TINY))
    assert (model.batch_size, model.buffer_size, model.gamma) == (config.batch_size, config.replay_capacity, config.gamma)
    assert model.target_update_interval == config.target_update_every
    assert (model.exploration_initial_eps, model.exploration_final_eps) == (config.epsilon_start, config.epsilon_end)
    assert model.step_config == config.step_config()
    group = model.policy.optimizer.param_groups[0]
    assert (group["lr"], group["weight_decay"], tuple(group["betas"])) == (config.learning_rate, config.weight_decay, config.betas)
    other = MPGDQN(MPGNetPolicy, FakeMPGEnv(("grasp",)), config=TrainConfig(batch_size=3, q_bounds=(-1.0, 2.0)), policy_kwargs=dict(TINY))
    assert other.batch_size == 3 and other.step_config.target_bounds == (-1.0, 2.0)
    with pytest.raises(ValueError, match="exploration_fraction"):
        MPGDQN(MPGNetPolicy, FakeMPGEnv(("grasp",)), config=TrainConfig(epsilon_decay_steps=10), policy_kwargs=dict(TINY))


def test_an_agent_from_weights_decides_with_the_checkpoints_q_star(tmp_path, rng):
    torch.manual_seed(0)
    space = PixelActionSpace(("push", "grasp"))
    agent = MPGAgent.build(observation_space(), space, coordination="grasp_first", q_star=0.7, **TINY)
    path = tmp_path / "net.safetensors"
    agent.save_weights(path)
    loaded = MPGAgent.from_weights(path, observation_space(), space)
    assert (loaded.q_star, loaded.coordination, loaded.branches) == (0.7, "grasp_first", ("push", "grasp"))
    scene = random_scene(rng, occluded=False)
    assert loaded.decide(scene).action == agent.decide(scene).action
    with pytest.raises(ValueError, match="one observation"):
        agent.decide({k: np.stack([v, v]) for k, v in scene.items()})
