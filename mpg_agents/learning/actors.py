"""The acting side of training: what chooses an action, and the actor that steps an env.

Every training step comes from an :class:`Actor`: it steps its env through the one episode loop
(:func:`~mpg_agents.acting.episode_loop.episode_steps`), deciding with :func:`choose_action` and
trying the stage's trials (:func:`~mpg_agents.learning.trials.try_alternatives`), and hands the
learner an :class:`ActorStep` to learn from. With ``TrainConfig.actors = 1`` the learner's own
actor runs in its process on the learner's env, agent and counters
(:mod:`mpg_agents.learning.learner_episodes`); with ``actors = N > 1`` (Ape-X style) N actors,
each in its own process (:mod:`mpg_agents.learning.actor_pool`,
:mod:`mpg_agents.learning.actor_feed`), step their own envs. The learner owns the replay, the
run's counters, the weights, Q*_g and the checkpoints; so every stage trains the same way.

What the learner keeps global, it sends with each :class:`ActRequest`: epsilon of the global
env-step counter (the exploration schedule), the curriculum's object count and the index of the
episode to start (so every episode seed of a run is used once, and a resumed run goes on with
new ones), and its weights with Q*_g when they are newer than the actor's. What is an episode's
own stays with the actor (:class:`EpisodeCounts`, counted by :func:`count_step`): the push
budget, the failed grasps before the heuristic grasp. An actor's generator (exploration,
trials) in its own process is seeded with (run seed, actor index, the iteration its pool started
at): a resumed run draws afresh. Each such actor computes on one torch thread.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch

import mpg_envs  # noqa: F401  (registers the envs in a fresh actor process)
from mpg_agents.acting.agent import MPGAgent
from mpg_agents.acting.discriminator import Discriminator
from mpg_agents.acting.episode_loop import Step, episode_steps
from mpg_agents.acting.seeds import episode_seed
from mpg_agents.acting.spaces import finger_geometry, geometry_of_config
from mpg_agents.learning.exploration import Explorer, TakenAction
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.training_objects import stage_env_config, training_object_set
from mpg_agents.learning.training_stages import TrainingStage
from mpg_agents.learning.trials import try_alternatives
from mpg_envs.grid.actions import PRIMITIVES
from mpg_envs.grid.primitive_specs import GRASP, PUSH
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.simulation.objects import check_not_held_out
from mpg_envs.tasks.config import EnvConfig


# ------------------------------------------------------------------ shared by learner and actors
def make_training_env(
    stage: TrainingStage, config: TrainConfig, num_objects: int | None, device: torch.device | str
) -> gym.Env:
    """The stage's training env (its rewards, the discriminator on ``device`` that scores states);
    refuses objects held out for testing (:func:`~mpg_envs.simulation.objects.check_not_held_out`)."""
    kwargs: dict[str, Any] = {}
    if num_objects is not None:
        kwargs["num_objects"] = num_objects
    options = dict(stage.env_options)  # the stage's object set, visual randomization, observation, config
    env_config = stage_env_config(options, stage.reward)
    if config.discriminator is not None:
        kwargs["grasp_scorer"] = Discriminator.from_weights(
            config.discriminator, geometry_of_config(env_config or EnvConfig()), device
        )
    if env_config is not None:
        kwargs["config"] = env_config
    for key, value in options.items():
        if key != "config":
            kwargs[key] = training_object_set(value) if key == "object_set" else value
    env = gym.make(stage.env_id, **kwargs)
    unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
    check_not_held_out("custom", unwrapped.object_set, f"training on {stage.env_id}")  # however they got there
    return env


def build_agent(stage: TrainingStage, config: TrainConfig, env: gym.Env) -> MPGAgent:
    """A fresh agent with the stage's branches and coordination and the config's network."""
    space: Any = env.unwrapped
    return MPGAgent.build(
        space.observation_space,
        space.action_space,
        variant=config.variant,
        branches=stage.branches or PRIMITIVES,
        coordination=stage.coordination,
        net_config=config.net_config,
        geometry=finger_geometry(env),
    )


def make_explorer(
    policy: MPGAgent, stage: TrainingStage, primitives: tuple[str, ...], rng: np.random.Generator, config: TrainConfig
) -> Explorer:
    """The exploration of ``policy``'s network settings (where a greedy action may act) on ``rng``."""
    net_cfg = policy.net_config
    return Explorer(
        primitives,
        rng,
        config.heuristic_after_failed_grasps,
        random_primitive=stage.coordination == "max_q",
        grasp_on_target=net_cfg.grasp_region in ("target", "visible"),
        usable=policy.usable_primitives,
        target_margin_px=net_cfg.target_margin_px,
        move_band_m=net_cfg.move_band_m if net_cfg.move_region == "top" else None,
        visible_band_m=net_cfg.visible_band_m if net_cfg.grasp_region == "visible" else None,
    )


