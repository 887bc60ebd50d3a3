"""The launcher of independent training runs (mpg_agents.learning.train_runs): planning and commands."""

import sys

import pytest

from mpg_agents.learning.train_runs import DEFAULT_CONFIG, RUNS, RunSpec, main, plan_runs, train_run


def test_plan_gives_one_folder_per_run_and_seed_with_its_pipeline_flags(tmp_path):
    specs = plan_runs(["mpgnet", "grasp-only"], [0, 1], DEFAULT_CONFIG, tmp_path)
    assert [(s.run, s.seed) for s in specs] == [("mpgnet", 0), ("mpgnet", 1), ("grasp-only", 0), ("grasp-only", 1)]
    assert specs[3].folder == tmp_path / "grasp-only-s1"
    cmd = specs[3].command()
    assert cmd[:4] == [sys.executable, "-m", "mpg_agents.cli", "--pipeline"]
    assert cmd[cmd.index("--seed") + 1] == "1" and cmd[cmd.index("--out") + 1] == str(tmp_path / "grasp-only-s1")
    assert cmd[-2:] == ["--baseline", "grasp-only"] and specs[0].command()[-1] == "0"


@pytest.mark.parametrize(
    "runs, seeds, config, match",
    [
        (["mpgnet", "dqn"], [0], DEFAULT_CONFIG, "unknown run 'dqn'"),
        (["mpgnet"], [-1], DEFAULT_CONFIG, "seed must be an integer >= 0"),
        ([], [0], DEFAULT_CONFIG, "at least one run"),
        (["mpgnet"], [0], "missing.toml", "does not exist"),
    ],
)
def test_plan_rejects_what_it_cannot_run(runs, seeds, config, match):
    with pytest.raises(ValueError, match=match):
        plan_runs(runs, seeds, config, "runs")


def test_every_run_is_mpgnet_an_ablation_or_a_learned_baseline():
    from mpg_agents.learning.stage_variants import BASELINES

    for flags in RUNS.values():
        if flags[:1] == ("--baseline",):
            assert len(flags) == 2 and flags[1] in BASELINES
        else:
            assert set(flags) <= {"--no-multistage", "--no-alternating"}
    assert set(BASELINES) <= {name for name in RUNS}


def test_a_finished_run_is_skipped_without_starting_anything(tmp_path):
    spec = RunSpec("mpgnet", 0, str(DEFAULT_CONFIG), str(tmp_path))
    spec.folder.mkdir(parents=True)
    (spec.folder / "pipeline.json").write_text("{}")
    assert train_run(spec).status == "finished before"


def test_dry_run_prints_the_commands(tmp_path, capsys):
    assert main(["--runs", "to-vpg", "--seeds", "2,3", "--out", str(tmp_path), "--dry-run"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and all("--baseline to-vpg" in line for line in lines)
    assert "to-vpg-s3" in lines[1]
