"""Where an exemplar shows in colour and depth heightmaps, by colour and shape (pure: numpy and
OpenCV, no simulator), as a robot with a reference picture of its target would look for it.

:func:`query_model` reads the exemplar: the object's pixels (above the table, whose level is a
low percentile of the heights: a camera's table is not at 0), its colour (their median in
CIELAB) and its extents (:func:`object_extents`: footprint rectangle and height, sorted, so any
resting pose of a box-like object gives the same three). :func:`find_blobs` finds the scene's
pixels of that colour (:func:`colour_match`), splits them into blobs at steps of height (two
objects of one colour side by side are two blobs) and scores each blob's shape
(:func:`shape_score`): its height above what surrounds it must be one of the query's extents and
its footprint must fit inside the other two; the score falls with the part of that footprint it
does not show. A blob with something higher of another colour along its rim is covered: only
part of its top shows, so its shape is judged without that part.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from mpg_envs.grid.grasp_geometry import footprint_rect

__all__ = [
    "Blob",
    "MatchSettings",
    "colour_gap",
    "colour_match",
    "find_blobs",
    "footprint_sides",
    "height_steps",
    "heights",
    "lab_colours",
    "object_extents",
    "pose_fit",
    "pose_table",
    "query_model",
    "shape_score",
]


@dataclass(frozen=True)
class MatchSettings:
    """How an exemplar is looked for.

    Attributes:
        min_height: pixels higher than this (m) above the table level are objects.
        table_percentile: the percentile of a heightmap's heights taken as the table's level.
        colour_distance: largest CIELAB distance (8-bit units, lightness counted half) of a
            scene pixel to the query's colour that still matches it.
        min_pixels: smaller colour blobs are noise.
        extent_tolerance: metres an extent may exceed the query's and still fit.
        height_sigma: metres over which a blob's height stops matching a query extent.
        step_height: a height step (m) between neighbouring pixels that splits blobs.
        cover_height: a rim pixel this much (m) above a blob's top covers it.
        covered_share: a blob with more of its rim covered than this is covered.
    """

    min_height: float = 0.01
    table_percentile: float = 25.0
    colour_distance: float = 14.0
    min_pixels: int = 5
    extent_tolerance: float = 0.008
    height_sigma: float = 0.006
    step_height: float = 0.006
    cover_height: float = 0.008
    covered_share: float = 0.1


@dataclass(frozen=True, eq=False)
class Blob:
    """Pixels of the query's colour that may be one object.

    Attributes:
        pixels: ``(H, W)`` bool image.
        score: :func:`shape_score` against the query (partial when covered).
        covered: something of another colour lies higher along its rim.
        height: its top above what surrounds it (m).
        top: its top above the table (m).
    """

    pixels: np.ndarray
    score: float
    covered: bool
    height: float
    top: float


def lab_colours(color: np.ndarray) -> np.ndarray:
    """``(..., 3)`` uint8 RGB -> float CIELAB (OpenCV's 8-bit scaling), lightness halved."""
    flat = np.ascontiguousarray(color, dtype=np.uint8).reshape(-1, 1, 3)
    lab = cv2.cvtColor(flat, cv2.COLOR_RGB2LAB).astype(np.float32)
    lab[..., 0] *= 0.5
    return lab.reshape(np.asarray(color).shape)


def heights(depth: np.ndarray, settings: MatchSettings = MatchSettings()) -> np.ndarray:
    """``depth`` less its table level (the ``table_percentile`` of its heights)."""
    depth = np.asarray(depth, dtype=np.float32)
    return depth - np.float32(np.percentile(depth, settings.table_percentile))


def colour_gap(lab: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``(H, W)`` float32: each pixel's CIELAB distance to the ``reference`` colour (a CIELAB
    triple as :func:`query_model` gives, lightness halved); ``lab`` is the image's
    :func:`lab_colours`."""
    return np.linalg.norm(np.asarray(lab) - np.asarray(reference, dtype=np.float32), axis=-1)


def colour_match(color: np.ndarray, reference: np.ndarray, distance: float) -> np.ndarray:
    """``(H, W)`` bool: the pixels of ``color`` (``(H, W, 3)`` uint8 RGB) within ``distance`` of
    the ``reference`` colour (a CIELAB triple as :func:`query_model` gives, lightness halved)."""
    return colour_gap(lab_colours(color), reference) <= distance


def footprint_sides(pixels: np.ndarray, resolution: float) -> np.ndarray:
    """``(long, short)`` sides (m) of the footprint rectangle of the bool image ``pixels``
    (the pixel centres' rectangle grown by one pixel).

    Raises:
        ValueError: no pixel.
    """
    rows, cols = np.nonzero(pixels)
    return _sides(rows, cols, resolution)


def _sides(rows: np.ndarray, cols: np.ndarray, resolution: float) -> np.ndarray:
    """:func:`footprint_sides` of the pixels at ``rows``, ``cols``."""
    if rows.size == 0:
        raise ValueError("a footprint needs at least one pixel")
    _, sides, _ = footprint_rect(np.stack([cols, rows], axis=1) + 0.5)
    return (sides + 1.0) * resolution


def object_extents(pixels: np.ndarray, height: float, resolution: float) -> np.ndarray:
    """The sorted ``(3,)`` extents (m) of an object whose footprint is the bool image
    ``pixels`` and whose top stands ``height`` above what it rests on: its footprint
    rectangle's two sides and its height."""
    return np.sort(np.array([*footprint_sides(pixels, resolution), height]))


def shape_score(
    height: float,
    sides: np.ndarray,
    extents: np.ndarray,
    settings: MatchSettings = MatchSettings(),
    partial: bool = False,
) -> float:
    """How well a blob of ``height`` (m, above what surrounds it) and footprint ``sides``
    (long, short; m) matches an object of sorted ``extents`` in some resting pose: for each
    choice of the extent standing up, the height's match (a Gaussian of ``height_sigma``) times
    whether the footprint fits the other two (within ``extent_tolerance``) times, unless
    ``partial`` (a covered blob shows only part of its footprint), the share of their rectangle
    it covers; the best choice's value, in [0, 1]."""
    best = 0.0
    long_side, short_side = float(max(sides)), float(min(sides))
    for k in range(3):
        rest = np.delete(np.asarray(extents, dtype=float), k)
        up = math.exp(-0.5 * ((height - float(extents[k])) / settings.height_sigma) ** 2)
        over = max(0.0, long_side - rest[1]) + max(0.0, short_side - rest[0])
        fit = math.exp(-0.5 * (over / settings.extent_tolerance) ** 2)
        cover = 1.0 if partial else min(1.0, long_side / rest[1]) * min(1.0, short_side / rest[0])
        best = max(best, up * fit * cover)
    return best


POSE_TILTS: tuple[float, ...] = tuple(math.radians(d) for d in range(0, 46, 5))
"""The tilts (radians) about each horizontal axis :func:`pose_table` takes an object through: in
clutter an object leans on others, so from above it shows more than one face."""


def pose_table(extents: Sequence[float] | np.ndarray, tilts: Sequence[float] = POSE_TILTS) -> np.ndarray:
    """``(N, 3)``: the footprint rectangle's (long, short) sides and the height (m) a box of
    ``extents`` shows from above in each of ``N`` poses: each assignment of its extents to the
    axes, tilted about the two horizontal axes by each pair of ``tilts`` (the yaw changes neither)."""
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))
    rows = []
    for order in itertools.permutations(range(3)):
        box = corners * np.asarray(extents, dtype=float)[list(order)]
        for a, b in itertools.product(tilts, tilts):
            about_x = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)], [0.0, math.sin(a), math.cos(a)]])
            about_y = np.array([[math.cos(b), 0.0, math.sin(b)], [0.0, 1.0, 0.0], [-math.sin(b), 0.0, math.cos(b)]])
            turned = box @ (about_y @ about_x).T
            _, sides, _ = footprint_rect(turned[:, :2])
            rows.append((*sides, float(np.ptp(turned[:, 2]))))
    return np.array(rows)


