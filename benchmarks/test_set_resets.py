"""The shipped test sets: the target's visible fraction in each, how long a reset from them
takes, and that two processes agree.

For each test env and object count, ``--resets`` resets on test ids (cycling through a set of
fewer scenes; after one warm-up reset
that reads the set's file), timed with the heightmaps on one thread; prints the median and the
95th percentile, then compares a digest of every observation with a second process's. Goal:
a reset from a test set in under 100 ms; identical observations in both processes.

    python benchmarks/test_set_resets.py [--resets 20] [--training-envs 50] [--envs MPG-OccludedHardNovel-v0 ...] [--cpu-time]

``--training-envs N`` also prints the visible fraction of the target over N generated resets
(seeds 0..N-1) of each training stage with a target.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time

os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401
from mpg_envs.perception.occlusion import VISIBILITY_BAND_LABELS, visibility_band  # noqa: E402
from mpg_envs.tasks.stages import STAGES  # noqa: E402
from mpg_envs.scenes.test_sets import TEST_SEED_START, find_test_set, test_set_name  # noqa: E402

CELLS = (
    ("MPG-Occluded-v0", 15), ("MPG-Occluded-v0", 30), ("MPG-OccludedHard-v0", 15), ("MPG-OccludedHard-v0", 30),
    ("MPG-OccludedHardNovel-v0", 15), ("MPG-OccludedHardNovel-v0", 30),
)  # fmt: skip


def shipped_set(env_id: str, n: int):
    """The shipped test set of a cell (the env's stage's sets on its object set)."""
    kwargs = gym.spec(env_id).kwargs
    return find_test_set(test_set_name(STAGES[kwargs["stage"]].test_set, kwargs.get("object_set", "blocks")), n)


def test_seeds(env_id: str, n: int, count: int) -> list[int]:
    """``count`` seeds of the cell's set after its first, cycling through the set when it holds fewer."""
    seeds = shipped_set(env_id, n).seeds.tolist()
    rest = seeds[1:] or seeds
    return [int(rest[i % len(rest)]) for i in range(count)]


def digests(resets: int, cells=CELLS) -> dict[str, list[str]]:
    """Observation digests of the first ``resets`` test ids of every cell."""
    out = {}
    for env_id, n in cells:
        env = gym.make(env_id, num_objects=n)
        out[f"{env_id}/{n}"] = [
            hashlib.sha256(b"".join(o[k].tobytes() for k in sorted(o))).hexdigest()
            for o, _ in (env.reset(seed=seed) for seed in test_seeds(env_id, n, resets))
        ]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resets", type=int, default=20)
    parser.add_argument("--envs", nargs="+", help="only these env ids' cells (default: all)")
    parser.add_argument("--cpu-time", action="store_true", help="time resets by the process's CPU time (a busy machine inflates wall time)")
    parser.add_argument("--training-envs", type=int, default=0, help="resets per training stage for its visible fraction (0: none)")
    parser.add_argument("--digests", action="store_true", help=argparse.SUPPRESS)  # the second process
    args = parser.parse_args(argv)
    cells = tuple(c for c in CELLS if not args.envs or c[0] in args.envs)
    if args.digests:
        print(json.dumps(digests(args.resets, cells)))
        return 0
    print("| env | objects | scenes | visible fraction: median [quartiles] | " + " | ".join(VISIBILITY_BAND_LABELS) + " |")
    for env_id, n in cells:
        test_set = shipped_set(env_id, n)
        v = test_set.visible_fraction
        counts = [sum(visibility_band(float(x)) == label for x in v) for label in VISIBILITY_BAND_LABELS]
        print(f"| {env_id} | {n} | {len(v)} | {np.median(v):.2f} [{np.quantile(v, 0.25):.2f}, {np.quantile(v, 0.75):.2f}] | " + " | ".join(map(str, counts)) + " |")
    for env_id in ("MPG-Stage2-v0", "MPG-Stage3-v0", "MPG-Stage4-v0", "MPG-Stage5-v0")[: 4 if args.training_envs else 0]:
        env = gym.make(env_id)
        v = np.array([env.reset(seed=i)[1]["visible_fraction"] for i in range(args.training_envs)])
        counts = [sum(visibility_band(float(x)) == label for x in v) for label in VISIBILITY_BAND_LABELS]
        print(f"| {env_id} | {env.unwrapped.num_objects} | {len(v)} generated | {np.median(v):.2f} [{np.quantile(v, 0.25):.2f}, {np.quantile(v, 0.75):.2f}] | " + " | ".join(map(str, counts)) + " |")
    print(f"load average {os.getloadavg()[0]:.2f} (timings want a quiet machine)")
    for env_id, n in cells:
        env = gym.make(env_id, num_objects=n)
        env.reset(seed=TEST_SEED_START)  # reads the set's file once
        times = []
        clock = time.process_time if args.cpu_time else time.perf_counter
        for seed in test_seeds(env_id, n, args.resets):
            start = clock()
            env.reset(seed=seed)
            times.append(clock() - start)
        ms = 1000 * np.array(times)
        print(f"{env_id} {n} objects: reset median {np.median(ms):.0f} ms, 95th percentile {np.percentile(ms, 95):.0f} ms ({args.resets} test ids{', CPU time' if args.cpu_time else ''})")
    here = digests(args.resets, cells)
    other = json.loads(subprocess.run([sys.executable, __file__, "--digests", "--resets", str(args.resets), *(["--envs", *args.envs] if args.envs else [])], capture_output=True, text=True, check=True).stdout)
    print(f"observations identical in two processes: {here == other} ({sum(len(v) for v in here.values())} resets)")
    return 0 if here == other else 1


if __name__ == "__main__":
    raise SystemExit(main())
