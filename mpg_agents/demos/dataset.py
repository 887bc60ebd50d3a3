"""Recorded episodes as a Minari dataset on disk, read back without a network.

A dataset is a folder ``DIR`` holding Minari's ``DIR/data`` (``metadata.json`` and the
episodes). :class:`DemoWriter` creates it and appends :class:`~mpg_agents.demos.recording.RecordedEpisode`
records in order: observations stored losslessly (Minari's JPEG encoding of colour images is
turned off), each episode's reset seed and options, the env's spec (so
``dataset.recover_environment()`` makes the same env: the MPG ids are registered with their
entry point), the infos as fixed columns (:mod:`mpg_agents.demos.step_info`) and per episode the
policy's name, success, end reason and motions. The dataset's own metadata carries, under
``"mpg"``, the env id and keywords, the policy, the seeds, the package and MuJoCo versions, and
the action space's primitives in order (``mpg_envs.grid.actions.decode_action(primitives, a)``
turns a flat action into ``(primitive, rotation, row, col)`` without making the env).

:func:`load_demos` opens ``DIR`` as a ``minari.MinariDataset``; with
``MINARI_DATASETS_PATH=ROOT`` and ``DIR = ROOT/<dataset id>``, ``minari.load_dataset(id)`` finds
the same dataset. :func:`dataset_digest` hashes the content (not the file bytes), and
:func:`replay_episode` steps an episode's actions again in the recovered env.

Minari is an optional extra (``pip install "mpg-grasp[demos]"``).
"""

from __future__ import annotations

import hashlib
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import mpg_envs
from mpg_agents.demos.recording import DemoJob, RecordedEpisode
from mpg_agents.demos.step_info import FIELD_NAMES
from mpg_envs.simulation.mujoco_version import mujoco_major, running_mujoco

FORMATS = ("parquet", "hdf5", "arrow")
"""Minari's storage backends: Parquet (compressed, lossless; the default), HDF5 and Arrow
(neither compressed)."""

DATA = "data"
"""The sub-folder of a dataset folder that Minari reads."""

DIGESTED_METADATA = (
    "algorithm_name",
    "env_spec",
    "observation_space",
    "action_space",
    "data_format",
    "jpeg_encoding",
    "total_episodes",
    "total_steps",
    "mpg",
)
"""The dataset metadata :func:`dataset_digest` covers (not the id, which names where it is kept, nor
the size on disk or Minari's version)."""

_DATASET_ID = re.compile(r"^(?:[-_\w][-_\w/]*[-_\w]+/)?[-_\w]+?-v\d+$")


def _minari() -> Any:
    try:
        import minari  # noqa: PLC0415  (optional extra: the demos)
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError('recording or reading demonstrations needs Minari: pip install "mpg-grasp[demos]"') from exc
    return minari


def check_dataset_id(dataset_id: str) -> str:
    """A Minari dataset id, ``(namespace/)name-vN`` (Minari reads the version of every dataset
    it opens); a ``ValueError`` naming the form otherwise."""
    if not isinstance(dataset_id, str) or not _DATASET_ID.fullmatch(dataset_id):
        raise ValueError(
            f"dataset id {dataset_id!r} is not of Minari's form (namespace/)name-vN, e.g. mpg/hard15-oracle-v0: "
            "letters, digits, '-' and '_', the namespace's parts separated by '/', a version at the end"
        )
    return dataset_id


def default_dataset_id(folder: str | Path) -> str:
    """The id a dataset in ``folder`` gets by default: the folder's name, ``-v0`` added when it
    does not end with a version (``runs/hard15`` -> ``hard15-v0``)."""
    name = Path(folder).resolve().name
    return name if re.search(r"-v\d+$", name) else f"{name}-v0"


