"""Evaluation episodes as Ray tasks: the same records for any number of workers.

An :class:`EvalJob` names a policy (a :func:`mpg_agents.evaluation.policy_zoo.make_policy` name or a
checkpoint path), an env and a number of episodes. :func:`evaluate_jobs` splits every
job's episode indices into ``workers`` interleaved chunks; each chunk is one Ray task that
builds its env and policy once (building the MuJoCo scene and loading a net take seconds)
and runs its episodes. Since episode ``i`` is seeded ``seed + i`` whatever process runs it
(:func:`mpg_agents.evaluation.evaluate.start_episode`), the gathered records, sorted by index, do not
depend on the split. ``workers=1`` without a cluster address runs in this process, no Ray.

Every task runs on one torch/OpenMP thread (``OMP_NUM_THREADS=1`` in Ray's runtime env and
:func:`mpg_envs.threads.worker_init` in the worker), so ``workers`` tasks use ``workers``
cores; in-process, episodes run on one torch thread too, so their records are the same.
``backend="processes"`` runs the same chunks on a local process pool instead of Ray: no
cluster, but no Ray start-up either (seconds on a small machine), and it works where Ray is
not installed. On a cluster (``ray_address``) every node needs this package installed and checkpoint
paths readable at the same absolute path.
"""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mpg_envs  # registers the envs in a fresh worker
from mpg_agents.evaluation.eval_result import EpisodeRecord, EvalResult
from mpg_agents.evaluation.evaluate import env_id_of, registered_options, run_episodes, summarise
from mpg_agents.evaluation.failures import EpisodeFailure
from mpg_agents.evaluation.policy_zoo import is_builtin, make_policy
from mpg_envs.threads import WORKER_THREAD_ENV as THREAD_ENV
from mpg_envs.threads import one_thread_children, worker_init


@dataclass(frozen=True)
class EvalJob:
    """One evaluation: ``episodes`` episodes of ``policy`` on ``env_id`` (seeds ``seed + i``)."""

    policy: str
    env_id: str = "MPG-Occluded-v0"
    episodes: int = 50
    seed: int = 0
    num_objects: int | None = None
    policy_kwargs: tuple[tuple[str, Any], ...] = ()  # to make_policy, e.g. (("coordination", "max_q"),)
    env_kwargs: tuple[tuple[str, Any], ...] = ()  # to gym.make besides num_objects, e.g. (("max_motions", 3),)

    def __post_init__(self) -> None:
        if self.episodes < 1:
            raise ValueError(f"episodes must be >= 1, got {self.episodes}")
        if self.num_objects is not None and self.num_objects < 1:
            raise ValueError(f"num_objects must be >= 1, got {self.num_objects}")
        if not is_builtin(self.policy) and Path(self.policy).exists():
            # workers may start in another directory
            object.__setattr__(self, "policy", str(Path(self.policy).resolve()))


@dataclass
class ChunkResult:
    """What one task returns: its records and how long it was busy (set-up included)."""

    policy_name: str
    env_id: str
    num_objects: int
    records: list[EpisodeRecord]
    seconds: float
    failures: list[EpisodeFailure] = field(default_factory=list)  # episodes that raised (with keep_going)


@dataclass
class RunTiming:
    """Wall time of a run against the time its tasks were busy (their serial cost)."""

    wall_seconds: float  # from the first task submitted to the last result (Ray start-up excluded)
    task_seconds: float
    workers: int
    tasks: int
    startup_seconds: float = 0.0  # starting a local Ray (or joining a cluster); 0 in-process
    per_job_wall: list[float] = field(default_factory=list)

    @property
    def parallelism(self) -> float:
        """Task seconds over wall seconds: how many tasks ran at once, on average (not a
        speed-up: tasks sharing cores each take longer)."""
        return self.task_seconds / self.wall_seconds if self.wall_seconds > 0 else float("nan")


def chunk_indices(episodes: int, chunks: int) -> list[list[int]]:
    """Episode indices ``0..episodes-1`` dealt round-robin into ``min(chunks, episodes)`` chunks
    (interleaved, so long and short episodes spread over the workers)."""
    if episodes < 1 or chunks < 1:
        raise ValueError(f"episodes and chunks must be >= 1, got {episodes} and {chunks}")
    n = min(chunks, episodes)
    return [list(range(k, episodes, n)) for k in range(n)]


