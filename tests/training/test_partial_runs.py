"""Evaluations that fail part-way keep what finished: the table and the JSON of the episodes (or
case runs) that ended, a record of which seeds failed and why, one line on stderr, exit status 1.
Case folders are checked whole before any run, and a run's own result file among them is no case."""

from __future__ import annotations

import json
import shutil

import pytest

from mpg_agents.cli import eval_main
from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import summarise
from mpg_agents.evaluation.failures import EpisodeFailure, NothingFinished, describe_failures, failures_line
from mpg_envs.scenes.cases import challenge_dir
from mpg_envs.scenes.generators import InvalidSceneError
from mpg_envs.tasks.env import MPGEnv

NO_SCENE = "MPG-Stage2-v0: no valid scene of 10 objects in 20 draws"


@pytest.fixture
def failing_seeds(monkeypatch):
    """``failing_seeds(*seeds)``: resets with these seeds raise as a band no scene meets does."""

    def fail_on(*seeds):
        reset = MPGEnv.reset

        def flaky(self, *, seed=None, options=None):
            if seed in seeds:
                raise InvalidSceneError(NO_SCENE)
            return reset(self, seed=seed, options=options)

        monkeypatch.setattr(MPGEnv, "reset", flaky)

    return fail_on


def record(index: int) -> EpisodeRecord:
    return EpisodeRecord(index, index, True, 2, "target_grasped", {"move": 1, "push": 0, "grasp": 1}, 1, 1, 0, 0)


def test_summarise_keeps_the_failures_beside_the_records():
    failure = EpisodeFailure.of(InvalidSceneError(NO_SCENE + "\nmore"), 1, 101)
    result = summarise([record(0), record(2)], "p", "MPG-Stage2-v0", 10, 100, 1.0, failures=[failure])
    assert (result.episodes, result.task_success_rate, result.average_motions) == (2, 1.0, 2.0)
    assert result.to_dict()["failures"] == [{"index": 1, "seed": 101, "error": "InvalidSceneError", "message": NO_SCENE}]
    assert "2 (seeds 100..102; 1 more failed, left out)" in result.table()
    assert result.failures_line() == f"1 of 3 episodes failed (2 finished and kept): seed 101: InvalidSceneError: {NO_SCENE}"
    with pytest.raises(ValueError, match=r"episodes 0\.\.2 once each, got indices \[0, 1, 1\]"):
        summarise([record(0), record(1)], "p", "e", 10, 100, 1.0, failures=[failure])
    with pytest.raises(NothingFinished, match=rf"all 1 episodes failed: seed 101: InvalidSceneError: {NO_SCENE}$"):
        summarise([], "p", "e", 10, 100, 1.0, failures=[failure])


def test_the_same_error_is_told_once():
    same = [EpisodeFailure(0, 5, "E", "m"), EpisodeFailure(2, 7, "E", "m"), EpisodeFailure(0, 1000, "F", "n", "tower")]
    assert describe_failures(same) == "seeds 5, 7: E: m; case 'tower' run 0 (seed 1000): F: n"
    assert failures_line([], 3) == ""


def test_mpg_eval_keeps_the_episodes_before_and_after_a_failed_one(tmp_path, capsys, failing_seeds):
    failing_seeds(1)
    out = tmp_path / "out.json"
    argv = ["--policy", "random", "--env", "MPG-Stage2-v0", "--num-objects", "2", "--episodes", "3", "--env-option", "max_motions=1", "--json", str(out)]
    assert eval_main(argv) == 1
    captured = capsys.readouterr()
    assert "episodes                  2 (seeds 0..2; 1 more failed, left out)" in captured.out
    assert f"seed 1: InvalidSceneError: {NO_SCENE}" in captured.out and "metrics written to" in captured.out
    assert captured.err == f"error: 1 of 3 episodes failed (2 finished and kept): seed 1: InvalidSceneError: {NO_SCENE}\n"
    data = json.loads(out.read_text())
    assert [r["seed"] for r in data["records"]] == [0, 2] and data["episodes"] == 2
    assert data["failures"] == [{"index": 1, "seed": 1, "error": "InvalidSceneError", "message": NO_SCENE}]


def test_mpg_eval_with_every_episode_failed_says_so_in_one_line(tmp_path, capsys, failing_seeds):
    failing_seeds(0, 1)
    out = tmp_path / "out.json"
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "2", "--json", str(out)]) == 1
    assert capsys.readouterr().err == f"error: all 2 episodes failed: seeds 0, 1: InvalidSceneError: {NO_SCENE}\n"
    assert not out.exists()


# ------------------------------------------------------------------------------ case folders
@pytest.fixture
def cases(tmp_path):
    """A folder of two challenge scenes the pixel heuristic ends at once (the block on top is lifted)."""
    folder = tmp_path / "cases"
    folder.mkdir()
    for name in ("tower", "bridge"):
        shutil.copy(challenge_dir() / f"{name}.json", folder / f"{name}.json")
    return folder


def run_cases(folder, *extra):
    return eval_main(["--policy", "pixel-heuristic", "--cases", str(folder), "--env-option", "max_motions=1", *extra])


def test_a_bad_scene_in_a_case_folder_is_named_before_any_run(cases, capsys):
    doc = json.loads((cases / "tower.json").read_text())
    doc["objects"][1]["position"] = doc["objects"][0]["position"]  # on top of each other
    (cases / "z-inside.json").write_text(json.dumps(doc))
    (cases / "z-notes.json").write_text('{"what": "not a scene"}')
    assert run_cases(cases) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # no run started
    err = captured.err.strip()
    assert len(err.splitlines()) == 1
    assert err.startswith("error: case set 'cases': 2 of 4 cases cannot be loaded, nothing was run: case 'z-inside': ")
    assert "objects interpenetrate: object 0" in err and f"case 'z-notes': scene file '{cases / 'z-notes.json'}': not an mpg-scene v1 file" in err


def test_a_result_written_into_the_case_folder_is_not_read_as_a_case(cases, capsys):
    out = cases / "result.json"
    for _ in range(2):  # the second run finds the first one's result among the scenes
        assert run_cases(cases, "--json", str(out), "--quiet") == 0
        assert [row["case"] for row in json.loads(out.read_text())["rows"]] == ["bridge", "tower"]
    scene = (cases / "tower.json").read_text()
    assert run_cases(cases, "--json", str(cases / "tower.json")) == 2
    assert "is the scene file of case 'tower': the result would overwrite it" in capsys.readouterr().err
    assert (cases / "tower.json").read_text() == scene


def test_a_case_run_that_fails_is_kept_as_a_failure(cases, tmp_path, capsys, failing_seeds):
    failing_seeds(1000)  # case 1 ('tower'), run 0
    out = tmp_path / "result.json"
    assert run_cases(cases, "--json", str(out), "--quiet") == 1
    captured = capsys.readouterr()
    assert f"failed: case 'tower' run 0 (seed 1000): InvalidSceneError: {NO_SCENE}" in captured.out
    assert captured.err == f"error: 1 of 2 case runs failed (1 finished and kept): case 'tower' run 0 (seed 1000): InvalidSceneError: {NO_SCENE}\n"
    data = json.loads(out.read_text())
    assert [row["case"] for row in data["rows"]] == ["bridge"] and list(data["records"]) == ["bridge"]
    assert data["failures"] == [{"index": 0, "seed": 1000, "error": "InvalidSceneError", "message": NO_SCENE, "case": "tower"}]
