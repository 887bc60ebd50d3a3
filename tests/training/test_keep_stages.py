"""``benchmarks/keep_stages.py`` keeps a run's finished stages (small files, no replay) and a
log without progress bars; a pipeline resumed from the kept files skips those stages."""

from __future__ import annotations

import pytest


@pytest.fixture()
def keep(benchmark_script):
    return benchmark_script("keep_stages")


def test_finished_stages_are_kept_without_the_replay_and_a_running_stage_is_left(keep, tmp_path):
    run, dest = tmp_path / "run", tmp_path / "kept"
    for stage, done in (("Stage1", True), ("Stage2", True), ("Stage3", False)):
        (run / stage / "state").mkdir(parents=True)
        (run / stage / "state" / "replay.npz").write_bytes(b"x" * 1000)
        (run / stage / "weights.safetensors").write_bytes(b"w")
        (run / stage / "progress.csv").write_text("iteration\n1\n")
        if done:
            (run / stage / "done.json").write_text("{}")
    (run / "Stage2" / "calibration.json").write_text("{}")
    (run / "pipeline.json").write_text("{}")
    (run / "train.log").write_text("Stage1: 600 iterations\nStage1:  1%|          | 1/600 [00:01<10:00,  1.00s/it]\rStage1:  2%|          | 2/600 [00:02<10:00,  1.00s/it]\nStage1: done\n")
    assert keep.keep_stages(run, dest) == ["Stage1", "Stage2"]
    assert sorted(p.name for p in (dest / "Stage1").iterdir()) == ["done.json", "progress.csv", "weights.safetensors"]
    assert (dest / "Stage2" / "calibration.json").is_file() and not (dest / "Stage3").exists()
    assert not list(dest.rglob("replay.npz")) and (dest / "pipeline.json").is_file()
    assert (dest / "train.log").read_text() == "Stage1: 600 iterations\nStage1: done\n"
    with pytest.raises(FileNotFoundError, match="no run folder"):
        keep.keep_stages(tmp_path / "missing", dest)


def test_a_console_log_named_by_log_is_kept_with_messages_printed_after_a_bar(keep, tmp_path):
    run, dest = tmp_path / "run", tmp_path / "kept"
    (run / "Stage1").mkdir(parents=True)
    (run / "Stage1" / "done.json").write_text("{}")
    out = tmp_path / "run.out"
    out.write_text(
        "Stage5: 1500 iterations\n"
        "Stage5:   0%|          | 0/1500 [00:00<?, ?it/s]Stage5: Q*_g 1.013 -> 0.6867 in its scenes\n"
        "Stage5:  99%|#########9| 1499/1500 [30:00<00:01,  1.20s/it]\r"
        "Stage5: 100%|##########| 1500/1500 [30:01<00:00,  1.20it/s]Traceback (most recent call last):\n"
    )
    assert keep.keep_stages(run, dest, log=out) == ["Stage1"]
    assert (dest / "train.log").read_text() == (
        "Stage5: 1500 iterations\nStage5: Q*_g 1.013 -> 0.6867 in its scenes\nTraceback (most recent call last):\n"
    )
    with pytest.raises(FileNotFoundError, match="no log file"):
        keep.keep_stages(run, dest, log=tmp_path / "missing.out")


def test_a_line_that_only_looks_like_a_bar_is_kept(keep):
    assert keep.log_without_progress_bars("grasp success 95%|target 92%\n") == "grasp success 95%|target 92%\n"
