"""The locator's inputs from an exemplar-mode observation: pure numpy, unit-tested by hand.

The scene is the colour and depth heightmaps; the exemplar is ``query_color`` and
``query_depth`` (the target alone on an empty table, at the scene's scale). Besides the raw
images the network gets cues a small network would spend much capacity and many samples
learning: per scene pixel, how far its colour is from the exemplar's mean colour
(:func:`colour_distance`); the colour-and-shape match of the exemplar matcher's perception
(:func:`match_cues`: the CIELAB distance to the exemplar's colour, and the shape score of the
blob of that colour each pixel belongs to, with whether that blob is covered); and a few
numbers that describe the exemplar whatever its yaw (:func:`query_descriptor`: its area, its
height and its mean colour). The network learns when to trust the matcher's blobs and when
not (lighting in camera images, look-alikes of the same footprint, blobs split by cover).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from mpg_agents.locator.template import ExemplarTemplate, exemplar_template
from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.exemplar_match import (
    Blob,
    MatchSettings,
    colour_gap,
    find_blobs,
    heights,
    lab_colours,
    pose_table,
    query_model,
)

DEPTH_SCALE = 10.0
"""Heights (m) are multiplied by this: 0.1 m of height reads 1.0."""
QUERY_MIN_HEIGHT = 0.002
"""A query pixel higher than this (m) shows the exemplar's object (the rest is bare table)."""
CUE_CHANNELS = 3
"""The matcher's cues (:func:`match_cues`): CIELAB distance, blob shape score, blob covered."""
SCENE_CHANNELS = 5 + CUE_CHANNELS
"""colour (3), height (1), distance to the exemplar's colour (1), the matcher's cues."""
LAB_SCALE = 100.0
"""CIELAB distances (8-bit units, lightness halved) are divided by this."""
RESOLUTION = Workspace().resolution
"""Metres per heightmap pixel the locator is trained at (the default workspace's)."""
QUERY_CHANNELS = 4
"""colour (3), height (1)."""
DESCRIPTOR_SIZE = 6
"""area, max height, mean height, mean colour (3) of the exemplar."""


def query_pixels(query_depth: np.ndarray) -> np.ndarray:
    """Boolean map of the query pixels that show the object (height above :data:`QUERY_MIN_HEIGHT`)."""
    return np.asarray(query_depth) > QUERY_MIN_HEIGHT


def query_descriptor(query_color: np.ndarray, query_depth: np.ndarray) -> np.ndarray:
    """``[area, max height, mean height, mean r, g, b]`` of the exemplar (float32): area as the
    share of the image, heights times :data:`DEPTH_SCALE`, colours in [0, 1]. All zeros for an
    empty query (nothing above the table)."""
    shown = query_pixels(query_depth)
    if not shown.any():
        return np.zeros(DESCRIPTOR_SIZE, np.float32)
    heights = np.asarray(query_depth, np.float64)[shown] * DEPTH_SCALE
    colour = np.asarray(query_color, np.float64)[shown].mean(axis=0) / 255.0
    return np.array([shown.mean(), heights.max(), heights.mean(), *colour], np.float32)


def colour_distance(color: np.ndarray, mean_colour: np.ndarray) -> np.ndarray:
    """Per pixel, the Euclidean distance of ``color`` (H x W x 3, uint8) to ``mean_colour`` (3
    values in [0, 1]), in [0, 1] units of colour (black to white is sqrt(3))."""
    scaled = np.asarray(color, np.float32) / 255.0
    return np.linalg.norm(scaled - np.asarray(mean_colour, np.float32), axis=-1).astype(np.float32)


