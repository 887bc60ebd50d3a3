"""mpg-demos: episodes recorded as a Minari dataset, loaded offline, replayed, and recorded again
to the same content."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

# The demos extra is installed by .ci/install: under CI a missing Minari fails, elsewhere it skips.
minari = __import__("minari") if os.environ.get("CI") else pytest.importorskip("minari")

from mpg_agents.demos.cli import main  # noqa: E402
from mpg_agents.demos.dataset import (  # noqa: E402
    check_dataset_id,
    check_new_folder,
    dataset_digest,
    default_dataset_id,
    load_demos,
    replay_episode,
)
from mpg_agents.demos.step_info import FIELD_NAMES, decode_infos  # noqa: E402
from mpg_envs.grid.actions import decode_action  # noqa: E402

COMMAND = [
    "--policy",
    "oracle",
    "--env",
    "MPG-Stage2-v0",
    "--num-objects",
    "2",
    "--episodes",
    "2",
    "--seed",
    "5",
    "--quiet",
]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("demos") / "stage2-oracle-v0"
    assert main([*COMMAND, "--out", str(out)]) == 0
    return out


def test_a_recorded_dataset_loads_offline_and_replays_to_the_same_rewards(recorded, monkeypatch):
    # minari's own loader, by id, from a local folder (it downloads only when asked to).
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(recorded.parent))
    dataset = minari.load_dataset("stage2-oracle-v0")
    assert dataset.total_episodes == 2 and dataset.storage.metadata["jpeg_encoding"] is False
    seeds = [m["seed"] for m in dataset.storage.get_episode_metadata(range(2))]
    assert seeds == [5, 6]
    episode = dataset[0]
    assert episode.observations["color"].dtype == np.uint8 and episode.observations["depth"].dtype == np.float32
    assert len(episode.observations["depth"]) == len(episode.actions) + 1
    # The per-step info the metrics read, one column per field, row 0 the reset's.
    assert set(episode.infos) == set(FIELD_NAMES)
    steps = decode_infos(episode.infos)
    assert steps[0]["visible_fraction"] is not None and steps[-1]["end_reason"] == "target_grasped"
    assert steps[-1]["target_grasped"] is True and steps[-1]["lifted"] is True
    # The recovered env, reset with the recorded seed, gives the recorded rewards and (lossless) observations.
    replay = replay_episode(dataset, 0)
    assert replay.matches, (
        replay.recorded_rewards,
        replay.replayed_rewards,
        replay.observations_equal,
    )
    assert replay.recorded_rewards.tolist() == [1.0] * len(replay.recorded_rewards)
    mpg = dataset.storage.metadata["mpg"]
    assert (mpg["env_id"], mpg["policy"], mpg["seed"], mpg["env_kwargs"]) == ("MPG-Stage2-v0", "oracle", 5, {"num_objects": 2})
    # A flat action decodes without the simulator, to the rotation and pixel the info recorded.
    first = decode_action(mpg["action_primitives"], int(episode.actions[0]))
    assert (first.primitive, first.rotation, (first.row, first.col)) == ("grasp", steps[1]["rotation"], steps[1]["pixel"])


def test_the_same_command_gives_the_same_data_on_two_workers(recorded, tmp_path):
    again = tmp_path / "again"
    assert main([*COMMAND, "--out", str(again), "--workers", "2"]) == 0
    assert dataset_digest(again) == dataset_digest(recorded)
    assert load_demos(again).storage.metadata["dataset_id"] == "again-v0"


def test_bad_input_ends_before_any_episode(tmp_path, capsys):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    cases = [
        (["--out", str(tmp_path / "full")], "already holds files"),
        (["--out", str(tmp_path / "new"), "--dataset-id", "no version"], "is not of Minari's form"),
        (["--out", str(tmp_path / "new"), "--env", "MPG-Nope-v0"], "unknown env id 'MPG-Nope-v0'"),
        (["--out", str(tmp_path / "new"), "--episodes", "0"], "--episodes must be >= 1"),
        (
            ["--out", str(tmp_path / "new"), "--policy", str(tmp_path / "missing.safetensors")],
            "does not exist",
        ),
        (["--out", str(tmp_path / "no" / "such" / "folder")], "does not exist"),
    ]
    for extra, says in cases:
        assert main([*COMMAND, *extra]) == 2
        assert says in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_dataset_ids_and_folders():
    assert default_dataset_id("runs/hard15") == "hard15-v0"
    assert default_dataset_id("runs/hard15-v3") == "hard15-v3"
    assert check_dataset_id("mpg/hard15-oracle-v0") == "mpg/hard15-oracle-v0"
    for bad in ("hard15", "mpg/", "a b-v0", "/x-v0"):
        with pytest.raises(ValueError, match="Minari's form"):
            check_dataset_id(bad)


def test_a_new_folder_is_absent_or_empty(tmp_path):
    assert check_new_folder(tmp_path / "fresh") == tmp_path / "fresh"
    (tmp_path / "empty").mkdir()
    assert check_new_folder(tmp_path / "empty") == tmp_path / "empty"
    (tmp_path / "file").write_text("")
    with pytest.raises(ValueError, match="is a file"):
        check_new_folder(tmp_path / "file")
    (tmp_path / "dataset" / "data").mkdir(parents=True)
    (tmp_path / "dataset" / "data" / "metadata.json").write_text("{}")
    with pytest.raises(ValueError, match="already holds a dataset"):
        check_new_folder(tmp_path / "dataset")


def test_a_stopped_recording_resumes_to_the_same_data(recorded, tmp_path, monkeypatch, capsys):
    import mpg_agents.demos.cli as cli

    out = tmp_path / "stopped"
    whole = cli.record_episodes

    def stops_after_one(*args, **kwargs):
        episodes = whole(*args, **kwargs)
        yield next(episodes)
        raise KeyboardInterrupt

    monkeypatch.setattr(cli, "record_episodes", stops_after_one)
    assert main([*COMMAND, "--out", str(out), "--dataset-id", "stage2-oracle-v0"]) == 130
    assert "1 of 2 episodes" in capsys.readouterr().err
    monkeypatch.setattr(cli, "record_episodes", whole)
    (out / "data" / "1").mkdir()  # an episode cut off while it was written
    (out / "data" / "1" / "part").write_text("cut off")
    assert main([*COMMAND, "--out", str(out), "--dataset-id", "stage2-oracle-v0", "--resume"]) == 0
    said = capsys.readouterr().out
    assert "episodes 0-0 are recorded, 1 to go" in said and "1 episodes (episodes 1-1; 1 recorded before)" in said
    assert dataset_digest(out) == dataset_digest(recorded)
    # Resuming a finished recording records nothing and changes nothing.
    assert main([*COMMAND, "--out", str(out), "--dataset-id", "stage2-oracle-v0", "--resume"]) == 0
    assert dataset_digest(out) == dataset_digest(recorded)


def test_resume_refuses_another_recordings_dataset(tmp_path, capsys):
    import json

    from mpg_agents.demos.dataset import job_record
    from mpg_agents.demos.recording import DemoJob
    from mpg_agents.demos.resume import resume_writer

    job = DemoJob("oracle", "MPG-Stage2-v0", 2, 5, (("num_objects", 2),))
    env = job.make_env()
    try:
        held = {"dataset_id": "stage2-oracle-v0", "data_format": "parquet", "mpg": job_record(job, env)}
        (tmp_path / "data").mkdir()
        (tmp_path / "data" / "metadata.json").write_text(json.dumps(held))
        with pytest.raises(ValueError, match="--resume works with the formats"):
            resume_writer(tmp_path, env, job, "stage2-oracle-v0", data_format="hdf5")
    finally:
        env.close()
    cases = [
        (["--seed", "6"], "its mpg is"),
        (["--num-objects", "3"], "its mpg is"),
        (["--dataset-id", "other-v0"], "its dataset_id is 'stage2-oracle-v0'"),
        (["--format", "arrow"], "its data_format is 'parquet'"),
    ]
    for extra, says in cases:
        args = [*COMMAND, "--dataset-id", "stage2-oracle-v0", *extra, "--out", str(tmp_path), "--resume"]
        assert main(args) == 2
        assert says in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "data").iterdir()) == ["metadata.json"]  # nothing written
