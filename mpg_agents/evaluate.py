"""Evaluation with the paper's metrics (Table I): task success within 10 motions, motions.

An evaluation is a list of per-episode records, then one summary. Episode ``i`` is the
seeded reset ``reset(seed=seed + i)`` run until the env ends it (target grasped, motion
cap, target out of the workspace, ...). Before it starts, the env's action space and the
policy (if it has ``seed(s)``) are seeded with the same ``seed + i`` and the policy is
``reset()``, so an episode's actions depend only on its index: any split of the episodes
over workers (:mod:`mpg_agents.parallel`) gives the same records.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Iterable, Sequence

import gymnasium as gym
import numpy as np

from mpg_agents.stats import bootstrap_mean_interval, wilson_interval

PRIMITIVES = ("move", "push", "grasp")
UNREPORTED = "unreported"  # an env that does not (yet) put end_reason in the last step's info


@dataclass(frozen=True)
class EpisodeRecord:
    """What one episode did; wall time is kept out of equality and JSON."""

    index: int
    seed: int
    success: bool
    motions: int
    end_reason: str
    primitives: dict[str, int]  # motions per primitive
    grasp_attempts: int
    target_grasps: int  # grasps that lifted the target
    wrong_grasps: int  # grasps that lifted another object
    objects_left: int | None
    # The actions taken, to replay or compare an episode: flat indices, or for a wrapped env
    # with a continuous action space (mpg_envs.wrappers.ContinuousAction) tuples of floats.
    actions: tuple[int | tuple[float, ...], ...] = ()
    seconds: float = field(default=0.0, compare=False)

    def to_dict(self) -> dict[str, Any]:
        data = asdict(self)
        del data["seconds"]
        return data

    def describe(self) -> str:
        outcome = "success" if self.success else "failure"
        used = ", ".join(f"{n} {p}" for p, n in self.primitives.items() if n)
        return f"episode {self.index} (seed {self.seed}): {outcome} after {self.motions} motions ({used}); end: {self.end_reason}"


@dataclass
class EvalResult:
    """The paper's metrics, their 95% intervals, and the episodes they were measured on."""

    policy: str
    env_id: str
    num_objects: int
    episodes: int
    seed: int
    task_success_rate: float  # episodes ending with the target grasped
    success_interval: tuple[float, float]  # Wilson 95%
    average_motions: float  # mean motions per episode (failures count all their motions)
    motions_interval: tuple[float, float] | None  # bootstrap 95% (None for one episode)
    average_motions_success: float | None  # mean motions of the successful episodes
    grasp_success_rate: float | None  # target grasps / grasp attempts
    grasp_attempts: int
    end_reasons: dict[str, int]
    primitive_counts: dict[str, int]  # motions per primitive over all episodes
    records: list[EpisodeRecord]
    seconds_per_motion: float
    wall_seconds: float = 0.0
    workers: int = 1

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready data; wall time and the worker count are left out so one seed gives one file."""
        data = asdict(self)
        for key in ("seconds_per_motion", "wall_seconds", "workers"):
            del data[key]
        data["records"] = [r.to_dict() for r in self.records]
        return data

    def table(self) -> str:
        lo, hi = self.success_interval
        motions = f"{self.average_motions:.2f}"
        if self.motions_interval is not None:
            motions += f" [{self.motions_interval[0]:.2f}, {self.motions_interval[1]:.2f}]"
        rows = [
            ("policy", self.policy),
            ("env", f"{self.env_id} ({self.num_objects} objects)"),
            ("episodes", f"{self.episodes} (seeds {self.seed}..{self.seed + self.episodes - 1})"),
            ("task success rate", f"{100 * self.task_success_rate:.1f}% [{100 * lo:.1f}, {100 * hi:.1f}]"),
            ("average motion number", motions),
            ("  in successful episodes", "n/a" if self.average_motions_success is None else f"{self.average_motions_success:.2f}"),
            ("grasp success rate", "n/a" if self.grasp_success_rate is None else f"{100 * self.grasp_success_rate:.1f}% of {self.grasp_attempts}"),
            ("primitives used", ", ".join(f"{p} {n}" for p, n in self.primitive_counts.items())),
            ("episodes ended by", ", ".join(f"{r} {n}" for r, n in self.end_reasons.items())),
            ("seconds per motion", f"{self.seconds_per_motion:.2f} ({self.workers} worker{'s' if self.workers > 1 else ''}, {self.wall_seconds:.1f} s)"),
        ]
        width = max(len(k) for k, _ in rows)
        return "\n".join(f"{k:<{width}}  {v}" for k, v in rows)


def env_id_of(env: gym.Env) -> str:
    """The registered id of ``env`` (or its stage's, for an env built without ``gym.make``)."""
    unwrapped = env.unwrapped
    if unwrapped.spec is not None:
        return unwrapped.spec.id
    stage = getattr(unwrapped, "stage", None) or getattr(unwrapped, "spec_stage", None)
    if stage is None:
        raise ValueError(f"cannot tell the env id of {unwrapped!r}: it was not made by gym.make and has no stage")
    return stage.env_id


def start_episode(policy, env: gym.Env, episode_seed: int) -> tuple[dict, dict]:
    """Seed the action space and the policy with ``episode_seed``, reset both, reset the env."""
    env.action_space.seed(episode_seed)
    seed = getattr(policy, "seed", None)
    if callable(seed):
        seed(episode_seed)
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()
    return env.reset(seed=episode_seed)


def _recorded(action: Any) -> int | tuple[float, ...]:
    """An action as the record keeps it: an int for a discrete action, floats for a vector."""
    arr = np.asarray(action)
    if arr.ndim == 0:
        return int(arr)
    return tuple(float(v) for v in arr.reshape(-1))


def run_episode(
    policy,
    env: gym.Env,
    index: int,
    seed: int,
    on_reset: Callable[[int, dict], None] | None = None,
    on_step: Callable[[int, float, dict], None] | None = None,
) -> EpisodeRecord:
    """Run episode ``index`` (reset seed ``seed + index``) to its end and record it."""
    start = time.perf_counter()
    episode_seed = seed + index
    obs, info = start_episode(policy, env, episode_seed)
    if on_reset is not None:
        on_reset(index, obs)
    primitives = dict.fromkeys(PRIMITIVES, 0)
    grasps = target_grasps = wrong_grasps = 0
    actions = []
    while True:
        actions.append(_recorded(policy.act(obs)))
        obs, reward, terminated, truncated, info = env.step(actions[-1])
        if on_step is not None:
            on_step(index, reward, info)
        primitives[info["primitive"]] += 1
        if info["primitive"] == "grasp":
            grasps += 1
            target_grasps += int(info["target_grasped"])
            wrong_grasps += int(info.get("wrong_grasp", False))
        if terminated or truncated:
            break
    return EpisodeRecord(
        index=index,
        seed=episode_seed,
        success=bool(info["is_success"]),
        motions=int(info["num_motions"]),
        end_reason=str(info.get("end_reason") or UNREPORTED),
        primitives=primitives,
        grasp_attempts=grasps,
        target_grasps=target_grasps,
        wrong_grasps=wrong_grasps,
        objects_left=None if info.get("objects_left") is None else int(info["objects_left"]),
        actions=tuple(actions),
        seconds=time.perf_counter() - start,
    )


def summarise(
    records: Iterable[EpisodeRecord],
    policy: str,
    env_id: str,
    num_objects: int,
    seed: int,
    wall_seconds: float,
    workers: int = 1,
) -> EvalResult:
    """The metrics over ``records`` (episodes 0..n-1 of one evaluation, in any order)."""
    ordered = sorted(records, key=lambda r: r.index)
    if not ordered:
        raise ValueError("no episode records to summarise")
    indices = [r.index for r in ordered]
    if indices != list(range(len(ordered))):
        raise ValueError(f"episode records must be episodes 0..{len(ordered) - 1} once each, got indices {indices}")
    motions = [r.motions for r in ordered]
    success_motions = [r.motions for r in ordered if r.success]
    successes = sum(r.success for r in ordered)
    grasps = sum(r.grasp_attempts for r in ordered)
    end_reasons: dict[str, int] = {}
    for r in ordered:
        end_reasons[r.end_reason] = end_reasons.get(r.end_reason, 0) + 1
    primitive_counts = {p: sum(r.primitives.get(p, 0) for r in ordered) for p in PRIMITIVES}
    return EvalResult(
        policy=policy,
        env_id=env_id,
        num_objects=int(num_objects),
        episodes=len(ordered),
        seed=seed,
        task_success_rate=successes / len(ordered),
        success_interval=wilson_interval(successes, len(ordered)),
        average_motions=float(np.mean(motions)),
        motions_interval=bootstrap_mean_interval(motions, seed=seed) if len(motions) > 1 else None,
        average_motions_success=float(np.mean(success_motions)) if success_motions else None,
        grasp_success_rate=sum(r.target_grasps for r in ordered) / grasps if grasps else None,
        grasp_attempts=grasps,
        end_reasons=dict(sorted(end_reasons.items())),
        primitive_counts=primitive_counts,
        records=ordered,
        seconds_per_motion=sum(r.seconds for r in ordered) / max(1, sum(motions)),
        wall_seconds=wall_seconds,
        workers=workers,
    )


def run_episodes(
    policy,
    env: gym.Env,
    indices: Sequence[int],
    seed: int,
    on_record: Callable[[EpisodeRecord], None] | None = None,
    on_reset: Callable[[int, dict], None] | None = None,
    on_step: Callable[[int, float, dict], None] | None = None,
) -> list[EpisodeRecord]:
    """Records of the episodes ``indices`` (each seeded ``seed + index``) on one env and policy."""
    records = []
    for index in indices:
        record = run_episode(policy, env, index, seed, on_reset=on_reset, on_step=on_step)
        records.append(record)
        if on_record is not None:
            on_record(record)
    return records


def evaluate(
    policy,
    env: gym.Env,
    episodes: int,
    seed: int,
    progress: bool = False,
    on_reset: Callable[[int, dict], None] | None = None,
    on_step: Callable[[int, float, dict], None] | None = None,
) -> EvalResult:
    """Run ``policy`` (with ``act(obs)``) for ``episodes`` seeded episodes of ``env``, in this process.

    ``on_reset(episode, obs)`` and ``on_step(episode, reward, info)`` let a caller (the demo)
    watch the episodes without keeping its own tally of the metrics. For several worker
    processes see :func:`mpg_agents.parallel.evaluate_parallel` (same records).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    start = time.perf_counter()
    on_record = (lambda r: print("  " + r.describe(), flush=True)) if progress else None
    records = run_episodes(policy, env, range(episodes), seed, on_record=on_record, on_reset=on_reset, on_step=on_step)
    return summarise(
        records,
        policy=getattr(policy, "name", type(policy).__name__),
        env_id=env_id_of(env),
        num_objects=int(env.unwrapped.num_objects),
        seed=seed,
        wall_seconds=time.perf_counter() - start,
    )