def pose_fit(
    sides: Sequence[float] | np.ndarray,
    height: float,
    table: np.ndarray,
    side_sigma: float = 0.006,
    height_sigma: float = 0.006,
) -> float:
    """How well a blob of footprint ``sides`` (long, short; m) whose top stands ``height`` above
    what surrounds it shows a box in one of the poses of ``table`` (:func:`pose_table`): the best
    pose's agreement, a Gaussian of the three differences (``side_sigma``, ``height_sigma``), in [0, 1].
    Unlike :func:`shape_score` it allows the object to lean (a tilted box is wider and higher)."""
    table = np.asarray(table, dtype=float)
    gaps = ((sides[0] - table[:, 0]) / side_sigma) ** 2 + ((sides[1] - table[:, 1]) / side_sigma) ** 2
    gaps += ((height - table[:, 2]) / height_sigma) ** 2
    return float(np.exp(-0.5 * gaps.min()))


def height_steps(up: np.ndarray, step: float) -> np.ndarray:
    """``(H, W)`` bool: the pixels of the height map ``up`` that differ from one of their four
    neighbours by more than ``step`` (m): the rims between objects."""
    up = np.asarray(up, dtype=np.float32)
    edges = np.zeros(up.shape, dtype=bool)
    vertical = np.abs(np.diff(up, axis=0)) > step
    horizontal = np.abs(np.diff(up, axis=1)) > step
    edges[:-1] |= vertical
    edges[1:] |= vertical
    edges[:, :-1] |= horizontal
    edges[:, 1:] |= horizontal
    return edges


