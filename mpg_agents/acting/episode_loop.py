"""The one episode loop: choose, step, until the env ends the episode.

Evaluation (:func:`mpg_agents.evaluation.evaluate.run_episode`), Q*_g calibration
(:func:`mpg_agents.acting.grasp_threshold.calibrate_q_star`), oracle demonstrations
(:func:`mpg_agents.learning.demonstrations.collect_demonstrations`) and training (every
:class:`mpg_agents.learning.actors.Actor`: the learner's own, or a parallel one) all step their
envs through :func:`episode_steps`, the one ``env.step`` of their episodes;
each resets its env its own way (seeds, options) and reads what it needs from the yielded
:class:`Step`. A generator in the manner of CleanRL's loops: the caller may stop between steps
(an actor answers one request at a time; the learner's budget, a stop signal) and the episode is left as it is.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

import gymnasium as gym

Chosen = TypeVar("Chosen")


@dataclass(frozen=True)
class Step(Generic[Chosen]):
    """One step of an episode: what was chosen on ``obs`` and what the env answered."""

    obs: Mapping[str, Any]
    choice: Chosen  # what ``choose`` returned (an action, a decision, ...)
    action: Any  # what went to ``env.step``
    next_obs: Mapping[str, Any]
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    choose_seconds: float  # time spent in ``choose``
    step_seconds: float  # time spent in ``env.step``

    @property
    def done(self) -> bool:
        """The episode ended with this step."""
        return self.terminated or self.truncated


def episode_steps(
    env: gym.Env,
    obs: Mapping[str, Any],
    choose: Callable[[Mapping[str, Any]], Chosen],
    action_of: Callable[[Chosen], Any] = lambda choice: choice,
) -> Iterator[Step[Chosen]]:
    """Step ``env`` from ``obs`` (its observation after a reset) until it ends the episode.

    Args:
        env: the env, already reset.
        obs: the observation the episode starts from.
        choose: ``obs -> choice``, called once per step.
        action_of: the action ``env.step`` takes from a choice (default: the choice itself).

    Yields:
        each :class:`Step`; the last has ``done``.
    """
    while True:
        start = time.perf_counter()
        choice = choose(obs)
        chosen = time.perf_counter()
        action = action_of(choice)
        next_obs, reward, terminated, truncated, info = env.step(action)
        step = Step(
            obs,
            choice,
            action,
            next_obs,
            float(reward),
            bool(terminated),
            bool(truncated),
            info,
            chosen - start,
            time.perf_counter() - chosen,
        )
        yield step
        if step.done:
            return
        obs = next_obs
