"""What a primitive did from a given world state, remembered so it is never simulated twice.

MuJoCo is deterministic: a motion run from the same state of the same world, with the same
arguments, ends in the same state with the same result, bit for bit. A planner that tries
actions in a copy of the simulation (the oracle verifies its grasps and looks ahead through
moves, :meth:`~mpg_envs.tasks.episode_sim.EpisodeSim.try_primitive`) then runs the action it
chose for real from that very state, and often tries again, at its next decision, the grasps
it already tried after the move it then made. :class:`MotionMemo` keeps, for each motion run
since the world was built, the state it started from (its key) and the state it ended in
(a :class:`~mpg_envs.simulation.world.WorldCheckpoint`); a motion asked again from a
remembered state is not simulated: the end state is restored and the same result returned.

The key holds everything a motion reads: the state MuJoCo integrates
(``mjSTATE_INTEGRATION``: time, positions, velocities, actuator activations, controls, warm
start), which objects are in the scene (their collision flags follow from it), the warning
counters, the motion and its arguments, and the depth heightmap it was handed. Every motion
begins by setting the arm's joints and recomputing what follows from the state
(``mj_forward``), so nothing else of the previous step is read. The model's other fields are
fixed while a world lives; :meth:`clear` forgets everything when a world is built or reset.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict

import mujoco
import numpy as np

from mpg_envs.simulation.motions import PrimitiveResult
from mpg_envs.simulation.world import World, WorldCheckpoint

MEMO_CAPACITY = 64
"""Motions remembered per world at most (the oldest forgotten first). A decision of the
oracle runs at most about 25; a remembered end state holds tens of kilobytes."""


class MotionMemo:
    """The results and end states of the motions run on one world, by their start state.

    ``capacity`` bounds how many are kept (least recently used forgotten first); ``hits``
    and ``misses`` count the lookups that found one and those that did not.
    """

    def __init__(self, capacity: int = MEMO_CAPACITY):
        if isinstance(capacity, bool) or not isinstance(capacity, int) or capacity < 1:
            raise ValueError(f"capacity must be a positive integer, got {capacity!r}")
        self.capacity = capacity
        self.hits = 0
        self.misses = 0
        self._entries: OrderedDict[bytes, tuple[PrimitiveResult, WorldCheckpoint]] = OrderedDict()

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        """Forget every motion (a new or reset world: its states are not comparable)."""
        self._entries.clear()

    @staticmethod
    def key(world: World, primitive: str, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None) -> bytes:
        """The digest of what a motion started now would read: the world's integration
        state, active objects and warning counters, the motion's arguments and ``depth``."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        state = np.empty(mujoco.mj_stateSize(world.model, spec))
        mujoco.mj_getState(world.model, world.data, state, spec)
        digest = hashlib.blake2b(digest_size=32)
        digest.update(state.tobytes())
        digest.update(np.ascontiguousarray(world.active, dtype=bool).tobytes())
        digest.update(np.asarray([w.number for w in world.data.warning], dtype=np.int64).tobytes())
        depth = np.ascontiguousarray(depth)
        digest.update(repr((primitive, int(rotation), int(row), int(col), target, depth.dtype.str, depth.shape)).encode())
        digest.update(depth.tobytes())
        return digest.digest()

    def recall(self, key: bytes) -> tuple[PrimitiveResult, WorldCheckpoint] | None:
        """The result and end state remembered for ``key`` (counted as a hit), else ``None``
        (a miss)."""
        entry = self._entries.get(key)
        if entry is None:
            self.misses += 1
            return None
        self._entries.move_to_end(key)
        self.hits += 1
        return entry

    def replay(self, key: bytes, world: World) -> PrimitiveResult | None:
        """The motion remembered for ``key``, run again without simulating it: ``world`` put in its
        end state, its step counter advanced by the motion's steps, and a copy of its result (no
        physics seconds or IK solves: none were spent); ``None`` when none is remembered."""
        remembered = self.recall(key)
        if remembered is None:
            return None
        known, end = remembered
        steps, seconds = world.counter.steps, world.counter.seconds
        end.restore()
        world.counter.steps, world.counter.seconds = steps + known.physics_steps, seconds
        return dataclasses.replace(known, physics_seconds=0.0, ik_solves=0)

    def remember(self, key: bytes, result: PrimitiveResult, end: WorldCheckpoint) -> None:
        """Keep ``result`` (a copy) and the end state ``end`` of the motion that started at ``key``."""
        self._entries[key] = (dataclasses.replace(result), end)
        self._entries.move_to_end(key)
        while len(self._entries) > self.capacity:
            self._entries.popitem(last=False)
