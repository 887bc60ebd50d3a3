"""Recording a policy's episodes, in this process or on worker processes, in seed order.

:func:`record_episode` runs episode ``index`` of a :class:`DemoJob` as evaluation does
(:func:`mpg_agents.evaluation.evaluate.start_episode`: the action space and the policy seeded
with ``seed + index`` and reset, then ``env.reset(seed=seed + index, options=...)``) and keeps
everything a dataset stores: the ``T + 1`` observations, the ``T`` actions, rewards and end
flags, and the infos as columns (:func:`mpg_agents.demos.step_info.encode_infos`).
:func:`record_episodes` yields the episodes in index order: with ``workers`` > 1 the episodes
are dealt to a pool of fresh processes, each on one compute thread that builds the env and the
policy once, and gathered back in index order, so any number of workers gives the same data.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from collections.abc import Iterator, Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs
from mpg_agents.acting.episode_loop import episode_steps
from mpg_agents.demos.step_info import encode_infos
from mpg_agents.evaluation.evaluate import start_episode
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_envs.threads import one_thread_children, worker_init


@dataclass(frozen=True)
class DemoJob:
    """What to record: ``episodes`` episodes of ``policy`` (a :func:`~mpg_agents.evaluation.policy_zoo.make_policy`
    name or checkpoint path) on ``env_id`` made with ``env_kwargs`` (``num_objects`` and other
    env keywords), episode ``i`` seeded ``seed + i`` and reset with ``reset_options``;
    ``policy_kwargs`` go to ``make_policy`` (e.g. ``(("device", "cpu"),)``)."""

    policy: str
    env_id: str
    episodes: int
    seed: int = 0
    env_kwargs: tuple[tuple[str, Any], ...] = ()
    policy_kwargs: tuple[tuple[str, Any], ...] = ()
    reset_options: tuple[tuple[str, Any], ...] | None = None

    def __post_init__(self) -> None:
        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int) or self.episodes < 1:
            raise ValueError(f"episodes must be a positive integer, got {self.episodes!r}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be a non-negative integer, got {self.seed!r}")

    def make_env(self) -> gym.Env:
        """The env, as ``mpg_envs.make(env_id, **env_kwargs)`` builds it."""
        return mpg_envs.make(self.env_id, **dict(self.env_kwargs))

    def make_policy(self, env: gym.Env) -> Any:
        """The policy for ``env`` (seeded with ``seed``; each episode reseeds it)."""
        return make_policy(self.policy, env, seed=self.seed, **dict(self.policy_kwargs))

    def options(self) -> dict[str, Any] | None:
        """The reset options every episode gets (``None``: none)."""
        return None if self.reset_options is None else dict(self.reset_options)


@dataclass(frozen=True)
class RecordedEpisode:
    """One recorded episode.

    Attributes:
        index: its position in the job (episode ``index`` of ``seed + index``).
        seed: the env's reset seed.
        options: the reset options (``None``: none).
        observations: ``T + 1`` observations, stacked per key for a ``Dict`` space (a
            dict of arrays), else one array.
        actions: the ``T`` actions as the env took them, stacked (a dict of arrays for a
            ``Dict`` action space).
        rewards, terminations, truncations: one per step.
        infos: the reset's and every step's info as columns (:func:`~mpg_agents.demos.step_info.encode_infos`).
        policy: the policy's name.
        success: the last step's ``is_success``.
        end_reason: the last step's ``end_reason``.
        seconds: wall time of the episode (not part of the data).
    """

    index: int
    seed: int
    options: dict[str, Any] | None
    observations: dict[str, np.ndarray] | np.ndarray
    actions: dict[str, np.ndarray] | np.ndarray
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    infos: dict[str, Any]
    policy: str
    success: bool
    end_reason: str
    seconds: float

    @property
    def steps(self) -> int:
        """``T``, the number of actions."""
        return len(self.rewards)

    def summary(self) -> dict[str, Any]:
        """The episode's metadata as a dataset keeps it (JSON-ready, no wall time)."""
        return {
            "index": self.index,
            "policy": self.policy,
            "success": self.success,
            "end_reason": self.end_reason,
            "motions": self.steps,
        }

    def describe(self) -> str:
        """One progress line."""
        outcome = "success" if self.success else "failure"
        return (
            f"episode {self.index} (seed {self.seed}): {outcome} after {self.steps} motions; "
            f"end: {self.end_reason} ({self.seconds:.1f} s)"
        )


