"""The track table: one table over the hard tracks, cell by cell on disk (runs what is missing,
resumes from what is written, reuses checked cells of earlier runs), and its policy and reuse
files in the repository."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import summarise
from mpg_agents.evaluation.reused_cells import read_reused
from mpg_agents.evaluation.table_runs import PolicySpec, read_policy_specs
from mpg_agents.evaluation.tables import TABLE_TRACKS, cell_json, tracks_rows, tracks_success_rows
from mpg_agents.evaluation.track_cells import CellMismatchError, cell_file_name
from mpg_agents.evaluation.track_table import make_track_table

ROOT = Path(__file__).resolve().parents[2]


def _records(start: int, successes: list[bool]) -> list[EpisodeRecord]:
    return [
        EpisodeRecord(i, start + i, ok, 2, "target_grasped" if ok else "motion_cap", {"move": 0, "push": 1, "grasp": 1}, 1, int(ok), 0, 29, visible_fraction=0.05)
        for i, ok in enumerate(successes)
    ]


def _eval_file(path: Path, policy: str, start: int, successes: list[bool], env_id: str = "MPG-OccludedHard-v0", objects: int = 30) -> Path:
    path.write_text(json.dumps(summarise(_records(start, successes), policy, env_id, objects, start, 1.0).to_dict()))
    return path


def test_the_tracks_are_registered_ids_with_the_strict_columns():
    assert {name: TABLE_TRACKS[name].env_id for name in ("hard", "hard-novel", "hard-camera")} == {
        "hard": "MPG-OccludedHard-v0", "hard-novel": "MPG-OccludedHardNovel-v0", "hard-camera": "MPG-OccludedHardCamera-v0",
    }
    import gymnasium as gym

    import mpg_envs  # noqa: F401  registers the ids

    assert all(TABLE_TRACKS[name].strict_columns and TABLE_TRACKS[name].env_id in gym.registry for name in ("hard", "hard-novel", "hard-camera"))


def test_tracks_rows_show_each_track_and_policy_with_a_cell_and_dash_for_a_cell_not_run():
    cell = cell_json(summarise(_records(0, [True, True, False, True]), "oracle", "MPG-OccludedHard-v0", 15, 0, 1.0))
    cells = {("hard", "Oracle", 15): cell, ("hard-camera", "Oracle", 30): cell}
    header, body = tracks_rows(["hard", "hard-novel", "hard-camera"], ["Oracle", "Random"], [15, 30], cells)
    assert header[:4] == ["Track", "Method", "success, 15 obj.", "success, 30 obj."] and "grasp success, 30 obj." in header
    assert [row[:2] for row in body] == [["blocks (MPG-OccludedHard-v0)", "Oracle"], ["camera images of blocks (MPG-OccludedHardCamera-v0)", "Oracle"]]
    assert body[0][2].startswith("75% [") and body[0][3] == "-" and body[1][2] == "-" and body[1][4] == "-"
    assert body[0][8] == "75% of 4"  # 3 target grasps of 4 attempts
    with pytest.raises(ValueError, match="strict tracks only"):
        tracks_rows(["table1"], ["Oracle"], [15], cells)
    header, body = tracks_success_rows(["hard", "hard-novel", "hard-camera"], ["Oracle", "Random"], [15, 30], cells)
    assert header == ["Method", "blocks, 15 obj.", "camera images of blocks, 30 obj."]  # no column without a cell
    assert len(body) == 1 and body[0][0] == "Oracle" and body[0][1] == body[0][2] and body[0][1].endswith("] in 2.00")


def test_a_cell_runs_once_is_written_and_is_read_back_then_a_changed_policy_entry_is_refused(tmp_path):
    spec = PolicySpec("Random, one motion", "random")
    seen = []
    args = (["hard"], [spec], [15], 2, 500000, tmp_path)
    kwargs = {"env_options": {"max_motions": 1}, "on_cell": lambda request, how, seconds: seen.append(how)}
    episodes = []
    ran, markdown = make_track_table(*args, run=lambda request: True, workers=1, on_record=lambda job, r: episodes.append(r.seed), **kwargs)
    assert episodes == [500000, 500001]
    path = tmp_path / "hard" / "cells" / cell_file_name(spec.label, 15)
    assert path.is_file() and json.loads(path.read_text())["table_policy"] == {"label": spec.label, "policy": "random"}
    cell = ran["rows"]["hard"][spec.label]["15"]
    assert cell["episodes"] == 2 and cell["motions"] == 1.0 and cell["env_options"] == {"max_motions": 1}
    assert "| blocks (MPG-OccludedHard-v0) | Random, one motion |" in markdown and ran["missing"] == []
    read, _ = make_track_table(*args, run=None, **kwargs)  # nothing runs: the written cell is read
    assert seen == ["ran", "recorded"] and read["rows"] == ran["rows"] and read["sources"]["hard"][spec.label]["15"] == str(path)
    with pytest.raises(CellMismatchError, match="delete the file"):
        make_track_table(["hard"], [PolicySpec(spec.label, "random", (("grasp_fingers", "clear"),))], [15], 2, 500000, tmp_path, env_options={"max_motions": 1})
    with pytest.raises(CellMismatchError, match="seeds are 500000..500001"):
        make_track_table(*args[:3], 3, 500000, tmp_path, env_options={"max_motions": 1})
    with pytest.raises(CellMismatchError, match="env options"):
        make_track_table(*args)


def test_a_cell_in_blocks_keeps_each_block_resumes_at_the_first_missing_one_and_pools_as_one_run(tmp_path):
    spec = PolicySpec("Random, one motion", "random")
    args = (["hard"], [spec], [15], 5, 500000)
    whole, _ = make_track_table(*args, tmp_path / "whole", env_options={"max_motions": 1}, run=lambda request: True)
    seeds = []
    blocks, _ = make_track_table(
        *args, tmp_path / "blocks", env_options={"max_motions": 1}, run=lambda request: True, block_episodes=2,
        on_record=lambda job, r: seeds.append(r.seed),
    )
    folder = tmp_path / "blocks" / "hard" / "cells" / (Path(cell_file_name(spec.label, 15)).stem + ".blocks")
    assert sorted(p.name for p in folder.iterdir()) == ["500000.json", "500002.json", "500004.json"]
    assert seeds == list(range(500000, 500005))
    assert blocks["rows"] == whole["rows"]  # the pooled blocks are the cell run in one go
    # A stop after two blocks: the cell file and the last block are missing; only that block runs again.
    (tmp_path / "blocks" / "hard" / "cells" / cell_file_name(spec.label, 15)).unlink()
    (folder / "500004.json").unlink()
    seeds.clear()
    again, _ = make_track_table(
        *args, tmp_path / "blocks", env_options={"max_motions": 1}, run=lambda request: True, block_episodes=2,
        on_record=lambda job, r: seeds.append(r.seed),
    )
    assert seeds == [500004] and again["rows"] == whole["rows"]
    with pytest.raises(ValueError, match="block_episodes must be a positive integer"):
        make_track_table(*args, tmp_path / "x", block_episodes=0)


def test_a_cell_not_run_is_absent_and_named(tmp_path):
    report, markdown = make_track_table(["hard", "hard-camera"], [PolicySpec("Oracle", "oracle")], [15, 30], 100, 500000, tmp_path)
    assert report["rows"] == {} and len(report["missing"]) == 4
    assert markdown.splitlines()[-1] == (
        "Not run yet: blocks (MPG-OccludedHard-v0), 2 of 2 cells; camera images of blocks (MPG-OccludedHardCamera-v0), 2 of 2 cells."
    )


def test_reused_cells_are_pooled_and_checked_against_the_table(tmp_path):
    _eval_file(tmp_path / "oracle_500000.json", "oracle", 500000, [True, True])
    _eval_file(tmp_path / "oracle_500002.json", "oracle", 500002, [True, False])
    reuse = tmp_path / "reused.toml"
    reuse.write_text(f'[[cell]]\ntrack = "hard"\nlabel = "Oracle"\nobjects = 30\nevals = "{tmp_path}/oracle_*.json"\n')
    cells = read_reused(reuse)
    out = tmp_path / "out"
    report, _ = make_track_table(["hard"], [PolicySpec("Oracle", "oracle")], [30], 4, 500000, out, cells)
    cell = report["rows"]["hard"]["Oracle"]["30"]
    assert cell["episodes"] == 4 and cell["success"] == 0.75 and report["sources"]["hard"]["Oracle"]["30"].endswith("oracle_*.json")
    with pytest.raises(CellMismatchError, match="is policy 'oracle', not 'random'"):
        make_track_table(["hard"], [PolicySpec("Oracle", "random")], [30], 4, 500000, out, cells)
    with pytest.raises(CellMismatchError, match="not 500000..500004"):
        make_track_table(["hard"], [PolicySpec("Oracle", "oracle")], [30], 5, 500000, out, cells)
    with pytest.raises(ValueError, match=r"labels the policy file does not have: \['Oracle'\]"):
        make_track_table(["hard"], [PolicySpec("Random", "random")], [30], 4, 500000, out, cells)
    with pytest.raises(CellMismatchError, match="not MPG-OccludedHardCamera-v0 with 30"):
        make_track_table(["hard-camera"], [PolicySpec("Oracle", "oracle")], [30], 4, 500000, out, {("hard-camera", "Oracle", 30): cells[("hard", "Oracle", 30)]})


def test_a_reused_row_of_a_table_report_must_have_run_the_same_policy_entry(tmp_path):
    cell = cell_json(summarise(_records(500000, [True, False]), "oracle", "MPG-OccludedHard-v0", 15, 500000, 1.0))
    report = {"env": "MPG-OccludedHard-v0", "env_options": {}, "episodes": 2, "seed": 500000, "objects": [15],
              "policies": {"Oracle": {"policy": "oracle"}}, "rows": {"Oracle": {"15": cell}}}
    (tmp_path / "hard.json").write_text(json.dumps(report))
    reuse = tmp_path / "reused.toml"
    reuse.write_text(f'[[cell]]\ntrack = "hard"\nlabel = "Oracle"\nobjects = 15\ntable = "{tmp_path}/hard.json"\n')
    out = tmp_path / "out"
    got, _ = make_track_table(["hard"], [PolicySpec("Oracle", "oracle")], [15], 2, 500000, out, read_reused(reuse))
    assert got["rows"]["hard"]["Oracle"]["15"] == cell
    with pytest.raises(CellMismatchError, match="the policy file says"):
        make_track_table(["hard"], [PolicySpec("Oracle", "oracle", (("q_star", 0.5),))], [15], 2, 500000, out, read_reused(reuse))
    with pytest.raises(CellMismatchError, match="the table asks"):
        make_track_table(["hard"], [PolicySpec("Oracle", "oracle")], [15], 2, 500001, out, read_reused(reuse))


@pytest.mark.parametrize(
    "text, match",
    [
        ('[[cell]]\ntrack = "hard"\nlabel = "A"\n', "needs 'track', 'label' and 'objects'"),
        ('[[cell]]\ntrack = "easy"\nlabel = "A"\nobjects = 15\nevals = "x"\n', "unknown track 'easy'"),
        ('[[cell]]\ntrack = "hard"\nlabel = "A"\nobjects = 15\nevals = "x"\ntable = "y"\n', "give one of 'evals'"),
        ('[[cell]]\ntrack = "hard"\nlabel = "A"\nobjects = 15\nevals = "x"\nseed = 1\n', "unknown keys"),
        ('[[cell]]\ntrack = "hard"\nlabel = "A"\nobjects = 15\nevals = "x"\n' * 2, "given twice"),
        ("[[cell", "not readable TOML"),
    ],
)
def test_a_bad_reuse_file_is_refused_naming_the_entry(tmp_path, text, match):
    path = tmp_path / "reused.toml"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        read_reused(path)


def test_the_repositorys_track_policies_and_reused_blocks_cells_hold(monkeypatch):
    from mpg_agents.evaluation.policy_zoo import is_builtin

    specs = read_policy_specs(ROOT / "benchmarks" / "tracks.toml")
    assert [s.policy for s in specs][:6] == [
        "oracle", "pixel-heuristic", "random", "shipped",
        "benchmarks/checkpoints/blocks_rand_s1.safetensors", "benchmarks/checkpoints/uncover_s1.safetensors",
    ] and len(specs) == 10
    assert all(is_builtin(s.policy) or (ROOT / s.policy).is_file() for s in specs)
    reused = read_reused(ROOT / "benchmarks" / "results" / "tracks" / "reused.toml")
    # The shipped net's blocks cells and the colour-trunk nets' are cell files in tracks/hard/cells/.
    in_files = {s.label for s in specs[3:6]}
    assert set(reused) == {("hard", s.label, n) for s in specs for n in (15, 30) if s.label not in in_files}  # every other blocks cell, nothing else
    monkeypatch.chdir(ROOT)  # the reuse file's paths are the repository's
    report, _ = make_track_table(["hard"], specs, [15, 30], 100, 500000, ROOT / "benchmarks" / "results" / "tracks", reused)
    rows = report["rows"]["hard"]
    assert report["missing"] == [] and rows["MPGNet (shipped)"]["15"]["success"] == 0.99 and rows["MPGNet (shipped)"]["30"]["success"] == 0.99
    assert rows[specs[4].label]["15"]["success"] == 1.0 and rows[specs[5].label]["30"]["success"] == 0.98


def test_every_table_track_runs_on_a_registered_env_id():
    import gymnasium as gym

    import mpg_envs
    from mpg_envs.tasks.tracks import TRACKS

    assert set(TRACKS) <= set(gym.registry)
    for name, track in TABLE_TRACKS.items():
        assert track.name == name and track.env_id in gym.registry, name
        assert track.env_id in TRACKS or track.env_id in mpg_envs.ENV_IDS, name
