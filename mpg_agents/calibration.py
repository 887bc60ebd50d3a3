"""Q*_g, the grasp threshold of the coordination, measured in a stage's own scenes.

The paper sets Q*_g from the Q values of successful grasps. Here it is measured the same way
wherever it is needed (before and during a training stage, by :class:`~mpg_agents.learner.Learner`,
and for any checkpoint by ``mpg-calibrate``): ``episodes`` greedy grasp-only episodes of the
net, without learning, on the calibration seeds of :func:`~mpg_agents.seeds.episode_seed` (clear
of the training and evaluation seeds), and Q*_g is a quantile of the Q of the grasps that took
the target. The same run seed gives the same scenes, so successive calibrations of one run
measure the net on one measuring stick.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable

import gymnasium as gym
import numpy as np

from mpg_agents.policy import MPGNetPolicy
from mpg_agents.seeds import episode_seed


@dataclass(frozen=True)
class Calibration:
    """One measurement of Q*_g.

    Attributes:
        q_star: the ``quantile`` of ``target_grasp_q``.
        quantile: 0.5 is the median (the paper's reading), 0.25 the lower quartile.
        episodes: grasp-only episodes run.
        grasps: grasps taken in them.
        target_grasp_q: the Q of each grasp that took the target, in the order taken.
    """

    q_star: float
    quantile: float
    episodes: int
    grasps: int
    target_grasp_q: tuple[float, ...]


def calibrate_q_star(
    policy: MPGNetPolicy, env: gym.Env, episodes: int, seed: int, quantile: float = 0.5,
    on_episode: Callable[[int, int, int], None] | None = None,
) -> Calibration:
    """Measure Q*_g of ``policy`` in ``env``'s scenes (greedy grasps only, nothing learned).

    Args:
        policy: the net; only its grasp branch acts.
        env: the scenes; episode ``k`` is reset with ``episode_seed(seed, k, calibration=True)``.
        episodes: how many episodes (>= 1).
        seed: the run seed that picks the calibration scenes.
        quantile: which quantile of the successful grasps' Q becomes Q*_g, in [0, 1].
        on_episode: called after each episode with (episode, grasps so far, target grasps so far).

    Raises:
        ValueError: the net has no grasp branch, ``episodes`` < 1 or ``quantile`` outside [0, 1].
        RuntimeError: no grasp took the target (there is nothing to take a quantile of).
    """
    if "grasp" not in policy.usable_primitives:
        raise ValueError(f"Q*_g calibration needs a grasp branch; the net has {policy.branches}")
    if episodes < 1:
        raise ValueError(f"calibration needs at least one episode, got {episodes}")
    if not 0.0 <= quantile <= 1.0:
        raise ValueError(f"calibration quantile must be in [0, 1], got {quantile}")
    taken: list[float] = []
    grasps = 0
    for k in range(episodes):
        obs, _ = env.reset(seed=episode_seed(seed, k, calibration=True))
        done = False
        while not done:
            decision = policy.decide(obs, "grasp")
            obs, _, terminated, truncated, info = env.step(decision.action)
            grasps += 1
            if info["target_grasped"] and math.isfinite(decision.q_value):
                taken.append(float(decision.q_value))
            done = bool(terminated or truncated)
        if on_episode is not None:
            on_episode(k, grasps, len(taken))
    if not taken:
        raise RuntimeError(f"no grasp took the target in {episodes} calibration episodes ({grasps} grasps)")
    return Calibration(float(np.quantile(taken, quantile)), quantile, episodes, grasps, tuple(taken))


def write_calibration(
    path: str | Path, calibration: Calibration, iteration: int, q_star_before: float, continue_history: bool,
) -> dict[str, Any]:
    """Write ``calibration.json``: the latest measurement whole, and one line per calibration.

    With ``continue_history`` the lines already in ``path`` are kept (a stage calibrating again);
    otherwise the history starts with this one. Returns what was written. A NaN ``q_star_before``
    (no Q*_g yet) is written as ``null``.
    """
    path = Path(path)
    history: list[dict[str, Any]] = []
    if continue_history and path.is_file():
        history = json.loads(path.read_text()).get("history", [])
    c = calibration
    history.append({"iteration": iteration, "q_star": c.q_star, "target_grasps": len(c.target_grasp_q), "grasps": c.grasps})
    record = {
        "iteration": iteration, "episodes": c.episodes, "grasps": c.grasps, "target_grasps": len(c.target_grasp_q),
        "quantile": c.quantile, "q_star_before": None if math.isnan(q_star_before) else q_star_before,
        "q_star": c.q_star, "target_grasp_q": list(c.target_grasp_q), "history": history,
    }
    path.write_text(json.dumps(record, indent=1))
    return record


def calibration_dict(calibration: Calibration) -> dict[str, Any]:
    """The measurement as plain JSON types."""
    data = asdict(calibration)
    data["target_grasp_q"] = list(calibration.target_grasp_q)
    return data
