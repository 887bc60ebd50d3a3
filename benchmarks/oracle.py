"""The scripted oracle on held-out ``MPG-Occluded-v0`` episodes: success, motions, and why it failed.

Episode ``i`` of a cell is reset with seed ``--seed + i`` (the same scenes for any run; the
episodes and their metrics are ``mpg-eval``'s, :mod:`mpg_agents.evaluation.evaluate`). For each object
count: the success rate and the mean motions per episode with their 95% intervals, and every
failed episode categorised:

* ``target_not_graspable`` -- the oracle's last look found no collision-free grasp angle;
* ``slip`` -- its last attempt was a grasp of the target that held nothing;
* ``push_without_effect`` -- its last attempt was a push that changed nothing;
* ``target_left_workspace`` -- the target was pushed or knocked out of the workspace;
* ``motion_cap`` -- the motions ran out while the oracle still made progress.

The env's own ``info["end_reason"]`` is printed too when the env reports it. The oracle tries
its candidate grasps and preparations in a checkpointed copy of the simulation before acting
(see :mod:`mpg_envs.policies.oracle`); ``--geometric`` plans by geometry alone, without trials. Goals:
>= 97% success in <= 2.8 mean motions at 15 objects, >= 93% in <= 3.7 at 30. The last output
line is JSON.

    OMP_NUM_THREADS=1 python benchmarks/oracle.py --episodes 100 --objects 15 30 --seed 90000 [--verbose]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import run_episodes, summarise
from mpg_envs.policies.oracle import OracleConfig, OraclePolicy

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


class PlanLog:
    """The oracle acting, with the kind of plan behind each of its motions in the episode."""

    def __init__(self, oracle: OraclePolicy) -> None:
        self.oracle, self.name = oracle, oracle.name
        self.plans: list[str] = []

    def reset(self) -> None:
        self.oracle.reset()
        self.plans = []

    def act(self, obs: Any) -> int:
        action = self.oracle.act(obs)
        self.plans.append(str((self.oracle.last_plan or {}).get("kind", "")))
        return action


def episode_of(record: EpisodeRecord, plans: list[str], steps: list[tuple[str, dict]], oracle: OraclePolicy) -> Episode:
    """An evaluation record with the oracle's view: its plans and, for a failure, why."""
    # "+": it uncovered or took the target; "!why": the grasp or move held nothing (info grasp_failure).
    actions = [
        f"{k}{'+' if i.get('target_grasped') or i.get('move_success') else ''}{'!' + i['grasp_failure'] if i.get('grasp_failure') else ''}"
        for k, (_, i) in zip(plans, steps)
    ]
    category = None if record.success else classify(steps[-1][1], oracle, steps)
    return Episode(record.seed, record.success, record.motions, category, record.end_reason, actions)


def run_cell(num_objects: int, episodes: int, seed: int, verbose: bool = False, config: OracleConfig = OracleConfig()) -> dict:
    env = gym.make(ENV_ID, num_objects=num_objects).unwrapped
    oracle = PlanLog(OraclePolicy(env, config))
    steps: list[tuple[str, dict]] = []
    results: list[Episode] = []

    def on_reset(index: int, obs: dict) -> None:
        steps.clear()

    def on_step(index: int, reward: float, info: dict) -> None:
        steps.append((info["primitive"], info))

    def on_record(record: EpisodeRecord) -> None:
        ep = episode_of(record, oracle.plans, steps, oracle.oracle)
        results.append(ep)
        if verbose or not ep.success:
            outcome = "ok  " if ep.success else "FAIL"
            print(f"  {num_objects} objects seed {ep.seed}: {outcome} {ep.motions} motions [{' '.join(ep.actions)}] "
                  f"{ep.category or ''} (end_reason {ep.end_reason})", flush=True)

    start = time.perf_counter()
    records = run_episodes(oracle, env, range(episodes), seed, on_record=on_record, on_reset=on_reset, on_step=on_step)
    wall = time.perf_counter() - start
    env.close()
    result = summarise(records, oracle.name, ENV_ID, num_objects, seed, wall)
    categories = Counter(r.category for r in results if r.category)
    return {
        "episodes": result.episodes,
        "success": round(result.task_success_rate, 4),
        "success_interval": [round(v, 4) for v in result.success_interval],
        "motions": round(result.average_motions, 3),
        "motions_interval": None if result.motions_interval is None else [round(v, 3) for v in result.motions_interval],
        "failures": {c: categories.get(c, 0) for c in CATEGORIES},
        "end_reasons": result.end_reasons,
        "failed_seeds": [r.seed for r in results if not r.success],
        "seconds_per_episode": round(wall / result.episodes, 2),
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
