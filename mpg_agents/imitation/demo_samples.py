"""The samples behaviour cloning learns from: every (observation, flat action) pair of the first
N episodes of a Minari dataset made by ``mpg-demos`` (:mod:`mpg_agents.demos.dataset`).

An episode of ``T`` steps gives ``T`` samples: the observation before each step and the action
the recorded policy took there (the last observation, after the episode's end, has none). The
samples are read once into memory, the observations as the env returned them (colour and mask
as bytes, depth as float32: about 0.2 MB per sample without the colour, 0.4 MB with it), so a
batch is an index into arrays. :class:`DemoSource` says where they come from: the dataset
folder, its id and content digest (:func:`~mpg_agents.demos.dataset.dataset_digest`), the env
and the policy recorded, and how many episodes were taken of how many.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpg_agents.demos.dataset import data_path, dataset_digest, load_demos
from mpg_envs.grid.actions import HEIGHTMAP_SIZE, check_primitives
from mpg_envs.grid.workspace import NUM_ROTATIONS

OBSERVATION_KEYS: tuple[str, ...] = ("depth", "mask", "occluded")
"""The observation planes every sample keeps (``color`` too when the net reads it)."""


@dataclass(frozen=True)
class DemoSource:
    """Where a run's samples come from (recorded in its checkpoint's header)."""

    folder: str  # the dataset folder, resolved
    dataset_id: str
    digest: str  # SHA-256 of the whole dataset's content (dataset_digest)
    env_id: str
    env_kwargs: Mapping[str, Any]
    policy: str  # the recorded policy, e.g. "oracle"
    action_primitives: tuple[str, ...]
    episodes: int  # the first this many episodes were taken
    total_episodes: int  # of this many in the dataset
    samples: int  # (observation, action) pairs in those episodes

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record."""
        record = asdict(self)
        record["env_kwargs"] = dict(self.env_kwargs)
        record["action_primitives"] = list(self.action_primitives)
        return record


def _not_a_dataset(folder: Path, why: str) -> ValueError:
    return ValueError(f"--demos {str(folder)!r} is not a dataset of mpg-demos ({why}); record one with mpg-demos --out DIR")


def open_demos(folder: str | Path) -> tuple[Any, Mapping[str, Any]]:
    """The Minari dataset in ``folder`` and its ``mpg`` metadata (what ``mpg-demos`` recorded).

    Raises:
        ValueError: ``folder`` is missing, holds no Minari dataset, or one that ``mpg-demos`` did
            not write (no ``mpg`` metadata naming the env and its action primitives).
        ImportError: Minari is not installed (the ``demos`` extra).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise _not_a_dataset(folder, "no such folder")
    try:
        data_path(folder)
    except FileNotFoundError:
        raise _not_a_dataset(folder, "no data/metadata.json in it") from None
    try:
        dataset = load_demos(folder)
    except ImportError:
        raise
    except Exception as exc:  # noqa: BLE001 - Minari's own errors on a damaged dataset, named
        raise _not_a_dataset(folder, f"Minari cannot read it: {exc}") from None
    mpg = dataset.storage.metadata.get("mpg")
    if not isinstance(mpg, Mapping) or not {"env_id", "action_primitives"} <= set(mpg):
        raise _not_a_dataset(folder, "its metadata has no 'mpg' record of the env and its action primitives")
    return dataset, mpg


class DemoSamples:
    """The (observation, flat action) samples of the first ``episodes`` episodes of a dataset.

    Args:
        folder: a dataset folder written by ``mpg-demos``.
        episodes: how many of its episodes, from the first (``None``: all).
        color: keep the colour heightmaps (a net that reads colour needs them).

    Raises:
        ValueError: not a dataset of ``mpg-demos`` (:func:`open_demos`), ``episodes`` outside
            ``1..`` the episodes it holds, observations that are not MPG's heightmaps, actions
            outside the env's action space, or no step at all in those episodes.
    """

    def __init__(self, folder: str | Path, episodes: int | None = None, color: bool = False) -> None:
        folder = Path(folder)
        dataset, mpg = open_demos(folder)
        total = int(dataset.total_episodes)
        if episodes is None:
            episodes = total
        if isinstance(episodes, bool) or not isinstance(episodes, int) or not 1 <= episodes <= total:
            raise ValueError(
                f"--demo-episodes {episodes!r}: the dataset {str(folder)!r} holds {total} episodes; valid: 1..{total}"
            )
        primitives = check_primitives(mpg["action_primitives"])
        self.num_actions = len(primitives) * NUM_ROTATIONS * HEIGHTMAP_SIZE * HEIGHTMAP_SIZE
        keys = (("color",) if color else ()) + OBSERVATION_KEYS
        planes: dict[str, list[np.ndarray]] = {k: [] for k in keys}
        actions: list[np.ndarray] = []
        for index, episode in zip(range(episodes), dataset.iterate_episodes(range(episodes))):
            observations = episode.observations
            if not isinstance(observations, Mapping) or not set(keys) <= set(observations):
                found = sorted(observations) if isinstance(observations, Mapping) else type(observations).__name__
                raise _not_a_dataset(folder, f"episode {index}'s observations are {found}, not MPG's {list(keys)}")
            steps = len(episode.actions)
            for key in keys:
                planes[key].append(np.asarray(observations[key][:steps]))
            actions.append(np.asarray(episode.actions, dtype=np.int64).reshape(-1))
        self.actions = np.concatenate(actions)
        if self.actions.size == 0:
            raise ValueError(f"--demos {str(folder)!r}: its first {episodes} episodes hold no step; take more episodes")
        bad = self.actions[(self.actions < 0) | (self.actions >= self.num_actions)]
        if bad.size:
            raise _not_a_dataset(
                folder, f"action {int(bad[0])} lies outside {list(primitives)}' action space 0..{self.num_actions - 1}"
            )
        self.observations = {k: np.concatenate(v) for k, v in planes.items()}
        self.episode_of = np.repeat(np.arange(episodes), [len(a) for a in actions])
        self.source = DemoSource(
            folder=str(folder.resolve()),
            dataset_id=str(dataset.storage.metadata.get("dataset_id", "")),
            digest=dataset_digest(folder),
            env_id=str(mpg["env_id"]),
            env_kwargs=dict(mpg.get("env_kwargs") or {}),
            policy=str(mpg.get("policy", "")),
            action_primitives=primitives,
            episodes=episodes,
            total_episodes=total,
            samples=int(self.actions.size),
        )

    @property
    def action_primitives(self) -> tuple[str, ...]:
        """The env's primitives in its action order (what the flat actions index)."""
        return self.source.action_primitives

    def __len__(self) -> int:
        return int(self.actions.size)

    def batch(self, indices: Sequence[int] | np.ndarray) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """The observations (a batch per plane) and actions of the samples at ``indices``; without
        the colour kept, the colour planes are zeros."""
        idx = np.asarray(indices, dtype=np.int64)
        batch = {k: v[idx] for k, v in self.observations.items()}
        if "color" not in batch:  # not kept: a net without colour input never reads these planes
            batch["color"] = np.zeros((idx.size, HEIGHTMAP_SIZE, HEIGHTMAP_SIZE, 3), dtype=np.uint8)
        return batch, self.actions[idx]
