"""Pixel-wise actions: encoding between flat ``Discrete`` indices and
``(primitive, rotation, row, col)``.

The flat index is C order over ``(primitive, rotation, row, col)``, where ``primitive``
indexes the env's allowed primitives in the fixed order ``move, push, grasp`` and then any
primitive registered later (:mod:`mpg_envs.grid.primitive_specs`; ``env.unwrapped.primitives``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from mpg_envs.grid.primitive_specs import PAPER_PRIMITIVES, registered_primitives
from mpg_envs.grid.workspace import NUM_ROTATIONS, Workspace, _is_int

PRIMITIVES: tuple[str, ...] = PAPER_PRIMITIVES
"""The paper's three primitives, in the fixed order every action space uses (a primitive
registered later comes after them: :func:`~mpg_envs.grid.primitive_specs.registered_primitives`)."""

HEIGHTMAP_SIZE: int = Workspace().shape[0]
"""Side of the square heightmap (pixels) of the default workspace: 224, read from its owner,
:attr:`~mpg_envs.grid.workspace.Workspace.shape`."""


class PixelAction(NamedTuple):
    """A decoded action: which primitive, at which rotation index, at which pixel."""

    primitive: str
    rotation: int
    row: int
    col: int


def check_primitives(primitives: Sequence[str]) -> tuple[str, ...]:
    """Validate an allowed-primitives list; returns it as a tuple in canonical order."""
    primitives = tuple(primitives)
    known = registered_primitives()
    unknown = [p for p in primitives if p not in known]
    if unknown or not primitives:
        raise ValueError(f"primitives must be a non-empty subset of {known}, got {primitives}")
    ordered = tuple(p for p in known if p in primitives)
    if ordered != primitives:
        raise ValueError(f"primitives must be listed in the order {known}, got {primitives}")
    return primitives


def action_space_size(primitives: Sequence[str], size: int = HEIGHTMAP_SIZE) -> int:
    """Number of flat actions: ``P * 16 * size * size``."""
    return len(check_primitives(primitives)) * NUM_ROTATIONS * size * size


def encode_action(
    primitives: Sequence[str], primitive: str, rotation: int, row: int, col: int, size: int = HEIGHTMAP_SIZE
) -> int:
    """Flat index of ``(primitive, rotation, row, col)`` for an env allowing ``primitives``."""
    primitives = check_primitives(primitives)
    if primitive not in primitives:
        raise ValueError(f"primitive {primitive!r} is not allowed here; allowed: {primitives}")
    if not _is_int(rotation) or not 0 <= rotation < NUM_ROTATIONS:
        raise ValueError(f"rotation must be an integer in 0..{NUM_ROTATIONS - 1}, got {rotation!r}")
    for name, value in (("row", row), ("col", col)):
        if not _is_int(value) or not 0 <= value < size:
            raise ValueError(f"pixel {name} must be an integer in 0..{size - 1}, got {value!r}")
    p = primitives.index(primitive)
    return int(((p * NUM_ROTATIONS + int(rotation)) * size + int(row)) * size + int(col))


def decode_action(primitives: Sequence[str], index: int | np.integer | np.ndarray, size: int = HEIGHTMAP_SIZE) -> PixelAction:
    """Inverse of :func:`encode_action`; raises ``ValueError`` for a malformed index."""
    primitives = check_primitives(primitives)
    n = len(primitives) * NUM_ROTATIONS * size * size
    if isinstance(index, np.ndarray):
        if index.size != 1:
            raise ValueError(f"action must be a single integer, got an array of shape {index.shape}")
        index = index.reshape(())[()]
    if not _is_int(index):
        raise ValueError(f"action must be an integer in 0..{n - 1}, got {index!r} of type {type(index).__name__}")
    index = int(index)
    if not 0 <= index < n:
        raise ValueError(f"action must be an integer in 0..{n - 1} (primitives {primitives}), got {index}")
    p, rest = divmod(index, NUM_ROTATIONS * size * size)
    rotation, rest = divmod(rest, size * size)
    row, col = divmod(rest, size)
    return PixelAction(primitives[p], rotation, row, col)


class PixelActionSpace(spaces.Discrete):
    """``Discrete(P * 16 * size * size)`` that also knows which primitives it covers.

    It is a plain ``Discrete`` for every RL library; ``primitives`` lets a policy (such as
    ``mpg_agents.MPGNetPolicy``) map the flat index back to Q maps without guessing.
    """

    def __init__(self, primitives: Sequence[str], size: int = HEIGHTMAP_SIZE, seed: int | np.random.Generator | None = None):
        self.primitives = check_primitives(primitives)
        self.size = int(size)
        super().__init__(action_space_size(self.primitives, self.size), seed=seed)

    def encode(self, primitive: str, rotation: int, row: int, col: int) -> int:
        """Flat index of ``(primitive, rotation, row, col)``."""
        return encode_action(self.primitives, primitive, rotation, row, col, self.size)

    def decode(self, index: Any) -> PixelAction:
        """``(primitive, rotation, row, col)`` of a flat index."""
        return decode_action(self.primitives, index, self.size)

    def __repr__(self) -> str:
        return f"PixelActionSpace(primitives={self.primitives}, n={int(self.n)})"

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, PixelActionSpace) and other.primitives == self.primitives and other.size == self.size) or (
            type(other) is spaces.Discrete and super().__eq__(other)
        )

    __hash__ = None  # type: ignore[assignment]  # mutable seedable space, like gymnasium's
