"""Evaluation with the paper's metrics (Table I) and the ones that separate methods.

The paper's: task success within the motion cap and mean motions per episode, and the grasp
success rate (target grasps / grasp attempts). Beside them: success without a mis-pick (no
grasp lifted a non-target object on the way; under strict retrieval every success is one),
mis-picks per episode, and success by the target's visible fraction at reset
(:data:`mpg_envs.perception.occlusion.VISIBILITY_BANDS`). Every rate has its 95% Wilson interval.

An evaluation is a list of per-episode records, then one summary. Episode ``i`` is the
seeded reset ``reset(seed=seed + i)`` run until the env ends it (target grasped, motion
cap, target out of the workspace, ...). Before it starts, the env's action space and the
policy (if it has ``seed(s)``) are seeded with the same ``seed + i`` and the policy is
``reset()``, so an episode's actions depend only on its index: any split of the episodes
over workers (:mod:`mpg_agents.evaluation.eval_runner`) gives the same records.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs
from mpg_agents.acting.episode_loop import episode_steps
from mpg_agents.evaluation.eval_result import EpisodeRecord, EvalResult
from mpg_agents.evaluation.failures import EpisodeFailure, NothingFinished, describe_failures
from mpg_agents.evaluation.finding import FindingTally, finding_summary
from mpg_agents.evaluation.motion_log import MotionRecord
from mpg_agents.evaluation.stats import bootstrap_mean_interval, wilson_interval
from mpg_envs.grid.actions import PRIMITIVES
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.perception.occlusion import VISIBILITY_BAND_LABELS, visibility_band
from mpg_envs.simulation.mujoco_version import MUJOCO_KEY, running_mujoco

UNREPORTED = "unreported"  # an env that does not (yet) put end_reason in the last step's info


def env_id_of(env: gym.Env) -> str:
    """The registered id of ``env`` (or its stage's, for an env built without ``gym.make``)."""
    unwrapped = env.unwrapped
    if unwrapped.spec is not None:
        return unwrapped.spec.id
    stage = getattr(unwrapped, "stage", None) or getattr(unwrapped, "spec_stage", None)
    if stage is None:
        raise ValueError(f"cannot tell the env id of {unwrapped!r}: it was not made by gym.make and has no stage")
    return stage.env_id


def start_episode(policy, env: gym.Env, episode_seed: int, options: dict[str, Any] | None = None) -> tuple[dict, dict]:
    """Seed the action space and the policy with ``episode_seed``, reset both, reset the env
    (with reset ``options``, e.g. a scene file to load)."""
    env.action_space.seed(episode_seed)
    seed = getattr(policy, "seed", None)
    if callable(seed):
        seed(episode_seed)
    reset = getattr(policy, "reset", None)
    if callable(reset):
        reset()
    return env.reset(seed=episode_seed, options=options)


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
    reset_options: dict[str, Any] | None = None,
) -> EpisodeRecord:
    """Run episode ``index`` (reset seed ``seed + index``, with ``reset_options``) to its end
    and record it."""
    start = time.perf_counter()
    episode_seed = seed + index
    obs, info = start_episode(policy, env, episode_seed, reset_options)
    reset_info = info
    visible = info.get("visible_fraction")
    if on_reset is not None:
        on_reset(index, obs)
    primitives = dict.fromkeys(PRIMITIVES, 0)
    grasps = target_grasps = wrong_grasps = 0
    actions, steps = [], []
    finding = FindingTally(visible)
    for step in episode_steps(env, obs, policy.act, _recorded):
        actions.append(step.action)
        steps.append(MotionRecord.from_info(step.info, info.get("visible_fraction")))
        info = step.info
        finding.step(info)
        if on_step is not None:
            on_step(index, step.reward, info)
        primitives[info["primitive"]] += 1
        if info["primitive"] == GRASP:
            grasps += 1
            target_grasps += int(info["target_grasped"])
            wrong_grasps += int(info.get("wrong_grasp", False))
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
        visible_fraction=None if visible is None else float(visible),
        actions=tuple(actions),
        visuals=reset_info.get("visual_randomization"),
        steps=tuple(steps),
        first_sight=finding.first_sight,
        lookalike_grasps=finding.lookalike_grasps,
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
    env_options: dict[str, Any] | None = None,
    failures: Sequence[EpisodeFailure] = (),
) -> EvalResult:
    """The metrics over ``records`` (with ``failures``, the episodes that raised: episodes
    0..n-1 of one evaluation once each, in any order); ``env_options``: the keywords the env
    was made with, for the record.

    Raises:
        NothingFinished: every episode failed (the message lists why).
    """
    ordered = sorted(records, key=lambda r: r.index)
    failed = sorted(failures, key=lambda f: f.index)
    if not ordered and failed:
        raise NothingFinished(f"all {len(failed)} episodes failed: {describe_failures(failed)}")
    if not ordered:
        raise ValueError("no episode records to summarise")
    indices = sorted([r.index for r in ordered] + [f.index for f in failed])
    if indices != list(range(len(indices))):
        raise ValueError(f"episode records must be episodes 0..{len(indices) - 1} once each, got indices {indices}")
    motions = [r.motions for r in ordered]
    success_motions = [r.motions for r in ordered if r.success]
    successes = sum(r.success for r in ordered)
    grasps = sum(r.grasp_attempts for r in ordered)
    end_reasons: dict[str, int] = {}
    for r in ordered:
        end_reasons[r.end_reason] = end_reasons.get(r.end_reason, 0) + 1
    primitive_counts = {p: sum(r.primitives.get(p, 0) for r in ordered) for p in PRIMITIVES}
    clean = sum(r.clean_success for r in ordered)
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
        clean_success_rate=clean / len(ordered),
        clean_success_interval=wilson_interval(clean, len(ordered)),
        mispicks_per_episode=sum(r.wrong_grasps for r in ordered) / len(ordered),
        success_by_visibility=success_by_visibility(ordered),
        finding=finding_summary(ordered),
        env_options=dict(env_options or {}),
        versions=versions(env_id),
        failures=failed,
    )


