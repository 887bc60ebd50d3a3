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


from mpg_envs.tasks.env import EnvConfig  # noqa: E402
from mpg_envs.tasks.grasp_ceiling import DROPS, run_shape  # noqa: E402
from mpg_envs.simulation.objects import load_object_set  # noqa: E402
from mpg_envs.simulation.robot import ArmIK  # noqa: E402

GOAL = 0.98


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
