"""Simulation-core speed on one core: per primitive and per observation mode.

For each primitive, runs it ``--trials`` times on seeded Stage-5 scenes (10 objects dropped
close together) with a sensible action (the oracle's kind of action at the target) and
reports the median wall time, the physics steps used, and the share of wall time spent
inside ``mj_step`` (the rest is our overhead: IK, bookkeeping). Then the observation time
of the GL-free ray-cast mode and, when OpenGL is available, of the camera mode.

Goals: every primitive under 150 ms median, at least 70% of its time in
``mj_step``; the GL-free observation under 15 ms. The last output line is one JSON object.

    python benchmarks/env_speed.py [--trials 20]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

if sys.platform.startswith("linux"):
    os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core, as the goal says
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from mpg_envs.tasks.env import MPGEnv  # noqa: E402
from mpg_envs.policies.oracle import footprint_rect, angle_to_rotation  # noqa: E402
from mpg_envs.grid.workspace import world_to_pixel  # noqa: E402


def action_for(env: MPGEnv, primitive: str) -> tuple[int, int, int]:
    """(rotation, row, col) of a meaningful ``primitive`` near the target."""
    world, target = env.world, env.target
    ws = world.workspace
    if primitive == "move":
        # The highest object near the target: what a move is for.
        t = world.object_position(target)[:2]
        near = [j for j in world.active_objects() if np.linalg.norm(world.object_position(j)[:2] - t) < 0.12]
        obj = max(near, key=world.object_top)
    else:
        obj = target
    centre, _, short_dir = footprint_rect(world.object_vertices(obj)[:, :2])
    if primitive == "push":
        rotation = 4
        start = centre - np.array([0.0, 0.06])  # 6 cm behind, pushing along +y
        return rotation, *world_to_pixel(ws, *start)
    return angle_to_rotation(short_dir), *world_to_pixel(ws, *centre)


def measure_primitives(trials: int) -> dict[str, dict[str, float]]:
    env = MPGEnv("Stage5")
    out = {}
    for primitive in ("move", "push", "grasp"):
        walls, steps, fractions = [], [], []
        for k in range(trials):
            env.reset(seed=k)
            rotation, row, col = action_for(env, primitive)
            result = env.sim.executor.execute(primitive, rotation, row, col, env.last_observation["depth"], env.target)
            walls.append(result.seconds)
            steps.append(result.physics_steps)
            fractions.append(result.physics_seconds / result.seconds)
        out[primitive] = {
            "ms": 1000 * statistics.median(walls),
            "steps": statistics.median(steps),
            "fraction": statistics.median(fractions),
            "ik_solves": result.ik_solves,
        }
    env.close()
    return out


def measure_obs(mode: str, repeats: int) -> float | None:
    try:
        env = MPGEnv("Stage5", obs_mode=mode)
        env.reset(seed=0)
    except RuntimeError as exc:  # no OpenGL for the camera mode
        print(f"  {mode}: skipped ({exc})")
        return None
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        env.sim.observe(env.target)
        times.append(time.perf_counter() - start)
    env.close()
    return 1000 * statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    args = parser.parse_args()
    prims = measure_primitives(args.trials)
    obs = {mode: measure_obs(mode, 30) for mode in ("raycast", "camera")}
    print(f"{'primitive':10s} {'median ms':>10s} {'steps':>7s} {'in mj_step':>11s} {'IK solves':>10s}")
    for name, m in prims.items():
        print(f"{name:10s} {m['ms']:10.1f} {m['steps']:7.0f} {100 * m['fraction']:10.1f}% {m['ik_solves']:10d}")
    for mode, ms in obs.items():
        print(f"observation ({mode}): " + ("n/a" if ms is None else f"{ms:.1f} ms"))
    goals = all(m["ms"] < 150 and m["fraction"] >= 0.7 for m in prims.values()) and (obs["raycast"] or 1e9) < 15
    print("goals met" if goals else "goals NOT met")
    print(
        json.dumps(
            {
                "primitive_ms": {k: round(v["ms"], 2) for k, v in prims.items()},
                "physics_steps": {k: v["steps"] for k, v in prims.items()},
                "physics_fraction": {k: round(v["fraction"], 3) for k, v in prims.items()},
                "obs_ms": {k: None if v is None else round(v, 2) for k, v in obs.items()},
            }
        )
    )


if __name__ == "__main__":
    main()