def choose_action(
    policy: MPGAgent,
    explorer: Explorer,
    stage: TrainingStage,
    obs: Mapping[str, np.ndarray],
    epsilon: float,
    pushes_in_episode: int,
    failed_grasps_in_a_row: int,
) -> TakenAction:
    """The action to take: the policy's decision (a grasp forced after the stage's push budget),
    then exploration and the training aids."""
    budget = stage.push_budget
    forced = GRASP if budget is not None and pushes_in_episode >= budget and GRASP in explorer.primitives else None
    return explorer.choose(obs, policy.decide(obs, forced), epsilon, failed_grasps_in_a_row)


def weights_of(policy: MPGAgent) -> dict[str, np.ndarray]:
    """The network's weights as host arrays (what goes to the actors)."""
    return {k: v.detach().cpu().numpy() for k, v in policy.q_net.mpgnet.state_dict().items()}


# ------------------------------------------------------------------------------- messages
@dataclass(frozen=True)
class ActorSpec:
    """What an actor builds itself from, in its own process."""

    config: TrainConfig
    stage: TrainingStage
    index: int  # 0..actors-1
    start_iteration: int  # the learner's iteration when the pool started (seeds the generator)
    num_objects: int | None  # the env's object count when built (a reset asks for the curriculum's)


@dataclass(frozen=True)
class Weights:
    """The learner's weights and the Q*_g they decide with, numbered."""

    version: int
    state: dict[str, np.ndarray]
    q_star: float | None


@dataclass(frozen=True)
class ActRequest:
    """One step asked of an actor, with what the learner holds global."""

    epsilon: float
    num_objects: int | None  # the curriculum's count, for a reset
    episode: int | None  # the index of the episode to start when the actor runs none
    weights: Weights | None = None  # newer weights than the actor's (None: keep its own)


@dataclass
class TrialCounts:
    """A step's trials, counted as the learner's :class:`~mpg_agents.learning.run_state.Counters` count them."""

    grasp_trials: int = 0
    grasp_trial_targets: int = 0
    move_trials: int = 0
    move_trial_successes: int = 0
    rival_trials: int = 0
    rival_trial_clears: int = 0
    covered_grasp_trials: int = 0
    covered_grasp_trial_targets: int = 0


@dataclass
class ActorStep:
    """What an actor did for one :class:`ActRequest`: a step of episode ``episode``, or
    ``skipped`` (why that episode's seed gave no valid scene; no step)."""

    actor: int
    episode: int
    skipped: str | None = None
    obs: dict[str, np.ndarray] = field(default_factory=dict)
    choice: TakenAction | None = None
    next_obs: dict[str, np.ndarray] = field(default_factory=dict)
    reward: float = 0.0
    terminated: bool = False
    truncated: bool = False
    info: dict[str, Any] = field(default_factory=dict)
    # The stage's trials from ``obs``, stored before the step: (next_obs, action, reward, terminated).
    trials: list[tuple[Mapping[str, Any], int, float, bool]] = field(default_factory=list)
    trial_counts: TrialCounts = field(default_factory=TrialCounts)
    choose_seconds: float = 0.0
    step_seconds: float = 0.0

    @property
    def done(self) -> bool:
        """The episode ended with this step."""
        return self.terminated or self.truncated


# ------------------------------------------------------------------------------ per episode
class EpisodeCounts(Protocol):
    """An episode's own counters, as :func:`count_step` updates them (the learner's
    :class:`~mpg_agents.learning.run_state.Counters` with one actor, an :class:`ActorCounts` in an actor)."""

    episode_motions: int
    failed_grasps_in_a_row: int
    pushes_in_episode: int


@dataclass
class ActorCounts:
    """An actor's :class:`EpisodeCounts`."""

    episode_motions: int = 0
    failed_grasps_in_a_row: int = 0
    pushes_in_episode: int = 0


def start_episode(counts: EpisodeCounts) -> None:
    """Zero the counters of an episode that starts."""
    counts.episode_motions = counts.failed_grasps_in_a_row = counts.pushes_in_episode = 0


def count_step(counts: EpisodeCounts, primitive: str, info: Mapping[str, Any]) -> None:
    """Count a step of ``primitive`` whose env ``info`` it was: a motion; a grasp that lifted
    nothing adds to the failed grasps in a row (one that lifted something ends them); a push
    spends the push budget."""
    if primitive == GRASP:
        counts.failed_grasps_in_a_row = 0 if info["lifted"] else counts.failed_grasps_in_a_row + 1
    if primitive == PUSH:
        counts.pushes_in_episode += 1
    counts.episode_motions += 1


# ---------------------------------------------------------------------------------- actor
ActorChoice = tuple[TakenAction, list[tuple[Mapping[str, Any], int, float, bool]], TrialCounts]
"""What an actor chose on an observation: the action, its trials' transitions and their counts."""


