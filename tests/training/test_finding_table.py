"""The finding tracks of the track table and the finding table: a track's own env keywords reach
its cells, the finding columns by hand, and cells of episodes that kept no first sight show none."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import summarise
from mpg_agents.evaluation.finding_table import FINDING_COLUMNS, finding_cells_text, finding_rows
from mpg_agents.evaluation.table_runs import PolicySpec, merged_result
from mpg_agents.evaluation.tables import TABLE_TRACKS, cell_json
from mpg_agents.evaluation.track_cells import CellRequest

FINDING_TRACKS = {
    "hard-visible": ("MPG-OccludedHardVisible-v0", ()),
    "hard-novel-visible": ("MPG-OccludedHardNovel-v0", (("target_spec", "visible"),)),
    "hard-camera-visible": ("MPG-OccludedHardCamera-v0", (("target_spec", "visible"),)),
    "hard-exemplar": ("MPG-OccludedHardExemplar-v0", ()),
    "hard-novel-exemplar": ("MPG-OccludedHardNovelExemplar-v0", ()),
    "hard-camera-exemplar": ("MPG-OccludedHardCameraExemplar-v0", ()),
}


def _records(
    first_sights: list[int | None], lookalikes: list[int | None], wrong: list[int] | None = None
) -> list[EpisodeRecord]:
    wrong = wrong or [0] * len(first_sights)
    return [
        EpisodeRecord(
            i,
            500000 + i,
            True,
            3,
            "target_grasped",
            {"move": 1, "push": 1, "grasp": 1},
            1 + w,
            1,
            w,
            14,
            visible_fraction=0.4 if sight == 0 else 0.0,
            first_sight=sight,
            lookalike_grasps=look,
        )
        for i, (sight, look, w) in enumerate(zip(first_sights, lookalikes, wrong))
    ]


def test_the_finding_tracks_are_registered_ids_with_their_keywords():
    import gymnasium as gym

    import mpg_envs  # noqa: F401  registers the ids

    for name, (env_id, options) in FINDING_TRACKS.items():
        track = TABLE_TRACKS[name]
        assert (track.env_id, track.env_options, track.strict_columns) == (env_id, options, True)
        assert env_id in gym.registry


def test_a_cell_runs_with_its_tracks_keywords_and_an_extra_one_wins():
    spec = PolicySpec("Random", "random", ())
    request = CellRequest("hard-novel-visible", spec, 15, 100, 500000)
    assert request.all_env_options == (("target_spec", "visible"),)
    assert request.recorded_env_options()["target_spec"] == "visible"
    assert request.recorded_env_options()["object_set"] == "random_urdfs_test"  # the id's own keywords stay
    wins = CellRequest("hard-novel-visible", spec, 15, 100, 500000, (("target_spec", "mask"),))
    assert wins.all_env_options == (("target_spec", "mask"),)


def test_finding_columns_by_hand():
    # 4 episodes: first sight at 0, 2, never, 0 motions (2 at reset, 3 ever, (0 + 2 + 0) / 3 = 0.67 motions);
    # mis-picks 1, 2, 0, 1 of which look-alikes 1, 0, 0, 1: 2 / 4 = 0.50 look-alike and 2 / 4 = 0.50 other per episode.
    records = _records([0, 2, None, 0], [1, 0, 0, 1], wrong=[1, 2, 0, 1])
    result = json.loads(json.dumps(cell_json(summarise(records, "matcher", "MPG-OccludedHardExemplar-v0", 15, 500000, 1.0))))
    assert finding_cells_text(result["finding"]) == ["2 of 4", "3 of 4", "0.67", "0.50", "0.50"]
    header, body = finding_rows(
        ["hard-exemplar", "hard"], ["Matcher", "Oracle"], [15, 30], {("hard-exemplar", "Matcher", 15): result}
    )
    assert header == ["Track", "Method", "objects", *FINDING_COLUMNS]
    assert body == [
        ["blocks, exemplar (MPG-OccludedHardExemplar-v0)", "Matcher", "15", "2 of 4", "3 of 4", "0.67", "0.50", "0.50"]
    ]
    with pytest.raises(ValueError, match="unknown tracks"):
        finding_rows(["hard-nowhere"], ["Matcher"], [15], {})


def test_a_cell_without_look_alike_reports_shows_n_a():
    result = summarise(_records([0, 1], [None, None]), "oracle", "MPG-OccludedHardVisible-v0", 15, 500000, 1.0)
    assert finding_cells_text(cell_json(result)["finding"]) == ["1 of 2", "2 of 2", "0.50", "n/a", "n/a"]
    assert finding_cells_text({}) == ["n/a"] * len(FINDING_COLUMNS)


def test_a_pooled_cell_of_episodes_recorded_without_first_sight_reports_no_finding(tmp_path: Path):
    new = summarise(_records([0, 1], [None, None]), "oracle", "MPG-OccludedHard-v0", 15, 500000, 1.0).to_dict()
    path = tmp_path / "new.json"
    path.write_text(json.dumps(new))
    assert merged_result([path]).finding["sighted"] == 2
    old = json.loads(json.dumps(new))
    for record in old["records"]:
        del record["first_sight"]  # as files written before first sight was kept
    path.write_text(json.dumps(old))
    assert merged_result([path]).finding["episodes"] == 0
    for record in old["records"]:
        record["first_sight"] = None  # as such files pooled and written again
    path.write_text(json.dumps(old))
    assert merged_result([path]).finding["episodes"] == 0


def test_another_tables_cell_files_are_reused_by_the_policy_entry_they_ran(tmp_path: Path):
    from mpg_agents.evaluation.reused_cells import ReusedCell
    from mpg_agents.evaluation.track_cells import CellMismatchError, write_cell_file

    result = summarise(_records([0, 0], [None, None]), "colorfree_s1.safetensors", "MPG-OccludedHard-v0", 15, 500000, 1.0)
    ran = CellRequest("hard", PolicySpec("MPGNet (shipped)", "shipped", ()), 15, 2, 500000)
    write_cell_file(ran, result, tmp_path / "shipped_15.json")
    reused = ReusedCell("hard", "MPGNet, mask", 15, evals=str(tmp_path / "shipped_15.json"))
    asked = CellRequest("hard", PolicySpec("MPGNet, mask", "shipped", ()), 15, 2, 500000)
    assert reused.load(asked)["success"] == 1.0  # the file's own name is the checkpoint's: its entry says shipped
    with pytest.raises(CellMismatchError, match="not 'random'"):
        reused.load(CellRequest("hard", PolicySpec("MPGNet, mask", "random", ()), 15, 2, 500000))


def test_a_blind_baselines_mask_cell_is_its_visible_twins_and_no_one_elses(tmp_path: Path):
    from mpg_agents.evaluation.reused_cells import ReusedCell, read_reused
    from mpg_agents.evaluation.track_cells import CellMismatchError, write_cell_file

    oracle = PolicySpec("Oracle", "oracle", ())
    for track, env_id in (("hard", "MPG-OccludedHard-v0"), ("hard-novel", "MPG-OccludedHardNovel-v0")):
        ran = CellRequest(track, oracle, 15, 2, 500000)
        records = _records([0, 1], [None, None])
        result = summarise(records, "oracle", env_id, 15, 500000, 1.0, env_options=ran.recorded_env_options())
        write_cell_file(ran, result, tmp_path / f"{track}.json")
    blocks = ReusedCell("hard-visible", "Oracle", 15, evals=str(tmp_path / "hard.json"), scenes_of="hard")
    assert blocks.load(CellRequest("hard-visible", oracle, 15, 2, 500000))["success"] == 1.0
    assert "the hard track's episodes" in blocks.source()
    novel = ReusedCell("hard-novel-visible", "Oracle", 15, evals=str(tmp_path / "hard-novel.json"), scenes_of="hard-novel")
    assert novel.load(CellRequest("hard-novel-visible", oracle, 15, 2, 500000))["success"] == 1.0
    with pytest.raises(CellMismatchError, match="may act on how the target is named"):  # the net reads the mask
        blocks.load(CellRequest("hard-visible", PolicySpec("Oracle", "shipped", ()), 15, 2, 500000))
    with pytest.raises(CellMismatchError, match="differ in more than how they name the target"):  # other scenes
        ReusedCell("hard-camera-visible", "Oracle", 15, evals=str(tmp_path / "hard.json"), scenes_of="hard").load(
            CellRequest("hard-camera-visible", oracle, 15, 2, 500000)
        )
    with pytest.raises(CellMismatchError, match="not the cell"):  # the files must be the named track's cell
        ReusedCell("hard-visible", "Oracle", 15, evals=str(tmp_path / "hard-novel.json"), scenes_of="hard").load(
            CellRequest("hard-visible", oracle, 15, 2, 500000)
        )
    bad = tmp_path / "reuse.toml"
    bad.write_text('[[cell]]\ntrack = "hard-visible"\nlabel = "Oracle"\nobjects = 15\nscenes_of = "nope"\nevals = "x"\n')
    with pytest.raises(ValueError, match="unknown scenes_of track 'nope'"):
        read_reused(bad)
