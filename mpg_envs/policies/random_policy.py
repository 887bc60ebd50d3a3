"""The random baseline: uniform over the whole action space, seeded (numpy and Gymnasium only)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np


class RandomPolicy:
    """Uniform over the whole action space; a :class:`~mpg_envs.policies.policy.Policy`.

    ``seed`` starts its action stream; evaluation restarts it with each episode's seed
    (:meth:`seed`), so an episode's actions depend on its seed alone.
    """

    def __init__(self, env: gym.Env, seed: int = 0):
        self.name = "random"
        space: Any = env.action_space  # a Discrete
        self._space: gym.spaces.Discrete = gym.spaces.Discrete(int(space.n), seed=seed)

    def seed(self, seed: int) -> None:
        """Restart the action stream; evaluation calls it with each episode's seed."""
        self._space.seed(seed)

    def reset(self) -> None:
        """Nothing to forget between episodes."""

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        """A uniformly drawn flat action (``obs`` unread)."""
        return int(self._space.sample())
