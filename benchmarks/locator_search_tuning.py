"""Choose the finding policy's cover and search rule on tuning episodes (seeds 700000 on).

A network policy on an exemplar track acts on what the target locator finds and, while the
target is not seen, on where the rule says it may hide
(:class:`mpg_agents.locator.cover.CoverRule`). This script plays the same tuning episodes with
each candidate rule, prints success, mean motions and look-alike grasps per rule with the
paired difference to the first rule (a 95% bootstrap interval over episodes), and with
``--write`` saves the locator with the best rule (most successes, then fewest motions) into its
weights, where policies read it. Never run it on test seeds.

Usage::

    MUJOCO_GL=egl python benchmarks/locator_search_tuning.py --locator runs/locator/locator.safetensors \\
        --env MPG-OccludedHardExemplar-v0 --objects 15 30 --episodes 30 \\
        --rules '{"search": "heap"}' '{"search": "empty"}' --workers 2 --write
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_agents.evaluation.evaluate import run_episode
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_agents.evaluation.stats import bootstrap_mean_interval
from mpg_agents.locator.cover import CoverRule
from mpg_agents.locator.locator import SNAPS, TargetLocator
from mpg_agents.locator.run import write_locator

TUNING_SEED = 700000
"""The first tuning seed: test seeds (500000 on) are never played here."""


def _play(job: tuple[str, str, int, dict[str, Any], int, str | None, float | None]) -> tuple[int, int, dict[str, Any]]:
    """Worker: one episode of one rule (``locator, env id, objects, rule, seed, snap, pose floor``), one thread."""
    torch.set_num_threads(1)
    locator, env_id, objects, rule, seed, snap, floor = job
    env = gym.make(env_id, num_objects=objects)
    try:
        policy = make_policy("shipped", env, locator=locator)
        policy.rule = CoverRule(**rule)
        if snap is not None:
            policy.locator.snap = snap
        if floor is not None:
            policy.locator.pose_floor = floor
        record = run_episode(policy, env, 0, seed)
    finally:
        env.close()
    return objects, seed, {"success": record.success, "motions": record.motions, "lookalike": record.lookalike_grasps or 0}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--locator", required=True, type=Path)
    parser.add_argument("--env", default="MPG-OccludedHardExemplar-v0")
    parser.add_argument("--objects", nargs="+", type=int, default=[15, 30])
    parser.add_argument("--episodes", type=int, default=30, help="tuning episodes per object count")
    parser.add_argument("--seed", type=int, default=TUNING_SEED)
    parser.add_argument(
        "--rules", nargs="+", default=['{"search": "heap"}', '{"search": "empty"}'], help="CoverRule fields as JSON"
    )
    parser.add_argument(
        "--snap", nargs="+", choices=SNAPS, help="how masks snap to the matcher's blobs, one or more (default: as saved)"
    )
    parser.add_argument("--pose-floor", type=float, help="the pose snapping's least fit (default: as saved)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--write", action="store_true", help="save the best rule and snapping into the locator's weights")
    args = parser.parse_args()
    if args.seed < TUNING_SEED:
        parser.error(f"--seed must be a tuning seed ({TUNING_SEED} or more), got {args.seed}")
    # Every rule with every snapping is a candidate, played on the same episodes.
    candidates = [(CoverRule(**json.loads(text)), snap) for text in args.rules for snap in (args.snap or [None])]
    seeds = range(args.seed, args.seed + args.episodes)
    jobs = [
        (str(args.locator), args.env, n, rule.to_dict(), s, snap, args.pose_floor)
        for rule, snap in candidates
        for n in args.objects
        for s in seeds
    ]
    with multiprocessing.get_context("spawn").Pool(args.workers) as pool:
        results = pool.map(_play, jobs, chunksize=1)
    per_candidate = len(args.objects) * args.episodes
    tables = [results[k * per_candidate : (k + 1) * per_candidate] for k in range(len(candidates))]
    first = tables[0]
    scores = []
    for (rule, snap), table in zip(candidates, tables):
        success = np.array([r["success"] for _, _, r in table], float)
        motions = np.array([r["motions"] for _, _, r in table], float)
        lookalike = sum(r["lookalike"] for _, _, r in table)
        base = np.array([r["success"] for _, _, r in first], float)
        low, high = bootstrap_mean_interval(success - base)
        by_count = {n: np.mean([r["success"] for m, _, r in table if m == n]) for n in args.objects}
        print(
            f"{json.dumps(rule.to_dict())}, snap {snap or 'as saved'}: success {success.mean():.1%} "
            f"({', '.join(f'{n} obj. {v:.0%}' for n, v in by_count.items())}), motions {motions.mean():.2f}, "
            f"look-alike grasps {lookalike}; minus the first candidate {np.mean(success - base):+.1%} [{low:+.1%}, {high:+.1%}]",
            flush=True,
        )
        scores.append((success.sum(), -motions.mean()))
    best, best_snap = candidates[max(range(len(candidates)), key=lambda k: scores[k])]
    print(f"best: {json.dumps(best.to_dict())}, snap {best_snap or 'as saved'}")
    if args.write:
        locator = TargetLocator.load(args.locator)
        locator.rule = best
        if best_snap is not None:
            locator.snap = best_snap
        if args.pose_floor is not None:
            locator.pose_floor = args.pose_floor
        locator.record["rule_tuning"] = {
            "env": args.env,
            "objects": args.objects,
            "episodes": args.episodes,
            "seed": args.seed,
            "rules": [r.to_dict() for r, _ in candidates],
            "snaps": args.snap,
        }
        card = write_locator(locator, args.locator)
        print(f"written the rule into {args.locator} and its model card {card}")


if __name__ == "__main__":
    main()
