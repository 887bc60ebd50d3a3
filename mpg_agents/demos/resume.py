"""Continuing a recording that stopped: the complete episodes kept, the rest recorded again.

A recording writes its episodes in order, each one whole before the next starts, so a run that
was killed or interrupted leaves a dataset of its first episodes, and perhaps a last one cut
off while it was written. :func:`resume_writer` opens such a dataset for the same recording (the
same env, keywords, policy, seeds, episode count, format, id, package and MuJoCo versions),
keeps the episodes that were written whole, removes a cut-off one, and returns a
:class:`~mpg_agents.demos.dataset.DemoWriter` that appends from there. Episode ``i`` depends on
nothing but its seed ``seed + i`` (the env and the policy are reseeded for it), so the resumed
dataset is the one an uninterrupted run writes, digest for digest.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import gymnasium as gym

from mpg_agents.demos.dataset import (
    DATA,
    DemoWriter,
    check_dataset_id,
    default_dataset_id,
    job_record,
)
from mpg_agents.demos.recording import DemoJob

RESUMABLE_FORMATS = ("parquet", "arrow")
"""The formats that keep each episode in a folder of its own (HDF5 keeps one file)."""

SUMMARY_KEY = "policy"
"""A key of the summary written after an episode's arrays: an episode without it was cut off."""


def resume_writer(
    folder: str | Path, env: gym.Env, job: DemoJob, dataset_id: str | None = None, data_format: str = "parquet"
) -> DemoWriter:
    """A writer for ``job`` in ``folder``: a new dataset when ``folder`` is absent or empty, else
    the dataset this same recording started there, its whole episodes kept.

    Raises:
        ValueError: ``folder`` holds files but no dataset, a dataset of another recording (the
            first setting that differs is named), or one in a format that cannot resume.
    """
    folder = Path(folder)
    metadata_file = folder / DATA / "metadata.json"
    if not metadata_file.is_file():
        return DemoWriter(folder, env, job, dataset_id, data_format)  # refuses a folder holding other files
    dataset_id = check_dataset_id(default_dataset_id(folder) if dataset_id is None else dataset_id)
    if data_format not in RESUMABLE_FORMATS:
        raise ValueError(f"--resume works with the formats {RESUMABLE_FORMATS}, not {data_format!r}")
    held = json.loads(metadata_file.read_text())
    expected: dict[str, Any] = {"dataset_id": dataset_id, "data_format": data_format, "mpg": job_record(job, env)}
    for key, value in expected.items():
        if held.get(key) != value:
            raise ValueError(
                f"--out {str(folder)!r} holds a dataset of another recording: its {key} is {held.get(key)!r}, "
                f"this command's {value!r}"
            )
    from minari.dataset.minari_storage import MinariStorage  # noqa: PLC0415  (optional extra)

    storage = MinariStorage.read(folder / DATA)
    whole, steps = _whole_episodes(storage)
    for path in (folder / DATA).iterdir():
        if path.is_dir() and path.name.isdigit() and int(path.name) >= whole:
            shutil.rmtree(path)  # cut off while it was written
    storage.update_metadata({"total_episodes": whole, "total_steps": steps, "dataset_size": storage.get_size()})
    return DemoWriter.continuing(folder, storage, dataset_id, whole)


def _whole_episodes(storage: Any) -> tuple[int, int]:
    """How many episodes from the first are written whole, and their steps."""
    steps = 0
    for index in range(int(storage.total_episodes)):
        episode_metadata = storage.data_path / str(index) / "metadata.json"
        if not episode_metadata.is_file():
            return index, steps
        record = json.loads(episode_metadata.read_text())
        if SUMMARY_KEY not in record:
            return index, steps
        steps += int(record["total_steps"])
    return int(storage.total_episodes), steps
