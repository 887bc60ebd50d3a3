"""How well a part of the scene shows the exemplar's object, by its height profile turned to
every yaw: pure numpy and OpenCV, unit-tested by hand.

The matcher's shape score (:func:`~mpg_envs.perception.exemplar_match.shape_score`) judges a
blob by the box of the exemplar's extents, which is right for the blocks and says little of an
irregular object. An object that rests in the pose the exemplar shows it in, turned about the
vertical, shows the exemplar's heights turned by some yaw (one leaning on another object in a
heap does not, and fits badly). :func:`template_fit` turns the exemplar's heights above its table through
:data:`YAWS` and slides them a few pixels over the candidate's heights above the scene's table,
and keeps the best agreement: the share of the two footprints that overlap (of the candidate's
alone when it is covered, whose hidden part cannot show), discounted by how far the
overlapping heights differ (all shifts of one yaw at once, as correlations). 1 is a perfect
fit; an object of another shape fits worse at every yaw. :func:`pick_candidate`,
:func:`component_of`, :func:`rated_parts`, :func:`component_parts` and :func:`grow_by_fit` are
the small steps the locator's ``"template"`` snapping takes around it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

YAWS = 16
"""Yaws tried, evenly over a turn (22.5 degrees apart, as the actions' rotations; 24 located
no better on tuning scenes)."""
SHIFT_PX = 6
"""Pixels the turned exemplar may slide each way over the candidate (centroids of a partly
shown object and of the whole one differ)."""
STRIDE = 3
"""The fit is worked on every this many pixels each way (6 mm at the default workspace: a
ninth of the work; every second pixel located no better on tuning scenes)."""
HEIGHT_SCALE = 0.01
"""Metres of root-mean-square height difference over the overlap that divide the fit by e
(``exp(-difference / HEIGHT_SCALE)``)."""


def _crop(values: np.ndarray, pixels: np.ndarray, size: int) -> np.ndarray:
    """``size`` x ``size`` of ``values`` on ``pixels`` (0 elsewhere), centred on their centroid."""
    rows, cols = np.nonzero(pixels)
    half = size // 2
    top, left = int(round(rows.mean())) - half, int(round(cols.mean())) - half
    out = np.zeros((size, size), np.float32)
    r0, c0 = max(top, 0), max(left, 0)
    r1, c1 = min(top + size, pixels.shape[0]), min(left + size, pixels.shape[1])
    window = (slice(r0, r1), slice(c0, c1))
    out[r0 - top : r1 - top, c0 - left : c1 - left] = np.where(pixels[window], values[window], 0.0)
    return out


@dataclass(frozen=True, eq=False)
class ExemplarTemplate:
    """The exemplar as :func:`fit_template` compares it, worked out once per exemplar
    (:func:`exemplar_template`): per yaw, its turned footprint (``on``, 0 or 1) and the
    3-channel template ``[heights^2, footprint, -2 heights]`` of the squared height differences,
    ``size`` pixels square, on every ``stride``-th pixel of the heightmaps."""

    on: tuple[np.ndarray, ...]
    squares: tuple[np.ndarray, ...]
    size: int
    stride: int


def exemplar_template(
    query_heights: np.ndarray, query_pixels: np.ndarray, yaws: int = YAWS, stride: int = STRIDE
) -> ExemplarTemplate | None:
    """The exemplar (``query_heights`` above its table, metres, and its object's
    ``query_pixels``) turned through ``yaws`` yaws, on every ``stride``-th pixel (``None`` when
    no pixel shows the object).

    Raises:
        ValueError: the arrays' shapes differ, or ``yaws`` or ``stride`` is below 1.
    """
    query_heights, query_pixels = np.asarray(query_heights, np.float32), np.asarray(query_pixels, bool)
    if query_heights.shape != query_pixels.shape:
        raise ValueError(f"heights and pixels must have the same shape: query {query_heights.shape} and {query_pixels.shape}")
    if yaws < 1 or stride < 1:
        raise ValueError(f"yaws and stride must be >= 1; got {yaws}, {stride}")
    query_heights, query_pixels = query_heights[::stride, ::stride], query_pixels[::stride, ::stride]
    if not query_pixels.any():
        return None
    size = 2 * _radius(query_pixels) + 3  # holds the object at any yaw
    query = _crop(query_heights, query_pixels, size)
    query_on = _crop(np.ones_like(query_heights), query_pixels, size)
    centre = ((size - 1) / 2.0, (size - 1) / 2.0)
    on, squares = [], []
    for k in range(yaws):
        turn = cv2.getRotationMatrix2D(centre, 360.0 * k / yaws, 1.0)
        turned = cv2.warpAffine(query, turn, (size, size), flags=cv2.INTER_NEAREST)
        turned_on = (cv2.warpAffine(query_on, turn, (size, size), flags=cv2.INTER_NEAREST) > 0.5).astype(np.float32)
        on.append(turned_on)
        squares.append(np.dstack([turned * turned, turned_on, -2.0 * turned]))
    return ExemplarTemplate(tuple(on), tuple(squares), size, stride)


def fit_template(
    template: ExemplarTemplate | None,
    heights: np.ndarray,
    pixels: np.ndarray,
    covered: bool = False,
    shift_px: int = SHIFT_PX,
    height_scale: float = HEIGHT_SCALE,
) -> float:
    """The best fit, in [0, 1], of the exemplar's ``template`` (:func:`exemplar_template`) to the
    candidate ``pixels`` of the scene's ``heights`` (above the table, metres), over its yaws and
    shifts of up to ``shift_px`` pixels: the overlap of the footprints over their union (over the
    candidate's alone when ``covered``), times ``exp(-rms height difference / height_scale)`` over
    the overlap, heights above the table (an object resting on another shows higher and fits
    worse). Worked on the template's every ``stride``-th pixel (an object a few samples across
    fits by how its pixels fall on them). 0 without a template or a candidate pixel.

    Raises:
        ValueError: the arrays' shapes differ, ``shift_px`` is negative or ``height_scale`` not positive.
    """
    heights, pixels = np.asarray(heights, np.float32), np.asarray(pixels, bool)
    if heights.shape != pixels.shape:
        raise ValueError(f"heights and pixels must have the same shape: scene {heights.shape} and {pixels.shape}")
    if shift_px < 0 or height_scale <= 0:
        raise ValueError(f"shift_px must be >= 0 and height_scale > 0; got {shift_px}, {height_scale}")
    if template is None:
        return 0.0
    stride = template.stride
    heights, pixels, shift_px = heights[::stride, ::stride], pixels[::stride, ::stride], shift_px // stride
    if not pixels.any():
        return 0.0
    window = template.size + 2 * shift_px
    scene = _crop(heights, pixels, window)
    scene_on = _crop(np.ones_like(heights), pixels, window)
    scene_count = float(pixels.sum())  # all of it, also what lies outside the window
    stacked = np.dstack([scene_on, scene * scene, scene])
    best = 0.0
    for turned_on, square in zip(template.on, template.squares):
        # Every shift at once, as correlations (both profiles are 0 off their footprints): the
        # overlap, and the squared height differences over it, on_a b^2 + a^2 on_b - 2 a b.
        both = _correlate(scene_on, turned_on)
        squared = _correlate(stacked, square)
        whole = scene_count if covered else scene_count + float(turned_on.sum()) - both
        with np.errstate(divide="ignore", invalid="ignore"):
            gap = np.sqrt(np.maximum(squared, 0.0) / both)
            fit = np.where(both >= 1.0, both / whole * np.exp(-gap / height_scale), 0.0)
        best = max(best, float(fit.max()))
    return min(best, 1.0)


def template_fit(
    query_heights: np.ndarray,
    query_pixels: np.ndarray,
    heights: np.ndarray,
    pixels: np.ndarray,
    covered: bool = False,
    yaws: int = YAWS,
    shift_px: int = SHIFT_PX,
    height_scale: float = HEIGHT_SCALE,
    stride: int = STRIDE,
) -> float:
    """:func:`fit_template` of the exemplar (``query_heights``, ``query_pixels``) turned by
    :func:`exemplar_template` (``yaws``, ``stride``) to the candidate ``pixels`` of ``heights``."""
    template = exemplar_template(query_heights, query_pixels, yaws, stride)
    return fit_template(template, heights, pixels, covered, shift_px, height_scale)


def _correlate(image: np.ndarray, template: np.ndarray) -> np.ndarray:
    """Sums of ``image`` times ``template`` (over channels too) at every placement of the
    template inside the image."""
    return cv2.matchTemplate(image, template, cv2.TM_CCORR)


def _radius(pixels: np.ndarray) -> int:
    """Pixels from the centroid of ``pixels`` to the farthest of them, rounded up."""
    rows, cols = np.nonzero(pixels)
    return int(np.ceil(np.hypot(rows - rows.mean(), cols - cols.mean()).max())) + 1


def component_of(
    pixels: np.ndarray, gap: np.ndarray, heights: np.ndarray, colour_distance: float, min_height: float, min_pixels: int
) -> np.ndarray | None:
    """The connected part (bool image) of the pixels within ``colour_distance`` of the
    exemplar's colour (``gap``: each pixel's CIELAB distance to it) standing more than
    ``min_height`` above the table (``heights``) that holds most of ``pixels``, of at least
    ``min_pixels`` pixels (``None`` when no such part holds any of them): one object, or objects of
    that colour that touch (the matcher's blobs split those at steps of height, and split an
    irregular object too)."""
    on = ((np.asarray(gap) <= colour_distance) & (np.asarray(heights) > min_height)).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(on)
    held = np.bincount(labels[np.asarray(pixels, bool)], minlength=count)
    held[0] = 0  # off every part
    held[stats[:, cv2.CC_STAT_AREA] < min_pixels] = 0
    best = int(np.argmax(held))
    return labels == best if held[best] > 0 else None


def pick_candidate(probability: np.ndarray, candidates: list[np.ndarray], weight: Callable[[int], float]) -> int | None:
    """The index of the candidate (bool image) whose mean ``probability`` times its ``weight``
    (in [0, 1], asked by index) is highest (``None`` when there is none or every product is 0).
    Candidates are weighed in falling order of mean probability, and no more once that mean cannot
    beat the best product: the weight is the costly part."""
    means = [float(probability[c].mean()) for c in candidates]
    best, best_value = None, 0.0
    for k in np.argsort(means)[::-1]:
        if means[k] <= best_value:
            break
        value = means[k] * weight(int(k))
        if value > best_value:
            best, best_value = int(k), value
    return best


def rated_parts(probability: np.ndarray, component: np.ndarray, blobs: list[np.ndarray], share: float) -> list[int]:
    """Indices of the matcher's ``blobs`` mostly inside ``component`` (more than half their
    pixels) whose mean ``probability`` is at least ``share`` of the highest such mean, highest
    first (empty only when no blob lies in it).

    Raises:
        ValueError: ``share`` is outside (0, 1].
    """
    if not 0.0 < share <= 1.0:
        raise ValueError(f"share must lie in (0, 1], got {share}")
    inside = [k for k, b in enumerate(blobs) if (b & component).sum() * 2 > b.sum()]
    means = {k: float(probability[blobs[k]].mean()) for k in inside}
    top = max(means.values(), default=0.0)
    return sorted((k for k in inside if means[k] >= share * top), key=lambda k: -means[k])


def component_parts(probability: np.ndarray, component: np.ndarray, blobs: list[np.ndarray], share: float) -> np.ndarray:
    """The located pixels within the chosen ``component``: its :func:`rated_parts` (so an object
    of the same colour touching the target, a blob of its own, is cut away when the network does
    not rate it); the whole component when no blob lies in it."""
    parts = rated_parts(probability, component, blobs, share)
    if not parts:
        return component
    mask = np.zeros(component.shape, bool)
    for k in parts:
        mask |= blobs[k]
    return mask


def grow_by_fit(
    chosen: np.ndarray,
    covered: bool,
    chosen_fit: float,
    parts: list[tuple[np.ndarray, bool]],
    fit: Callable[[np.ndarray, bool], float],
) -> np.ndarray:
    """The ``chosen`` blob (bool image; ``covered``, fitting the exemplar by ``chosen_fit``)
    grown by each of ``parts`` (``(pixels, covered)``, in the order tried) whose addition leaves
    the grown object fitting at least as well, by ``fit(pixels, covered)`` (an object covered
    when any of its parts is): the parts of an irregular object that the matcher split at steps
    of height join it, an object of the same colour touching it (another shape) does not."""
    grown, best = np.asarray(chosen, bool).copy(), float(chosen_fit)
    for pixels, part_covered in parts:
        trial = grown | np.asarray(pixels, bool)
        value = fit(trial, covered or part_covered)
        if value >= best:
            grown, best, covered = trial, value, covered or part_covered
    return grown
