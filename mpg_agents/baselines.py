"""Policies by name for evaluation and the demo: a checkpoint or a built-in baseline.

Every policy has ``name`` and ``act(obs) -> flat action``; network policies also have
``save_qmaps(path, obs)``.

- ``oracle``: :class:`mpg_envs.policies.OraclePolicy` (reads the simulator: upper baseline).
- ``random``: uniform over the whole action space (seeded).
- ``grasp-only``: the pixel-only heuristic grasp at the target mask, every step.
- ``shipped``: the checkpoint trained on this project's CPU (Stages I-II) that ships in
  ``mpg_agents/checkpoints/``.
- a path: an MPGNet safetensors checkpoint (``mpg-train``'s ``weights.safetensors``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import gymnasium as gym
import numpy as np

from mpg_agents.heuristics import heuristic_grasp_action

BUILTIN = ("oracle", "random", "grasp-only", "shipped")
SHIPPED_CHECKPOINT = "stage2_grasp_small.safetensors"


def shipped_checkpoint() -> Path:
    """Path of the checkpoint shipped with the package."""
    path = Path(str(resources.files("mpg_agents").joinpath("checkpoints", SHIPPED_CHECKPOINT)))
    if not path.is_file():
        raise FileNotFoundError(f"the shipped checkpoint {path} is missing from this installation")
    return path


class OracleBaseline:
    def __init__(self, env: gym.Env):
        from mpg_envs.policies import OraclePolicy

        self.name = "oracle"
        self._oracle = OraclePolicy(env)

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        return self._oracle.act()


class RandomBaseline:
    def __init__(self, env: gym.Env, seed: int = 0):
        self.name = "random"
        self._space = gym.spaces.Discrete(int(env.action_space.n), seed=seed)

    def seed(self, seed: int) -> None:
        """Restart the action stream; evaluation calls it with each episode's seed."""
        self._space.seed(seed)

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        return int(self._space.sample())


class GraspOnlyBaseline:
    def __init__(self, env: gym.Env):
        self.name = "grasp-only"
        self.primitives = tuple(env.unwrapped.primitives)
        if "grasp" not in self.primitives:
            raise ValueError(f"grasp-only needs an env that allows grasping; this one allows {self.primitives}")
        self._space = env.action_space

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        if not np.asarray(obs["mask"]).any():
            return int(self._space.sample())  # no target visible: nothing better to do
        return heuristic_grasp_action(obs, self.primitives)


class NetworkPolicy:
    """An MPGNet checkpoint with the paper's coordination (greedy, no exploration)."""

    def __init__(self, path: str | Path, env: gym.Env, coordination: str | None = None):
        import torch

        from mpg_agents.policy import MPGNetPolicy

        torch.set_flush_denormal(True)  # see mpg_agents.learner: denormals slow CPUs down
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"checkpoint {str(path)!r} does not exist")
        self.name = path.name
        self.policy = MPGNetPolicy.from_weights(path, env.observation_space, env.action_space)
        if coordination is not None:
            self.policy.set_coordination(coordination)

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        return int(self.policy.decide(obs).action)

    def save_qmaps(self, path: str | Path, obs: Mapping[str, np.ndarray]) -> None:
        from mpg_agents.visualize import save_qmap_png

        decision = self.policy.decide(obs)
        save_qmap_png(path, obs, decision.q_maps, decision, primitives=self.policy.action_primitives)


def make_policy(name: str, env: gym.Env, seed: int = 0, **kwargs: Any):
    """A policy by name (see the module docstring) for ``env``."""
    if name == "oracle":
        return OracleBaseline(env)
    if name == "random":
        return RandomBaseline(env, seed)
    if name == "grasp-only":
        return GraspOnlyBaseline(env)
    if name == "shipped":
        policy = NetworkPolicy(shipped_checkpoint(), env, **kwargs)
        policy.name = "shipped:" + SHIPPED_CHECKPOINT
        return policy
    path = Path(name)
    if path.suffix == ".safetensors" or path.exists():
        return NetworkPolicy(path, env, **kwargs)
    raise ValueError(f"unknown policy {name!r}: use one of {BUILTIN} or the path of a .safetensors checkpoint")
