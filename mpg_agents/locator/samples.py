"""Labelled samples for the locator, drawn from simulated exemplar-mode episodes.

A sample is what a policy sees in exemplar mode (the scene's colour and depth heightmaps and
the exemplar's) with the simulator's label: the pixels where the target is the top surface
(:meth:`~mpg_envs.tasks.episode_sim.EpisodeSim.top_mask`, empty while it is hidden) and its
visible fraction. Episodes come from :data:`SOURCES` (data: the stage 4 and 5 scenes and the hard
track's, ray-cast and through the cameras, with visual randomization) on the training object
families and the blocks (:func:`training_objects`), at seeds of the run's own (below 500000): never a test seed
or the unseen-shape test split. Each episode gives its reset and the states after a few
disturbing motions (moves and pushes at objects, half of them over the target's footprint,
so the target is uncovered, covered again, or knocked about), so visibility spans hidden to
whole.

Samples are kept in shards, compressed ``.npz`` files written whole (temporary file, then a
rename): a stopped collection resumes at its first missing shard.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the ids)
from mpg_envs.grid.actions import encode_action
from mpg_envs.grid.primitive_specs import MOVE, PUSH
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.simulation.families import FAMILY_SEED_RANGES
from mpg_envs.simulation.objects import ObjectAsset, load_object_set

ARRAYS = ("color", "depth", "query_color", "query_depth", "label", "visible_fraction", "source", "seed")
"""What a shard holds, one row per sample."""


@dataclass(frozen=True)
class SampleSource:
    """Episodes of one env recipe: ``env_id`` in exemplar mode with ``kwargs``, an object count
    drawn from ``objects``, ``motions`` disturbing motions after the reset."""

    name: str
    env_id: str
    objects: tuple[int, ...]
    motions: int
    share: float
    kwargs: Mapping[str, Any] = field(default_factory=dict)


SOURCES: tuple[SampleSource, ...] = (
    SampleSource("stage4", "MPG-Stage4-v0", (10, 15, 20), 3, 0.25, {"visual_randomization": True}),
    SampleSource("stage5", "MPG-Stage5-v0", (10, 15), 4, 0.3, {"visual_randomization": True}),
    SampleSource("hard", "MPG-OccludedHard-v0", (15,), 6, 0.15, {"visual_randomization": True}),
    SampleSource("stage4-camera", "MPG-Stage4-v0", (10, 15, 20), 3, 0.1, {"obs_mode": "camera", "visual_randomization": True}),
    SampleSource("stage5-camera", "MPG-Stage5-v0", (10, 15), 4, 0.1, {"obs_mode": "camera", "visual_randomization": True}),
    SampleSource("hard-camera", "MPG-OccludedHard-v0", (15,), 6, 0.1, {"obs_mode": "camera", "visual_randomization": True}),
    # The ray-cast exemplar tracks show the palette's clean colours: the same recipe without randomization.
    SampleSource("stage4-clean", "MPG-Stage4-v0", (10, 15, 20), 3, 0.15),
    SampleSource("stage5-clean", "MPG-Stage5-v0", (10, 15), 4, 0.2),
    SampleSource("hard-clean", "MPG-OccludedHard-v0", (15, 30), 6, 0.15),
)
"""The training recipe: which episodes the samples come from, and in what shares. Sources are
only ever appended, with shares that keep the earlier sources' shard counts (80 shards of the
first six are the first 80 of 120), so an earlier run's shards stay valid."""


def training_objects(set_seed: int) -> list[ObjectAsset]:
    """The objects of a shard: the blocks and the procedural training families drawn with
    ``set_seed`` (a seed of the families' training split; ``ValueError`` otherwise)."""
    if set_seed not in FAMILY_SEED_RANGES["train"]:
        train = FAMILY_SEED_RANGES["train"]
        raise ValueError(
            f"set seed must lie in the families' training split [{train.start}, {train.stop - 1}], got {set_seed}"
        )
    return [*load_object_set("blocks"), *load_object_set("procedural", seed=set_seed)]


def disturbing_action(primitives: Sequence[str], depth: np.ndarray, footprint: np.ndarray, rng: np.random.Generator) -> int:
    """A move or push (those ``primitives`` allows; a move 60% of the time when both) at a
    pixel showing an object (height above 1 cm), half the time one over
    the target's ``footprint`` (where its cover lies), at a random rotation; a random pixel
    when nothing stands out."""
    tall = np.asarray(depth) > 0.01
    over = tall & (np.asarray(footprint) > 0)
    pool = over if over.any() and rng.random() < 0.5 else tall
    if not pool.any():
        pool = np.ones_like(tall)
    rows, cols = np.nonzero(pool)
    k = int(rng.integers(len(rows)))
    allowed = [p for p in (MOVE, PUSH) if p in primitives]
    primitive = allowed[0] if len(allowed) == 1 or rng.random() < 0.6 else allowed[1]
    return encode_action(primitives, primitive, int(rng.integers(NUM_ROTATIONS)), int(rows[k]), int(cols[k]))


def _labelled(env: gym.Env, obs: Mapping[str, np.ndarray]) -> tuple[np.ndarray, float, np.ndarray]:
    """The label of the env's current state: the target's top-surface pixels, its visible
    fraction and its whole footprint (from the simulator)."""
    sim, target = env.unwrapped.sim, env.unwrapped.target  # type: ignore[attr-defined]
    full, visible = sim.observe(target, env.unwrapped.num_motions, top_mask=True)  # type: ignore[attr-defined]
    if not (np.array_equal(full["depth"], obs["depth"]) and np.array_equal(full["color"], obs["color"])):
        raise RuntimeError("the simulator's view differs from the observation it labels")
    return full["top_mask"].astype(np.uint8), float(visible or 0.0), full["mask"]


