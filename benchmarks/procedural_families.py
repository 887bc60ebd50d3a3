"""The procedural object sets: how long they take to make and load, and whether the oracle grasps them.

For each set (``--sets``, default every family and the ``procedural`` mix, with ``blocks`` for
reference):

* ``cold_s`` -- making the set (``--set-seed``) into an empty geometry cache;
* ``cached_s`` -- loading it again from that cache;
* ``world_s`` -- compiling a world of ``--objects`` objects picked from it with the arm, as a
  reset does (``first_world_s``: the process's first, which also loads the arm's files);
* the scripted oracle (:class:`~mpg_envs.policies.oracle.OraclePolicy`) on ``MPG-OccludedHard-v0``'s
  rules with ``object_set=<set>``: episode ``i`` reset with seed ``--seed + i`` (``mpg-eval``'s
  episodes and metrics), its success rate with a Wilson 95% interval, mean motions, end reasons
  and the mean reset time (dropping the objects until the hard track's start condition holds);
  a seed that makes no start scene (``InvalidSceneError``) is listed and not played.

Defaults use the tuning splits (object-set seed 700000, env seeds 700000-), so tuning a
family's ranges never looks at held-out seeds. Prints a Markdown table; ``--json`` writes
every number and episode record.

    OMP_NUM_THREADS=1 python benchmarks/procedural_families.py --episodes 10 [--sets bent hollow] [--json out.json]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401  (registers the envs)
from mpg_agents.evaluation.evaluate import run_episodes, summarise  # noqa: E402
from mpg_envs.policies.oracle import OraclePolicy  # noqa: E402
from mpg_envs.scenes.generators import InvalidSceneError  # noqa: E402
from mpg_envs.simulation.families import PROCEDURAL_SETS  # noqa: E402
from mpg_envs.simulation.objects import load_object_set  # noqa: E402
from mpg_envs.simulation.world import World  # noqa: E402
from mpg_envs.tasks.config import EnvConfig  # noqa: E402

ENV_ID = "MPG-OccludedHard-v0"


def timings(name: str, set_seed: int, objects: int) -> dict[str, float]:
    """Seconds to make the set cold, to load it cached, and to compile a world of ``objects``."""
    with tempfile.TemporaryDirectory() as cache:
        start = time.perf_counter()
        load_object_set(name, seed=set_seed, cache_dir=cache)
        cold = time.perf_counter() - start
        start = time.perf_counter()
        assets = load_object_set(name, seed=set_seed, cache_dir=cache)
        cached = time.perf_counter() - start
    picks = [assets[int(k)] for k in np.random.default_rng(set_seed).integers(len(assets), size=objects)]
    worlds = []
    for _ in range(2):  # the first build in a process also loads the arm
        start = time.perf_counter()
        World(picks, robot_visual=False)  # as the env builds it when nothing renders
        worlds.append(time.perf_counter() - start)
    return {"cold_s": cold, "cached_s": cached, "first_world_s": worlds[0], "world_s": worlds[1], "set_size": len(assets)}


def oracle_cell(name: str, set_seed: int, objects: int, episodes: int, seed: int) -> dict:
    """The oracle's episodes on the hard track's rules with ``object_set=name``."""
    env = gym.make(ENV_ID, object_set=name, num_objects=objects, config=EnvConfig(object_set_seed=set_seed))
    oracle = OraclePolicy(env)
    resets: list[float] = []

    def on_reset(_episode: int, _obs: dict) -> None:
        resets.append(time.perf_counter() - reset_start[0])

    reset_start = [0.0]

    def on_record(record) -> None:
        print(f"  {name}: {record.describe()}", flush=True)

    start = time.perf_counter()
    records, no_scene = [], []
    for index in range(episodes):
        reset_start[0] = time.perf_counter()
        try:
            records += run_episodes(oracle, env, [index], seed, on_record=on_record, on_reset=on_reset)
        except InvalidSceneError as exc:  # the seed makes no start scene: counted, not played
            print(f"  {name}: episode {index} (seed {seed + index}): no start scene ({exc})", flush=True)
            no_scene.append(seed + index)
    env.close()
    if not records:
        return {"no_start_scene": no_scene}
    # Numbered as played (summarise wants 0..n-1); each record keeps its own env seed.
    records = [dataclasses.replace(r, index=k) for k, r in enumerate(records)]
    result = summarise(records, policy="oracle", env_id=ENV_ID, num_objects=objects, seed=seed, wall_seconds=time.perf_counter() - start)
    return {"result": result.to_dict(), "mean_reset_s": float(np.mean(resets)) if resets else None, "no_start_scene": no_scene}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", nargs="+", default=[*PROCEDURAL_SETS, "blocks"], choices=[*PROCEDURAL_SETS, "blocks"])
    parser.add_argument("--episodes", type=int, default=10, help="oracle episodes per set (0: timings only)")
    parser.add_argument("--objects", type=int, default=15)
    parser.add_argument("--seed", type=int, default=700000, help="env seed of episode 0 (tuning seeds by default)")
    parser.add_argument("--set-seed", type=int, default=700000, help="the object sets' seed (a tuning set by default)")
    parser.add_argument("--json", type=Path, default=None)
    args = parser.parse_args(argv)
    rows = {}
    for name in args.sets:
        row = timings(name, args.set_seed, args.objects)
        print(f"{name}: {row}", flush=True)
        if args.episodes > 0:
            row.update(oracle_cell(name, args.set_seed, args.objects, args.episodes, args.seed))
        rows[name] = row
        if args.json is not None:  # written after every set, so a long run keeps what it measured
            args.json.write_text(json.dumps({"args": {k: str(v) for k, v in vars(args).items()}, "sets": rows}, indent=1))
    print("\n| set | shapes | cold (s) | cached (s) | world of %d (s) | oracle success [95%%] | motions | mean reset (s) |" % args.objects)
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for name, row in rows.items():
        cells = ["-", "-", "-"]
        if "result" in row:
            r = row["result"]
            lo, hi = r["success_interval"]
            cells = [f"{r['task_success_rate']:.0%} [{lo:.0%}, {hi:.0%}] of {r['episodes']}", f"{r['average_motions']:.2f}", f"{row['mean_reset_s']:.1f}"]
            if row["no_start_scene"]:
                cells[0] += f" (no start scene: seeds {row['no_start_scene']})"
        print(f"| {name} | {row['set_size']} | {row['cold_s']:.2f} | {row['cached_s']:.3f} | {row['world_s']:.2f} | {' | '.join(cells)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
