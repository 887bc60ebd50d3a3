"""The physical ceiling of grasping: can the 2F-85 hold every shape of an object set alone?

Each trial places one object alone on the table (a seeded random position inside the
workspace and yaw, or with ``drop="random"`` a random orientation, so it lands on any face as
in cluttered scenes) and runs one grasp at the centre of its footprint, closing across its
short axis (the nearest of the 16 rotations), through the env's own grasp primitive. A
failure is ``closed_empty`` (the fingers closed on nothing), ``not_lifted`` (the object was
between the pads but did not come up) or ``ik`` (the pose was out of reach).
``benchmarks/grasp_ceiling.py`` runs it over a whole object set.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from mpg_envs.grid.grasp_geometry import angle_to_rotation, footprint_rect
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.grid.workspace import world_to_pixel
from mpg_envs.perception.heightmap import RaycastHeightmapper
from mpg_envs.scenes.generators import random_quat, yaw_quat
from mpg_envs.simulation.objects import ObjectAsset
from mpg_envs.simulation.primitives import PrimitiveExecutor
from mpg_envs.simulation.robot import ArmIK
from mpg_envs.simulation.world import World
from mpg_envs.tasks.config import EnvConfig

DROPS = ("yaw", "random")
"""How a trial places its object: on its base with a random yaw, or in a random orientation."""

EDGE_MARGIN = 0.07
"""Placements stay this far inside the workspace edges (as the scenes do)."""


@dataclass
class ShapeResult:
    """Grasp trials of one shape."""

    name: str
    trials: int = 0
    successes: int = 0
    failures: Counter = field(default_factory=Counter)

    @property
    def success_rate(self) -> float:
        return self.successes / self.trials if self.trials else 0.0

    def as_dict(self) -> dict:
        return {"trials": self.trials, "success": round(self.success_rate, 4), "failures": dict(self.failures)}


class GraspBench:
    """One object alone on the table, the env's world, heightmapper and primitive executor."""

    def __init__(self, asset: ObjectAsset, config: EnvConfig = EnvConfig(), ik: ArmIK | None = None):
        self.config = config
        self.world = World([asset], config.workspace, config.robot, config.physics)
        self.executor = PrimitiveExecutor(self.world, config.primitives, ik)
        self.heightmapper = RaycastHeightmapper(self.world.model, config.workspace, num_threads=1)

    @property
    def primitives(self) -> PrimitiveExecutor:
        """The executor's former attribute name (kept)."""
        return self.executor

    def close(self) -> None:
        self.heightmapper.close()

    def trial(self, rng: np.random.Generator, drop: str = "yaw") -> str | None:
        """Place the object at random, grasp it at its centre across its short axis.

        Returns ``None`` on success, else the failure kind.
        """
        if drop not in DROPS:
            raise ValueError(f"drop must be one of {DROPS}, got {drop!r}")
        world, ws = self.world, self.config.workspace
        world.reset()
        xy = (
            rng.uniform(ws.x_min + EDGE_MARGIN, ws.x_max - EDGE_MARGIN),
            rng.uniform(ws.y_min + EDGE_MARGIN, ws.y_max - EDGE_MARGIN),
        )
        world.drop_object(0, xy, yaw_quat(rng) if drop == "yaw" else random_quat(rng))
        if len(world.objects_outside_workspace()):
            return "rolled_away"
        depth = self.heightmapper(world.data).depth
        centre, _, short_dir = footprint_rect(world.object_vertices(0)[:, :2])
        row, col = world_to_pixel(ws, float(centre[0]), float(centre[1]))
        try:
            result = self.executor.execute(GRASP, angle_to_rotation(short_dir), row, col, depth, target=0)
        except RuntimeError:
            return "ik"
        if result.lifted and result.grasped_object == 0:
            return None
        return result.grasp_failure or "other"


def run_shape(asset: ObjectAsset, placements: int, seed: int, drop: str = "yaw", ik: ArmIK | None = None) -> ShapeResult:
    """``placements`` seeded grasp trials of one shape."""
    bench = GraspBench(asset, ik=ik)
    out = ShapeResult(asset.name)
    rng = np.random.default_rng([seed, sum(map(ord, asset.name))])
    try:
        for _ in range(placements):
            failure = bench.trial(rng, drop)
            out.trials += 1
            if failure is None:
                out.successes += 1
            else:
                out.failures[failure] += 1
    finally:
        bench.close()
    return out
