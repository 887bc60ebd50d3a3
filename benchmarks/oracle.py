"""The scripted oracle on held-out ``MPG-Occluded-v0`` episodes: success, motions, and why it failed.

Episode ``i`` of a cell is reset with seed ``--seed + i`` (the same scenes for any run). For
each object count: the success rate, the mean motions per episode, and every failed episode
categorised:

* ``target_not_graspable`` -- the oracle's last look found no collision-free grasp angle;
* ``slip`` -- its last attempt was a grasp of the target that held nothing;
* ``push_without_effect`` -- its last attempt was a push that changed nothing;
* ``target_left_workspace`` -- the target was pushed or knocked out of the workspace;
* ``motion_cap`` -- the motions ran out while the oracle still made progress.

The env's own ``info["end_reason"]`` is printed too when the env reports it. The oracle tries
its candidate grasps and preparations in a checkpointed copy of the simulation before acting
(see :mod:`mpg_envs.policies`); ``--geometric`` plans by geometry alone, without trials. Goals (issue
13): >= 97% success in <= 2.8 mean motions at 15 objects, >= 93% in <= 3.7 at 30. The last
output line is JSON.

    OMP_NUM_THREADS=1 python benchmarks/oracle.py --episodes 100 --objects 15 30 --seed 90000 [--verbose]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from dataclasses import dataclass


import gymnasium as gym  # noqa: E402

import mpg_envs  # noqa: E402,F401  (registers the envs)
from mpg_envs.policies import OracleConfig, OraclePolicy  # noqa: E402

ENV_ID = "MPG-Occluded-v0"
GOALS = {15: (0.97, 2.8), 30: (0.93, 3.7)}
CATEGORIES = ("target_not_graspable", "slip", "push_without_effect", "target_left_workspace", "motion_cap")


@dataclass
class Episode:
    seed: int
    success: bool
    motions: int
    category: str | None  # None when it succeeded
    end_reason: str
    actions: list[str]


def classify(last_info: dict, oracle: OraclePolicy, steps: list[tuple[str, dict]]) -> str:
    """Why a failed episode failed (one of :data:`CATEGORIES`)."""
    if last_info.get("target_out_of_workspace"):
        return "target_left_workspace"
    if oracle.last_plan is not None and oracle.last_plan.get("no_free_grasp"):
        return "target_not_graspable"
    if steps:
        primitive, info = steps[-1]
        if primitive == "grasp" and not info.get("target_grasped"):
            return "slip"
        if primitive == "push" and not info.get("change_detected"):
            return "push_without_effect"
    return "motion_cap"


def run_episode(env: gym.Env, oracle: OraclePolicy, seed: int) -> Episode:
    obs, info = env.reset(seed=seed)
    oracle.reset()
    steps: list[tuple[str, dict]] = []
    plans: list[str] = []
    terminated = truncated = False
    while not (terminated or truncated):
        action = oracle.act(obs)
        plans.append(str((oracle.last_plan or {}).get("kind", "")))
        obs, _, terminated, truncated, info = env.step(action)
        steps.append((info["primitive"], info))
    success = bool(info.get("is_success"))
    # "+": it uncovered or took the target; "!why": the grasp or move held nothing (info grasp_failure).
    actions = [
        f"{k}{'+' if i.get('target_grasped') or i.get('move_success') else ''}{'!' + i['grasp_failure'] if i.get('grasp_failure') else ''}"
        for k, (_, i) in zip(plans, steps)
    ]
    category = None if success else classify(info, oracle, steps)
    return Episode(seed, success, len(steps), category, str(info.get("end_reason", "unreported")), actions)


def run_cell(num_objects: int, episodes: int, seed: int, verbose: bool = False, config: OracleConfig = OracleConfig()) -> dict:
    env = gym.make(ENV_ID, num_objects=num_objects).unwrapped
    oracle = OraclePolicy(env, config)
    results = []
    start = time.perf_counter()
    for i in range(episodes):
        ep = run_episode(env, oracle, seed + i)
        results.append(ep)
        if verbose or not ep.success:
            outcome = "ok  " if ep.success else "FAIL"
            print(f"  {num_objects} objects seed {ep.seed}: {outcome} {ep.motions} motions [{' '.join(ep.actions)}] "
                  f"{ep.category or ''} (end_reason {ep.end_reason})", flush=True)
    env.close()
    n = len(results)
    success = sum(r.success for r in results) / n
    motions = sum(r.motions for r in results) / n
    categories = Counter(r.category for r in results if r.category)
    return {
        "episodes": n,
        "success": round(success, 4),
        "motions": round(motions, 3),
        "failures": {c: categories.get(c, 0) for c in CATEGORIES},
        "end_reasons": dict(Counter(r.end_reason for r in results)),
        "failed_seeds": [r.seed for r in results if not r.success],
        "seconds_per_episode": round((time.perf_counter() - start) / n, 2),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--objects", type=int, nargs="+", default=[15, 30])
    parser.add_argument("--seed", type=int, default=90000)
    parser.add_argument("--verbose", action="store_true", help="print every episode, not only the failures")
    parser.add_argument("--geometric", action="store_true", help="plan by geometry alone (no trials in a copy of the simulation)")
    parser.add_argument("--json", help="also write the JSON here")
    args = parser.parse_args(argv)
    if args.episodes < 1:
        parser.error("--episodes must be >= 1")
    cells = {}
    for n in args.objects:
        config = OracleConfig(verify_grasps=0) if args.geometric else OracleConfig()
        cell = run_cell(n, args.episodes, args.seed, args.verbose, config)
        cells[str(n)] = cell
        goal = GOALS.get(n)
        met = "" if goal is None else f"; goal >= {100 * goal[0]:.0f}% in <= {goal[1]} motions " + (
            "met" if cell["success"] >= goal[0] and cell["motions"] <= goal[1] else "NOT met")
        fails = ", ".join(f"{k} {v}" for k, v in cell["failures"].items() if v) or "none"
        print(f"oracle, {ENV_ID}, {n} objects, {cell['episodes']} episodes: success {100 * cell['success']:.1f}%, "
              f"{cell['motions']:.2f} motions{met}; failures: {fails}; {cell['seconds_per_episode']} s/episode", flush=True)
    summary = {"env": ENV_ID, "seed": args.seed, "trials": not args.geometric, "cells": cells}
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summary, fh, indent=2)
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