def episode_samples(env: gym.Env, source: SampleSource, seed: int) -> list[dict[str, Any]]:
    """The samples of one episode of ``source`` on ``env`` (its exemplar-mode env) reset with ``seed``."""
    rng = np.random.default_rng([seed, 0x10CA7])
    obs, _ = env.reset(seed=seed)
    primitives = env.action_space.primitives  # type: ignore[attr-defined]
    samples = []
    for motion in range(source.motions + 1):
        label, visible, footprint = _labelled(env, obs)
        samples.append(
            {
                "color": obs["color"],
                "depth": obs["depth"].astype(np.float16),
                "query_color": obs["query_color"],
                "query_depth": obs["query_depth"].astype(np.float16),
                "label": label,
                "visible_fraction": np.float32(visible),
                "seed": np.int64(seed),
            }
        )
        if motion == source.motions:
            break
        obs, _, terminated, truncated, _ = env.step(disturbing_action(primitives, obs["depth"], footprint, rng))
        if terminated or truncated:
            break
    return samples


def source_env(source: SampleSource, objects: str | Sequence[Any], num_objects: int) -> gym.Env:
    """``source``'s env in exemplar mode on ``objects`` (a set's name or assets) with ``num_objects`` objects."""
    object_set = objects if isinstance(objects, str) else list(objects)
    return gym.make(source.env_id, target_spec="exemplar", object_set=object_set, num_objects=num_objects, **source.kwargs)


TUNING_SEEDS = range(700000, 1000000)
"""Seeds the tuning samples come from (the threshold's calibration and the model card's tuning figures)."""


def shard_plan(
    shards: int, episodes_per_shard: int, run_seed: int, tuning: bool = False
) -> list[tuple[int, SampleSource, list[int]]]:
    """``(shard, source, episode seeds)`` of each shard, sources in their shares. Training seeds
    are the run's own, ``run_seed * 1,000,003 + k`` (as the training pipeline's); with
    ``tuning`` they are :data:`TUNING_SEEDS` from their start. Raises ``ValueError`` when a
    training seed would fall among the test or tuning seeds (500000-999999)."""
    if shards < 1 or episodes_per_shard < 1:
        raise ValueError(f"shards and episodes per shard must be positive, got {shards} and {episodes_per_shard}")
    first = TUNING_SEEDS.start if tuning else run_seed * 1_000_003
    last = first + shards * episodes_per_shard - 1
    if not tuning and (run_seed < 0 or (first <= 999999 and last >= 500000)):
        raise ValueError(
            f"run seed {run_seed} gives training seeds {first}..{last}, which meet the test and tuning seeds "
            "(500000-999999): use a run seed of 1 or more, or fewer samples"
        )
    weights = [Fraction(str(s.share)) for s in SOURCES]  # exact: no share loses a shard to rounding
    counts = [math.floor(w * shards / sum(weights)) for w in weights]
    counts[weights.index(max(weights))] += shards - sum(counts)
    plan, index = [], 0
    for source, count in zip(SOURCES, counts):
        for _ in range(count):
            plan.append((index, source, [first + index * episodes_per_shard + k for k in range(episodes_per_shard)]))
            index += 1
    return plan


def write_shard(path: Path, samples: Sequence[Mapping[str, Any]], source_index: int, skipped: Sequence[int] = ()) -> None:
    """``samples`` as one compressed ``.npz`` at ``path``, written whole, with the ``skipped_seeds``
    whose scene could not be made."""
    arrays = {key: np.stack([s[key] for s in samples]) for key in ARRAYS if key != "source"}
    arrays["source"] = np.full(len(samples), source_index, np.int16)
    arrays["skipped_seeds"] = np.asarray(skipped, np.int64)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, allow_pickle=False, **arrays)
    os.replace(tmp, path)


def collect_shard(folder: Path, shard: int, source: SampleSource, seeds: Sequence[int], set_seed: int) -> Path:
    """Collect one shard into ``folder`` (skipped when its file is there) and return its path; a
    seed whose scene the generator cannot make is left out and named in the shard's
    ``skipped_seeds``;
    its objects are :func:`training_objects` with ``set_seed``, its object count drawn from
    ``source.objects`` by the shard's index."""
    path = folder / f"shard_{shard:04d}.npz"
    if path.is_file():
        return path
    objects = training_objects(set_seed)
    num_objects = int(np.random.default_rng([shard, set_seed]).choice(source.objects))
    env = source_env(source, objects, num_objects)
    samples, skipped = [], []
    try:
        for seed in seeds:
            try:
                samples.extend(episode_samples(env, source, seed))
            except InvalidSceneError:  # the generator found no valid scene for this seed: kept on record
                skipped.append(seed)
    finally:
        env.close()
    if not samples:
        raise RuntimeError(f"shard {shard} ({source.name}): no seed of {list(seeds)} gave a valid scene")
    write_shard(path, samples, SOURCES.index(source), skipped)
    return path


def sample_observation(sample: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """One sample's arrays (a record of :func:`episode_samples`, or a row of the shards' arrays)
    as the exemplar-mode observation it was recorded from (heights back to float32)."""
    return {
        "color": np.asarray(sample["color"]),
        "depth": np.asarray(sample["depth"], np.float32),
        "query_color": np.asarray(sample["query_color"]),
        "query_depth": np.asarray(sample["query_depth"], np.float32),
    }


def read_shards(paths: Sequence[Path]) -> dict[str, np.ndarray]:
    """The samples of ``paths`` concatenated (arrays of :data:`ARRAYS`)."""
    loaded = [dict(np.load(p)) for p in paths]
    if not loaded:
        raise ValueError("no sample shards to read")
    return {key: np.concatenate([d[key] for d in loaded]) for key in ARRAYS}
