"""The workspace and its heightmap grid: pure geometry, no simulator.

Conventions (as on the Environments page of the documentation): the robot base sits at the
world origin facing +x; the workspace is
x in [0.276, 0.724], y in [-0.224, 0.224], z in [0, 0.4] metres above the table top. A
heightmap pixel ``(row, col)`` covers ``y`` (rows) and ``x`` (columns):
``row = floor((y - y_min) / res)``, ``col = floor((x - x_min) / res)``.

Rotation ``k`` is the angle ``theta_k = k * 22.5 deg`` about +z, measured from the +x axis
(image columns) toward +y (image rows). For push it is the push direction; for grasp and
move it is the direction along which the two fingers close.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

NUM_ROTATIONS = 16
"""Number of discrete orientations of every primitive (22.5 degrees apart)."""


@dataclass(frozen=True)
class Workspace:
    """An axis-aligned box above the table and its heightmap grid."""

    x_min: float = 0.276
    x_max: float = 0.724
    y_min: float = -0.224
    y_max: float = 0.224
    z_min: float = 0.0
    z_max: float = 0.4
    resolution: float = 0.002

    def __post_init__(self) -> None:
        if not (self.x_max > self.x_min and self.y_max > self.y_min and self.z_max > self.z_min):
            raise ValueError(f"workspace bounds must be increasing, got {self}")
        if self.resolution <= 0:
            raise ValueError(f"resolution must be positive, got {self.resolution}")

    @property
    def shape(self) -> tuple[int, int]:
        """Heightmap shape ``(rows, cols)``; 224 x 224 for the default workspace."""
        rows = int(round((self.y_max - self.y_min) / self.resolution))
        cols = int(round((self.x_max - self.x_min) / self.resolution))
        return rows, cols

    @property
    def center(self) -> np.ndarray:
        """Centre of the workspace on the table top, ``(x, y, 0)``."""
        return np.array([(self.x_min + self.x_max) / 2, (self.y_min + self.y_max) / 2, self.z_min])

    def contains_xy(self, x: np.ndarray | float, y: np.ndarray | float) -> np.ndarray | bool:
        """Whether world points lie inside the workspace footprint (bounds inclusive)."""
        x, y = np.asarray(x), np.asarray(y)
        inside = (x >= self.x_min) & (x <= self.x_max) & (y >= self.y_min) & (y <= self.y_max)
        return inside if inside.ndim else bool(inside)

    def pixel_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """World ``(x, y)`` of every pixel centre, each of heightmap shape."""
        rows, cols = self.shape
        xs = self.x_min + (np.arange(cols) + 0.5) * self.resolution
        ys = self.y_min + (np.arange(rows) + 0.5) * self.resolution
        gx, gy = np.meshgrid(xs, ys)
        return gx, gy


def check_pixel(workspace: Workspace, row: int, col: int) -> None:
    """Raise ``ValueError`` naming the valid range unless ``(row, col)`` is on the grid."""
    rows, cols = workspace.shape
    for name, value, size in (("row", row, rows), ("col", col, cols)):
        if not _is_int(value) or not 0 <= int(value) < size:
            raise ValueError(f"pixel {name} must be an integer in 0..{size - 1}, got {value!r}")


def check_rotation(rotation: int) -> None:
    """Raise ``ValueError`` unless ``rotation`` is an integer in ``0..15``."""
    if not _is_int(rotation) or not 0 <= int(rotation) < NUM_ROTATIONS:
        raise ValueError(f"rotation must be an integer in 0..{NUM_ROTATIONS - 1}, got {rotation!r}")


def pixel_to_world(workspace: Workspace, row: float, col: float) -> tuple[float, float]:
    """World ``(x, y)`` of the centre of pixel ``(row, col)``."""
    x = workspace.x_min + (col + 0.5) * workspace.resolution
    y = workspace.y_min + (row + 0.5) * workspace.resolution
    return float(x), float(y)


def world_to_pixel(workspace: Workspace, x: float, y: float) -> tuple[int, int]:
    """Pixel ``(row, col)`` containing world point ``(x, y)`` (may lie off the grid)."""
    # The tiny epsilon puts points lying exactly on a pixel edge (up to float error, e.g.
    # x = 0.5 is 0.22399999999999998 past x_min) in the pixel that starts there.
    row = math.floor((y - workspace.y_min) / workspace.resolution + 1e-9)
    col = math.floor((x - workspace.x_min) / workspace.resolution + 1e-9)
    return int(row), int(col)


def rotation_angle(rotation: int) -> float:
    """Angle in radians of rotation index ``k``: ``k * 2 pi / 16``."""
    check_rotation(rotation)
    return int(rotation) * 2.0 * math.pi / NUM_ROTATIONS


def rotation_direction(rotation: int) -> np.ndarray:
    """Unit world vector ``(dx, dy)`` of rotation index ``k``."""
    theta = rotation_angle(rotation)
    return np.array([math.cos(theta), math.sin(theta)])


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))