def success_by_visibility(records: Sequence[EpisodeRecord]) -> dict[str, dict[str, Any]]:
    """Task success per band of the target's visible fraction at reset (episodes whose
    env reports none are left out)."""
    cells: dict[str, dict[str, Any]] = {}
    for label in VISIBILITY_BAND_LABELS:
        band = [r for r in records if r.visible_fraction is not None and visibility_band(r.visible_fraction) == label]
        if band:
            k = sum(r.success for r in band)
            cells[label] = {
                "episodes": len(band),
                "successes": k,
                "rate": k / len(band),
                "interval": list(wilson_interval(k, len(band))),
            }
    return cells


def versions(env_id: str) -> dict[str, str]:
    """The package version, the env id's version (``v0`` of ``MPG-Occluded-v0``) and the
    MuJoCo version the episodes run on (``"mujoco"``: results depend on its major version, see
    :mod:`mpg_envs.simulation.mujoco_version`; a file without it was measured on MuJoCo 3.x)."""
    return {
        "package": str(getattr(mpg_envs, "__version__", "unknown")),
        "env": env_id.rsplit("-", 1)[-1],
        MUJOCO_KEY: running_mujoco(),
    }


def env_options_of(env: gym.Env) -> dict[str, Any]:
    """The keywords ``env`` was made with besides its registered ones (from its spec),
    JSON-ready (other values by ``repr``)."""
    spec = env.unwrapped.spec
    return {} if spec is None else _json_options(spec.kwargs)


def registered_options(env_id: str) -> dict[str, Any]:
    """The keywords ``env_id`` is registered with besides its stage (a track's fixed ones,
    such as ``MPG-OccludedHardCamera-v0``'s ``obs_mode``), JSON-ready; ``{}`` for an id
    Gymnasium does not know."""
    return _json_options(gym.registry[env_id].kwargs) if env_id in gym.registry else {}


def _json_options(kwargs: dict[str, Any]) -> dict[str, Any]:
    options = {}
    for key, value in kwargs.items():
        if key in ("stage", "num_objects"):  # the env and the object count are recorded apart
            continue
        options[key] = value if isinstance(value, (bool, int, float, str, type(None), list, tuple)) else repr(value)
    return options


def run_episodes(
    policy,
    env: gym.Env,
    indices: Sequence[int],
    seed: int,
    on_record: Callable[[EpisodeRecord], None] | None = None,
    on_reset: Callable[[int, dict], None] | None = None,
    on_step: Callable[[int, float, dict], None] | None = None,
    reset_options: dict[str, Any] | None = None,
    failures: list[EpisodeFailure] | None = None,
) -> list[EpisodeRecord]:
    """Records of the episodes ``indices`` (each seeded ``seed + index``, reset with
    ``reset_options``) on one env and policy. An episode that raises ends the run, or with a
    ``failures`` list is appended to it (:class:`~mpg_agents.evaluation.failures.EpisodeFailure`)
    and the run goes on with the next episode."""
    records = []
    for index in indices:
        try:
            record = run_episode(policy, env, index, seed, on_reset=on_reset, on_step=on_step, reset_options=reset_options)
        except Exception as exc:
            if failures is None:
                raise
            failures.append(EpisodeFailure.of(exc, index, seed + index))
            continue
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
    processes see :func:`mpg_agents.evaluation.eval_runner.evaluate_parallel` (same records).
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    start = time.perf_counter()
    on_record = (lambda r: print("  " + r.describe(), flush=True)) if progress else None
    records = run_episodes(policy, env, range(episodes), seed, on_record=on_record, on_reset=on_reset, on_step=on_step)
    unwrapped: Any = env.unwrapped  # the MPG env (gym.Env does not declare its attributes)
    return summarise(
        records,
        policy=getattr(policy, "name", type(policy).__name__),
        env_id=env_id_of(env),
        num_objects=int(unwrapped.num_objects),
        seed=seed,
        wall_seconds=time.perf_counter() - start,
        env_options=env_options_of(env),
    )
