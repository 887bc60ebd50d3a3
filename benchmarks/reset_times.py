"""How long a reset takes: a test seed (its shipped scene) and a dropped seed (a fresh drop).

Median wall time of ``--resets`` resets of ``MPG-OccludedHard-v0`` (one ray-casting thread)
for: the same test seed again and again, distinct test seeds, and the same dropped seed again
and again (after one warm-up reset each). The last output line is one JSON object.

    python benchmarks/reset_times.py [--resets 10] [--test-seed 500000] [--dropped-seed 123]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402

import mpg_envs  # noqa: E402,F401


def median_reset(env: gym.Env, seeds: list[int]) -> float:
    """Median seconds of ``env.reset(seed=s)`` over ``seeds`` (after a warm-up reset)."""
    env.reset(seed=seeds[0])
    times = []
    for seed in seeds:
        start = time.perf_counter()
        env.reset(seed=seed)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="MPG-OccludedHard-v0")
    parser.add_argument("--resets", type=int, default=10)
    parser.add_argument("--test-seed", type=int, default=500000)
    parser.add_argument("--dropped-seed", type=int, default=123)
    args = parser.parse_args(argv)
    env = gym.make(args.env)
    n = args.resets
    out = {
        "env": args.env,
        "resets": n,
        "same_test_seed_s": median_reset(env, [args.test_seed] * n),
        "distinct_test_seeds_s": median_reset(env, list(range(args.test_seed, args.test_seed + n))),
        "same_dropped_seed_s": median_reset(env, [args.dropped_seed] * n),
    }
    env.close()
    for key, value in out.items():
        print(f"{key}: {value:.4f}" if isinstance(value, float) else f"{key}: {value}")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
