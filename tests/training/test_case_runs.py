"""A policy on a case set: one row per case, the overall row, seeds, and ``mpg-eval --cases``."""

from __future__ import annotations

import json

import pytest

from mpg_agents.evaluation.case_runs import CASE_SEED_STRIDE, CaseRow, run_case_set
from mpg_agents.cli import eval_main
from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_envs.scenes.cases import CaseSet, challenge_dir, load_cases


def record(index: int, success: bool, motions: int, grasps: int, target: int, wrong: int, reason: str, visible: float | None = None) -> EpisodeRecord:
    return EpisodeRecord(index, index, success, motions, reason, {"move": 0, "push": 0, "grasp": grasps}, grasps, target, wrong, 0, visible_fraction=visible)


def test_a_case_row_counts_successes_motions_mis_picks_and_grasp_success():
    rows = [
        record(0, True, 2, 1, 1, 0, "target_grasped", 0.25),
        record(1, False, 1, 1, 0, 1, "wrong_object", 0.5),
        record(2, True, 3, 2, 1, 0, "target_grasped", 0.0),
    ]
    row = CaseRow.of("tower", rows, "a note")
    assert (row.runs, row.successes, row.mean_motions, row.mis_picks) == (3, 2, 2.0, pytest.approx(1 / 3))
    assert (row.grasp_attempts, row.target_grasps, row.grasp_success_rate) == (4, 2, 0.5)
    assert row.end_reasons == {"target_grasped": 2, "wrong_object": 1}
    assert row.cells() == ["tower", "0.25", "2/3", "2.00", "0.33", "50% (2/4)"]
    no_grasp = CaseRow.of("x", [record(0, False, 10, 0, 0, 0, "motion_cap")])
    assert no_grasp.grasp_success_rate is None and no_grasp.cells()[-1] == no_grasp.cells()[1] == "n/a"
    with pytest.raises(ValueError, match="no runs"):
        CaseRow.of("x", [])


def test_runs_are_seeded_per_case_and_strict_by_default():
    cases = CaseSet("two", load_cases("challenge").cases[:2])
    result = run_case_set("pixel-heuristic", cases, runs=2, seed=7, env_kwargs={"max_motions": 1})
    assert [row.case for row in result.rows] == [c.name for c in cases]
    assert [[r.seed for r in result.records[c.name]] for c in cases] == [[7, 8], [7 + CASE_SEED_STRIDE, 8 + CASE_SEED_STRIDE]]
    assert result.env_kwargs == {"wrong_grasp": "fail", "max_motions": 1}
    assert result.overall.runs == 4 and result.overall.mean_motions == 1.0
    data = json.loads(json.dumps(result.to_dict()))
    assert data["overall"]["runs"] == 4 and len(data["rows"]) == 2 and data["case_set"] == "two"
    assert result.markdown().splitlines()[-1].startswith("| **overall** | **")


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--cases", "nope"], "unknown case set 'nope': valid are challenge, epg, gti"),
        (["--cases", "epg"], "case set 'epg' is read from the peers' files"),
        (["--cases", "challenge", "--runs", "0"], "--runs must be >= 1"),
        (["--cases", "gti", "--peers", "/nonexistent"], "--peers '/nonexistent' is not a folder"),
        (["--cases", "challenge", "--workers", "2"], "--cases runs in this process"),
    ],
)
def test_mpg_eval_cases_rejects_bad_input_in_one_line(argv, message, capsys):
    assert eval_main(["--policy", "random", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_mpg_eval_cases_prints_a_row_per_case_and_writes_json(tmp_path, capsys):
    out = tmp_path / "cases.json"
    scene = challenge_dir() / "tower.json"  # the pixel heuristic (by its former name) lifts the block on top: each run ends at once
    assert eval_main(["--policy", "grasp-only", "--cases", str(scene), "--runs", "2", "--json", str(out), "--quiet"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["case", "visible", "success", "motions", "mis-picks/run", "grasp", "success"]
    assert lines[1].startswith("tower") and lines[2].startswith("overall")
    data = json.loads(out.read_text())
    assert data["policy"] == "pixel-heuristic" and data["runs"] == 2 and data["env_kwargs"] == {"wrong_grasp": "fail"}
    assert [r["case"] for r in data["rows"]] == ["tower"] and len(data["records"]["tower"]) == 2
    assert data["overall"]["end_reasons"] == {"wrong_object": 2} and data["overall"]["mis_picks"] == 1.0
