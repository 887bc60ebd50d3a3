"""Try a primitive in the simulation and put everything back: what a planner with a perfect
model of the physics can do (the scripted oracle checks its candidate grasps this way).

:class:`~mpg_envs.world.WorldCheckpoint` (re-exported here) saves a world's full MuJoCo
state (``mjData``, warm starts included), which objects are in the scene and the physics
counters, and restores them exactly; MuJoCo is deterministic, so a primitive run after
:meth:`~mpg_envs.world.WorldCheckpoint.restore` does what the trial run did.
"""

from __future__ import annotations

import numpy as np

from mpg_envs.primitives import PrimitiveResult, Primitives
from mpg_envs.world import WorldCheckpoint

__all__ = ["WorldCheckpoint", "try_primitive"]


def try_primitive(
    primitives: Primitives, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None = None
) -> PrimitiveResult:
    """Run a primitive on ``primitives.world`` and undo it; its result says what it would do."""
    checkpoint = WorldCheckpoint(primitives.world)
    try:
        return primitives.execute(primitive, rotation, row, col, depth, target)
    finally:
        checkpoint.restore()
