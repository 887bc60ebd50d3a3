"""What the locator's mask says of cover, and where a hidden target may lie: pure numpy and
OpenCV, unit-tested by hand.

MPGNet reads the target's mask and the "occluded" flag the simulator gives in mask mode. From
a camera there is no simulator: :func:`estimate_occluded` says the target is covered when
little of it shows (less than :attr:`CoverRule.area_share` of the exemplar's top-view area)
and something next to the part that shows stands higher than it (an object lying on it).
While the target is not seen at all, :func:`search_mask` names where it may hide, by one of
:data:`SEARCHES` (the rule's ``search``): ``"heap"``, the largest region of the heap standing
high enough to cover the exemplar's object (moving what stands there uncovers it, or shows it is
not there); ``"empty"``, nothing, as the visible track shows a hidden target (an empty mask
flagged covered, on which MPGNet moves and pushes the heap itself). Which, and the settings, are
chosen on tuning seeds and travel with the locator's weights.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import cv2
import numpy as np

from mpg_agents.locator.features import query_pixels

SEARCHES = ("heap", "empty")
"""What :func:`search_mask` names while the target is not seen (see the module docstring)."""


@dataclass(frozen=True)
class CoverRule:
    """The settings of :func:`estimate_occluded` and :func:`search_mask` (metres, pixels).

    Raises:
        ValueError: ``search`` is not one of :data:`SEARCHES`, or a setting is negative.
    """

    area_share: float = 0.8  # less of the exemplar's top-view area than this shows: maybe covered
    ring_px: int = 4  # the neighbourhood of the visible part that is looked at
    higher_by: float = 0.01  # a neighbour this much higher than the visible top lies on the target
    cover_margin: float = 0.005  # a heap covers the object where it stands this much above the object's height
    search: str = "heap"  # one of SEARCHES
    misfit_motions: int = 0  # decisions per episode a located object that misfits the exemplar is taken as covered

    def __post_init__(self) -> None:
        if self.search not in SEARCHES:
            raise ValueError(f"CoverRule.search must be one of {SEARCHES}, got {self.search!r}")
        for name in ("area_share", "ring_px", "higher_by", "cover_margin", "misfit_motions"):
            if getattr(self, name) < 0:
                raise ValueError(f"CoverRule.{name} must not be negative, got {getattr(self, name)}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def estimate_occluded(depth: np.ndarray, mask: np.ndarray, query_depth: np.ndarray, rule: CoverRule = CoverRule()) -> bool:
    """Whether the target whose visible pixels are ``mask`` in the heightmap ``depth`` is
    covered, judged against the exemplar's ``query_depth``: nothing shows, or less than
    ``rule.area_share`` of the exemplar's area shows and a pixel within ``rule.ring_px`` of it
    stands ``rule.higher_by`` above the visible part's top."""
    shown = np.asarray(mask) > 0
    if not shown.any():
        return True
    if shown.sum() >= rule.area_share * query_pixels(query_depth).sum():
        return False
    kernel = np.ones((2 * rule.ring_px + 1, 2 * rule.ring_px + 1), np.uint8)
    ring = (cv2.dilate(shown.astype(np.uint8), kernel) > 0) & ~shown
    top = float(np.percentile(np.asarray(depth)[shown], 90))
    return bool(np.any(np.asarray(depth)[ring] > top + rule.higher_by))


def search_mask(depth: np.ndarray, query_depth: np.ndarray, rule: CoverRule = CoverRule()) -> np.ndarray:
    """Where a hidden target may lie (uint8 map): by the ``"heap"`` search, the largest
    connected region of ``depth`` standing at least the exemplar's height (its top in
    ``query_depth``) plus ``rule.cover_margin``, empty when nothing stands that high; by the
    ``"empty"`` search, nothing."""
    if rule.search == "empty":
        return np.zeros(np.shape(depth), np.uint8)
    shown = query_pixels(query_depth)
    height = float(np.asarray(query_depth)[shown].max()) if shown.any() else 0.0
    tall = (np.asarray(depth) >= height + rule.cover_margin).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(tall, connectivity=8)
    if count <= 1:
        return np.zeros_like(tall)
    largest = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return (labels == largest).astype(np.uint8)
