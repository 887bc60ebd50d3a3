"""The cover estimate and the search region by hand (mpg_agents.locator.cover)."""

from __future__ import annotations

import numpy as np
import pytest

from mpg_agents.locator.cover import CoverRule, estimate_occluded, search_mask


def _query(area: int, height: float = 0.03) -> np.ndarray:
    query = np.zeros((40, 40), np.float32)
    query[:1, :area] = height  # `area` pixels of the object
    return query


def test_nothing_shown_is_covered_and_all_of_it_shown_is_not():
    depth = np.zeros((40, 40), np.float32)
    mask = np.zeros((40, 40), np.uint8)
    assert estimate_occluded(depth, mask, _query(10))
    mask[10:12, 10:15] = 1  # 10 pixels show: the whole exemplar's area
    depth[10:12, 10:15] = 0.03
    depth[12:16, 10:15] = 0.08  # a taller object right beside it
    assert not estimate_occluded(depth, mask, _query(10))


def test_part_shown_is_covered_only_with_something_higher_beside_it():
    depth = np.zeros((40, 40), np.float32)
    mask = np.zeros((40, 40), np.uint8)
    mask[10:12, 10:15] = 1  # 10 of the exemplar's 40 pixels show
    depth[10:12, 10:15] = 0.03
    assert not estimate_occluded(depth, mask, _query(40))  # nothing higher around: a smaller pose, not cover
    depth[12:14, 10:15] = 0.045  # 1.5 cm higher, within 4 pixels: something lies on it
    assert estimate_occluded(depth, mask, _query(40))
    assert not estimate_occluded(depth, mask, _query(40), CoverRule(higher_by=0.02))  # not 2 cm higher
    far = np.zeros_like(depth)
    far[10:12, 10:15], far[30:32, 30:35] = 0.03, 0.1  # the higher object is far away
    assert not estimate_occluded(far, mask, _query(40))


def test_the_search_region_is_the_largest_heap_high_enough_to_hide_the_object():
    depth = np.zeros((40, 40), np.float32)
    depth[0:3, 0:3] = 0.05  # 9 pixels high enough
    depth[20:26, 20:26] = 0.04  # 36 pixels high enough
    depth[30:40, 0:10] = 0.02  # 100 pixels, too low to hide a 3 cm object
    region = search_mask(depth, _query(5, 0.03))
    assert region.sum() == 36 and region[22, 22] == 1 and region.dtype == np.uint8
    assert not search_mask(np.zeros((40, 40), np.float32), _query(5)).any()
    empty = search_mask(depth, _query(5, 0.03), CoverRule(search="empty"))  # as the visible track shows it
    assert empty.shape == (40, 40) and empty.dtype == np.uint8 and not empty.any()


def test_a_bad_rule_is_named():
    with pytest.raises(ValueError, match="search must be one of"):
        CoverRule(search="everywhere")
    with pytest.raises(ValueError, match="area_share must not be negative"):
        CoverRule(area_share=-0.1)