def query_model(
    query_color: np.ndarray,
    query_depth: np.ndarray,
    resolution: float,
    settings: MatchSettings = MatchSettings(),
) -> tuple[np.ndarray, np.ndarray]:
    """``(colour, extents)`` of the exemplar: the CIELAB median of its pixels (lightness
    halved) and its sorted extents (:func:`object_extents`).

    Raises:
        ValueError: the query shows no object (no pixel ``min_height`` above the table).
    """
    up = heights(query_depth, settings)
    above = (up > settings.min_height).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(above)
    if count < 2:
        raise ValueError("the query shows no object above the table")
    pixels = labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    colour = np.median(lab_colours(np.asarray(query_color)[pixels]), axis=0)
    return colour, object_extents(pixels, float(np.percentile(up[pixels], 98)), resolution)


def split_blobs(matched: np.ndarray, up: np.ndarray, step: float, min_pixels: int) -> list[np.ndarray]:
    """The blobs of ``matched`` (bool image) split at the steps of height of ``up``
    (:func:`height_steps`): the components off the steps, each grown back over the matched step
    pixels beside it no more than ``step`` from its heights, then the components of the matched
    pixels left (a sliver of an object between taller ones lies on steps only); blobs under
    ``min_pixels`` are left out."""
    core_image = (matched & ~height_steps(up, step)).astype(np.uint8)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(core_image)
    blobs, taken = [], np.zeros(matched.shape, dtype=bool)
    for k in range(1, count):
        if stats[k, cv2.CC_STAT_AREA] < min_pixels:
            continue
        # Worked in the component's box grown by the one pixel the growth reaches: the same
        # pixels as over the whole image, a fraction of the work.
        left, top, width, height = (int(v) for v in stats[k, :4])
        box = (slice(max(0, top - 1), top + height + 1), slice(max(0, left - 1), left + width + 1))
        core, up_box = labels[box] == k, up[box]
        near = (up_box >= up_box[core].min() - step) & (up_box <= up_box[core].max() + step)
        grown = cv2.dilate(core.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        pixels = np.zeros(matched.shape, dtype=bool)
        pixels[box] = grown & matched[box] & near & ~taken[box]
        taken[box] |= pixels[box]
        blobs.append(pixels)
    count, labels, stats, _ = cv2.connectedComponentsWithStats((matched & ~taken).astype(np.uint8))
    blobs += [labels == k for k in range(1, count) if stats[k, cv2.CC_STAT_AREA] >= min_pixels]
    return blobs


def find_blobs(
    color: np.ndarray,
    depth: np.ndarray,
    query_color: np.ndarray,
    query_depth: np.ndarray,
    resolution: float,
    settings: MatchSettings = MatchSettings(),
    *,
    model: tuple[np.ndarray, np.ndarray] | None = None,
    gap: np.ndarray | None = None,
) -> list[Blob]:
    """The blobs of the query's colour in the scene's ``color`` and ``depth`` heightmaps, best
    shape match first (see the module docstring). A caller that looks often may pass what does
    not change between looks, ``model``, the exemplar's :func:`query_model` (then the query
    images are not read), and what it has worked out already, ``gap``, the scene's
    :func:`colour_gap` to the model's colour; the blobs are the same.

    Raises:
        ValueError: the query shows no object (from :func:`query_model`).
    """
    s = settings
    colour, extents = query_model(query_color, query_depth, resolution, s) if model is None else model
    up = heights(depth, s)
    gap = colour_gap(lab_colours(color), colour) if gap is None else gap
    matched = (gap <= s.colour_distance) & (up > s.min_height)
    found = []
    for pixels in split_blobs(matched, up, s.step_height, s.min_pixels):
        # Each blob's rim is looked at in a window around it (3 pixels of growth fit in 4):
        # the same pixels as over the whole image, a fraction of the work.
        rows, cols = np.nonzero(pixels)
        window = (slice(max(0, rows.min() - 4), rows.max() + 5), slice(max(0, cols.min() - 4), cols.max() + 5))
        inside, up_w = pixels[window], up[window]
        grown = cv2.dilate(inside.astype(np.uint8), np.ones((3, 3), np.uint8), iterations=3) > 0
        ring = grown & ~inside
        top = float(np.percentile(up_w[inside], 95))
        base = float(np.clip(np.percentile(up_w[ring], 10), 0.0, top)) if ring.any() else 0.0
        # Higher pixels of another colour along the rim: something lies on it (its own colour: itself).
        higher = (up_w[ring] > top + s.cover_height) & ~matched[window][ring]
        covered = bool(ring.any() and np.mean(higher) > s.covered_share)
        sides = _sides(rows, cols, resolution)
        score = shape_score(top - base, sides, extents, s, partial=covered)
        found.append(Blob(pixels, score, covered, top - base, top))
    return sorted(found, key=lambda b: -b.score)
