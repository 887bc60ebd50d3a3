"""The learner's own steps: with one actor (``TrainConfig.actors == 1``) this process decides and acts.

:func:`own_steps` is the one-actor source of the learner's steps, the counterpart of
:func:`mpg_agents.learning.actor_feed.actor_steps`: an :class:`~mpg_agents.learning.actors.Actor`
on the learner's own env, agent, exploration, generator and counters, asked for a step at a time
with the current epsilon. Each episode starts on the next seed that gives a valid scene, with
the curriculum's object count; the running episode's index is the learner's
``counters.episode`` (a resumed run restarts an interrupted episode on the same scene), counted
on when the episode ends, before the learner learns from its last step.
"""

from __future__ import annotations

from collections.abc import Generator

from mpg_agents.acting.seeds import MAX_SKIPPED_SEEDS
from mpg_agents.learning.actors import Actor, ActorStep, ActRequest
from mpg_agents.learning.learner_handle import LearnerHandle
from mpg_envs.scenes.generators import InvalidSceneError


def own_actor(learner: LearnerHandle) -> Actor:
    """The learner's own actor: its env, agent, exploration, generator and counters."""
    return Actor(
        learner.env, learner.policy, learner.explorer, learner.rng, learner.stage, learner.config.seed, learner.counters
    )


def own_steps(learner: LearnerHandle, actor: Actor | None = None) -> Generator[ActorStep, None, None]:
    """The steps of ``learner``'s own actor (:func:`own_actor` unless given) until its iteration
    budget is spent (read again before each step).

    Raises:
        InvalidSceneError: more than :data:`~mpg_agents.acting.seeds.MAX_SKIPPED_SEEDS` seeds in a
            row gave no valid scene.
    """
    actor = own_actor(learner) if actor is None else actor
    c = learner.counters
    skips = 0
    while c.iteration < learner.steps:
        episode = None if actor.running else c.episode
        step = actor.step(ActRequest(learner.epsilon(), learner.objects_now(c.iteration), episode))
        if step.skipped is not None:
            skips += 1
            if skips > MAX_SKIPPED_SEEDS:
                raise InvalidSceneError(
                    f"{skips} seeds in a row up to episode {step.episode} gave no valid scene: {step.skipped}"
                )
            learner.skipped_scene(step.episode, RuntimeError(step.skipped))
            c.episode = step.episode + 1
            continue
        skips = 0
        if step.done:
            c.episode += 1  # the next episode's index, counted before the learner saves its state
        yield step
