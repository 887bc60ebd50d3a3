"""Per-motion records of an evaluation and their counts by primitive, cover and visibility."""

from __future__ import annotations

import json
from dataclasses import asdict

import pytest

from mpg_agents.evaluation.motion_log import (
    MotionRecord,
    VisibilityCount,
    motions_by_visibility,
    visibility_table,
)
from mpg_envs.perception.occlusion import VISIBILITY_BAND_LABELS


def test_a_record_takes_the_step_info_and_the_visibility_it_started_from():
    info = {"primitive": "grasp", "occluded_before": True, "target_grasped": True, "wrong_grasp": False, "visible_fraction": None}
    record = MotionRecord.from_info(info, visible_before=0.25)
    assert record == MotionRecord("grasp", True, 0.25, True, False)
    # an env that reports neither cover nor visibility leaves them unknown
    assert MotionRecord.from_info({"primitive": "push"}, None) == MotionRecord("push", None, None)


def test_a_record_survives_json_and_bad_ones_are_named():
    record = MotionRecord("move", True, 0.05)
    assert MotionRecord.from_dict(json.loads(json.dumps(asdict(record)))) == record
    with pytest.raises(ValueError, match="visible_before"):
        MotionRecord.from_dict({"primitive": "push", "covered_before": True})
    with pytest.raises(ValueError, match="'lift'"):
        MotionRecord.from_dict({"primitive": "lift", "covered_before": True, "visible_before": 0.5})


def test_counts_by_primitive_cover_and_band():
    steps = [
        MotionRecord("push", True, 0.2),
        MotionRecord("push", True, 0.25),
        MotionRecord("push", True, 0.7),
        MotionRecord("grasp", True, 0.05, target_grasped=True),
        MotionRecord("grasp", False, 1.0, target_grasped=False, wrong_grasp=True),
        MotionRecord("grasp", False, 0.95, target_grasped=True),
        MotionRecord("move", True, None),  # unknown visibility: left out
    ]
    counts = motions_by_visibility(steps)
    assert counts == {
        ("push", True, "0.1-0.3"): VisibilityCount(2),
        ("push", True, "0.6-1"): VisibilityCount(1),
        ("grasp", True, "0-0.1"): VisibilityCount(1, 1, 0),
        ("grasp", False, "0.6-1"): VisibilityCount(2, 1, 1),
    }
    # primitive order of the action space (move, push, grasp), covered first, bands low to high
    assert list(counts) == [("push", True, "0.1-0.3"), ("push", True, "0.6-1"), ("grasp", True, "0-0.1"), ("grasp", False, "0.6-1")]
    with pytest.raises(ValueError, match="visible fraction"):
        motions_by_visibility([MotionRecord("push", True, 1.5)])


def test_the_table_has_a_row_per_primitive_and_cover_and_rates_per_episode():
    counts = motions_by_visibility(
        [MotionRecord("push", True, 0.2), MotionRecord("push", True, 0.5), MotionRecord("grasp", False, 0.9, target_grasped=True)]
    )
    lines = visibility_table(counts, episodes=4).splitlines()
    assert lines[0] == "| motion | target | " + " | ".join(f"visible {b}" for b in VISIBILITY_BAND_LABELS) + " | per episode |"
    assert lines[2] == "| push | covered | . | 1 | 1 | . | 0.50 |"
    assert lines[3] == "| grasp | uncovered | . | . | . | 1 (target 1) | 0.25 |"
    assert len(lines) == 4
    with pytest.raises(ValueError, match="episodes"):
        visibility_table(counts, episodes=0)


def test_motion_records_come_back_from_an_eval_file(tmp_path):
    from mpg_agents.evaluation.eval_result import EpisodeRecord
    from mpg_agents.evaluation.evaluate import summarise
    from mpg_agents.evaluation.table_runs import merged_result

    steps = (MotionRecord("push", True, 0.2), MotionRecord("grasp", False, 0.9, target_grasped=True))
    records = [
        EpisodeRecord(i, 100 + i, True, 2, "target_grasped", {"move": 0, "push": 1, "grasp": 1}, 1, 1, 0, 14, 0.2, steps=steps)
        for i in range(2)
    ]
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(summarise(records, "p", "MPG-OccludedHard-v0", 15, 100, 1.0).to_dict()))
    assert [r.steps for r in merged_result([path]).records] == [steps, steps]


def test_uncovering_outcomes_count_covered_moves_and_pushes_by_what_the_next_motion_met():
    from mpg_agents.evaluation.motion_log import uncovering_outcomes

    episodes = [
        # push frees it, then a grasp: 1 of 1
        [MotionRecord("push", True, 0.2), MotionRecord("grasp", False, 0.9, target_grasped=True)],
        # move leaves it covered, push frees it, the last push has no next motion: 1 of 2
        [MotionRecord("move", True, 0.1), MotionRecord("push", True, 0.3), MotionRecord("push", False, 1.0), MotionRecord("push", True, 0.2)],
        # a grasp on a covered target and an unreported cover count for nothing
        [MotionRecord("grasp", True, 0.2), MotionRecord("push", True, 0.2), MotionRecord("grasp", None, None)],
        [],
    ]
    assert uncovering_outcomes(episodes) == (2, 3)


def test_the_script_prints_a_file_table_and_refuses_files_without_motion_records(tmp_path, benchmark_script, capsys):
    from mpg_agents.evaluation.eval_result import EpisodeRecord
    from mpg_agents.evaluation.evaluate import summarise

    script = benchmark_script("visibility_steps")
    steps = (MotionRecord("push", True, 0.2), MotionRecord("grasp", False, 0.9, target_grasped=True))
    record = EpisodeRecord(0, 7, True, 2, "target_grasped", {"move": 0, "push": 1, "grasp": 1}, 1, 1, 0, 14, 0.2, steps=steps)
    data = summarise([record], "p", "MPG-OccludedHard-v0", 15, 7, 1.0).to_dict()
    good, old = tmp_path / "good.json", tmp_path / "old.json"
    good.write_text(json.dumps(data))
    for r in data["records"]:
        del r["steps"]
    old.write_text(json.dumps(data))
    assert script.main([str(good)]) == 0
    out = capsys.readouterr().out
    assert "| push | covered | . | 1 | . | . | 1.00 |" in out
    assert "left it uncovered: 1 of 1 (100%)" in out
    assert script.main([str(good), str(old)]) == 2
    assert "old.json has no per-motion records" in capsys.readouterr().err
