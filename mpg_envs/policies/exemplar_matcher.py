"""The matching heuristic: find the exemplar in the heightmaps by colour and shape, uncover it,
grasp it, as the peers' robots with a reference picture of their target did (numpy and OpenCV
only; no simulator).

For the exemplar tracks (``target_spec="exemplar"``): the observation shows the scene
(``color``, ``depth``) and the target alone (``query_color``, ``query_depth``). Each motion the
heuristic finds the blobs of the query's colour and scores their shapes
(:func:`mpg_envs.perception.exemplar_match.find_blobs`), then

1. grasps the best uncovered blob when its score reaches ``grasp_score`` (an uncovered object
   shows its whole top, so a look-alike of another shape falls short), where the open fingers
   land least blocked (:func:`free_grasp`), at another angle than grasps that failed;
2. else moves (or pushes, where the env has no move) what lies on the best covered blob, then
   its tallest neighbours: what hides the target goes first;
3. with no covered blob in sight, moves the scene's objects, tallest first; after ``patience``
   such motions it also grasps an uncovered blob scoring ``accept_score`` (an object resting in
   a pose whose extents differ from the query's).

Actions it already took on an unchanged scene are not taken again
(:class:`~mpg_envs.policies.action_memory.ActionMemory`). ``last_plan`` says what it decided and why.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import gymnasium as gym
import numpy as np

from mpg_envs.grid.grasp_geometry import (
    GRASP_ROTATIONS,
    angle_to_rotation,
    fingers_blocked,
    footprint_rect,
)
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.perception.exemplar_match import Blob, MatchSettings, find_blobs, heights, lab_colours
from mpg_envs.policies.action_memory import ActionMemory

__all__ = ["ExemplarMatcher", "MatcherConfig", "free_grasp"]

Option = tuple[str, int, int, int, dict[str, Any]]
"""An action the heuristic may take: primitive, rotation, row, col, and why."""


@dataclass(frozen=True)
class MatcherConfig(MatchSettings):
    """The heuristic's settings: how it looks (:class:`~mpg_envs.perception.exemplar_match.MatchSettings`)
    and what it does; tuned on the tuning seeds 700000 and up, never on test seeds.

    Attributes:
        grasp_score: an uncovered blob scoring this much is grasped.
        accept_score: ... and after ``patience`` motions with no covered blob of the query's
            colour in sight, one scoring this much.
        patience: see ``accept_score``.
        partial_score: a covered blob scoring at least this (judged partial) is a partial match,
            uncovered before covered blobs scoring less.
        neighbourhood: pixels around a partial match where its neighbours are looked for.
        repeat_pixels, repeat_window, repeat_height_change: what repeats a remembered action
            (:class:`~mpg_envs.policies.action_memory.RepeatConfig`).
    """

    grasp_score: float = 0.75
    accept_score: float = 0.5
    patience: int = 3
    partial_score: float = 0.2
    neighbourhood: int = 12
    repeat_pixels: int = 4
    repeat_window: int = 30
    repeat_height_change: float = 0.005


def free_grasp(
    pixels: np.ndarray, blocked: np.ndarray, inset: float = 2.0, avoid: Sequence[int] = ()
) -> tuple[int, int, int, float]:
    """``(rotation, row, col, blocked)``: the grasp on ``pixels`` whose fingers land least
    blocked (``blocked``: :func:`~mpg_envs.grid.grasp_geometry.fingers_blocked`'s maps), at
    pixels at least ``inset`` pixels inside the blob's rim where it has any, the blob's middle
    preferred among equally free ones (1 mm per 10 pixels from the rim); grasp angles in
    ``avoid`` (0..7) and beside them are taken only when no other is left."""
    inside = cv2.distanceTransform(np.pad(pixels.astype(np.uint8), 1), cv2.DIST_L2, 3)[1:-1, 1:-1]
    rows, cols = np.nonzero(inside >= min(inset, float(inside.max())))
    near = {(a + d) % GRASP_ROTATIONS for a in avoid for d in (-1, 0, 1)}
    penalty = np.array([1.0 if k in near else 0.0 for k in range(GRASP_ROTATIONS)])[:, None]
    cost = blocked[:GRASP_ROTATIONS, rows, cols] - 1e-4 * inside[rows, cols] + penalty
    k, j = np.unravel_index(int(np.argmin(cost)), cost.shape)
    return int(k), int(rows[j]), int(cols[j]), float(blocked[k, rows[j], cols[j]])


def _grip(pixels: np.ndarray) -> tuple[int, int, int]:
    """``(rotation, row, col)``: the point of ``pixels`` farthest from their rim, closing
    across their footprint rectangle's short side."""
    inside = cv2.distanceTransform(np.pad(pixels.astype(np.uint8), 1), cv2.DIST_L2, 3)[1:-1, 1:-1]
    row, col = np.unravel_index(int(np.argmax(inside)), inside.shape)
    rows, cols = np.nonzero(pixels)
    _, _, short_dir = footprint_rect(np.stack([cols, rows], axis=1) + 0.5)
    return angle_to_rotation(short_dir), int(row), int(col)


class ExemplarMatcher:
    """The matching heuristic (see the module docstring), a :class:`~mpg_envs.policies.policy.Policy`."""

    name = "matcher"

    def __init__(self, env: gym.Env, config: MatcherConfig = MatcherConfig()):
        unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
        if not {"query_color", "query_depth"} <= set(getattr(env.observation_space, "spaces", {})):
            raise ValueError(
                "the matching heuristic needs an exemplar (query_color, query_depth): make the env with target_spec='exemplar'"
            )
        self.config = config
        self.primitives = tuple(unwrapped.primitives)
        if GRASP not in self.primitives:
            raise ValueError(f"the matching heuristic grasps; this env allows only {self.primitives}")
        self.resolution = float(unwrapped.config.workspace.resolution)
        self.grasp_depth = float(unwrapped.config.primitives.grasp_depth)
        self.grasp_min_height = float(unwrapped.config.primitives.grasp_min_height)
        self.action_space = unwrapped.action_space
        self.memory = ActionMemory(config)
        self.last_plan: dict[str, Any] | None = None
        self._grasp_angles: list[int] = []  # grasp angles that did not take the target
        self._searches = 0  # motions made with no covered blob of the query's colour in sight

    def reset(self) -> None:
        """Forget the episode's actions."""
        self.memory.clear()
        self.last_plan = None
        self._grasp_angles = []
        self._searches = 0

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        depth = np.asarray(obs["depth"])
        chosen = None
        for option in self._options(obs):
            chosen = option
            if not self.memory.repeats(*option[:4], depth):
                break
        assert chosen is not None  # _options always ends with a grasp at the tallest point
        primitive, rotation, row, col, self.last_plan = chosen
        self.memory.record(primitive, rotation, row, col, depth)
        if primitive == GRASP:  # asked again afterwards: it did not take the target
            self._grasp_angles.append(rotation % GRASP_ROTATIONS)
        self._searches += self.last_plan["kind"] == "dig"
        return int(self.action_space.encode(primitive, rotation, row, col))

    def blobs(self, obs: Mapping[str, np.ndarray]) -> list[Blob]:
        """The scene's blobs of the query's colour, best shape match first
        (:func:`~mpg_envs.perception.exemplar_match.find_blobs`)."""
        return find_blobs(
            obs["color"],
            obs["depth"],
            obs["query_color"],
            obs["query_depth"],
            self.resolution,
            self.config,
        )

    def _options(self, obs: Mapping[str, np.ndarray]) -> Iterator[Option]:
        """The actions to take, best first."""
        c = self.config
        up = heights(obs["depth"], c)
        lab = lab_colours(np.asarray(obs["color"]))
        blobs = self.blobs(obs)
        clearing = bool({MOVE, PUSH} & set(self.primitives))
        uncovered = [b for b in blobs if not b.covered]
        best = uncovered[0] if uncovered else None
        threshold = c.grasp_score if self._searches < c.patience else min(c.grasp_score, c.accept_score)
        if best is not None and best.score >= threshold:
            blocked = fingers_blocked(np.asarray(obs["depth"]), self.resolution, self.grasp_depth, self.grasp_min_height)
            rotation, row, col, height = free_grasp(best.pixels, blocked, avoid=self._grasp_angles)
            plan = {
                "kind": "grasp_match",
                "score": round(best.score, 3),
                "blocked": round(height, 4),
            }
            yield (GRASP, rotation, row, col, plan)
        partial = [b for b in blobs if b.covered] if clearing else []
        for blob in ([b for b in partial if b.score >= c.partial_score] or partial)[:1]:
            plan = {"kind": "uncover", "score": round(blob.score, 3)}
            grown = blob.pixels.astype(np.uint8)
            rim = (cv2.dilate(grown, np.ones((3, 3), np.uint8), iterations=3) > 0) & ~blob.pixels
            around = (cv2.dilate(grown, np.ones((3, 3), np.uint8), iterations=c.neighbourhood) > 0) & ~blob.pixels
            # What lies on it first (its rim's pixels above its top), then its tallest neighbours.
            for where in (rim & (up > blob.top + c.cover_height), around & (up > c.min_height)):
                for region in self._regions(lab, up, where):
                    yield self._clear(region, blob.pixels, plan)
        where = (up > c.min_height) & clearing
        if best is not None:
            where &= ~best.pixels
        for region in self._regions(lab, up, where):  # no partial match: what lies highest goes first
            yield self._clear(region, None, {"kind": "dig"})
        for blob in blobs:
            yield (
                GRASP,
                *_grip(blob.pixels),
                {"kind": "grasp_last_resort", "score": round(blob.score, 3)},
            )
        top_row, top_col = np.unravel_index(int(np.argmax(up)), up.shape)
        yield (GRASP, 0, int(top_row), int(top_col), {"kind": "grasp_tallest"})

    def _regions(self, lab: np.ndarray, up: np.ndarray, where: np.ndarray, limit: int = 6) -> Iterator[np.ndarray]:
        """Up to ``limit`` objects seen at ``where``, tallest first: each the pixels of one colour
        and a continuous height connected to a seed pixel (the highest one left)."""
        c = self.config
        left = where.copy()
        for _ in range(limit):
            if not left.any():
                return
            rows, cols = np.nonzero(left)
            k = int(np.argmax(up[rows, cols]))
            seed = (int(rows[k]), int(cols[k]))
            same_colour = np.linalg.norm(lab - lab[seed], axis=-1) <= c.colour_distance
            same = same_colour & (np.abs(up - up[seed]) < 0.03) & (up > c.min_height)
            _, labels = cv2.connectedComponents(same.astype(np.uint8))
            region = labels == labels[seed]
            left &= ~region
            if region.sum() >= c.min_pixels:
                yield region

    def _clear(self, region: np.ndarray, away_from: np.ndarray | None, plan: dict[str, Any]) -> Option:
        """A move of ``region``'s object (a push away from ``away_from``, or from the
        workspace centre, where the env has no move)."""
        rotation, row, col = _grip(region)
        if MOVE in self.primitives:
            return (MOVE, rotation, row, col, plan)
        rows, cols = np.nonzero(region)
        if away_from is not None and away_from.any():
            from_rows, from_cols = np.nonzero(away_from)
            origin = np.array([from_cols.mean(), from_rows.mean()])
        else:
            origin = np.array(region.shape[::-1], dtype=float) / 2
        direction = math.atan2(rows.mean() - origin[1], cols.mean() - origin[0])
        return (PUSH, angle_to_rotation(direction, symmetric=False), row, col, plan)
