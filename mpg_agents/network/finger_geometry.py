"""Where a grasp's open fingers come down: the geometry MPGNet's finger masks are made with.

The values belong to the env the network acts on (its workspace's pixel size, how deep its
grasp primitive goes, the open 2F-85); :func:`mpg_agents.acting.spaces.finger_geometry` reads
them from an env. This module holds them without MuJoCo (pure :mod:`mpg_envs.grid` types).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mpg_envs.grid.grasp_geometry import JawGeometry, fingers_blocked
from mpg_envs.grid.workspace import Workspace


@dataclass(frozen=True)
class FingerGeometry:
    """An env's grasp as seen on its heightmap.

    Attributes:
        workspace: the heightmap's grid (its ``resolution`` sizes the finger strips in pixels).
        grasp_depth: a grasp (or a move, which grasps the same way) brings the tool centre this
            far below the height at its pixel (metres) ...
        grasp_min_height: ... but no lower than this above the table (metres).
        jaw: the open gripper's fingers.
    """

    workspace: Workspace
    grasp_depth: float
    grasp_min_height: float
    jaw: JawGeometry = JawGeometry()

    def __post_init__(self) -> None:
        if not self.grasp_depth >= 0 or not self.grasp_min_height >= 0:
            raise ValueError(
                f"grasp_depth and grasp_min_height must be >= 0 metres, got {self.grasp_depth}, {self.grasp_min_height}"
            )

    def check_size(self, heightmap_size: int) -> None:
        """Fail when the workspace's grid is not the network's ``heightmap_size`` square."""
        if self.workspace.shape != (heightmap_size, heightmap_size):
            raise ValueError(
                f"the finger geometry's workspace is a {self.workspace.shape} grid; the network reads "
                f"{heightmap_size} x {heightmap_size} heightmaps"
            )

    def blocked(self, depth: np.ndarray, num_rotations: int) -> np.ndarray:
        """How far the open fingers of a grasp at every pixel and rotation land blocked,
        ``(B, R, H, W)`` float32 metres, from depth heightmaps ``(B, H, W)`` in metres
        (:func:`mpg_envs.grid.grasp_geometry.fingers_blocked` of each)."""
        res = self.workspace.resolution
        return np.stack(
            [fingers_blocked(d, res, self.grasp_depth, self.grasp_min_height, num_rotations, self.jaw) for d in depth]
        )
