"""A run's env steps counted from its folder (mpg_agents.learning.env_steps), on hand-made folders."""

import json
from pathlib import Path

import pytest

from mpg_agents.learning.env_steps import StageSteps, format_env_steps, main, run_env_steps, stage_env_steps
from mpg_agents.learning.run_state import STATE_FORMAT


def _stage(
    folder: Path,
    iterations: int,
    demo_steps: int | None = None,
    calibration_grasps: tuple[int, ...] = (),
    old_state: bool = False,
) -> Path:
    state = folder / ("state.old" if old_state else "state")  # state.old: a kill between a save's renames
    state.mkdir(parents=True)
    (state / "FORMAT").write_text(STATE_FORMAT)
    (state / "counters.json").write_text(json.dumps({"iteration": iterations, "episode": 7}))
    if demo_steps is not None:
        record = {"episodes": 2, "kept": demo_steps - 1, "dropped": 1, "successes": 2, "seconds": 1.5, "env_steps": demo_steps}
        (folder / "demonstrations.json").write_text(json.dumps(record))
    if calibration_grasps:
        history = [
            {"iteration": 100 * i, "q_star": 0.5, "target_grasps": 1, "grasps": g} for i, g in enumerate(calibration_grasps)
        ]
        (folder / "calibration.json").write_text(json.dumps({"grasps": calibration_grasps[-1], "history": history}))
    return folder


def test_a_stage_counts_iterations_demonstrations_and_every_calibration(tmp_path):
    stage = _stage(tmp_path / "Stage5", 500, demo_steps=25, calibration_grasps=(40, 38, 41))
    counted = stage_env_steps(stage)
    assert counted == StageSteps("Stage5", 500, 25, 119)
    assert counted.total == 644  # 500 + 25 + 40 + 38 + 41


def test_a_pipeline_counts_each_stage_folder_in_order_and_sums_them(tmp_path):
    _stage(tmp_path / "Stage2", 450, demo_steps=10)
    _stage(tmp_path / "Stage1", 200, old_state=True)
    _stage(tmp_path / "Stage5", 500, calibration_grasps=(30,))
    (tmp_path / "notes").mkdir()  # not a stage: ignored
    stages = run_env_steps(tmp_path)
    assert [s.name for s in stages] == ["Stage1", "Stage2", "Stage5"]
    assert [s.total for s in stages] == [200, 460, 530]
    table = format_env_steps(stages, extra=248)
    assert table.splitlines()[-1] == "| all | 1150 | 258 | 30 | 1438 |"  # 1190 + 248 from a dataset
    assert "| elsewhere (a cloned net's dataset) | | 248 | | 248 |" in table


def test_a_single_stage_run_folder_is_its_own_stage(tmp_path):
    _stage(tmp_path, 3)
    assert run_env_steps(tmp_path) == [StageSteps(tmp_path.name, 3, 0, 0)]


def test_a_folder_without_a_run_is_refused_by_name(tmp_path):
    with pytest.raises(FileNotFoundError, match="holds no training run"):
        run_env_steps(tmp_path)
    with pytest.raises(FileNotFoundError, match="no stage run folder"):
        stage_env_steps(tmp_path)
    (tmp_path / "state").mkdir()
    (tmp_path / "state" / "FORMAT").write_text("some other format")  # not a state this version saved
    with pytest.raises(FileNotFoundError, match="no stage run folder"):
        stage_env_steps(tmp_path)


def test_the_command_prints_the_table_and_refuses_negative_extra_steps(tmp_path, capsys):
    _stage(tmp_path / "Stage1", 12, demo_steps=3)
    assert main([str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "| all | 12 | 3 | 0 | 15 |"
    with pytest.raises(SystemExit):
        main([str(tmp_path), "--extra", "-1"])
    assert "--extra must be >= 0" in capsys.readouterr().err