class Actor:
    """Steps one env of the stage, an episode through the one episode loop
    (:func:`~mpg_agents.acting.episode_loop.episode_steps`); one :meth:`step` per request.

    An actor in its own process (:meth:`from_spec`) holds a copy of the learner's agent and is
    sent newer weights; the learner's own actor (one actor) acts with the learner's env,
    agent, exploration, generator and counters themselves.

    Args:
        env: the stage's training env it steps.
        policy: the agent it decides with.
        explorer: its exploration.
        rng: its generator (exploration's draws).
        stage: the training stage it acts in.
        run_seed: the run's seed (the episodes' env seeds, :func:`~mpg_agents.acting.seeds.episode_seed`).
        counts: where its episode's counters are kept.
        index: which actor (in messages and its steps).
        given_weights: whether ``policy`` already holds the weights to act with (else it waits
            for a request that brings some).
    """

    def __init__(
        self,
        env: gym.Env,
        policy: MPGAgent,
        explorer: Explorer,
        rng: np.random.Generator,
        stage: TrainingStage,
        run_seed: int,
        counts: EpisodeCounts,
        index: int = 0,
        given_weights: bool = True,
    ) -> None:
        self.env, self.policy, self.explorer, self.rng, self.stage = env, policy, explorer, rng, stage
        self.run_seed, self.counts, self.index = run_seed, counts, index
        self.has_weights = given_weights
        self.episode = -1
        self.epsilon = 0.0  # the current request's
        self.steps: Iterator[Step[ActorChoice]] | None = None  # the running episode's (None: none runs)

    @classmethod
    def from_spec(cls, spec: ActorSpec) -> Actor:
        """An actor built in its own process, on one torch thread, waiting for the learner's weights."""
        torch.set_num_threads(1)
        torch.set_flush_denormal(True)  # as the learner: a young net's denormals slow the CPU down
        cfg = spec.config
        env = make_training_env(spec.stage, cfg, spec.num_objects, "cpu")
        policy = build_agent(spec.stage, cfg, env)
        rng = np.random.default_rng([cfg.seed, spec.index, spec.start_iteration])
        unwrapped: Any = env.unwrapped
        explorer = make_explorer(policy, spec.stage, tuple(unwrapped.primitives), rng, cfg)
        return cls(env, policy, explorer, rng, spec.stage, cfg.seed, ActorCounts(), spec.index, given_weights=False)

    @property
    def running(self) -> bool:
        """Whether an episode runs (else the next request must name one to start)."""
        return self.steps is not None

    def load(self, weights: Weights) -> None:
        """Act with ``weights`` (and their Q*_g) from now on."""
        # Copies: Ray hands over read-only arrays, which torch.from_numpy warns about.
        self.policy.q_net.mpgnet.load_state_dict({k: torch.tensor(np.asarray(v)) for k, v in weights.state.items()})
        self.policy.set_q_star(weights.q_star)
        self.has_weights = True

    def step(self, request: ActRequest) -> ActorStep:
        """One env step (a reset first when no episode runs)."""
        if request.weights is not None:
            self.load(request.weights)
        if not self.has_weights:
            raise RuntimeError(f"actor {self.index}: asked to act before it was given weights")
        if self.steps is None:
            skipped = self._reset(request)
            if skipped is not None:
                return ActorStep(self.index, self.episode, skipped=skipped)
        assert self.steps is not None
        self.epsilon = request.epsilon
        step = next(self.steps)
        choice, trials, counts = step.choice
        count_step(self.counts, choice.primitive, step.info)
        if step.done:
            self.steps = None
        return ActorStep(
            self.index,
            self.episode,
            None,
            dict(step.obs),
            choice,
            dict(step.next_obs),
            step.reward,
            step.terminated,
            step.truncated,
            step.info,
            trials,
            counts,
            step.choose_seconds,
            step.step_seconds,
        )

    def choose(self, obs: Mapping[str, Any]) -> ActorChoice:
        """The action on ``obs`` (:func:`choose_action`) and the stage's trials around it, tried and undone."""
        choice = choose_action(
            self.policy,
            self.explorer,
            self.stage,
            obs,
            self.epsilon,
            self.counts.pushes_in_episode,
            self.counts.failed_grasps_in_a_row,
        )
        trials: list[tuple[Mapping[str, Any], int, float, bool]] = []
        counts = TrialCounts()
        try_alternatives(
            self.env.unwrapped,
            self.policy,
            self.stage,
            counts,
            obs,
            choice,
            self.rng,
            lambda _, next_obs, action, reward, terminated: trials.append((next_obs, action, reward, terminated)),
        )
        return choice, trials, counts

    def _reset(self, request: ActRequest) -> str | None:
        """Start episode ``request.episode``; returns why its seed gave no valid scene, if it did not."""
        if request.episode is None:
            raise RuntimeError(f"actor {self.index}: no episode runs and the request names none to start")
        self.episode = request.episode
        options = None if request.num_objects is None else {"num_objects": request.num_objects}
        try:
            obs, _ = self.env.reset(seed=episode_seed(self.run_seed, self.episode), options=options)
        except InvalidSceneError as exc:
            return str(exc)
        start_episode(self.counts)
        self.steps = episode_steps(self.env, obs, self.choose, lambda chosen: chosen[0].action)
        return None

    def close(self) -> None:
        """Close the env."""
        self.env.close()
