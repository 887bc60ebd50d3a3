"""Pixel-only heuristics: the paper's fallback grasp after two failed grasps.

They read the observation alone (target mask and depth heightmap), as a real robot could.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import cv2
import numpy as np

from mpg_envs.grid.actions import encode_action
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.grid.workspace import NUM_ROTATIONS


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
