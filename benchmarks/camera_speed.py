"""Time of one observation's heightmaps: the camera mode beside the ray casts, in one run.

On one hard-track scene (``MPG-OccludedHard-v0``, 15 objects, a tuning seed), the ray-cast
heightmaps (one thread), the camera mode's (two rendered RGB-D views back-projected and
fused) and, where this version has it, the camera mode with the default visual
randomization (a tilted light with shadows, colours, calibration error, depth noise), are
timed in turn ``--repeats`` times; the medians are printed, and the last line is one JSON
object. Rendering needs OpenGL (``MUJOCO_GL=egl`` or ``osmesa`` on a headless machine).

    MUJOCO_GL=egl python benchmarks/camera_speed.py [--repeats 50] [--seed 700000]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from mpg_envs.perception.camera import CameraConfig, CameraHeightmapper  # noqa: E402
from mpg_envs.perception.heightmap import RaycastHeightmapper  # noqa: E402
from mpg_envs.tasks.env import MPGEnv  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=50)
    parser.add_argument("--seed", type=int, default=700000, help="a tuning seed (not a test seed)")
    args = parser.parse_args()

    env = MPGEnv("OccludedHard", obs_mode="camera")  # its world carries the cameras
    env.reset(seed=args.seed)
    model, data = env.world.model, env.world.data
    rng = np.random.default_rng(0)
    modes = {
        "raycast": RaycastHeightmapper(model, env.config.workspace, num_threads=1),
        "camera": CameraHeightmapper(model, CameraConfig(), env.config.workspace),
    }
    calls = {"raycast": lambda: modes["raycast"](data), "camera": lambda: modes["camera"](data)}
    try:
        from mpg_envs.perception.visual_randomization import VisualRandomization, draw_visuals
    except ImportError:  # a version without visual randomization
        pass
    else:
        visuals = draw_visuals(VisualRandomization(), args.seed)
        calls["camera_randomized"] = lambda: modes["camera"](data, rng, visuals)
    times: dict[str, list[float]] = {name: [] for name in calls}
    for name, call in calls.items():
        call()  # warm-up: caches, GL state
    for _ in range(args.repeats):  # interleaved, so a busy machine slows every mode alike
        for name, call in calls.items():
            start = time.perf_counter()
            call()
            times[name].append(time.perf_counter() - start)
    for mapper in modes.values():
        mapper.close()
    env.close()
    medians = {name: round(1000 * statistics.median(t), 1) for name, t in times.items()}
    for name, ms in medians.items():
        print(f"{name:18s} median {ms:7.1f} ms over {args.repeats}")
    print(json.dumps({"median_ms": medians, "repeats": args.repeats, "seed": args.seed, "cpus": len(os.sched_getaffinity(0))}))


if __name__ == "__main__":
    main()
