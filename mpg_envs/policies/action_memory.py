"""What a policy already did in an episode, so it never does it again on an unchanged scene."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from mpg_envs.grid.grasp_geometry import GRASP_ROTATIONS
from mpg_envs.grid.primitive_specs import half_turn_symmetric

__all__ = ["ActionMemory", "RepeatConfig", "RepeatRule"]


class RepeatConfig(Protocol):
    """When an action repeats a remembered one (e.g. :class:`RepeatRule`,
    :class:`mpg_envs.policies.oracle.OracleConfig`): read-only, so frozen dataclasses qualify."""

    @property
    def repeat_pixels(self) -> int:
        """An action this close to a tried one (same primitive and angle) ..."""
        ...

    @property
    def repeat_window(self) -> int:
        """... on a heightmap unchanged within this many pixels around it ..."""
        ...

    @property
    def repeat_height_change(self) -> float:
        """... (no pixel moved by more than this, metres) repeats it."""
        ...


@dataclass(frozen=True)
class RepeatRule:
    """The default :class:`RepeatConfig` (the oracle's, and a network policy's ``avoid_repeats``)."""

    repeat_pixels: int = 4
    repeat_window: int = 30
    repeat_height_change: float = 0.005


class ActionMemory:
    """The actions taken in an episode, each with the depth heightmap it was taken on.

    An action *repeats* a remembered one when it has the same primitive and angle (grasp and
    move angles modulo 180 degrees), its pixel lies within ``repeat_pixels`` of it, and the
    heightmap around that pixel has not changed since: doing it again would meet the same
    scene that made it fail.
    """

    def __init__(self, config: RepeatConfig):
        self.config = config
        self._tried: list[tuple[str, int, int, int, np.ndarray]] = []

    def __len__(self) -> int:
        return len(self._tried)

    def clear(self) -> None:
        self._tried = []

    def record(self, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray) -> None:
        self._tried.append((primitive, self._angle(primitive, rotation), int(row), int(col), np.array(depth, copy=True)))

    def repeats(self, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray) -> bool:
        c = self.config
        angle = self._angle(primitive, rotation)
        for p, k, r, col0, before in self._tried:
            if p != primitive or k != angle or abs(r - row) > c.repeat_pixels or abs(col0 - col) > c.repeat_pixels:
                continue
            w = c.repeat_window
            window = (slice(max(0, row - w), row + w + 1), slice(max(0, col - w), col + w + 1))
            if float(np.abs(depth[window] - before[window]).max(initial=0.0)) <= c.repeat_height_change:
                return True
        return False

    def forbidden(self, primitive: str, depth: np.ndarray, num_rotations: int) -> np.ndarray:
        """``(num_rotations, H, W)`` bool: the actions of ``primitive`` that would repeat a
        remembered one on ``depth`` (the map form of :meth:`repeats`, for a Q-map policy; the
        heightmap is compared around the remembered pixel)."""
        c = self.config
        h, w = depth.shape
        out = np.zeros((num_rotations, h, w), dtype=bool)
        for p, angle, r, col, before in self._tried:
            if p != primitive:
                continue
            win = c.repeat_window
            window = (slice(max(0, r - win), r + win + 1), slice(max(0, col - win), col + win + 1))
            if float(np.abs(depth[window] - before[window]).max(initial=0.0)) > c.repeat_height_change:
                continue  # the scene changed there: trying again is a new action
            rotations = [k for k in range(num_rotations) if self._angle(primitive, k) == angle]
            near = (
                slice(max(0, r - c.repeat_pixels), r + c.repeat_pixels + 1),
                slice(max(0, col - c.repeat_pixels), col + c.repeat_pixels + 1),
            )
            out[(rotations, *near)] = True
        return out

    @staticmethod
    def _angle(primitive: str, rotation: int) -> int:
        return int(rotation) % GRASP_ROTATIONS if half_turn_symmetric(primitive) else int(rotation)
