"""The physical ceiling of grasping: can the 2F-85 hold every shape of the object set?

For each shape of the set, ``--placements`` seeded random placements of the object alone on
the table (a random position inside the workspace and a random yaw; with ``--drop random``
a random orientation, so it lands on any face as in the cluttered scenes). Each placement
gets one grasp at the centre of the object's footprint, closing across its short axis
(the nearest of the 16 rotations), through the env's own grasp primitive. Prints a table
per shape (success rate and the failure kinds: ``closed_empty`` the fingers closed on
nothing, ``not_lifted`` the object was between the pads but did not come up, ``ik`` the
pose was out of reach) and, as the last line, JSON. The goal is >= 98% per shape.

    python benchmarks/grasp_ceiling.py [--placements 100] [--seed 0] [--drop yaw|random] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections import Counter
from dataclasses import dataclass, field


import numpy as np  # noqa: E402

from mpg_envs.env import EnvConfig  # noqa: E402
from mpg_envs.heightmap import RaycastHeightmapper  # noqa: E402
from mpg_envs.objects import ObjectAsset, load_object_set  # noqa: E402
from mpg_envs.grasp_geometry import angle_to_rotation, footprint_rect  # noqa: E402
from mpg_envs.primitives import Primitives  # noqa: E402
from mpg_envs.robot import ArmIK  # noqa: E402
from mpg_envs.scenes import random_quat, yaw_quat  # noqa: E402
from mpg_envs.workspace import world_to_pixel  # noqa: E402
from mpg_envs.world import World  # noqa: E402

GOAL = 0.98
DROPS = ("yaw", "random")
EDGE_MARGIN = 0.07  # placements stay this far inside the workspace edges (as the scenes do)


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
    """One object alone on the table, the env's world, heightmapper and primitives."""

    def __init__(self, asset: ObjectAsset, config: EnvConfig = EnvConfig(), ik: ArmIK | None = None):
        self.config = config
        self.world = World([asset], config.workspace, config.robot, config.physics)
        self.primitives = Primitives(self.world, config.primitives, ik)
        self.heightmapper = RaycastHeightmapper(self.world.model, config.workspace, num_threads=1)

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
        xy = (rng.uniform(ws.x_min + EDGE_MARGIN, ws.x_max - EDGE_MARGIN), rng.uniform(ws.y_min + EDGE_MARGIN, ws.y_max - EDGE_MARGIN))
        world.drop_object(0, xy, yaw_quat(rng) if drop == "yaw" else random_quat(rng))
        if len(world.objects_outside_workspace()):
            return "rolled_away"
        depth = self.heightmapper(world.data).depth
        centre, _, short_dir = footprint_rect(world.object_vertices(0)[:, :2])
        row, col = world_to_pixel(ws, float(centre[0]), float(centre[1]))
        try:
            result = self.primitives.execute("grasp", angle_to_rotation(short_dir), row, col, depth, target=0)
        except RuntimeError:
            return "ik"
        if result.grasp_success and result.grasped_object == 0:
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--placements", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--drop", choices=DROPS, default="yaw")
    parser.add_argument("--object-set", default="blocks")
    parser.add_argument("--shapes", nargs="*", help="only these shapes (default: all)")
    parser.add_argument("--json", help="also write the JSON here")
    args = parser.parse_args(argv)
    assets = load_object_set(args.object_set)
    if args.shapes:
        unknown = set(args.shapes) - {a.name for a in assets}
        if unknown:
            parser.error(f"unknown shapes {sorted(unknown)}; valid: {[a.name for a in assets]}")
        assets = [a for a in assets if a.name in args.shapes]
    ik = ArmIK(EnvConfig().robot)
    start = time.perf_counter()
    results = []
    print(f"{'shape':<18} {'success':>8}  failures  (drop={args.drop}, {args.placements} placements)")
    for asset in assets:
        r = run_shape(asset, args.placements, args.seed, args.drop, ik)
        results.append(r)
        fails = ", ".join(f"{k} {v}" for k, v in sorted(r.failures.items())) or "-"
        print(f"{r.name:<18} {100 * r.success_rate:7.1f}%  {fails}", flush=True)
    worst = min((r.success_rate for r in results), default=math.nan)
    print(f"worst shape {100 * worst:.1f}% (goal >= {100 * GOAL:.0f}% per shape: {'met' if worst >= GOAL else 'NOT met'}); {time.perf_counter() - start:.0f} s")
    summary = {
        "drop": args.drop,
        "placements": args.placements,
        "seed": args.seed,
        "shapes": {r.name: r.as_dict() for r in results},
        "goal_met": bool(worst >= GOAL),
    }
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summary, fh, indent=2)
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
