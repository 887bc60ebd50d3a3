"""The exemplar's pictures: the target alone, resting on an empty table, seen as the episode's
observations are (``target_spec="exemplar"``).

:class:`ExemplarQuery` drops the target's object in a random orientation onto the empty table
at the workspace centre, lets it come to rest (a stable pose, found by the physics the scenes
are made with), turns it by a random yaw about the vertical, and takes its colour and depth
heightmaps with the episode's observation mode: ray casts, or the RGB-D cameras with the
episode's visual randomization (its light, camera errors and depth noise; the object's colour
jittered by a draw of its own, as another object of that colour would be). The heightmaps have
the observation's grid, so the query shows the object at the scene's scale. Every draw comes
from the generator it is handed (the env's exemplar stream, :mod:`mpg_envs.tasks.target_spec`).

One world per object is kept (up to :data:`KEPT_WORLDS`): a later query of the same object puts
it back in its freshly built state rather than compiling it again.
"""

from __future__ import annotations

import dataclasses
import math
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np

from mpg_envs.perception.visual_randomization import (
    EpisodeVisuals,
    VisualRandomization,
    draw_visuals,
)
from mpg_envs.scenes.generators import random_quat
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.robot import ArmIK
from mpg_envs.tasks.config import EnvConfig
from mpg_envs.tasks.episode_sim import EpisodeSim

QUERY_DROP_HEIGHT = 0.02
"""Height (m) of the object's lowest point above the table when it is let go."""

QUERY_DROP_TIMESTEP = 0.004
"""Physics timestep (s) of the drop: only where the object comes to rest matters (as the
unseen-object track's drops)."""

KEPT_WORLDS = 8
"""Query worlds kept per env in ray-cast mode (one per object; the eight blocks all stay compiled)."""


def yaw_turned(quat: Sequence[float] | np.ndarray, yaw: float) -> np.ndarray:
    """The orientation ``quat`` (w first) turned by ``yaw`` radians about the world's vertical."""
    w, x, y, z = np.asarray(quat, dtype=float)
    c, s = math.cos(yaw / 2), math.sin(yaw / 2)
    # (c, 0, 0, s) * (w, x, y, z)
    return np.array([c * w - s * z, c * x - s * y, c * y + s * x, c * z + s * w])


class ExemplarQuery:
    """Colour and depth heightmaps of one object alone on the empty table (see the module docstring).

    Args:
        config: the env's settings (workspace, robot, physics); the query's ray casts use one thread.
        obs_mode: the env's observation mode (``raycast`` or ``camera``).
        camera_config: the camera mode's cameras (``None``: the default ones).
        randomization: the env's visual randomization ranges (``None``: off), whose object
            colour ranges the query's own jitter is drawn in.
    """

    def __init__(
        self,
        config: EnvConfig,
        obs_mode: str,
        camera_config: Any = None,
        randomization: VisualRandomization | None = None,
    ):
        self.config = dataclasses.replace(config, raycast_threads=1)
        self.obs_mode = obs_mode
        self.camera_config = camera_config
        self.randomization = randomization
        self._sims: OrderedDict[int, tuple[ObjectAsset, EpisodeSim]] = OrderedDict()

    def images(
        self,
        asset: ObjectAsset,
        rgba: Sequence[float],
        rng: np.random.Generator,
        visuals: EpisodeVisuals | None = None,
        ik: ArmIK | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(color, depth)``: ``(H, W, 3)`` uint8 and ``(H, W)`` float32 heightmaps of ``asset``
        painted ``rgba``, in a stable pose and yaw drawn from ``rng``, seen with the episode's
        ``visuals`` (``None``: unrandomized). ``ik``: the env's arm kinematics, shared by a
        world made for the query (making one takes a while; ``None``: it makes its own)."""
        sim = self._sim(asset, ik)
        world = sim.build([asset])
        sim.paint_objects([rgba])
        centre = np.asarray(world.workspace.center[:2], dtype=float)
        with world.stepping(QUERY_DROP_TIMESTEP):
            world.drop_object(0, centre, random_quat(rng), height=QUERY_DROP_HEIGHT)
            world.settle()  # at rest twice: an object slowed down only for an instant (tipping over) goes on
        position, quat = world.object_pose(0)
        yaw = float(rng.uniform(0.0, 2.0 * math.pi))
        world.set_object_pose(0, (centre[0], centre[1], position[2]), yaw_turned(quat, yaw))
        world.forward()
        sim.initialize_episode(rng)
        sim.visuals = self._visuals(visuals, rng)
        maps = sim.heightmaps(0)
        return maps.color.copy(), maps.depth.astype(np.float32)

    def _visuals(self, visuals: EpisodeVisuals | None, rng: np.random.Generator) -> EpisodeVisuals | None:
        """The episode's visuals with the object's colour jitter (and the depth noise's seed)
        drawn afresh, so the query's colour is no copy of the target's in the scene."""
        if visuals is None:
            return None
        seed = int(rng.integers(2**63))
        gains = visuals.object_gains if self.randomization is None else draw_visuals(self.randomization, seed).object_gains
        return dataclasses.replace(visuals, seed=seed, object_gains=gains)

    def _sim(self, asset: ObjectAsset, ik: ArmIK | None) -> EpisodeSim:
        """The kept simulation of ``asset`` (made, and the oldest one closed past :data:`KEPT_WORLDS`)."""
        kept = self._sims.pop(id(asset), None)
        if kept is not None and kept[0] is asset:
            self._sims[id(asset)] = kept  # the newest again
            return kept[1]
        if kept is not None:  # another asset that had the same id
            kept[1].close()
        # The cameras see only the table and the objects: the arm's visual meshes are left out.
        sim = EpisodeSim(self.config, obs_mode=self.obs_mode, camera_config=self.camera_config, ik=ik)
        self._sims[id(asset)] = (asset, sim)
        # The camera mode compiles every world afresh (EpisodeSim.build): one is enough to keep.
        while len(self._sims) > (KEPT_WORLDS if self.obs_mode == "raycast" else 1):
            _, (_, old) = self._sims.popitem(last=False)
            old.close()
        return sim

    def close(self) -> None:
        """Free every kept world's views (threads, renderers)."""
        for _, sim in self._sims.values():
            sim.close()
        self._sims.clear()
