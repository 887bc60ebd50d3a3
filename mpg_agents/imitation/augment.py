"""Quarter-turn augmentation of recorded samples: the scene and its action turned together.

A quarter turn of the heightmaps is exact (pixel centres land on pixel centres), and the action
space turns with it: with rotation ``k`` the direction ``theta_k = k * 22.5 deg`` from image
columns toward image rows (:mod:`mpg_envs.grid.workspace`), ``np.rot90`` of a square ``W x W``
map sends pixel ``(row, col)`` to ``(W - 1 - col, row)`` and a direction ``theta`` to
``theta - 90 deg``: rotation ``k`` becomes ``k - R / 4``. So a recorded (observation, action)
pair turned by ``t`` quarters is another pair the recorded policy would stand by in a scene
turned about the workspace's centre. Pure functions of arrays; no network, no env.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

IMAGE_KEYS: tuple[str, ...] = ("color", "depth", "mask")
"""The observation planes a quarter turn turns (the others, as ``occluded``, stay as they are)."""


def turn_action(actions: np.ndarray, turns: np.ndarray, num_rotations: int, size: int) -> np.ndarray:
    """Flat actions ``(B,)`` (C order over primitive, rotation, row, col) after turning each
    sample's scene by ``turns[b]`` quarter turns of ``np.rot90``.

    Raises:
        ValueError: ``num_rotations`` not a multiple of 4 (a quarter turn would fall between
            rotations), or ``actions`` and ``turns`` of different lengths.
    """
    if num_rotations % 4:
        raise ValueError(f"a quarter turn needs a number of rotations divisible by 4, got {num_rotations}")
    actions = np.asarray(actions, dtype=np.int64).reshape(-1)
    turns = np.asarray(turns, dtype=np.int64).reshape(-1) % 4
    if actions.shape != turns.shape:
        raise ValueError(f"one turn per action: {actions.size} actions, {turns.size} turns")
    primitive, rest = np.divmod(actions, num_rotations * size * size)
    rotation, pixel = np.divmod(rest, size * size)
    row, col = np.divmod(pixel, size)
    for _ in range(3):  # up to three quarter turns, each on the samples that still need one
        todo = turns > 0
        row[todo], col[todo] = size - 1 - col[todo], row[todo].copy()
        rotation[todo] = (rotation[todo] - num_rotations // 4) % num_rotations
        turns = np.where(todo, turns - 1, 0)
    return ((primitive * num_rotations + rotation) * size + row) * size + col


def turn_planes(obs: Mapping[str, np.ndarray], turns: np.ndarray) -> dict[str, np.ndarray]:
    """The batch ``obs`` (planes ``(B, H, W)`` or ``(B, H, W, C)``) with sample ``b``'s images
    turned by ``turns[b]`` quarter turns of ``np.rot90`` (``IMAGE_KEYS``; the rest copied as is).

    Raises:
        ValueError: an image plane that is not square.
    """
    turns = np.asarray(turns, dtype=np.int64).reshape(-1) % 4
    out: dict[str, np.ndarray] = {}
    for key, value in obs.items():
        value = np.asarray(value)
        if key not in IMAGE_KEYS:
            out[key] = value.copy()
            continue
        if value.shape[1] != value.shape[2]:
            raise ValueError(f"{key} planes must be square to turn, got {value.shape[1]} x {value.shape[2]}")
        out[key] = np.stack([np.rot90(plane, int(t)) for plane, t in zip(value, turns, strict=True)])
    return out