def _stack(values: Sequence[Any]) -> dict[str, np.ndarray] | np.ndarray:
    """Observations (or actions) of an episode as arrays stacked on a new first axis."""
    first = values[0]
    if isinstance(first, dict):
        return {key: np.stack([np.asarray(v[key]) for v in values]) for key in first}
    return np.stack([np.asarray(v) for v in values])


def record_episode(policy: Any, env: gym.Env, index: int, seed: int, options: dict[str, Any] | None = None) -> RecordedEpisode:
    """Run episode ``index`` (reset seed ``seed + index``, reset ``options``) to its end and keep it."""
    start = time.perf_counter()
    episode_seed = seed + index
    obs, info = start_episode(policy, env, episode_seed, options)
    observations: list[Any] = [obs]
    infos: list[Mapping[str, Any]] = [info]
    actions: list[Any] = []
    rewards: list[float] = []
    terminations: list[bool] = []
    truncations: list[bool] = []
    for step in episode_steps(env, obs, policy.act):
        observations.append(step.next_obs)
        infos.append(step.info)
        actions.append(step.action)
        rewards.append(step.reward)
        terminations.append(step.terminated)
        truncations.append(step.truncated)
    last = infos[-1]
    return RecordedEpisode(
        index=index,
        seed=episode_seed,
        options=options,
        observations=_stack(observations),
        actions=_stack(actions),
        rewards=np.asarray(rewards, dtype=np.float64),
        terminations=np.asarray(terminations, dtype=bool),
        truncations=np.asarray(truncations, dtype=bool),
        infos=encode_infos(infos),
        policy=str(getattr(policy, "name", type(policy).__name__)),
        success=bool(last.get("is_success", False)),
        end_reason=str(last.get("end_reason") or ""),
        seconds=time.perf_counter() - start,
    )


_worker: tuple[DemoJob, gym.Env, Any] | None = None
"""A worker process's job, env and policy, built once by :func:`_start_worker`."""


def _start_worker(job: DemoJob) -> None:
    global _worker
    worker_init()  # one compute thread: the workers' parallelism is their number
    env = job.make_env()
    _worker = (job, env, job.make_policy(env))


def _record_in_worker(index: int) -> RecordedEpisode:
    if _worker is None:
        raise RuntimeError("the worker was not started with its job")
    job, env, policy = _worker
    return record_episode(policy, env, index, job.seed, job.options())


def record_episodes(job: DemoJob, workers: int = 1, env: gym.Env | None = None, start: int = 0) -> Iterator[RecordedEpisode]:
    """Episodes ``start`` on of ``job`` (default: every one), in index order; ``workers`` > 1 runs them on that many worker
    processes (one compute thread each), a record coming back as soon as it and every one
    before it are done. An episode that raises ends the iteration with its exception.
    With one worker the episodes run in this process, on ``env`` when given (it must be
    ``job.make_env()``'s; the caller closes it), else on an env made and closed here.

    Raises:
        ValueError: ``workers`` below 1, or ``start`` outside ``0..episodes``.
    """
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be a positive integer, got {workers!r}")
    if isinstance(start, bool) or not isinstance(start, int) or not 0 <= start <= job.episodes:
        raise ValueError(f"start must be an integer in 0..{job.episodes}, got {start!r}")
    indices = range(start, job.episodes)
    if not indices:
        return
    if workers == 1:
        own = env is None
        env = job.make_env() if env is None else env
        try:
            policy = job.make_policy(env)
            for index in indices:
                yield record_episode(policy, env, index, job.seed, job.options())
        finally:
            if own:
                env.close()
        return
    with one_thread_children():  # the workers start (as episodes are submitted) on one thread each
        with ProcessPoolExecutor(
            min(workers, len(indices)),
            mp_context=mp.get_context("forkserver"),
            initializer=_start_worker,
            initargs=(job,),
        ) as pool:
            yield from pool.map(_record_in_worker, indices)
