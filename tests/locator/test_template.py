"""The exemplar's height profile fitted to a scene's candidate, by hand (mpg_agents.locator.template)."""

from __future__ import annotations

import numpy as np
import pytest

from mpg_agents.locator.template import (
    component_of,
    component_parts,
    grow_by_fit,
    pick_candidate,
    rated_parts,
    template_fit,
)


def _box(rows: slice, cols: slice, height: float, size: int = 120) -> tuple[np.ndarray, np.ndarray]:
    heights = np.zeros((size, size), np.float32)
    heights[rows, cols] = height
    return heights, heights > 0.002


def test_the_same_box_turned_a_quarter_and_moved_fits_perfectly():
    query = _box(slice(50, 60), slice(40, 70), 0.03)  # 10 x 30 pixels, 3 cm high
    scene = _box(slice(10, 40), slice(80, 90), 0.03)  # the same box turned 90 degrees elsewhere
    assert template_fit(*query, *scene) == pytest.approx(1.0, abs=1e-6)


def test_a_box_of_another_footprint_fits_by_its_overlap_over_the_union():
    query = _box(slice(50, 60), slice(40, 70), 0.03)  # 10 x 30 = 300 pixels
    scene = _box(slice(10, 40), slice(10, 20), 0.03)  # 30 x 10: the same; now a 20 x 20 square
    square = _box(slice(10, 30), slice(10, 30), 0.03)  # 400 pixels; best overlap 10 x 20 = 200
    # Quarter turns only (a diagonal turn overlaps more); on every second pixel: 5 x 15 = 75
    # and 10 x 10 = 100 samples, overlap 5 x 10 = 50.
    assert template_fit(*query, *square, yaws=4, stride=2) == pytest.approx(50 / (75 + 100 - 50), abs=1e-6)
    assert template_fit(*query, *scene, stride=2) == pytest.approx(1.0, abs=1e-6)


def test_a_taller_box_of_the_same_footprint_is_discounted_by_the_height_difference():
    query = _box(slice(50, 60), slice(40, 70), 0.03)
    taller = _box(slice(50, 60), slice(40, 70), 0.05)  # 2 cm higher everywhere
    assert template_fit(*query, *taller) == pytest.approx(np.exp(-0.02 / 0.01), rel=1e-4)


def test_a_covered_candidate_is_judged_by_the_part_that_shows():
    query = _box(slice(50, 60), slice(40, 72), 0.03)  # 10 x 32
    half = _box(slice(50, 60), slice(40, 56), 0.03)  # half of the box shows
    assert template_fit(*query, *half, covered=True) == pytest.approx(1.0, abs=1e-6)
    assert template_fit(*query, *half, stride=2) == pytest.approx(0.5, abs=1e-6)  # uncovered: half the union


def test_nothing_to_fit_gives_zero_and_bad_input_is_named():
    query = _box(slice(50, 60), slice(40, 70), 0.03)
    empty = np.zeros((120, 120), np.float32)
    assert template_fit(*query, empty, empty > 0) == 0.0
    with pytest.raises(ValueError, match="same shape"):
        template_fit(query[0], query[1][:10], *query)
    with pytest.raises(ValueError, match="yaws"):
        template_fit(*query, *query, yaws=0)


def test_the_component_of_a_blob_is_the_object_of_the_colour_standing_high_enough_that_holds_it():
    gap = np.full((20, 20), 50.0, np.float32)
    heights = np.zeros((20, 20), np.float32)
    gap[2:6, 2:6], heights[2:6, 2:6] = 5.0, 0.03  # 16 pixels of the colour, standing: kept
    gap[10:12, 10:12], heights[10:12, 10:12] = 5.0, 0.03  # 4 pixels: under min_pixels
    gap[15:19, 2:6], heights[15:19, 2:6] = 5.0, 0.001  # of the colour, but flat on the table
    heights[15:19, 12:16] = 0.03  # standing, of another colour

    def blob(rows: slice, cols: slice) -> np.ndarray:
        pixels = np.zeros((20, 20), bool)
        pixels[rows, cols] = True
        return pixels

    part = component_of(blob(slice(3, 5), slice(3, 5)), gap, heights, 14.0, 0.005, 5)
    assert part is not None and part.sum() == 16 and part[2:6, 2:6].all()
    for rows, cols in ((slice(10, 12), slice(10, 12)), (slice(15, 19), slice(2, 6)), (slice(15, 19), slice(12, 16))):
        assert component_of(blob(rows, cols), gap, heights, 14.0, 0.005, 5) is None
    # A blob reaching over two parts belongs to the one holding most of it.
    gap[2:6, 8:10], heights[2:6, 8:10] = 5.0, 0.03  # a second part, 8 pixels
    part = component_of(blob(slice(2, 6), slice(5, 10)), gap, heights, 14.0, 0.005, 5)
    assert part is not None and part.sum() == 8 and part[2:6, 8:10].all()


