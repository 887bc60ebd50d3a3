"""Synthetic MPG-like observations and a small fake env with exactly the MPG spaces.

The fake env lets the agent tests run without the simulator; the integration tests in
``test_envs_integration.py`` use the registered ``MPG-*`` ids instead.
"""

from __future__ import annotations

from typing import Any, Sequence

import gymnasium as gym
import numpy as np

from mpg_envs.tasks.env import observation_space

from mpg_envs.grid.actions import PixelActionSpace, decode_action

SIZE = 224
TABLE_RGB = (120, 110, 100)


def random_scene(rng: np.random.Generator, num_blocks: int = 6, occluded: bool | None = None) -> dict[str, np.ndarray]:
    """A heightmap-like scene: flat table, axis-aligned coloured blocks, the first one the target."""
    color = np.empty((SIZE, SIZE, 3), np.uint8)
    color[:] = TABLE_RGB
    depth = np.zeros((SIZE, SIZE), np.float32)
    mask = np.zeros((SIZE, SIZE), np.uint8)
    for i in range(num_blocks):
        h, w = rng.integers(12, 40, size=2)
        r, c = rng.integers(20, SIZE - 60, size=2)
        height = np.float32(rng.uniform(0.02, 0.08))
        color[r : r + h, c : c + w] = rng.integers(0, 255, 3, dtype=np.uint8)
        # A slight slope so depth is not a handful of values (like ray-cast faces).
        slope = np.linspace(0.0, 0.004, w, dtype=np.float32)[None, :]
        depth[r : r + h, c : c + w] = height + slope
        if i == 0:
            mask[r : r + h, c : c + w] = 1
    occ = bool(rng.integers(0, 2)) if occluded is None else occluded
    return {"color": color, "depth": depth, "mask": mask, "occluded": np.array([int(occ)], np.int8)}


class FakeMPGEnv(gym.Env):
    """Random scenes with the MPG spaces; reward 1 for a grasp inside the target mask.

    Episodes end after ``horizon`` steps or a rewarded grasp.
    """

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(self, primitives: Sequence[str] = ("grasp",), horizon: int = 4) -> None:
        self.observation_space = observation_space()
        self.action_space = PixelActionSpace(primitives)
        self.primitives = self.action_space.primitives
        self.horizon = horizon
        self._obs: dict[str, np.ndarray] | None = None
        self._t = 0

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self._t = 0
        self._obs = random_scene(self.np_random)
        return {k: v.copy() for k, v in self._obs.items()}, {}

    def step(self, action):
        assert self._obs is not None
        a = decode_action(self.primitives, action)
        self._t += 1
        reward = float(a.primitive == "grasp" and self._obs["mask"][a.row, a.col] == 1)
        self._obs = random_scene(self.np_random)
        terminated = reward > 0
        truncated = self._t >= self.horizon
        return {k: v.copy() for k, v in self._obs.items()}, reward, terminated, truncated, {"is_success": terminated}
