"""Valid scenes at every reset: reset each registered env N times and count the
scenes that break the start conditions below.

A scene is invalid when it has fewer active objects than the env's ``num_objects``, any
object outside the workspace or not at rest, ``info["objects_left"]`` differing from the
object count, or a target that breaks the stage's rule (Occluded: one of the first five
dropped and occluded at reset; Stage 5: the first or second dropped; Stage 3: occluded;
Stage 4: not occluded). A reset that raises ``InvalidSceneError`` counts as an error.
Every count must be 0. Also reports the median reset time. Seeds are ``seed .. seed+N-1``.

    python benchmarks/scene_validity.py [--resets 200] [--seed 0] [--envs MPG-Occluded-v0 ...]

The last output line is one JSON object:
``{"resets": N, "envs": {label: {"invalid": k, "errors": e, "reasons": {...}, "median_reset_s": t}}}``.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import statistics
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402

import mpg_envs  # noqa: E402,F401  (registers the envs)
from mpg_envs.tasks.env import MPGEnv  # noqa: E402
from mpg_envs.scenes.generators import InvalidSceneError  # noqa: E402
from mpg_envs.tasks.stages import STAGES  # noqa: E402

TARGET_RULES: dict[str, tuple[int, ...]] = {"Occluded": (0, 1, 2, 3, 4), "Stage5": (0, 1)}
"""Stage name -> the dropped positions the target may have."""


def scene_problems(env: MPGEnv, info: dict) -> list[str]:
    """What is wrong with the env's freshly reset scene (empty: valid)."""
    world, stage = env.world, env.stage
    problems = []
    if int(world.active.sum()) != env.num_objects:
        problems.append("object_count")
    if len(world.objects_outside_workspace()):
        problems.append("outside_workspace")
    if not world.objects_at_rest():
        problems.append("not_at_rest")
    if info["objects_left"] != env.num_objects:
        problems.append("objects_left")
    if stage.mask_all_objects:
        return problems
    if env.target is None:
        problems.append("no_target")
        return problems
    allowed = TARGET_RULES.get(stage.name)
    if allowed is not None and env.target not in allowed:
        problems.append("target_position")
    if stage.start_occluded is not None and info["occluded"] != stage.start_occluded:
        problems.append("target_occlusion")
    return problems


def check_env(env_id: str, resets: int, seed: int, **kwargs) -> dict:
    env = gym.make(env_id, **kwargs)
    unwrapped = env.unwrapped
    invalid, errors = 0, 0
    reasons: collections.Counter[str] = collections.Counter()
    times = []
    for k in range(resets):
        start = time.perf_counter()
        try:
            _, info = env.reset(seed=seed + k)
        except InvalidSceneError as exc:
            errors += 1
            reasons["InvalidSceneError"] += 1
            print(f"  seed {seed + k}: {exc}", flush=True)
            continue
        times.append(time.perf_counter() - start)
        problems = scene_problems(unwrapped, info)
        if problems:
            invalid += 1
            reasons.update(problems)
            print(f"  seed {seed + k}: invalid ({', '.join(problems)})", flush=True)
    env.close()
    return {
        "num_objects": unwrapped.num_objects,
        "invalid": invalid,
        "errors": errors,
        "reasons": dict(reasons),
        "median_reset_s": round(statistics.median(times), 4) if times else None,
    }


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--resets", type=int, default=200, help="resets per env (default 200)")
    parser.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    all_envs = [spec.env_id for spec in STAGES.values()]
    parser.add_argument("--envs", nargs="+", default=all_envs, choices=all_envs, metavar="ENV_ID")
    parser.add_argument("--no-30", dest="with_30", action="store_false", help="skip MPG-Occluded-v0 with 30 objects")
    args = parser.parse_args(argv)
    if args.resets < 1:
        parser.error("--resets must be at least 1")

    runs = [(env_id, env_id, {}) for env_id in args.envs]
    if args.with_30 and "MPG-Occluded-v0" in args.envs:
        runs.append(("MPG-Occluded-v0 (30 objects)", "MPG-Occluded-v0", {"num_objects": 30}))
    results = {}
    for label, env_id, kwargs in runs:
        print(f"{label}: {args.resets} resets", flush=True)
        results[label] = check_env(env_id, args.resets, args.seed, **kwargs)
        r = results[label]
        print(f"{label}: invalid {r['invalid']}, errors {r['errors']}, median reset {r['median_reset_s']} s", flush=True)
    summary = {"resets": args.resets, "seed": args.seed, "envs": results}
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    summary = main()
    sys.exit(0 if all(r["invalid"] == 0 and r["errors"] == 0 for r in summary["envs"].values()) else 1)
