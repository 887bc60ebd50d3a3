"""Sizing outside objects for the Robotiq 2F-85: the extent range the blocks keep, and the scale that fits it.

Objects from outside come in every size. :data:`BLOCKS_EXTENTS` is the range the generated
blocks keep (every bounding-box extent 2.5-10 cm, the two smallest at most 6 cm, so some
width fits the 85 mm opening with margin in any resting pose); :func:`fit_scale` is the
scale nearest 1 that brings an object's extents into such a range. Pure maths, no files.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ExtentRange:
    """Allowed bounding-box extents (m) of an object: each in ``[min_extent, max_extent]``,
    and the two smallest at most ``max_two_smallest``."""

    min_extent: float
    max_extent: float
    max_two_smallest: float

    def __post_init__(self) -> None:
        values = (self.min_extent, self.max_extent, self.max_two_smallest)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in values):
            raise ValueError(f"extent range bounds must be positive numbers, got {values}")
        if not self.min_extent <= self.max_two_smallest <= self.max_extent:
            raise ValueError(f"extent range needs min_extent <= max_two_smallest <= max_extent, got {values}")

    def contains(self, extents: Sequence[float], tolerance: float = 1e-9) -> bool:
        """Whether ``extents`` (3 values, m) lie in the range (up to ``tolerance``)."""
        e = np.sort(np.asarray(extents, dtype=np.float64))
        return bool(
            e[0] >= self.min_extent - tolerance
            and e[2] <= self.max_extent + tolerance
            and e[1] <= self.max_two_smallest + tolerance
        )


BLOCKS_EXTENTS = ExtentRange(min_extent=0.025, max_extent=0.10, max_two_smallest=0.06)
"""The blocks' range, sized for the 2F-85 (85 mm opening)."""


class FitError(ValueError):
    """No uniform scale brings an object's extents into the range."""


def scale_bounds(extents: Sequence[float] | np.ndarray, extent_range: ExtentRange) -> tuple[float, float]:
    """The interval ``[low, high]`` of uniform scales that put ``extents`` in ``extent_range``.

    With sorted extents ``e1 <= e2 <= e3``: ``low = min_extent / e1`` and
    ``high = min(max_extent / e3, max_two_smallest / e2)``; empty (``low > high``) when the
    object is too slender or too flat for the range.

    Raises:
        ValueError: not three positive finite extents.
    """
    e = np.asarray(extents, dtype=np.float64)
    if e.shape != (3,) or not np.all(np.isfinite(e)) or not np.all(e > 0):
        raise ValueError(f"extents must be three positive finite lengths, got {np.asarray(extents).tolist()}")
    e = np.sort(e)
    low = extent_range.min_extent / e[0]
    high = min(extent_range.max_extent / e[2], extent_range.max_two_smallest / e[1])
    return float(low), float(high)


def fit_scale(extents: Sequence[float] | np.ndarray, extent_range: ExtentRange = BLOCKS_EXTENTS) -> float:
    """The uniform scale nearest 1 that puts ``extents`` (m) in ``extent_range``.

    An object already in range keeps its size (1.0); a larger one shrinks just enough, a
    smaller one grows just enough, so a set keeps its spread of sizes where it can.

    Raises:
        FitError: no scale fits (the message gives the extents and why: the smallest extent
            would have to grow past what the others allow).
        ValueError: not three positive finite extents.
    """
    low, high = scale_bounds(extents, extent_range)
    if low > high * (1.0 + 1e-12):
        e = np.sort(np.asarray(extents, dtype=np.float64))
        raise FitError(
            f"extents {np.round(e * 100, 2).tolist()} cm cannot be scaled into the range (every extent "
            f"{extent_range.min_extent * 100:g}-{extent_range.max_extent * 100:g} cm, the two smallest at most "
            f"{extent_range.max_two_smallest * 100:g} cm): the smallest would need a scale of at least {low:.3g}, "
            f"the others allow at most {high:.3g} (too slender or too flat)"
        )
    return float(min(max(1.0, low), high))
