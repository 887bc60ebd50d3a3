"""Plane geometry of parallel-jaw grasps on the heightmap grid (pure functions).

Used by the scripted oracle, the grasp-ceiling benchmark and MPGNet's finger mask: an
object's footprint rectangle and short axis, the nearest of the 16 rotations, the regions the
two open fingers sweep, the highest point of the heightmap inside a polygon, and for every
pixel and rotation at once how far the open fingers' landing strips are blocked
(:func:`fingers_blocked`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from mpg_envs.grid.workspace import NUM_ROTATIONS, Workspace

GRASP_ROTATIONS = NUM_ROTATIONS // 2
"""Distinct grasp angles: a parallel jaw is the same turned by 180 degrees."""


@dataclass(frozen=True)
class JawGeometry:
    """The open Robotiq 2F-85 seen from above, as a grasp primitive brings it down (metres).

    Each open finger's pad is a strip ``finger_thickness`` thick along the closing direction,
    its inner face ``finger_open_inner`` from the jaw's centre, ``2 * finger_half_width``
    wide across the jaw (the sizes carry a margin). The pads' lower edge lies
    ``pad_below_tcp`` below the tool centre point; a strip is free when nothing in it rises
    above that edge plus ``finger_clearance`` (the pads push a few millimetres aside).
    """

    finger_open_inner: float = 0.0425
    finger_thickness: float = 0.0095
    finger_half_width: float = 0.013
    pad_below_tcp: float = 0.005
    finger_clearance: float = 0.004

    def __post_init__(self) -> None:
        for name in ("finger_open_inner", "finger_thickness", "finger_half_width"):
            if not getattr(self, name) > 0:
                raise ValueError(f"JawGeometry.{name} must be > 0 metres, got {getattr(self, name)}")


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
    return np.array(
        [
            c + d * inner + n * half_width,
            c + d * outer + n * half_width,
            c + d * outer - n * half_width,
            c + d * inner - n * half_width,
        ]
    )


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


def finger_landing_kernel(theta: float, resolution: float, jaw: JawGeometry = JawGeometry()) -> np.ndarray:
    """Where the two open fingers come down, relative to the grasp pixel: a square ``uint8``
    kernel (odd side, the grasp pixel at its centre) marking the pixels whose centres lie in
    either pad's strip for a jaw closing along world direction ``theta`` (radians; +x is
    +column, +y is +row). Symmetric under a half turn, as a parallel jaw is."""
    if not resolution > 0:
        raise ValueError(f"resolution must be > 0 metres per pixel, got {resolution}")
    outer = jaw.finger_open_inner + jaw.finger_thickness
    radius = int(math.ceil(math.hypot(outer, jaw.finger_half_width) / resolution))
    dr, dc = np.mgrid[-radius : radius + 1, -radius : radius + 1] * resolution
    s = dc * math.cos(theta) + dr * math.sin(theta)  # along the closing direction
    t = -dc * math.sin(theta) + dr * math.cos(theta)  # across the jaw
    eps = 1e-9  # pixel centres exactly on a strip's edge count as inside, whatever the float error
    inside = (
        (np.abs(t) <= jaw.finger_half_width + eps) & (np.abs(s) >= jaw.finger_open_inner - eps) & (np.abs(s) <= outer + eps)
    )
    return inside.astype(np.uint8)


def fingers_blocked(
    depth: np.ndarray,
    resolution: float,
    grasp_depth: float,
    grasp_min_height: float,
    num_rotations: int = NUM_ROTATIONS,
    jaw: JawGeometry = JawGeometry(),
) -> np.ndarray:
    """How far the open fingers' landing strips are blocked, for a grasp at every pixel and
    rotation: ``(num_rotations, H, W)`` float32 metres.

    Rotation ``k`` closes along ``k * 2 pi / num_rotations``. A grasp at pixel ``p`` brings the
    tool centre down to ``max(depth[p] - grasp_depth, grasp_min_height)`` (as the grasp
    primitive does); the value is the highest point of ``depth`` under either pad's strip
    (:func:`finger_landing_kernel`) minus the pads' lower edge plus the clearance. ``<= 0``:
    both fingers come down on free space; ``> 0``: that many metres of something stand in
    their way. Off the grid counts as table (height 0).
    """
    depth = np.asarray(depth, dtype=np.float32)
    if depth.ndim != 2:
        raise ValueError(f"depth must be a (H, W) heightmap, got shape {depth.shape}")
    if num_rotations < 1:
        raise ValueError(f"num_rotations must be >= 1, got {num_rotations}")
    limit = np.maximum(depth - grasp_depth, grasp_min_height) - jaw.pad_below_tcp + jaw.finger_clearance
    out = np.empty((num_rotations, *depth.shape), dtype=np.float32)
    half = num_rotations // 2 if num_rotations % 2 == 0 else None
    for k in range(num_rotations):
        if half is not None and k >= half:
            out[k] = out[k - half]  # a half turn later the same jaw comes down
            continue
        # cv2.dilate takes, at each pixel, the max over the kernel's offsets: the strips' highest point.
        kernel = finger_landing_kernel(k * 2 * math.pi / num_rotations, resolution, jaw)
        out[k] = cv2.dilate(depth, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0.0) - limit
    return out
