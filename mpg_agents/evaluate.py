"""Evaluation with the paper's metrics (Table I): task success within 10 motions, motions.

Each episode is a seeded reset (seed ``seed + k``) run until the env ends it: the target
grasped (success) or the motion cap (10 in Stage V and the test scenes).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any, Callable

import gymnasium as gym
import numpy as np


@dataclass
class EvalResult:
    """The paper's metrics plus what they were measured on."""

    policy: str
    env_id: str
    num_objects: int
    episodes: int
    seed: int
    task_success_rate: float  # episodes ending with the target grasped
    average_motions: float  # mean motions per episode (failures count all their motions)
    average_motions_success: float | None  # mean motions of the successful episodes
    grasp_success_rate: float | None  # target grasps / grasp attempts
    grasp_attempts: int
    seconds_per_motion: float

    def to_dict(self) -> dict[str, Any]:
        """The metrics as JSON-ready data; wall time is left out so one seed gives one file."""
        data = asdict(self)
        del data["seconds_per_motion"]
        return data

    def table(self) -> str:
        rows = [
            ("policy", self.policy),
            ("env", f"{self.env_id} ({self.num_objects} objects)"),
            ("episodes", f"{self.episodes} (seeds {self.seed}..{self.seed + self.episodes - 1})"),
            ("task success rate", f"{100 * self.task_success_rate:.1f}%"),
            ("average motion number", f"{self.average_motions:.2f}"),
            ("  in successful episodes", "n/a" if self.average_motions_success is None else f"{self.average_motions_success:.2f}"),
            ("grasp success rate", "n/a" if self.grasp_success_rate is None else f"{100 * self.grasp_success_rate:.1f}% of {self.grasp_attempts}"),
            ("seconds per motion", f"{self.seconds_per_motion:.2f}"),
        ]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def evaluate(
    policy,
    env: gym.Env,
    episodes: int,
    seed: int,
    progress: bool = False,
    on_reset: Callable[[int, dict], None] | None = None,
    on_step: Callable[[int, float, dict], None] | None = None,
) -> EvalResult:
    """Run ``policy`` (with ``act(obs)``) for ``episodes`` seeded episodes of ``env``.

    ``on_reset(episode, obs)`` and ``on_step(episode, reward, info)`` let a caller (the demo)
    watch the episodes without keeping its own tally of the metrics.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    successes, motions, success_motions = 0, [], []
    grasps = target_grasps = 0
    start = time.perf_counter()
    for k in range(episodes):
        obs, info = env.reset(seed=seed + k)
        if on_reset is not None:
            on_reset(k, obs)
        while True:
            obs, reward, terminated, truncated, info = env.step(policy.act(obs))
            if on_step is not None:
                on_step(k, reward, info)
            if info["primitive"] == "grasp":
                grasps += 1
                target_grasps += int(info["target_grasped"])
            if terminated or truncated:
                break
        successes += int(info["is_success"])
        motions.append(info["num_motions"])
        if info["is_success"]:
            success_motions.append(info["num_motions"])
        if progress:
            print(f"  episode {k}: {'success' if info['is_success'] else 'failure'} after {info['num_motions']} motions", flush=True)
    unwrapped = env.unwrapped
    return EvalResult(
        policy=getattr(policy, "name", type(policy).__name__),
        env_id=unwrapped.spec.id if unwrapped.spec is not None else unwrapped.spec_stage.env_id,
        num_objects=int(unwrapped.num_objects),
        episodes=episodes,
        seed=seed,
        task_success_rate=successes / episodes,
        average_motions=float(np.mean(motions)),
        average_motions_success=float(np.mean(success_motions)) if success_motions else None,
        grasp_success_rate=target_grasps / grasps if grasps else None,
        grasp_attempts=grasps,
        seconds_per_motion=(time.perf_counter() - start) / max(1, sum(motions)),
    )