@contextmanager
def _one_torch_thread() -> Iterator[None]:
    import torch  # noqa: PLC0415 - start-up time: the command lines import this module without torch

    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def run_chunk(
    job: EvalJob, indices: Sequence[int], on_record: Callable[[EpisodeRecord], None] | None = None, keep_going: bool = False
) -> ChunkResult:
    """Build ``job``'s env and policy once and run the episodes ``indices`` on one thread; with
    ``keep_going`` an episode that raises is kept as a failure and the others still run."""
    start = time.perf_counter()
    with _one_torch_thread():
        kwargs = dict(job.env_kwargs)
        if job.num_objects is not None:
            kwargs["num_objects"] = job.num_objects
        env = mpg_envs.make(job.env_id, **kwargs)
        try:
            policy = make_policy(job.policy, env, seed=job.seed, **dict(job.policy_kwargs))
            failures: list[EpisodeFailure] | None = [] if keep_going else None
            records = run_episodes(policy, env, indices, job.seed, on_record=on_record, failures=failures)
            name = getattr(policy, "name", type(policy).__name__)
            unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
            env_id, num_objects = env_id_of(env), int(unwrapped.num_objects)
        finally:
            env.close()
    return ChunkResult(name, env_id, num_objects, records, time.perf_counter() - start, failures or [])


def _ray_chunk(job: EvalJob, indices: Sequence[int], keep_going: bool = False) -> ChunkResult:
    """:func:`run_chunk` in a Ray worker, which keeps one compute thread for good."""
    worker_init()
    return run_chunk(job, indices, keep_going=keep_going)


def start_ray(workers: int | None = None, address: str | None = None, **init_kwargs: Any):
    """``ray.init`` as this module's tasks need it: a local Ray with ``workers`` CPUs, or the
    cluster at ``address``; one OpenMP thread per worker. Returns the ``ray`` module."""
    import ray  # noqa: PLC0415 - Ray is an optional extra

    env_vars = dict(THREAD_ENV)
    if "MUJOCO_GL" in os.environ:
        env_vars["MUJOCO_GL"] = os.environ["MUJOCO_GL"]
    settings: dict[str, Any] = {
        "runtime_env": {"env_vars": env_vars},
        "include_dashboard": False,
        "logging_level": logging.WARNING,
        **init_kwargs,
    }
    if address is not None:
        ray.init(address=address, **settings)
    else:
        ray.init(num_cpus=workers or 1, **settings)
    return ray


@contextmanager
def ray_session(workers: int | None = None, address: str | None = None) -> Iterator[Any]:
    """The running Ray if there is one (left running), else one started here and shut down after."""
    import ray  # noqa: PLC0415 - Ray is an optional extra

    if ray.is_initialized():
        yield ray
        return
    start_ray(workers, address)
    try:
        yield ray
    finally:
        ray.shutdown()


def _check_workers(workers: int | None, address: str | None) -> None:
    if workers is None and address is None:
        raise ValueError("workers must be given without a Ray address")
    if workers is not None and (int(workers) != workers or workers < 1):
        raise ValueError(f"workers must be a positive integer, got {workers}")


RecordHook = Callable[[EvalJob, EpisodeRecord], None]
BACKENDS = ("ray", "processes")


def _run_in_process(
    jobs: Sequence[EvalJob], on_record: RecordHook | None, keep_going: bool
) -> tuple[list[list[ChunkResult]], list[float]]:
    """Every job as one chunk, one after the other; the time each finished."""
    start = time.perf_counter()
    chunks, done_at = [], []
    for job in jobs:
        hook = None if on_record is None else (lambda r, job=job: on_record(job, r))
        chunks.append([run_chunk(job, range(job.episodes), on_record=hook, keep_going=keep_going)])
        done_at.append(time.perf_counter() - start)
    return chunks, done_at


def _run_on_ray(
    ray: Any, jobs: Sequence[EvalJob], chunks_per_job: int, on_record: RecordHook | None, keep_going: bool
) -> tuple[list[list[ChunkResult]], list[float]]:
    """Every chunk of every job submitted at once, gathered as they finish; when each job finished."""
    start = time.perf_counter()
    chunks: list[list[ChunkResult]] = [[] for _ in jobs]
    done_at = [0.0] * len(jobs)
    remote = ray.remote(num_cpus=1)(_ray_chunk)
    pending = {
        remote.remote(job, indices, keep_going): j
        for j, job in enumerate(jobs)
        for indices in chunk_indices(job.episodes, chunks_per_job)
    }
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1)
        j = pending.pop(ready[0])
        chunk = ray.get(ready[0])
        chunks[j].append(chunk)
        done_at[j] = time.perf_counter() - start
        if on_record is not None:
            for record in chunk.records:
                on_record(jobs[j], record)
    return chunks, done_at


