"""Where a grasp net's first greedy grasp lands on an isolated target, per grasp region.

For each ``MPG-Stage2-v0`` scene (the target kept apart from the others) and each target
margin, the network's first greedy grasp is executed and, on the same scene reset again, the
pixel heuristic's grasp (the target mask's centre across its short side). It prints, per
margin: the share of first grasps that took the target, the mean distance (pixels) from the
heuristic's grasp point and the share within one rotation step (mod 180 degrees) of the
heuristic's angle; the heuristic's own success is the reference. A negative margin keeps the
grasp that many pixels inside the target's rim (:func:`mpg_agents.network.regions.target_pixels`).

    python benchmarks/grasp_placement.py --policy mpg_agents/checkpoints/stage2_grasp_small.safetensors \
        --margins 2 -4 -8 --scenes 20 --seed 900000

Ends with one JSON line.
"""

from __future__ import annotations

import argparse
import json

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_agents.evaluation.policy_zoo import NetworkPolicy
from mpg_agents.acting.heuristics import heuristic_grasp
from mpg_envs.threads import set_torch_threads
from mpg_envs.grid.workspace import NUM_ROTATIONS


def first_grasps(policy: NetworkPolicy, env: gym.Env, scenes: int, seed: int) -> dict[str, float]:
    """The policy's and the heuristic's first grasp on each scene, summarised."""
    space = env.unwrapped.action_space
    half = NUM_ROTATIONS // 2  # grasp angles repeat every 180 degrees
    taken, heuristic_taken, distance, aligned = [], [], [], []
    for i in range(scenes):
        obs, _ = env.reset(seed=seed + i)
        policy.reset()
        action = policy.act(obs)
        _, rot, row, col = space.decode(action)
        h_rot, h_row, h_col = heuristic_grasp(obs)
        taken.append(bool(env.step(action)[4]["target_grasped"]))
        env.reset(seed=seed + i)
        heuristic_taken.append(bool(env.step(space.encode("grasp", h_rot, h_row, h_col))[4]["target_grasped"]))
        distance.append(float(np.hypot(row - h_row, col - h_col)))
        steps = (rot - h_rot) % half
        aligned.append(min(steps, half - steps) <= 1)
    return {
        "first_grasp_success": float(np.mean(taken)),
        "heuristic_success": float(np.mean(heuristic_taken)),
        "mean_distance_px": float(np.mean(distance)),
        "within_one_rotation": float(np.mean(aligned)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", required=True, help="an MPGNet checkpoint with a grasp branch")
    parser.add_argument("--margins", type=int, nargs="+", default=[2, -4, -8], help="target margins in pixels")
    parser.add_argument("--scenes", type=int, default=20)
    parser.add_argument("--seed", type=int, default=900000, help="scene i is reset with seed + i")
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    if args.scenes < 1:
        parser.error(f"--scenes must be >= 1, got {args.scenes}")
    set_torch_threads(args.threads)
    env = gym.make("MPG-Stage2-v0")
    rows = {}
    for margin in args.margins:
        policy = NetworkPolicy(args.policy, env, grasp_region="target", target_margin_px=margin)
        rows[margin] = first_grasps(policy, env, args.scenes, args.seed)
        r = rows[margin]
        print(f"margin {margin:+d} px: first grasp took the target {r['first_grasp_success']:.0%} "
              f"(heuristic {r['heuristic_success']:.0%}), {r['mean_distance_px']:.1f} px from the heuristic's point, "
              f"{r['within_one_rotation']:.0%} within one rotation of its angle", flush=True)
    print(json.dumps({"policy": args.policy, "scenes": args.scenes, "seed": args.seed, "margins": rows}))


if __name__ == "__main__":
    main()
