"""The registered env suite: reset/step times per env and the oracle's success.

Per env id: the median reset time and the median step time (OraclePolicy actions, so the
primitives do real work). Then the OraclePolicy on MPG-Occluded-v0 with 15 and with 30
objects over ``--episodes`` seeded episodes: task success (target grasped within 10
motions) and mean motions per episode. The goal is >= 80% success on 15 objects. Then ``--random-actions``
uniformly random actions per env, counting NaNs, objects out of the room and MuJoCo warnings.
The last output line is one JSON object.

    python benchmarks/suite.py [--episodes 20] [--resets 5]
"""

from __future__ import annotations

import argparse
import json
import statistics
import time


import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402
from mpg_agents.evaluation.evaluate import evaluate  # noqa: E402
from mpg_envs.policies.oracle import OraclePolicy  # noqa: E402


def time_env(env_id: str, resets: int) -> tuple[float, float]:
    env = gym.make(env_id).unwrapped
    oracle = OraclePolicy(env)
    reset_s, step_s = [], []
    for seed in range(resets):
        start = time.perf_counter()
        env.reset(seed=seed)
        reset_s.append(time.perf_counter() - start)
        for _ in range(3):
            action = oracle.act()
            start = time.perf_counter()
            _, _, term, trunc, _ = env.step(action)
            step_s.append(time.perf_counter() - start)
            if term or trunc:
                break
    env.close()
    return 1000 * statistics.median(reset_s), 1000 * statistics.median(step_s)


def random_soak(env_id: str, actions: int) -> dict[str, int]:
    """``actions`` uniformly random actions (resetting when an episode ends): count NaNs,
    objects thrown out of the room and MuJoCo warnings (the env reports and clears them)."""
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    env.action_space.seed(0)
    counts = {"nan": 0, "out_of_room": 0, "sim_warnings": 0, "episodes": 1}
    for k in range(actions):
        obs, _, term, trunc, info = env.step(env.action_space.sample())
        counts["nan"] += int(not (np.isfinite(env.world.data.qpos).all() and np.isfinite(obs["depth"]).all()))
        counts["out_of_room"] += int(env.world.objects_out_of_room().size)
        counts["sim_warnings"] += sum(info["sim_warnings"].values())
        if term or trunc:
            env.reset(seed=k + 1)
            counts["episodes"] += 1
    env.close()
    return counts


def oracle_eval(num_objects: int, episodes: int) -> dict[str, float]:
    env = gym.make("MPG-Occluded-v0", num_objects=num_objects)
    result = evaluate(OraclePolicy(env), env, episodes, seed=10_000, progress=True)
    env.close()
    return {"success": result.task_success_rate, "motions": result.average_motions}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--resets", type=int, default=5)
    parser.add_argument("--random-actions", type=int, default=200, help="per env, for the NaN / out-of-room / warning soak")
    args = parser.parse_args()
    reset_ms, step_ms = {}, {}
    for env_id in mpg_envs.ENV_IDS:
        reset_ms[env_id], step_ms[env_id] = time_env(env_id, args.resets)
        print(f"{env_id:18s} reset {reset_ms[env_id]:7.1f} ms   step {step_ms[env_id]:7.1f} ms", flush=True)
    soak = {}
    for env_id in mpg_envs.ENV_IDS:
        soak[env_id] = random_soak(env_id, args.random_actions)
        print(f"{env_id:18s} {args.random_actions} random actions: {soak[env_id]}", flush=True)
    oracle = {str(n): oracle_eval(n, args.episodes) for n in (15, 30)}
    for n, m in oracle.items():
        print(f"OraclePolicy, MPG-Occluded-v0, {n} objects: success {100 * m['success']:.0f}%, {m['motions']:.2f} motions")
    print("oracle goal (>= 80% on 15 objects) " + ("met" if oracle["15"]["success"] >= 0.8 else "NOT met"))
    print(
        json.dumps(
            {
                "reset_ms": {k: round(v, 1) for k, v in reset_ms.items()},
                "step_ms": {k: round(v, 1) for k, v in step_ms.items()},
                "oracle": {k: {"success": v["success"], "motions": round(v["motions"], 2)} for k, v in oracle.items()},
                "random_soak": soak,
            }
        )
    )


if __name__ == "__main__":
    main()
