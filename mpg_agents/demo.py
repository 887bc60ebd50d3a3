"""The short demo: build a scene, run a policy, print metrics, write pictures.

    python -m mpg_agents.demo [--policy shipped|oracle|random|CKPT] [--env MPG-Stage2-v0]
                              [--episodes 3] [--seed 0] [--out demo_out]

Runs ``--episodes`` seeded episodes, prints each step and a summary (task success,
motions, grasp success), and writes ``scene.png`` (the colour heightmap of the first scene
with the target outlined, beside a rendered view when OpenGL is available) and, for a
network policy, ``qmaps.png`` (the Q maps of its first decision).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import cv2  # noqa: E402
import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401  (registers the envs)


def scene_picture(env: gym.Env, obs: dict[str, np.ndarray]) -> np.ndarray:
    """Colour heightmap (target outlined), enlarged, beside the rendered scene if GL works."""
    color = cv2.resize(obs["color"], (448, 448), interpolation=cv2.INTER_NEAREST)
    mask = cv2.resize(obs["mask"], (448, 448), interpolation=cv2.INTER_NEAREST)
    contours, _ = cv2.findContours(mask, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(color, contours, -1, (255, 255, 255), 2)
    try:
        from mpg_envs.render import OverviewRenderer

        renderer = OverviewRenderer(env.unwrapped.world.model, 448, 597)
        view = renderer.render(env.unwrapped.world.data)
        renderer.close()
        return np.concatenate([color, view], axis=1)
    except RuntimeError as exc:
        print(f"(no rendered view: {exc})")
        return color


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="MPG demo: a policy on a few seeded scenes.")
    parser.add_argument("--policy", default="shipped", help="shipped (the trained checkpoint), oracle, random, grasp-only or a checkpoint path")
    parser.add_argument("--env", default="MPG-Stage2-v0")
    parser.add_argument("--episodes", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default="demo_out")
    args = parser.parse_args(argv)

    from mpg_agents.baselines import make_policy
    from mpg_agents.evaluate import evaluate

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(args.env)
    policy = make_policy(args.policy, env)
    print(f"policy {policy.name} on {args.env}, {args.episodes} episodes from seed {args.seed}")

    def on_reset(episode: int, obs: dict[str, np.ndarray]) -> None:
        if episode == 0:
            cv2.imwrite(str(out / "scene.png"), cv2.cvtColor(scene_picture(env, obs), cv2.COLOR_RGB2BGR))
            if hasattr(policy, "save_qmaps"):
                policy.save_qmaps(out / "qmaps.png", obs)

    def on_step(episode: int, reward: float, info: dict) -> None:
        print(
            f"  episode {episode} motion {info['num_motions']}: {info['primitive']:5s} rot {info['rotation']:2d} "
            f"at {info['pixel']} reward {reward:+.1f}"
            + ("  grasped the target" if info["target_grasped"] else "  grasped another object" if info["grasp_success"] else "")
        )

    result = evaluate(policy, env, args.episodes, args.seed, on_reset=on_reset, on_step=on_step)
    grasps = "n/a" if result.grasp_success_rate is None else f"{100 * result.grasp_success_rate:.0f}% of {result.grasp_attempts}"
    print(
        f"task success {round(result.task_success_rate * args.episodes)}/{args.episodes} "
        f"({100 * result.task_success_rate:.0f}%), mean motions {result.average_motions:.2f}, "
        f"target grasp success {grasps}, {result.seconds_per_motion:.2f} s per motion"
    )
    print(f"pictures in {out.resolve()}")
    env.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
