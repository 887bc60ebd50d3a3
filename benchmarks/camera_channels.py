"""Which camera channel costs a policy its success: colour, depth, or both.

A policy trained on ray casts plays camera-track episodes four ways on the same seeds: as the
camera gives them, and with the camera's colour, its depth or both replaced by a clean top-down
ray cast of the same state (the ray-cast track's view; the target mask and the occlusion flag
are the camera mode's, which already come from the true state). Paired differences against
the plain camera episodes say which channel the gap comes from, and so whether a policy for
camera images must read colour, learn camera depth, or both. Tuning seeds by default (700000
on), never the held-out test sets.

    MUJOCO_GL=egl python benchmarks/camera_channels.py --policy shipped --episodes 20 --objects 15 \\
        --json benchmarks/results/generalize/camera_channels_shipped.json

``--env-option`` changes the env (``"visual_randomization={'shadows': False}"``: which part of
the randomization costs what). The last output line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.evaluation.comparison import EvalRecords, compare_paired
from mpg_agents.evaluation.env_options import parse_env_options
from mpg_agents.evaluation.evaluate import run_episode
from mpg_agents.evaluation.policy_zoo import make_network_policy, make_policy
from mpg_agents.evaluation.stats import wilson_interval
from mpg_envs.perception.heightmap import RaycastHeightmapper

CONDITIONS: dict[str, tuple[str, ...]] = {
    "camera": (),
    "raycast depth": ("depth",),
    "raycast colour": ("color",),
    "raycast both": ("color", "depth"),
}
"""Each condition: the observation keys taken from the clean ray cast instead of the camera."""


class RaycastSwap:
    """A policy that sees some channels of a camera env's observation from a ray cast instead.

    The ray caster is bound to the compiled model, and a camera env compiles a new world on
    every reset, so it is made again whenever the env's world changes.
    """

    def __init__(self, policy: Any, env: gym.Env, keys: tuple[str, ...]):
        self.policy, self.keys = policy, keys
        self.name = f"{policy.name} ({'+'.join(keys) or 'camera'})"
        self._sim = env.unwrapped.sim
        self._world = self._caster = None

    def seed(self, seed: int) -> None:
        seeder = getattr(self.policy, "seed", None)
        if callable(seeder):
            seeder(seed)

    def reset(self) -> None:
        self.policy.reset()

    def act(self, obs: dict[str, np.ndarray]) -> Any:
        if not self.keys:
            return self.policy.act(obs)
        world = self._sim.world
        if world is not self._world:
            self.close()
            self._world = world
            self._caster = RaycastHeightmapper(world.model, self._sim.config.workspace, num_threads=1)
        maps = self._caster(world.data)
        swapped = dict(obs)
        if "color" in self.keys:
            swapped["color"] = maps.color
        if "depth" in self.keys:
            swapped["depth"] = maps.depth.astype(np.float32)
        return self.policy.act(swapped)

    def close(self) -> None:
        if self._caster is not None:
            self._caster.close()
        self._caster = None


def summary(records: list[dict[str, Any]]) -> dict[str, Any]:
    wins = sum(r["success"] for r in records)
    lo, hi = wilson_interval(wins, len(records))
    return {
        "episodes": len(records),
        "success": wins / len(records),
        "success_interval": [lo, hi],
        "motions": float(np.mean([r["motions"] for r in records])),
        "pushes": sum(r["primitives"]["push"] for r in records),
        "grasps": sum(r["primitives"]["grasp"] for r in records),
        "motion_caps": sum(r["end_reason"] == "motion_cap" for r in records),
    }


def paired(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> dict[str, Any]:
    """``a`` minus ``b`` on the same seeds (success points and motions, 95% paired bootstrap:
    :func:`~mpg_agents.evaluation.comparison.compare_paired`)."""
    side = lambda records: EvalRecords("", "", None, {int(r["seed"]): r for r in records})  # noqa: E731
    c = compare_paired(side(a), side(b))
    return {
        "success_difference": c.success_difference,
        "success_interval": list(c.success_interval),
        "motions_difference": c.motions_difference,
        "motions_interval": list(c.motions_interval),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="shipped", help="shipped, or a .safetensors checkpoint")
    parser.add_argument("--env", default="MPG-OccludedHardCamera-v0")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--objects", type=int, default=15)
    parser.add_argument("--seed", type=int, default=700000, help="first episode seed (700000 on: tuning seeds)")
    parser.add_argument("--conditions", nargs="+", default=list(CONDITIONS), choices=list(CONDITIONS))
    parser.add_argument("--env-option", action="append", metavar="KEY=VALUE",
                        help="an env keyword (repeatable), e.g. \"visual_randomization={'shadows': False}\"")
    parser.add_argument("--q-star", type=float, help="a network policy's grasp threshold Q*_g (default: its checkpoint's)")
    parser.add_argument("--json", help="write the records and the summary here")
    args = parser.parse_args()
    if args.seed >= 500000 and args.seed < 700000:
        parser.error("seeds 500000-699999 are held-out test scenes: diagnose on tuning seeds (700000 on)")
    options = parse_env_options(args.env_option)
    env = gym.make(args.env, num_objects=args.objects, **options)
    try:
        base = make_policy(args.policy, env) if args.q_star is None else make_network_policy(args.policy, env, q_star=args.q_star)
    except ValueError as exc:
        parser.error(str(exc))
    results: dict[str, list[dict[str, Any]]] = {}
    for name in args.conditions:
        policy = RaycastSwap(base, env, CONDITIONS[name])
        results[name] = [run_episode(policy, env, i, args.seed).to_dict() for i in range(args.episodes)]
        policy.close()
        s = summary(results[name])
        print(f"{name:15s} success {100 * s['success']:5.1f}% [{100 * s['success_interval'][0]:.0f}, "
              f"{100 * s['success_interval'][1]:.0f}]  motions {s['motions']:.2f}  pushes {s['pushes']}  "
              f"grasps {s['grasps']}  motion caps {s['motion_caps']}", flush=True)
    env.close()
    out = {
        "policy": args.policy, "env_id": args.env, "num_objects": args.objects, "seed": args.seed, "q_star": args.q_star, "env_options": options,
        "summary": {k: summary(v) for k, v in results.items()},
        "paired_vs_camera": {k: paired(v, results["camera"]) for k, v in results.items() if k != "camera" and "camera" in results},
    }
    if args.json:
        Path(args.json).write_text(json.dumps({**out, "records": results}, indent=1))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
