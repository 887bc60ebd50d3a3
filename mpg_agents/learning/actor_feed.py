"""The learner's side of parallel actors (Ape-X): what it asks them for, and their steps as its source.

:func:`actor_steps` is the many-actor source of a learner's steps (a
:class:`~mpg_agents.learning.learner_handle.LearnerHandle`), the counterpart of
:func:`mpg_agents.learning.learner_episodes.own_steps`: ``TrainConfig.actors`` actors
(:mod:`mpg_agents.learning.actors`) in an :class:`~mpg_agents.learning.actor_pool.ActorPool`.
Before each step is handed to the learner (which stores it, its trials first, learns from it
at the replay ratio, counts, logs and saves it as any step), its actor is asked for its next
step, so it acts while the learner learns. An iteration is one env step of any actor: the
curriculum, the exploration schedule, the alternation and the periodic Q*_g calibration follow
the global count, as with one actor. Steps in flight when the run stops (the budget reached, a
signal) are dropped; the saved state holds the steps learnt from, and a resumed run's actors
start episodes the run has not handed out.

:class:`ActorLedger` is the learner's record of its actors: the weights each holds (new ones
are published every ``weights_refresh`` gradient steps, and at once when Q*_g changes), whether
its episode runs, and the seeds in a row that gave it no valid scene.
"""

from __future__ import annotations

from collections.abc import Callable, Generator

import numpy as np

from mpg_agents.acting.seeds import MAX_SKIPPED_SEEDS
from mpg_agents.learning.actor_pool import open_actor_pool
from mpg_agents.learning.actors import ActorSpec, ActorStep, ActRequest, Weights, weights_of
from mpg_agents.learning.learner_handle import LearnerHandle
from mpg_envs.scenes.generators import InvalidSceneError


def actor_steps(learner: LearnerHandle) -> Generator[ActorStep, None, None]:
    """The steps of ``learner``'s config's actors until its iteration budget is spent (the pool
    closes when the iteration ends or is closed)."""
    c, cfg = learner.counters, learner.config
    specs = [ActorSpec(cfg, learner.stage, a, c.iteration, learner.objects_now(c.iteration)) for a in range(cfg.actors)]
    ledger = ActorLedger(cfg.actors, cfg.weights_refresh)
    with open_actor_pool(cfg, specs) as pool:
        for actor in range(min(cfg.actors, learner.steps - c.iteration)):
            pool.submit(actor, next_request(learner, ledger, actor))
        while pool.in_flight:
            step = pool.next_step()
            ledger.received(step, MAX_SKIPPED_SEEDS)
            if step.skipped is not None:
                learner.skipped_scene(step.episode, RuntimeError(step.skipped))
            if c.iteration + (step.skipped is None) + pool.in_flight < learner.steps:
                pool.submit(step.actor, next_request(learner, ledger, step.actor))
            if step.skipped is None:
                yield step


def next_request(learner: LearnerHandle, ledger: ActorLedger, actor: int) -> ActRequest:
    """``actor``'s next request: the global epsilon and object count, the learner's weights when due."""
    c, policy = learner.counters, learner.policy
    if ledger.stale(c.gradient_steps, policy.q_star):
        ledger.publish(weights_of(policy), policy.q_star, c.gradient_steps)

    def next_episode() -> int:
        c.episode += 1  # with actors: the episodes handed out (each index once, across resumes)
        return c.episode - 1

    return ledger.request(actor, learner.epsilon(), learner.objects_now(c.iteration), next_episode)


class ActorLedger:
    """The learner's record of its actors: which weights each holds, whether its episode runs,
    how many seeds in a row gave it no scene; it writes their :class:`ActRequest` s.

    Args:
        actors: how many.
        refresh: publish new weights after this many gradient steps (``TrainConfig.weights_refresh``);
            a changed Q*_g is published at once.
    """

    def __init__(self, actors: int, refresh: int) -> None:
        self.refresh = refresh
        self.weights: Weights | None = None
        self.published_at = 0  # gradient steps when ``weights`` were published
        self.held = [0] * actors  # weight version each actor holds
        self.running = [False] * actors  # an episode runs in the actor
        self.skips = [0] * actors  # seeds in a row that gave the actor no valid scene

    def stale(self, gradient_steps: int, q_star: float | None) -> bool:
        """Whether the learner should :meth:`publish` before its next request."""
        w = self.weights
        return w is None or gradient_steps - self.published_at >= self.refresh or not _same_q_star(w.q_star, q_star)

    def publish(self, state: dict[str, np.ndarray], q_star: float | None, gradient_steps: int) -> None:
        """The weights (and Q*_g) the next requests carry to every actor that has older ones."""
        version = 1 if self.weights is None else self.weights.version + 1
        self.weights, self.published_at = Weights(version, state, q_star), gradient_steps

    def request(self, actor: int, epsilon: float, num_objects: int | None, next_episode: Callable[[], int]) -> ActRequest:
        """The request for ``actor``'s next step; ``next_episode()`` hands out an episode index
        when the actor has no episode running."""
        if self.weights is None:
            raise RuntimeError("publish weights before the first request")
        fresh = self.weights if self.held[actor] != self.weights.version else None
        self.held[actor] = self.weights.version
        return ActRequest(epsilon, num_objects, None if self.running[actor] else next_episode(), fresh)

    def received(self, step: ActorStep, most_skips: int) -> None:
        """Note what ``step`` says of its actor's episode.

        Raises:
            InvalidSceneError: more than ``most_skips`` seeds in a row gave the actor no valid scene.
        """
        a = step.actor
        if step.skipped is not None:
            self.running[a] = False
            self.skips[a] += 1
            if self.skips[a] > most_skips:
                raise InvalidSceneError(
                    f"{self.skips[a]} seeds in a row up to episode {step.episode} gave no valid scene: {step.skipped}"
                )
            return
        self.skips[a] = 0
        self.running[a] = not step.done


def _same_q_star(a: float | None, b: float | None) -> bool:
    return a == b or (a is not None and b is not None and np.isnan(a) and np.isnan(b))
