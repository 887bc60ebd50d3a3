"""Occlusion, visibility and change detection on heightmaps (pure functions).

Occlusion (paper, Stage III): crop the depth heightmap with the target mask and compare
its highest value with the target's own highest point taken from the simulator; the
target is occluded when something in its footprint stands higher than it. That is a flag:
a target with one corner under a neighbour counts as occluded. The visible fraction
measures it: the share of the target's footprint where the target is the top surface.

Change detection (VPG convention): enough pixels changed height by a plausible amount
anywhere, or around the target, or an object was grasped.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np


@dataclass(frozen=True)
class OcclusionConfig:
    """Tolerances of the occlusion check."""

    # Height above the target's top that counts as something lying on it (metres).
    tolerance: float = 0.01
    # Pixels eroded off the mask's rim: a neighbour touching the target's edge is beside
    # it, not on it, and heightmap pixels straddle both.
    erode_pixels: int = 2


@dataclass(frozen=True)
class ChangeConfig:
    """Thresholds of change detection (VPG's values)."""

    min_height_change: float = 0.01
    max_height_change: float = 0.3
    scene_pixels: int = 300
    target_pixels: int = 50
    target_dilation_pixels: int = 10


def is_occluded(
    depth: np.ndarray, target_mask: np.ndarray, target_top: float, config: OcclusionConfig = OcclusionConfig()
) -> bool:
    """Whether anything inside the target's footprint rises above the target's top.

    ``depth`` is the depth heightmap, ``target_mask`` the target's footprint (nonzero
    inside), ``target_top`` the height of the target's highest point.
    """
    _check_same_shape(depth, target_mask)
    mask: np.ndarray = target_mask.astype(np.uint8)
    if config.erode_pixels > 0:
        eroded = cv2.erode(mask, np.ones((3, 3), np.uint8), iterations=config.erode_pixels)
        # A target thinner than the erosion keeps its original footprint.
        mask = eroded if eroded.any() else mask
    inside = mask > 0
    if not inside.any():
        return False
    return bool(depth[inside].max() > target_top + config.tolerance)


def visible_fraction(target_mask: np.ndarray, top_geom: np.ndarray, target_geoms: np.ndarray) -> float | None:
    """Share of the target's footprint where the target itself is the top surface.

    ``target_mask`` is the target's whole footprint seen from above (covered parts
    included: the ``mask`` observation), ``top_geom`` the id of the geom seen first from
    above at each pixel (-1 where none), ``target_geoms`` the target's geom ids. 1.0 means
    nothing lies on the target, 0.0 that every footprint pixel shows something else.
    ``None`` when the footprint is empty (no target in view).
    """
    _check_same_shape(top_geom, target_mask)
    inside = target_mask > 0
    count = int(inside.sum())
    if count == 0:
        return None
    on_target = np.isin(top_geom[inside], np.asarray(target_geoms).reshape(-1))
    return float(on_target.sum()) / count


VISIBILITY_BANDS: tuple[tuple[float, float], ...] = ((0.0, 0.1), (0.1, 0.3), (0.3, 0.6), (0.6, 1.0))
"""Bands of the target's visible fraction at reset that results are reported by: each
includes its lower bound and excludes its upper one, except the last, which ends at 1."""

VISIBILITY_BAND_LABELS: tuple[str, ...] = tuple(f"{low:g}-{high:g}" for low, high in VISIBILITY_BANDS)
"""The bands' labels in :data:`VISIBILITY_BANDS`' order (``"0-0.1"``, ``"0.1-0.3"``, ...), as
:func:`visibility_band` names them and the results report them."""


def visibility_band(value: float | None) -> str | None:
    """The :data:`VISIBILITY_BANDS` label (``"0.1-0.3"``) of a visible fraction, ``None`` for none."""
    if value is None:
        return None
    if not 0.0 <= value <= 1.0:
        raise ValueError(f"a visible fraction lies in [0, 1], got {value!r}")
    for (low, high), label in zip(VISIBILITY_BANDS, VISIBILITY_BAND_LABELS):
        if low <= value < high or value == high == VISIBILITY_BANDS[-1][1]:
            return label
    raise AssertionError("the bands cover [0, 1]")


def in_band(value: float | None, band: tuple[float, float] | None) -> bool:
    """Whether ``value`` lies in the closed interval ``band`` (always true without a band)."""
    if band is None:
        return True
    return value is not None and band[0] <= value <= band[1]


def check_band(band: object, name: str = "visible_range") -> tuple[float, float] | None:
    """``band`` as a ``(low, high)`` pair of fractions with 0 <= low <= high <= 1, or ``None``;
    raises ``ValueError`` naming ``name`` otherwise."""
    if band is None:
        return None
    try:
        pair: Any = band  # anything: checked here
        low, high = (float(v) for v in pair)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (low, high) pair of fractions, got {band!r}") from None
    if not 0.0 <= low <= high <= 1.0:
        raise ValueError(f"{name} must satisfy 0 <= low <= high <= 1, got {band!r}")
    return (low, high)


def changed_pixels(before: np.ndarray, after: np.ndarray, config: ChangeConfig = ChangeConfig()) -> np.ndarray:
    """Boolean map of pixels whose height changed by a plausible amount."""
    _check_same_shape(before, after)
    diff = np.abs(after.astype(np.float32) - before.astype(np.float32))
    return (diff > config.min_height_change) & (diff < config.max_height_change)


def change_detected(
    before: np.ndarray,
    after: np.ndarray,
    target_mask: np.ndarray | None = None,
    lifted: bool = False,
    config: ChangeConfig = ChangeConfig(),
) -> bool:
    """VPG's change test: > 300 changed pixels, > 50 around the target, or an object lifted."""
    if lifted:
        return True
    changed = changed_pixels(before, after, config)
    if int(changed.sum()) > config.scene_pixels:
        return True
    if target_mask is not None and target_mask.any():
        _check_same_shape(before, target_mask)
        size = 2 * config.target_dilation_pixels + 1
        near = cv2.dilate(target_mask.astype(np.uint8), np.ones((size, size), np.uint8)) > 0
        return int(changed[near].sum()) > config.target_pixels
    return False


def _check_same_shape(a: np.ndarray, b: np.ndarray) -> None:
    if a.shape[:2] != b.shape[:2]:
        raise ValueError(f"heightmaps must have the same shape, got {a.shape} and {b.shape}")


def surrounded_sectors(
    depth: np.ndarray, target_mask: np.ndarray, reach_pixels: int = 15, sectors: int = 8, occupied_height: float = 0.005
) -> int:
    """In how many of ``sectors`` directions around the target an object lies within reach.

    The ring of pixels within ``reach_pixels`` of the target's footprint is split into equal
    angular sectors about the footprint's centre; a sector counts when some ring pixel in it
    is occupied (higher than ``occupied_height``). 8 of 8 means boxed in on every side.
    """
    _check_same_shape(depth, target_mask)
    mask = target_mask > 0
    if not mask.any():
        return 0
    size = 2 * reach_pixels + 1
    ring = (cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))) > 0) & ~mask
    rows, cols = np.nonzero(ring & (depth > occupied_height))
    if rows.size == 0:
        return 0
    cr, cc = np.argwhere(mask).mean(axis=0)
    angles = np.arctan2(rows - cr, cols - cc) % (2 * np.pi)
    return int(np.unique((angles / (2 * np.pi / sectors)).astype(int) % sectors).size)
