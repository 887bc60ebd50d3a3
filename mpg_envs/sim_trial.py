"""Try a primitive in the simulation and put everything back: what a planner with a perfect
model of the physics can do (the scripted oracle checks its candidate grasps this way).

:class:`WorldCheckpoint` saves a :class:`~mpg_envs.world.World`'s full MuJoCo state (``mjData``,
warm starts included), which objects are in the scene and the physics counters, and restores
them exactly; MuJoCo is deterministic, so a primitive run after :meth:`WorldCheckpoint.restore`
does what the trial run did.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mpg_envs.primitives import PrimitiveResult, Primitives
from mpg_envs.world import World

__all__ = ["WorldCheckpoint", "try_primitive"]


class WorldCheckpoint:
    """The state of a world at one moment, to return to."""

    def __init__(self, world: World):
        self.world = world
        self._data = mujoco.MjData(world.model)
        mujoco.mj_copyData(self._data, world.model, world.data)
        self._active = world.active.copy()
        self._counter = (world.counter.steps, world.counter.seconds)

    def restore(self) -> None:
        """Put the world back as it was when the checkpoint was made."""
        world = self.world
        for i in np.flatnonzero(world.active != self._active):
            if self._active[i]:
                pos, quat = self._pose(int(i))
                world.set_object_pose(int(i), pos, quat)  # back in the scene (collisions, ray casts)
            else:
                world.remove_object(int(i))
        mujoco.mj_copyData(world.data, world.model, self._data)
        world.counter.steps, world.counter.seconds = self._counter

    def _pose(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        adr = self.world.object_qpos_adr[i]
        return self._data.qpos[adr : adr + 3].copy(), self._data.qpos[adr + 3 : adr + 7].copy()


def try_primitive(
    primitives: Primitives, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None = None
) -> PrimitiveResult:
    """Run a primitive on ``primitives.world`` and undo it; its result says what it would do."""
    checkpoint = WorldCheckpoint(primitives.world)
    try:
        return primitives.execute(primitive, rotation, row, col, depth, target)
    finally:
        checkpoint.restore()
