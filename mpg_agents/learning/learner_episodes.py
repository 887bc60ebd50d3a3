"""The learner's own episodes: with one actor (``TrainConfig.actors == 1``) this process decides and acts.

:func:`train_alone` runs a :class:`~mpg_agents.learning.learner.Learner`'s remaining iterations
through the one episode loop (:func:`mpg_agents.acting.episode_loop.episode_steps`) on the
learner's env, the counterpart of :func:`mpg_agents.learning.actor_feed.train_with_actors`. Each
episode starts on the next seed that gives a valid scene, with the curriculum's object count
(:func:`reset_episode`); each step is decided by :func:`choose` (the action and the stage's
trials of the actions not taken) and learnt from by the learner's ``iteration``, then saved
when due.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from mpg_agents.acting.episode_loop import episode_steps
from mpg_agents.acting.seeds import episode_seed, reset_first_valid
from mpg_agents.learning.exploration import Choice

if TYPE_CHECKING:
    from mpg_agents.learning.learner import Learner


def train_alone(learner: Learner, bar: Any = None) -> None:
    """Run ``learner``'s remaining iterations in this process (``bar``: a progress bar)."""
    while learner.counters.iteration < learner.steps:
        for step in episode_steps(
            learner.env, reset_episode(learner), lambda obs: choose(learner, obs), lambda chosen: chosen[0].action
        ):
            learner.iteration(step)
            if bar is not None:
                bar.update(1)
            learner.save_or_stop()
            if learner.counters.iteration >= learner.steps:
                break


def reset_episode(learner: Learner) -> dict[str, np.ndarray]:
    """Reset ``learner``'s env for its next episode (the curriculum's object count, without
    rebuilding the env; seeds that give no valid scene skipped) and zero the episode's counters."""
    c = learner.counters
    n = learner.objects_now(c.iteration)
    options = None if n is None else {"num_objects": n}
    obs, _, c.episode = reset_first_valid(
        learner.env, lambda k: episode_seed(learner.config.seed, k), c.episode, options, learner.skipped_scene
    )
    c.episode_motions = c.failed_grasps_in_a_row = c.pushes_in_episode = 0
    return obs


def choose(learner: Learner, obs: Mapping[str, Any]) -> tuple[Choice, list[int]]:
    """What ``learner``'s step does on ``obs``: the action (its ``act``) and the stage's trials of
    the actions not taken, tried and stored before it (its ``try_alternatives``)."""
    choice = learner.act(obs)
    return choice, learner.try_alternatives(obs, choice)