def test_pick_candidate_weighs_mean_probability_by_fit_and_stops_when_no_better_can_come():
    probability = np.zeros((10, 10), np.float32)
    a, b, c = (np.zeros((10, 10), bool) for _ in range(3))
    a[0:2, 0:2], b[5:7, 5:7], c[8:10, 0:2] = True, True, True
    probability[a], probability[b], probability[c] = 0.9, 0.6, 0.2
    weighed = []

    def fit(k: int) -> float:
        weighed.append(k)
        return 0.5 if k == 0 else 1.0

    assert pick_candidate(probability, [a, b, c], fit) == 1  # 0.9 * 0.5 < 0.6 * 1.0
    assert weighed == [0, 1]  # c (0.2) cannot beat 0.6: never weighed
    assert pick_candidate(probability, [], fit) is None
    assert pick_candidate(probability, [a], lambda k: 0.0) is None


def test_component_parts_cut_away_a_touching_blob_the_network_does_not_rate():
    probability = np.zeros((10, 10), np.float32)
    component = np.zeros((10, 10), bool)
    component[0:4, 0:8] = True  # two objects of one colour side by side
    left, right = np.zeros((10, 10), bool), np.zeros((10, 10), bool)
    left[0:4, 0:4], right[0:4, 4:8] = True, True
    probability[left], probability[right] = 0.8, 0.05  # 0.05 < 0.1 * 0.8
    assert np.array_equal(component_parts(probability, component, [left, right], 0.1), left)
    assert np.array_equal(component_parts(probability, component, [], 0.1), component)  # no blob: all of it


def test_grow_by_fit_keeps_a_part_that_fits_as_well_and_leaves_one_that_fits_worse():
    chosen, half, other = (np.zeros((6, 6), bool) for _ in range(3))
    chosen[0:2, 0:3], half[2:4, 0:3], other[0:2, 3:6] = True, True, True
    asked: list[tuple[int, bool]] = []

    def fit(pixels: np.ndarray, covered: bool) -> float:
        asked.append((int(pixels.sum()), covered))
        return 0.9 if not (pixels & other).any() else 0.2  # the chosen blob with its other half: the exemplar

    grown = grow_by_fit(chosen, False, 0.4, [(other, False), (half, True)], fit)
    assert np.array_equal(grown, chosen | half)
    assert asked == [(12, False), (12, True)]  # tried in the order given; a covered part makes the object covered
    assert np.array_equal(grow_by_fit(chosen, False, 0.4, [], fit), chosen) and grown is not chosen


def test_rated_parts_are_the_blobs_inside_rated_near_the_best_highest_first():
    probability = np.zeros((10, 10), np.float32)
    component = np.zeros((10, 10), bool)
    component[0:4, 0:9] = True
    left, middle, right, outside = (np.zeros((10, 10), bool) for _ in range(4))
    left[0:4, 0:3], middle[0:4, 3:6], right[0:4, 6:9], outside[5:9, 0:3] = True, True, True, True
    probability[left], probability[middle], probability[right], probability[outside] = 0.3, 0.8, 0.05, 0.9
    # outside lies off the component; right rates under 0.1 of the best inside (0.8)
    assert rated_parts(probability, component, [left, middle, right, outside], 0.1) == [1, 0]
    assert rated_parts(probability, component, [outside], 0.1) == []
    with pytest.raises(ValueError, match=r"share must lie in \(0, 1\]"):
        rated_parts(probability, component, [left], 1.5)