def _run_on_processes(
    jobs: Sequence[EvalJob], workers: int, on_record: RecordHook | None, keep_going: bool
) -> tuple[list[list[ChunkResult]], list[float]]:
    """:func:`_run_on_ray` on a local pool of ``workers`` fresh processes (one thread each)."""
    with one_thread_children():  # the workers start (lazily, as jobs are submitted) on one thread each
        start = time.perf_counter()
        chunks: list[list[ChunkResult]] = [[] for _ in jobs]
        done_at = [0.0] * len(jobs)
        with ProcessPoolExecutor(workers, mp_context=mp.get_context("forkserver"), initializer=worker_init) as pool:
            pending = {
                pool.submit(run_chunk, job, indices, None, keep_going): j
                for j, job in enumerate(jobs)
                for indices in chunk_indices(job.episodes, workers)
            }
            while pending:
                finished, _ = wait(list(pending), return_when=FIRST_COMPLETED)
                for future in finished:
                    j = pending.pop(future)
                    chunk = future.result()
                    chunks[j].append(chunk)
                    done_at[j] = time.perf_counter() - start
                    if on_record is not None:
                        for record in chunk.records:
                            on_record(jobs[j], record)
    return chunks, done_at


def evaluate_jobs(
    jobs: Sequence[EvalJob],
    workers: int | None = 1,
    ray_address: str | None = None,
    on_record: RecordHook | None = None,
    backend: str = "ray",
    keep_going: bool = False,
) -> tuple[list[EvalResult], RunTiming]:
    """Run every job (all their chunks at once on Ray) and summarise each; results in job order.

    ``workers`` is how many chunks each job is split into (and a local Ray's CPU count);
    with ``ray_address`` and ``workers=None`` it is the cluster's CPU count. ``on_record``
    sees records as they arrive (in index order in-process, a chunk at a time on Ray).
    ``backend`` is ``"ray"`` or ``"processes"`` (a local pool; no ``ray_address``). An episode
    that raises ends the run, or with ``keep_going`` is kept in its result's ``failures`` while
    the other episodes run (:class:`~mpg_agents.evaluation.failures.NothingFinished` when none finished).
    """
    _check_workers(workers, ray_address)
    if backend not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {backend!r}")
    if backend == "processes" and ray_address is not None:
        raise ValueError("a Ray address needs backend='ray'; the 'processes' backend is local")
    if not jobs:
        raise ValueError("no evaluation jobs given")
    startup = 0.0
    if workers == 1 and ray_address is None:
        chunks, done_at = _run_in_process(jobs, on_record, keep_going)
        used_workers = 1
    elif backend == "processes":
        assert workers is not None  # _check_workers: None only with a Ray address
        used_workers = int(workers)
        chunks, done_at = _run_on_processes(jobs, used_workers, on_record, keep_going)
    else:
        start = time.perf_counter()
        with ray_session(workers, ray_address) as ray:
            startup = time.perf_counter() - start
            used_workers = workers or max(1, int(ray.cluster_resources().get("CPU", 1)))
            chunks, done_at = _run_on_ray(ray, jobs, used_workers, on_record, keep_going)
    results = []
    for job, job_chunks, job_wall in zip(jobs, chunks, done_at):
        first = job_chunks[0]
        records = [r for c in job_chunks for r in c.records]
        results.append(
            summarise(
                records,
                first.policy_name,
                first.env_id,
                first.num_objects,
                job.seed,
                job_wall,
                used_workers,
                {**registered_options(job.env_id), **dict(job.env_kwargs)},  # a track's own keywords too
                [f for c in job_chunks for f in c.failures],
            )
        )
    timing = RunTiming(
        wall_seconds=max(done_at),  # Ray's start-up and shutdown are not part of the run
        task_seconds=sum(c.seconds for job_chunks in chunks for c in job_chunks),
        workers=used_workers,
        tasks=sum(len(c) for c in chunks),
        startup_seconds=startup,
        per_job_wall=done_at,
    )
    return results, timing


def evaluate_parallel(
    job: EvalJob,
    workers: int | None = 1,
    ray_address: str | None = None,
    on_record: Callable[[EpisodeRecord], None] | None = None,
    backend: str = "ray",
    keep_going: bool = False,
) -> EvalResult:
    """One job through :func:`evaluate_jobs`."""
    hook = None if on_record is None else (lambda _job, r: on_record(r))
    (result,), _ = evaluate_jobs([job], workers, ray_address, on_record=hook, backend=backend, keep_going=keep_going)
    return result