def check_new_folder(path: str | Path) -> Path:
    """``path`` as a folder a new dataset may be written to: absent or empty, its parent a folder.

    Raises:
        ValueError: ``path`` is a file, or a folder that holds anything (a dataset or not).
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"--out {str(path)!r} is a file; give a folder for the dataset")
    if path.is_dir() and any(path.iterdir()):
        held = "a dataset" if (path / DATA / "metadata.json").is_file() else "files"
        raise ValueError(f"--out {str(path)!r} already holds {held}; give a new or empty folder")
    if not path.parent.is_dir():
        raise ValueError(f"--out {str(path)!r}: its parent folder {str(path.parent)!r} does not exist")
    return path


def _requirements() -> list[str]:
    """What recovering the env needs: this package's version, MuJoCo's major version."""
    major = mujoco_major(running_mujoco())
    return [f"mpg-grasp=={mpg_envs.__version__}", f"mujoco>={major}.0,<{major + 1}"]


class DemoWriter:
    """A new Minari dataset in ``folder`` for ``env``'s episodes, filled by :meth:`add`.

    Args:
        folder: the dataset folder (absent or empty; :func:`check_new_folder`).
        env: the env the episodes come from (its spaces and spec are recorded).
        job: what is recorded (kept in the metadata under ``"mpg"``).
        dataset_id: the dataset's Minari id (default: the folder's name, with ``-v0`` added
            when it has no version).
        data_format: one of :data:`FORMATS`.
    """

    def __init__(
        self,
        folder: str | Path,
        env: gym.Env,
        job: DemoJob,
        dataset_id: str | None = None,
        data_format: str = "parquet",
    ):
        if data_format not in FORMATS:
            raise ValueError(f"data format {data_format!r} is not one of {FORMATS}")
        self.folder = check_new_folder(folder)
        self.dataset_id = check_dataset_id(default_dataset_id(self.folder) if dataset_id is None else dataset_id)
        minari = _minari()
        from minari.dataset.minari_storage import MinariStorage  # noqa: PLC0415  (optional extra)

        if env.spec is None:
            raise ValueError("the env has no spec (it was not made by gym.make): a dataset could not recover it")
        self.folder.mkdir(exist_ok=True)
        self.storage = MinariStorage.new(
            self.folder / DATA,
            observation_space=env.observation_space,
            action_space=env.action_space,
            env_spec=env.spec,
            data_format=data_format,
            jpeg_encoding=False,
        )
        self.storage.update_metadata(
            {
                "dataset_id": self.dataset_id,
                "minari_version": minari.__version__,
                "algorithm_name": job.policy,
                "description": f"{job.policy} on {job.env_id}: {job.episodes} episodes, reset seeds "
                f"{job.seed}..{job.seed + job.episodes - 1} "
                "(mpg-demos); infos as the columns named in mpg.info_fields, row 0 the reset's",
                "requirements": _requirements(),
                "mpg": job_record(job, env),
            }
        )
        self.episodes = 0

    @classmethod
    def continuing(cls, folder: str | Path, storage: Any, dataset_id: str, episodes: int) -> DemoWriter:
        """A writer appending to the dataset in ``folder`` (Minari's open ``storage``, id
        ``dataset_id``) after its first ``episodes`` episodes; :func:`mpg_agents.demos.resume.resume_writer`
        checks that they are this recording's."""
        writer = cls.__new__(cls)
        writer.folder, writer.dataset_id, writer.storage, writer.episodes = Path(folder), dataset_id, storage, episodes
        return writer

    def add(self, episode: RecordedEpisode) -> None:
        """Append ``episode``, the next one in order (its ``index`` must be the count so far).

        Raises:
            ValueError: an episode out of order.
        """
        if episode.index != self.episodes:
            raise ValueError(f"episodes are written in order: expected episode {self.episodes}, got {episode.index}")
        from minari.data_collector.episode_buffer import EpisodeBuffer  # noqa: PLC0415  (optional extra)

        buffer = EpisodeBuffer(
            id=episode.index,
            seed=episode.seed,
            options=episode.options,
            observations=episode.observations,
            actions=episode.actions,
            rewards=list(episode.rewards),
            terminations=list(episode.terminations),
            truncations=list(episode.truncations),
            infos=episode.infos,
        )
        self.storage.update_episodes([buffer])
        self.storage.update_episode_metadata([episode.summary()], [episode.index])
        if self.episodes == 0:
            self.storage.update_metadata({"algorithm_name": episode.policy})
        self.episodes += 1

    def size_bytes(self) -> int:
        """Bytes the dataset takes on disk now."""
        return sum(p.stat().st_size for p in (self.folder / DATA).rglob("*") if p.is_file())

    def metadata_bytes(self) -> int:
        """Bytes of Minari's ``metadata.json`` (a fixed cost: it spells out the observation
        space's bounds, a number per pixel)."""
        return (self.folder / DATA / "metadata.json").stat().st_size


def job_record(job: DemoJob, env: gym.Env) -> dict[str, Any]:
    """What a dataset keeps of its recording under ``"mpg"`` (JSON-ready): env id and keywords,
    policy, seeds, episodes, reset options, info columns, primitives, package and MuJoCo versions."""
    return {
        "env_id": job.env_id,
        "env_kwargs": _json_ready(dict(job.env_kwargs)),
        "policy": job.policy,
        "policy_kwargs": _json_ready(dict(job.policy_kwargs)),
        "seed": job.seed,
        "episodes": job.episodes,
        "reset_options": _json_ready(job.options()),
        "info_fields": list(FIELD_NAMES),
        "action_primitives": list(mpg_envs.env_primitives(env)),
        "package_version": str(mpg_envs.__version__),
        "mujoco": running_mujoco(),
    }


