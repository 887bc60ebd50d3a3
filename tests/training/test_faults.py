"""Runs and command lines under faults and bad input: the log survives a kill with its state, a run
folder has one owner, a resume with other settings refuses, output paths and settings are checked
before any work."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from mpg_agents.cli import calibrate_main, eval_main, plot_main, train_main
from mpg_agents.learning.learner import Learner
from mpg_agents.learning.run_folder import LOCK_NAME, RunFolderBusy, RunLock, prepare_run_folder, resume_differences
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.train_log import CSV_COLUMNS, rewind_progress
from .tiny import TINY

REPO = Path(__file__).resolve().parents[2]
TINY_TOML = """batch_size = 1
replay_capacity = 64
checkpoint_every = 2
target_update_every = 2
torch_threads = 1
[net_config]
trunk_depth = 2
"""


def iterations(path: Path) -> list[int]:
    lines = path.read_text().splitlines()
    assert lines[0] == ",".join(CSV_COLUMNS)
    return [int(line.split(",")[0]) for line in lines[1:]]


# ------------------------------------------------------------------------ the log and the state
def row(it: int) -> str:
    return ",".join([str(it), "0", "grasp", "greedy"] + ["0"] * (len(CSV_COLUMNS) - 4))


def test_rewind_keeps_each_iteration_up_to_the_state_once(tmp_path):
    path = tmp_path / "progress.csv"
    # What a kill leaves: no header (it was still buffered), a repeat, rows after the state, a cut row.
    path.write_text("\n".join([row(1), row(2), row(2), row(3), row(4), row(5)]) + "\n5,0,gra")
    assert rewind_progress(path, 4) == 4
    assert iterations(path) == [1, 2, 3, 4]
    assert rewind_progress(tmp_path / "fresh.csv", 0) == 0 and iterations(tmp_path / "fresh.csv") == []
    assert not [p.name for p in tmp_path.iterdir() if ".tmp" in p.name]  # no temporary file left


def test_rewind_warns_about_rows_it_cannot_write_again(tmp_path):
    path = tmp_path / "progress.csv"
    path.write_text(row(3) + "\n")
    with pytest.warns(UserWarning, match=r"lacks the rows of 2 iterations \(\[1, 2\]\) that its saved state \(iteration 3\) has done"):
        rewind_progress(path, 3)
    assert iterations(path) == [3]


class Crash(Exception):
    """A process dying between two saves."""


def test_a_run_crashed_between_saves_resumes_with_every_iteration_once(tmp_path):
    cfg = TrainConfig(steps=6, **TINY)
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    original = learner.learn_from

    def iteration_then_crash(step):
        out = original(step)
        if learner.counters.iteration == 5:
            raise Crash()  # the state holds iteration 4, the log rows 1..5
        return out

    learner.learn_from = iteration_then_crash
    with pytest.raises(Crash):
        learner.run()
    log = tmp_path / "progress.csv"
    lines = log.read_text().splitlines()
    log.write_text("\n".join(lines[1:]) + "\n6,1,gr")  # and lost its header, and a row was cut short
    resumed = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    assert resumed.counters.iteration == 4
    resumed.run()
    assert iterations(log) == [1, 2, 3, 4, 5, 6]


# ------------------------------------------------------------------------------ one owner
def hold_lock(folder: Path) -> subprocess.Popen:
    code = "import sys, time; from mpg_agents.learning.run_folder import RunLock; RunLock(sys.argv[1]); print('held', flush=True); time.sleep(120)"
    proc = subprocess.Popen([sys.executable, "-c", code, str(folder)], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    assert proc.stdout.readline().strip() == "held"
    return proc


def test_a_second_training_on_a_run_folder_refuses_naming_the_owner(tmp_path, capsys):
    import socket

    out = prepare_run_folder(tmp_path / "run")
    owner = hold_lock(out)
    try:
        code = train_main(["--env", "MPG-Stage2-v0", "--steps", "1", "--out", str(out)])
        err = capsys.readouterr().err
        assert code == 2
        assert f"run folder {str(out)!r} is in use by process {owner.pid} on host {socket.gethostname()!r}" in err
        assert "wait for it to finish, stop it, or give another --out" in err
        with pytest.raises(RunFolderBusy, match=f"process {owner.pid}"):
            Learner(TrainConfig(steps=1, **TINY), "MPG-Stage2-v0", out, log=lambda s: None)
    finally:
        owner.kill()
        owner.wait()
    # Its owner died (kill -9): the lock is free, and taken over.
    lock = RunLock(out)
    assert f'"pid": {os.getpid()}' in (out / LOCK_NAME).read_text()
    lock.release()


def test_a_stale_lock_file_of_a_dead_process_is_taken_over(tmp_path):
    (tmp_path / LOCK_NAME).write_text('{"pid": 999999, "host": "elsewhere", "started": "2020-01-01T00:00:00"}')
    with RunLock(tmp_path):
        assert f'"pid": {os.getpid()}' in (tmp_path / LOCK_NAME).read_text()
        with RunLock(tmp_path):  # the same process may hold it twice (a learner and its resume)
            pass


# ------------------------------------------------------------------------ settings and resumes
def test_resume_differences_lists_every_changed_setting():
    saved = {"seed": 0, "betas": [0.9, 0.99], "stage": {"env_id": "MPG-Stage2-v0", "iterations": 10}}
    asked = {"seed": 1, "betas": (0.9, 0.99), "stage": {"env_id": "MPG-Stage2-v0", "iterations": 12}}
    assert resume_differences(saved, asked) == ["seed: saved 0, asked 1", "stage.iterations: saved 10, asked 12"]
    assert resume_differences({"seed": 0}, {"seed": 0, "window": 200}) == []  # a run saved before `window` existed


def test_a_resume_with_other_settings_refuses_unless_asked_to_continue(tmp_path, capsys):
    config = tmp_path / "tiny.toml"
    config.write_text(TINY_TOML)
    out = str(tmp_path / "run")
    base = ["--env", "MPG-Stage2-v0", "--steps", "2", "--config", str(config), "--out", out]
    assert train_main(base) == 0
    capsys.readouterr()
    assert train_main([*base, "--seed", "1", "--num-objects", "3"]) == 2
    err = capsys.readouterr().err
    assert "holds a run with other settings (num_objects: saved None, asked 3; seed: saved 0, asked 1)" in err
    assert "--resume-anyway to continue it with the new ones" in err
    config.write_text(TINY_TOML.replace("batch_size = 1", "batch_size = 2"))
    assert train_main(base) == 2
    assert "batch_size: saved 1, asked 2" in capsys.readouterr().err
    config.write_text(TINY_TOML)
    assert train_main([*base, "--seed", "1", "--resume-anyway"]) == 0


@pytest.mark.parametrize("setting, message", [
    ("learning_rate = \"fast\"", "training setting learning_rate must be a positive finite number, got 'fast'"),
    ("checkpoint_every = 0", "training setting checkpoint_every must be an integer >= 1, got 0"),
    ("batch_size = 0", "training setting batch_size must be an integer >= 1, got 0"),
    ("gamma = 1.5", "training setting gamma must be a number in [0, 1], got 1.5"),
    ("grasp_symmetry = \"no\"", "training setting grasp_symmetry must be true or false, got 'no'"),
])
def test_bad_training_settings_are_named(tmp_path, capsys, setting, message):
    config = tmp_path / "bad.toml"
    config.write_text(setting + "\n")
    assert train_main(["--env", "MPG-Stage2-v0", "--config", str(config), "--out", str(tmp_path / "run")]) == 2
    assert f"error: {message}" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_positive_settings_refuse_zero_with_a_strict_bound():
    """learning_rate, replay_ratio and max_grad_norm refuse 0 by a strict bound (a lower bound of
    ``math.ulp(0.0)`` reads as 0 where denormals are flushed, as torch sets them in this process)
    and take a tiny positive number."""
    from mpg_agents.learning.train_config import TrainConfig

    for name in ("learning_rate", "replay_ratio", "max_grad_norm"):
        with pytest.raises(ValueError, match=f"training setting {name} must be a positive finite number"):
            TrainConfig(**{name: 0.0})
        assert getattr(TrainConfig(**{name: 1e-300}), name) == 1e-300


@pytest.mark.parametrize("flag, message", [
    (["--steps", "-1"], "training setting steps must be an integer >= 0 or None, got -1"),
    (["--seed", "-5"], "--seed must be >= 0, got -5"),
    (["--seed", "18446744073709551616"], "--seed must be an integer in 0..18446744073709551615 (2**64 - 1), got 18446744073709551616"),
    (["--num-objects", "0"], "training setting num_objects must be an integer >= 1 or None, got 0"),
])
def test_bad_training_flags_are_named(tmp_path, capsys, flag, message):
    assert train_main(["--env", "MPG-Stage2-v0", *flag, "--out", str(tmp_path / "run")]) == 2
    assert f"error: {message}" in capsys.readouterr().err


def test_an_out_that_is_a_file_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    out.write_text("not a folder")
    for argv in (["--env", "MPG-Stage2-v0"], ["--pipeline"]):
        assert train_main([*argv, "--steps", "1", "--out", str(out)]) == 2
        assert f"run folder {str(out)!r}: {str(out)!r} is a file, not a folder; give --out a folder path" in capsys.readouterr().err
    assert out.read_text() == "not a folder"


# ------------------------------------------------------------------------------ output paths
def test_output_paths_are_checked_before_any_episode(tmp_path, capsys, monkeypatch):
    import mpg_agents.evaluation.eval_runner as eval_runner

    def no_episodes(*args, **kwargs):
        raise AssertionError("episodes ran before the output path was checked")

    monkeypatch.setattr(eval_runner, "evaluate_parallel", no_episodes)
    missing = tmp_path / "missing" / "dir" / "out.json"
    eval_args = ["--policy", "oracle", "--env", "MPG-Stage2-v0", "--episodes", "3", "--quiet"]
    assert eval_main([*eval_args, "--json", str(missing)]) == 2
    assert f"--json {str(missing)!r}: the folder {str(missing.parent)!r} does not exist; create it first" in capsys.readouterr().err
    assert eval_main([*eval_args, "--json", str(tmp_path)]) == 2
    assert f"--json {str(tmp_path)!r} is a folder; give a file path" in capsys.readouterr().err
    assert calibrate_main(["--policy", "shipped", "--json", str(missing)]) == 2
    assert "does not exist; create it first" in capsys.readouterr().err
    assert plot_main([str(tmp_path), "--out", str(tmp_path / "no" / "curves.png")]) == 2
    assert "does not exist; create it first" in capsys.readouterr().err


def test_a_negative_eval_seed_is_named(capsys):
    assert eval_main(["--policy", "oracle", "--env", "MPG-Stage2-v0", "--episodes", "1", "--seed", "-5"]) == 2
    assert "error: --seed must be >= 0, got -5" in capsys.readouterr().err
    assert calibrate_main(["--policy", "shipped", "--seed", "-5"]) == 2
    assert "error: --seed must be >= 0, got -5" in capsys.readouterr().err


def test_demo_and_train_runs_refuse_an_out_that_is_a_file(tmp_path, capsys):
    from mpg_agents.demo import main as demo_main
    from mpg_agents.learning.train_runs import main as runs_main

    out = tmp_path / "file"
    out.write_text("x")
    assert demo_main(["--out", str(out)]) == 2
    assert f"--out {str(out)!r} is a file; give a folder (made if missing)" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exit_info:
        runs_main(["--out", str(out)])
    assert exit_info.value.code == 2
    assert f"--out {str(out)!r} is a file; give a folder (made if missing)" in capsys.readouterr().err


# -------------------------------------------------- settings, files and signals named in one line
@pytest.mark.parametrize("option, message", [
    ("config={'scene_tries': 'x'}", "--env-option: config scene_tries must be an integer >= 1 (draws of a whole scene before "
                                    "InvalidSceneError), got 'x'"),
    ("config=fast", "--env-option: config must be an EnvConfig or a dict of its fields (e.g. {'scene_tries': 40}; valid "
                    "fields: workspace, robot, "),
    ("camera_config=3", "--env-option: camera_config must be None (the default cameras) or a CameraConfig, got 3"),
    ("object_set=[1, 2]", "--env-option: object_set must be an object set's name (e.g. 'blocks'), a mesh folder's path or a "
                          "list of ObjectAsset, got [1, 2] (it holds 1 of type int)"),
])
def test_a_bad_env_option_is_named_before_any_episode(capsys, monkeypatch, option, message):
    import mpg_agents.evaluation.eval_runner as eval_runner

    monkeypatch.setattr(eval_runner, "evaluate_parallel", lambda *a, **k: pytest.fail("episodes ran before the options were checked"))
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "1", "--env-option", option]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {message}") and err.count("\n") == 1


def test_human_rendering_without_pygame_is_named(capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "pygame" else real(name, *a))
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "1", "--env-option", "render_mode=human"]) == 2
    assert capsys.readouterr().err == (
        "error: --env-option render_mode=human shows each frame in a window through pygame, which is not installed "
        "(pip install pygame); valid without it: render_mode=rgb_array, or no render_mode\n"
    )


def test_eval_and_calibrate_name_a_seed_out_of_range_and_a_bad_thread_count(capsys, monkeypatch):
    too_big = "--seed must be an integer in 0..18446744073709551615 (2**64 - 1), got 18446744073709551616"
    assert eval_main(["--policy", "oracle", "--env", "MPG-Stage2-v0", "--seed", "18446744073709551616"]) == 2
    assert capsys.readouterr().err == f"error: {too_big}\n"
    assert calibrate_main(["--policy", "shipped", "--seed", "18446744073709551616"]) == 2
    assert capsys.readouterr().err == f"error: {too_big}\n"
    monkeypatch.setenv("MPG_NUM_THREADS", "abc")
    threads = "error: MPG_NUM_THREADS must be a positive integer (or unset for automatic), got 'abc'\n"
    for main, argv in ((eval_main, ["--policy", "oracle"]), (calibrate_main, ["--policy", "shipped"]),
                       (train_main, ["--env", "MPG-Stage2-v0", "--out", "unused"])):
        assert main(argv) == 2
        assert capsys.readouterr().err == threads
    assert not Path("unused").exists()


def test_a_train_config_that_is_no_table_is_named(tmp_path, capsys):
    for name, text, held in (("list.json", "[1, 2]", "list"), ("binary.json", "\udcff", None)):
        path = tmp_path / name
        path.write_bytes(text.encode("utf-8", "surrogateescape"))
        assert train_main(["--env", "MPG-Stage2-v0", "--config", str(path), "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err
        expected = f"holds a {held}; valid: a JSON object (or TOML table) of settings by name" if held else "is not readable JSON: "
        assert f"config file {str(path)!r} {expected}" in err and err.count("\n") == 1
    assert not (tmp_path / "run").exists()


def test_an_out_that_takes_no_files_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    import mpg_agents.learning.run_folder as run_folder
    from mpg_envs.files import WriteFailed

    def read_only(folder):  # what a read-only mount answers (the tests may run as root, whom chmod does not stop)
        raise WriteFailed(folder, "Read-only file system")

    monkeypatch.setattr(run_folder, "check_folder_writable", read_only)
    out = tmp_path / "run"
    assert train_main(["--env", "MPG-Stage2-v0", "--steps", "1", "--out", str(out)]) == 2
    assert capsys.readouterr().err == (f"error: run folder {str(out)!r} cannot be written (Read-only file system); "
                                       "give --out a folder you may write in\n")
    assert not out.exists()
    if os.geteuid() != 0 and Path("/proc").is_dir():  # a folder no process writes in, without mocks
        monkeypatch.undo()
        assert train_main(["--env", "MPG-Stage2-v0", "--steps", "1", "--out", "/proc/run"]) == 2
        assert "run folder '/proc/run' cannot be written (" in capsys.readouterr().err


@pytest.mark.parametrize("index, message", [
    ('{"cases": []}', "index.json holds a JSON object; valid: a JSON list of {\"name\": "),
    ('[{"name"', "index.json: not valid JSON (Expecting ':' delimiter: line 1 column 9 (char 8)); valid: a JSON list of "),
    ('[{"note": "no name"}]', "index.json: entry 0 is {'note': 'no name'}; valid: a JSON list of "),
])
def test_a_case_folder_index_that_is_no_list_is_named(tmp_path, capsys, index, message):
    (tmp_path / "index.json").write_text(index)
    assert eval_main(["--policy", "random", "--cases", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {tmp_path}{os.sep}{message}") and err.count("\n") == 1


def test_an_interrupted_eval_is_one_line(capsys, monkeypatch):
    import mpg_agents.evaluation.eval_runner as eval_runner

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(eval_runner, "evaluate_parallel", interrupted)
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "3", "--quiet"]) == 130
    assert capsys.readouterr().err == "interrupted\n"


def test_sigint_during_mpg_eval_prints_interrupted_and_exits_130():
    import signal

    code = ("import sys; from mpg_agents.cli import eval_main; "
            "sys.exit(eval_main(['--policy', 'random', '--env', 'MPG-Stage2-v0', '--episodes', '50']))")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")})
    assert "seed" in proc.stdout.readline()  # the first episode finished: the run is under way
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130 and err.strip().splitlines()[-1] == "interrupted" and "Traceback" not in err