def centred_query(color: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An exemplar as the exemplar envs show it, from heightmaps of the object alone on the
    empty table (a photo of it through :func:`~mpg_envs.perception.rgbd.heightmap_from_rgbd`,
    say): the heightmaps shifted so the middle of the object's pixels' extent is at the grid's
    centre (the table around it comes round from the other side). ``ValueError`` when no pixel
    stands above the table (:data:`QUERY_MIN_HEIGHT`)."""
    shown = query_pixels(depth)
    if not shown.any():
        raise ValueError(f"no pixel of the object's heightmap stands above the table (higher than {QUERY_MIN_HEIGHT} m)")
    rows, cols = np.nonzero(shown)
    shift = (
        shown.shape[0] // 2 - (int(rows.min()) + int(rows.max()) + 1) // 2,
        shown.shape[1] // 2 - (int(cols.min()) + int(cols.max()) + 1) // 2,
    )
    return (
        np.roll(np.asarray(color), shift, axis=(0, 1)).astype(np.uint8),
        np.roll(np.asarray(depth, np.float32), shift, axis=(0, 1)),
    )


@dataclass(frozen=True, eq=False)
class Exemplar:
    """What the locator reads of one exemplar, worked out once (:meth:`of`) and reused for every
    look at a scene while the exemplar stays the same (:meth:`shows`): its images
    (``query_color``, ``query_depth``), their network channels ``query`` (:func:`query_input`),
    its ``descriptor`` (:func:`query_descriptor`), the matcher's ``model`` of it (colour and
    extents, :func:`~mpg_envs.perception.exemplar_match.query_model`; ``None`` when it shows no
    object); :attr:`poses` is worked out when first asked for."""

    query_color: np.ndarray
    query_depth: np.ndarray
    query: np.ndarray
    descriptor: np.ndarray
    model: tuple[np.ndarray, np.ndarray] | None

    @cached_property
    def poses(self) -> np.ndarray | None:
        """The footprints and heights a box of the exemplar's extents shows from above
        (:func:`~mpg_envs.perception.exemplar_match.pose_table`; ``None`` without a model)."""
        return None if self.model is None else pose_table(self.model[1])

    @cached_property
    def template(self) -> ExemplarTemplate | None:
        """The exemplar's heights above its table turned through the yaws the ``"template"``
        snapping tries (:func:`~mpg_agents.locator.template.exemplar_template`; its object's
        pixels as the matcher reads them, above ``min_height``)."""
        settings = MatchSettings()
        up = heights(self.query_depth, settings)
        return exemplar_template(up, up > settings.min_height)

    @classmethod
    def of(
        cls, obs: Mapping[str, np.ndarray], resolution: float = RESOLUTION, settings: MatchSettings | None = None
    ) -> Exemplar:
        """The exemplar of the exemplar-mode observation ``obs`` (its arrays copied)."""
        settings = MatchSettings() if settings is None else settings
        color, depth = np.array(obs["query_color"]), np.array(obs["query_depth"])
        try:
            model: tuple[np.ndarray, np.ndarray] | None = query_model(color, depth, resolution, settings)
        except ValueError:  # nothing above the table in the exemplar: nothing can match it
            model = None
        return cls(color, depth, query_input(obs), query_descriptor(color, depth), model)

    def shows(self, obs: Mapping[str, np.ndarray]) -> bool:
        """Whether ``obs``' exemplar images are this exemplar's (equal arrays)."""
        return np.array_equal(self.query_color, obs["query_color"]) and np.array_equal(self.query_depth, obs["query_depth"])


def exemplar_blobs(
    obs: Mapping[str, np.ndarray],
    resolution: float = RESOLUTION,
    settings: MatchSettings | None = None,
    exemplar: Exemplar | None = None,
    gap: np.ndarray | None = None,
) -> list[Blob]:
    """The exemplar matcher's blobs of the exemplar's colour in the scene, best shape match first
    (:func:`~mpg_envs.perception.exemplar_match.find_blobs`; ``settings``: the matcher's,
    default :class:`MatchSettings`); none when the exemplar shows no object. ``exemplar`` (its
    :class:`Exemplar`, made with the same ``resolution`` and ``settings``) and ``gap`` (the
    scene's :func:`~mpg_envs.perception.exemplar_match.colour_gap` to its colour) spare working
    them out again."""
    settings = MatchSettings() if settings is None else settings
    exemplar = Exemplar.of(obs, resolution, settings) if exemplar is None else exemplar
    if exemplar.model is None:  # nothing above the table in the exemplar: nothing can match it
        return []
    return find_blobs(
        obs["color"], obs["depth"], exemplar.query_color, exemplar.query_depth, resolution, settings,
        model=exemplar.model, gap=gap,
    )  # fmt: skip


def match_cues(
    obs: Mapping[str, np.ndarray],
    blobs: Sequence[Blob] | None = None,
    resolution: float = RESOLUTION,
    settings: MatchSettings | None = None,
    exemplar: Exemplar | None = None,
    gap: np.ndarray | None = None,
) -> np.ndarray:
    """The exemplar matcher's view of an exemplar-mode observation (:data:`CUE_CHANNELS` x H x
    W, float32): per pixel, the CIELAB distance of its colour to the exemplar's (divided by
    :data:`LAB_SCALE`); the shape score of the blob of the exemplar's colour it belongs to
    (``blobs``: :func:`exemplar_blobs`, found when not given; 0 off every blob); 1 where that
    blob is covered. An exemplar showing no object gives distance 1 everywhere and no blob.
    ``exemplar`` and ``gap`` as for :func:`exemplar_blobs`."""
    settings = MatchSettings() if settings is None else settings
    color = np.asarray(obs["color"])
    cues = np.zeros((CUE_CHANNELS, *color.shape[:2]), np.float32)
    exemplar = Exemplar.of(obs, resolution, settings) if exemplar is None else exemplar
    if exemplar.model is None:  # nothing above the table in the exemplar: nothing can match it
        cues[0] = 1.0
        return cues
    gap = colour_gap(lab_colours(color), exemplar.model[0]) if gap is None else gap
    cues[0] = gap / LAB_SCALE
    blobs = exemplar_blobs(obs, resolution, settings, exemplar, gap) if blobs is None else blobs
    for blob in reversed(blobs):  # best last: where blobs share a pixel, the best one's score stays
        cues[1][blob.pixels] = blob.score
        cues[2][blob.pixels] = float(blob.covered)
    return cues


def scene_input(
    obs: Mapping[str, np.ndarray],
    blobs: Sequence[Blob] | None = None,
    exemplar: Exemplar | None = None,
    gap: np.ndarray | None = None,
) -> np.ndarray:
    """The scene's channels (:data:`SCENE_CHANNELS` x H x W, float32) of an exemplar-mode
    observation: colour in [0, 1], scaled height, distance to the exemplar's mean colour (from its
    :func:`query_descriptor`) and the matcher's cues (:func:`match_cues`; ``exemplar``, made when
    not given, and ``gap`` as for :func:`exemplar_blobs`)."""
    exemplar = Exemplar.of(obs) if exemplar is None else exemplar
    color = np.asarray(obs["color"], np.float32).transpose(2, 0, 1) / 255.0
    depth = np.asarray(obs["depth"], np.float32)[None] * DEPTH_SCALE
    distance = colour_distance(obs["color"], exemplar.descriptor[3:6])[None]
    cues = match_cues(obs, blobs, exemplar=exemplar, gap=gap)
    return np.concatenate([color, depth, distance, cues]).astype(np.float32)


def query_input(obs: Mapping[str, np.ndarray]) -> np.ndarray:
    """The exemplar's channels (:data:`QUERY_CHANNELS` x H x W, float32): colour in [0, 1]
    and scaled height."""
    color = np.asarray(obs["query_color"], np.float32).transpose(2, 0, 1) / 255.0
    depth = np.asarray(obs["query_depth"], np.float32)[None] * DEPTH_SCALE
    return np.concatenate([color, depth]).astype(np.float32)


def net_inputs(obs: Mapping[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(scene, query, descriptor)``: the network's three inputs of one exemplar-mode
    observation (:func:`scene_input`, :func:`query_input`, :func:`query_descriptor`), what is read
    of the exemplar worked out once (:class:`Exemplar`)."""
    exemplar = Exemplar.of(obs)
    return scene_input(obs, exemplar=exemplar), exemplar.query, exemplar.descriptor