def _json_ready(value: Any) -> Any:
    """Tuples as lists, other non-JSON values by ``repr``, for the metadata."""
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v) for v in value]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)


def data_path(folder: str | Path) -> Path:
    """Minari's data folder of a dataset folder (``folder/data``; ``folder`` itself when it is one).

    Raises:
        FileNotFoundError: neither holds a Minari ``metadata.json``.
    """
    folder = Path(folder)
    for candidate in (folder / DATA, folder):
        if (candidate / "metadata.json").is_file():
            return candidate
    raise FileNotFoundError(f"{str(folder)!r} holds no Minari dataset (no {DATA}/metadata.json)")


def load_demos(folder: str | Path) -> Any:
    """The dataset in ``folder`` as a ``minari.MinariDataset`` (read from disk, no network)."""
    return _minari().MinariDataset(data_path(folder))


def _digest_value(h: Any, value: Any) -> None:
    """Feed ``value`` (arrays, dicts, lists, scalars, text) into hash ``h``, with its structure."""
    if isinstance(value, Mapping):
        h.update(b"{")
        for key in sorted(value):
            h.update(str(key).encode() + b":")
            _digest_value(h, value[key])
        h.update(b"}")
        return
    array = np.asarray(value)
    if array.dtype.kind in "OSU":  # text (HDF5 gives bytes, Arrow str): as str
        h.update(json.dumps([v.decode() if isinstance(v, bytes) else str(v) for v in array.reshape(-1).tolist()]).encode())
    else:
        h.update(f"{array.dtype.str}{array.shape}".encode())
        h.update(np.ascontiguousarray(array).tobytes())


def dataset_digest(folder: str | Path) -> str:
    """SHA-256 of a dataset's content: :data:`DIGESTED_METADATA`, every episode's metadata
    (seed, options, summary) and arrays (observations, actions, rewards, end flags, infos).
    Two recordings with the same data give the same digest whatever their files' timestamps."""
    dataset = load_demos(folder)
    storage = dataset.storage
    h = hashlib.sha256()
    raw = json.loads((storage.data_path / "metadata.json").read_text())
    h.update(json.dumps({k: raw.get(k) for k in DIGESTED_METADATA}, sort_keys=True).encode())
    indices = range(storage.total_episodes)
    for metadata, episode in zip(storage.get_episode_metadata(indices), storage.get_episodes(indices)):
        h.update(json.dumps(_json_ready(dict(metadata)), sort_keys=True, default=str).encode())
        _digest_value(h, {k: v for k, v in episode.items() if k != "id"})
    return h.hexdigest()


@dataclass(frozen=True)
class Replay:
    """An episode stepped again: the recorded and replayed rewards, and whether every replayed
    observation equals the recorded one."""

    recorded_rewards: np.ndarray
    replayed_rewards: np.ndarray
    observations_equal: bool

    @property
    def matches(self) -> bool:
        """Same rewards and observations."""
        return self.observations_equal and np.array_equal(self.recorded_rewards, self.replayed_rewards)


def _equal(a: Any, b: Any) -> bool:
    if isinstance(a, Mapping):
        return set(a) == set(b) and all(_equal(a[k], b[k]) for k in a)
    return np.array_equal(np.asarray(a), np.asarray(b), equal_nan=np.asarray(a).dtype.kind == "f")


def replay_episode(dataset: Any, index: int = 0, env: gym.Env | None = None) -> Replay:
    """Reset ``env`` (default: ``dataset.recover_environment()``) with episode ``index``'s
    recorded seed and options, step its recorded actions and compare rewards and observations."""
    storage = dataset.storage
    if not 0 <= index < storage.total_episodes:
        raise ValueError(f"episode {index} is not in the dataset (0..{storage.total_episodes - 1})")
    metadata = next(iter(storage.get_episode_metadata([index])))
    episode = dataset[index]
    own = env is None
    env = dataset.recover_environment() if env is None else env
    try:
        obs, _ = env.reset(seed=metadata.get("seed"), options=metadata.get("options") or None)
        same = _equal(obs, _at(episode.observations, 0))
        rewards = []
        for t, action in enumerate(np.asarray(episode.actions)):
            obs, reward, *_ = env.step(action)
            rewards.append(float(reward))
            same = same and _equal(obs, _at(episode.observations, t + 1))
    finally:
        if own:
            env.close()
    return Replay(
        np.asarray(episode.rewards, dtype=np.float64),
        np.asarray(rewards, dtype=np.float64),
        bool(same),
    )


def _at(observations: Any, t: int) -> Any:
    if isinstance(observations, Mapping):
        return {k: v[t] for k, v in observations.items()}
    return observations[t]
