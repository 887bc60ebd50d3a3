"""The pixel heuristic: a grasp at the target mask's centre across its short side.

It reads the observation alone (the target mask), as a real robot could, with numpy and OpenCV.
:func:`heuristic_grasp` is the grasp; :class:`PixelHeuristic` the scripted baseline that takes it
every step (policy name ``pixel-heuristic``, formerly ``grasp-only``). MPGNet's training takes
the same grasp after failed grasps (``mpg_agents.learning.exploration``), as the paper does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

from mpg_envs.grid.actions import encode_action
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.policies.policy import check_has_mask


def heuristic_grasp(obs: Mapping[str, np.ndarray]) -> tuple[int, int, int]:
    """``(rotation, row, col)`` of a grasp at the target mask's centre across its short side.

    The target's footprint (largest connected blob of the mask) is fitted with a
    minimum-area rectangle; the fingers close along the rectangle's short side. Raises
    ``ValueError`` when the mask is empty (no target visible to grasp).
    """
    mask = np.asarray(obs["mask"]).astype(np.uint8)
    if mask.ndim != 2 or not mask.any():
        raise ValueError("heuristic_grasp needs a non-empty (H, W) target mask")
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask)
    biggest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    rows, cols = np.nonzero(labels == biggest)
    points = np.stack([cols, rows], axis=1).astype(np.float32)  # (x = col, y = row)
    (cx, cy), (w, h), angle = cv2.minAreaRect(points)
    a = math.radians(angle)
    short_dir = a if w <= h else a + math.pi / 2
    rotation = int(round(short_dir / (2 * math.pi / NUM_ROTATIONS))) % (NUM_ROTATIONS // 2)
    # The centre of a concave blob may fall outside it: snap to the nearest mask pixel.
    k = int(np.argmin((cols - cx) ** 2 + (rows - cy) ** 2))
    return rotation, int(rows[k]), int(cols[k])


def heuristic_grasp_action(obs: Mapping[str, np.ndarray], primitives: Sequence[str]) -> int:
    """:func:`heuristic_grasp` as a flat action index for an env allowing ``primitives``."""
    rotation, row, col = heuristic_grasp(obs)
    return encode_action(primitives, GRASP, rotation, row, col, size=np.asarray(obs["mask"]).shape[0])


class PixelHeuristic:
    """The heuristic grasp at the target every step (a random action when no target shows);
    a :class:`~mpg_envs.policies.policy.Policy`.

    Raises ``ValueError`` for an env without a target mask (an exemplar env) or one that does
    not allow grasping.
    """

    def __init__(self, env: gym.Env):
        check_has_mask(env, "the pixel heuristic")
        self.name = "pixel-heuristic"
        unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
        self.primitives = tuple(unwrapped.primitives)
        if GRASP not in self.primitives:
            raise ValueError(f"the pixel heuristic needs an env that allows grasping; this one allows {self.primitives}")
        self._space = env.action_space

    def reset(self) -> None:
        """Nothing to forget between episodes."""

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        """The heuristic grasp's flat action, or a sample of the env's action space when the mask is empty."""
        if not np.asarray(obs["mask"]).any():
            return int(self._space.sample())  # no target visible: nothing better to do
        return heuristic_grasp_action(obs, self.primitives)
