"""Plane geometry of parallel-jaw grasps on the heightmap grid (pure functions).

Used by the scripted oracle and the grasp-ceiling benchmark: an object's footprint
rectangle and short axis, the nearest of the 16 rotations, the regions the two open
fingers sweep, and the highest point of the heightmap inside a polygon.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from mpg_envs.workspace import NUM_ROTATIONS, Workspace

GRASP_ROTATIONS = NUM_ROTATIONS // 2
"""Distinct grasp angles: a parallel jaw is the same turned by 180 degrees."""


def footprint_rect(points_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Minimum-area rectangle of 2-D points: centre, (long, short) sizes, short-axis angle.

    The angle (radians, in [0, pi)) is the direction of the rectangle's short side, i.e.
    the direction the fingers should close along.
    """
    (cx, cy), (w, h), angle = cv2.minAreaRect(np.asarray(points_xy, dtype=np.float32))
    a = math.radians(angle)
    # OpenCV's width runs along ``angle``; the short side is the one to close across.
    short_dir = a if w <= h else a + math.pi / 2
    return np.array([cx, cy]), np.array([max(w, h), min(w, h)]), short_dir % math.pi


def angle_to_rotation(theta: float, symmetric: bool = True) -> int:
    """Nearest rotation index to ``theta`` (radians); with ``symmetric`` taken mod 180 deg (0..7)."""
    step = 2 * math.pi / NUM_ROTATIONS
    k = int(round(theta / step)) % NUM_ROTATIONS
    return k % GRASP_ROTATIONS if symmetric else k


def other_grasp_angles(rotation: int) -> list[int]:
    """The grasp angles (0..GRASP_ROTATIONS-1) other than the one rotation index ``rotation`` gives."""
    return [k for k in range(GRASP_ROTATIONS) if k != int(rotation) % GRASP_ROTATIONS]


def angle_gap(a: float, b: float) -> float:
    """Distance between two grasp angles modulo pi (radians, in [0, pi/2])."""
    d = (a - b) % math.pi
    return min(d, math.pi - d)


def extent_along(points_xy: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> tuple[float, float]:
    """``(min, max)`` of the points' coordinates along a unit ``direction`` from ``origin``."""
    proj = (np.asarray(points_xy) - origin) @ direction
    return float(proj.min()), float(proj.max())


def finger_region(centre: np.ndarray, theta: float, side: int, inner: float, outer: float, half_width: float) -> np.ndarray:
    """Corners (4, 2) of the strip one finger sweeps: along ``side * (cos theta, sin theta)``
    from ``inner`` to ``outer`` metres off ``centre``, ``half_width`` to each side."""
    if side not in (-1, 1):
        raise ValueError(f"side must be -1 or 1, got {side!r}")
    if not outer > inner:
        raise ValueError(f"finger region must have outer > inner, got {inner} and {outer}")
    d = side * np.array([math.cos(theta), math.sin(theta)])
    n = np.array([-d[1], d[0]])
    c = np.asarray(centre, dtype=float)
    return np.array([c + d * inner + n * half_width, c + d * outer + n * half_width, c + d * outer - n * half_width, c + d * inner - n * half_width])


def polygon_mask(workspace: Workspace, corners_xy: np.ndarray) -> np.ndarray:
    """Boolean heightmap-shaped mask of the pixels whose centres lie in a convex polygon."""
    pts = (np.asarray(corners_xy, dtype=float) - (workspace.x_min, workspace.y_min)) / workspace.resolution - 0.5
    mask = np.zeros(workspace.shape, np.uint8)
    # Sub-pixel precision (4 bits) so thin strips are filled where their area lies.
    cv2.fillConvexPoly(mask, np.round(pts * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
    return mask > 0


def region_max(values: np.ndarray, mask: np.ndarray, outside: float = 0.0) -> float:
    """Largest value inside ``mask`` (``outside`` when the mask is empty, e.g. off the grid)."""
    return float(values[mask].max()) if mask.any() else outside


def jaw_strip_heights(
    s: np.ndarray, heights: np.ndarray, width: float, offset: float, open_inner: float, finger_thickness: float, margin: float
) -> tuple[float, float]:
    """Highest points under the two fingers of an open parallel jaw as they come down and close.

    ``s`` holds the coordinates along the closing direction of the heightmap pixels in the
    band the fingers sweep (measured from the object's middle), ``heights`` their heights.
    The object spans ``[-width/2, width/2]``; the jaw's centre is ``offset`` along that
    direction and its open fingers' inner faces ``open_inner`` from it, each finger
    ``finger_thickness`` thick. Each finger sweeps from its open position to the object's
    side (less ``margin``). Returns the highest height in the lower (-) and upper (+) strip,
    0 where a strip holds no pixel.
    """
    s = np.asarray(s, dtype=float)
    heights = np.asarray(heights, dtype=float)
    edge = width / 2 + margin
    low = (s <= -edge) & (s >= offset - open_inner - finger_thickness)
    high = (s >= edge) & (s <= offset + open_inner + finger_thickness)
    return region_max(heights, low), region_max(heights, high)
