"""mpg-train --baseline bc: MPGNet's nets trained to copy the oracle's recorded actions, on a
dataset of 3 oracle episodes recorded with mpg-demos; the loss falls, the checkpoint acts, a
stopped run resumes as if it had not stopped, and bad input is one line."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from safetensors.torch import load_file

# The demos extra is installed by .ci/install: under CI a missing Minari fails, elsewhere it skips.
minari = __import__("minari") if os.environ.get("CI") else pytest.importorskip("minari")

from mpg_agents.acting.weights import read_checkpoint_header  # noqa: E402
from mpg_agents.cli import eval_main, train_main  # noqa: E402
from mpg_agents.demos.cli import main as demos_main  # noqa: E402
from mpg_agents.demos.dataset import dataset_digest, load_demos  # noqa: E402
from mpg_agents.evaluation.evaluate import evaluate  # noqa: E402
from mpg_agents.evaluation.policy_zoo import make_policy  # noqa: E402
from mpg_agents.imitation.bc_config import BCConfig  # noqa: E402
from mpg_agents.imitation.bc_training import PROGRESS, WEIGHTS, train_bc  # noqa: E402
from mpg_agents.imitation.demo_samples import DemoSamples  # noqa: E402

GRASP_ACTIONS = 16 * 224 * 224  # MPG-Stage2-v0 acts with the grasp alone


@pytest.fixture(scope="module")
def demos(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bc") / "stage2-oracle"
    command = ["--policy", "oracle", "--env", "MPG-Stage2-v0", "--num-objects", "2", "--episodes", "3", "--seed", "5"]
    assert demos_main([*command, "--quiet", "--out", str(out)]) == 0
    return out


def progress(run: Path) -> list[dict[str, str]]:
    lines = (run / PROGRESS).read_text().splitlines()
    keys = lines[0].split(",")
    return [dict(zip(keys, line.split(","))) for line in lines[1:]]


def test_the_samples_are_the_first_episodes_steps(demos):
    dataset = load_demos(demos)
    steps = [len(e.actions) for e in dataset.iterate_episodes(range(3))]
    first = DemoSamples(demos, 2)
    assert len(first) == sum(steps[:2]) and first.episode_of.tolist() == [0] * steps[0] + [1] * steps[1]
    assert first.source.episodes == 2 and first.source.total_episodes == 3 and first.action_primitives == ("grasp",)
    assert first.source.digest == dataset_digest(demos) and first.source.policy == "oracle"
    episode = dataset[1]
    obs, actions = first.batch([steps[0]])  # episode 1's first step
    assert actions.tolist() == [int(episode.actions[0])]
    assert np.array_equal(obs["depth"][0], episode.observations["depth"][0])
    assert not obs["color"].any()  # not kept: zeros, which a net without colour input never reads
    with_color = DemoSamples(demos, color=True)
    assert len(with_color) == sum(steps)
    assert np.array_equal(with_color.batch([steps[0]])[0]["color"][0], episode.observations["color"][0])
    with pytest.raises(ValueError, match=r"--demo-episodes 4: the dataset .* holds 3 episodes; valid: 1\.\.3"):
        DemoSamples(demos, 4)


def test_a_few_steps_lower_the_loss_and_the_checkpoint_plays_an_episode(demos, tmp_path, capsys):
    samples = len(DemoSamples(demos))
    config = tmp_path / "bc.toml"
    # Every step the exact loss on all the samples, as they were recorded.
    config.write_text(f"batch_size = {samples}\nlearning_rate = 0.001\nrotations_per_sample = 16\nquarter_turns = false\n")
    run = tmp_path / "run"
    command = ["--baseline", "bc", "--demos", str(demos), "--out", str(run), "--steps", "4", "--config", str(config)]
    assert train_main(command) == 0
    summary = json.loads(capsys.readouterr().out.splitlines()[-1])
    losses = [float(row["loss"]) for row in progress(run)]
    assert [row["step"] for row in progress(run)] == ["1", "2", "3", "4"]
    assert losses[0] == pytest.approx(math.log(GRASP_ACTIONS), abs=1e-4)  # untrained: every action equally likely
    assert all(b < a for a, b in zip(losses, losses[1:])), losses
    header = read_checkpoint_header(run / WEIGHTS)
    card = header["extra"]["imitation"]
    assert header["extra"]["coordination"] == "max_q" and header["extra"]["env_id"] == "MPG-Stage2-v0"
    assert card["dataset"]["digest"] == dataset_digest(demos) and card["demo_episodes"] == 3
    assert card["steps"] == 4 and card["wall_time_s"] > 0 and summary["steps"] == 4
    assert header["config"]["rough_mask"] is False and header["primitives"] == ["grasp"]
    assert header["config"]["grasp_fingers"] == "clear" and card["grasp_fingers"] == "clear"  # how it acts
    # The checkpoint acts as any MPGNet checkpoint does: through make_policy, and mpg-eval.
    env = gym.make("MPG-Stage2-v0", num_objects=2)
    policy = make_policy(str(run / WEIGHTS), env)
    assert policy.policy.coordination == "max_q" and policy.primitives == ("grasp",)
    result = evaluate(policy, env, episodes=1, seed=900000)
    env.close()
    record = result.records[0]
    assert len(result.records) == 1 and record.motions >= 1 and len(record.actions) == record.motions
    evaluated = tmp_path / "eval.json"
    eval_command = ["--policy", str(run / WEIGHTS), "--env", "MPG-Stage2-v0", "--num-objects", "2", "--episodes", "1"]
    assert eval_main([*eval_command, "--seed", "900000", "--quiet", "--json", str(evaluated)]) == 0
    assert json.loads(evaluated.read_text())["records"][0]["actions"] == list(record.actions)
    # The same command on the finished run changes nothing.
    before = load_file(str(run / WEIGHTS))
    assert train_main(command) == 0
    after = load_file(str(run / WEIGHTS))
    assert all(np.array_equal(before[k].numpy(), after[k].numpy()) for k in before)


@pytest.mark.parametrize(
    "draws", [{"rotations_per_sample": 16, "quarter_turns": False}, {"rotations_per_sample": 3}], ids=["exact", "sampled"]
)
def test_a_stopped_run_resumes_as_if_it_had_not_stopped(demos, tmp_path, draws):
    """Also with a sampled softmax and quarter turns: their draws come from the run's saved generator."""
    settings = {"batch_size": 2, "save_every": 1, "learning_rate": 1e-3, "seed": 3, **draws}
    straight = tmp_path / "straight"
    train_bc(BCConfig(steps=3, **settings), demos, straight)
    stopped = tmp_path / "stopped"
    train_bc(BCConfig(steps=2, **settings), demos, stopped)
    with open(stopped / PROGRESS, "a") as f:  # a step logged, then killed before its state was saved
        f.write("3,99.0,0.0,1.0,1.0\n")
    train_bc(BCConfig(steps=3, **settings), demos, stopped)
    a, b = load_file(str(straight / WEIGHTS)), load_file(str(stopped / WEIGHTS))
    assert all(np.array_equal(a[k].numpy(), b[k].numpy()) for k in a)
    assert [r["loss"] for r in progress(stopped)] == [r["loss"] for r in progress(straight)]
    # Other settings or other data are named, and refused.
    with pytest.raises(ValueError, match="settings.learning_rate: saved 0.001, asked 0.01"):
        train_bc(BCConfig(steps=4, **{**settings, "learning_rate": 1e-2}), demos, stopped)
    with pytest.raises(ValueError, match="demo_episodes: saved 3, asked 2"):
        train_bc(BCConfig(steps=4, demo_episodes=2, **settings), demos, stopped)


def straight_run_and_command(demos: Path, tmp_path: Path, steps: int, save_every: int, out: Path) -> tuple[Path, list[str]]:
    """A run of ``steps`` trained in this process, and the ``mpg-train`` command of the same run
    into ``out`` (to be stopped, then resumed, in a process of its own)."""
    settings = {"batch_size": 2, "save_every": save_every, "learning_rate": 1e-3, "seed": 3}
    straight = tmp_path / "straight"
    train_bc(BCConfig(steps=steps, **settings), demos, straight)
    config = tmp_path / "bc.toml"
    config.write_text("".join(f"{key} = {value}\n" for key, value in settings.items()))
    command = [sys.executable, "-m", "mpg_agents.cli", "--baseline", "bc", "--demos", str(demos), "--out", str(out)]
    return straight, [*command, "--steps", str(steps), "--config", str(config)]


ONE_THREAD = {**os.environ, "MPG_NUM_THREADS": "1"}  # as this process: one thread, the same sums


def assert_same_run(a: Path, b: Path) -> None:
    """The same weights, bit for bit, and the same losses step by step."""
    first, second = load_file(str(a / WEIGHTS)), load_file(str(b / WEIGHTS))
    assert all(np.array_equal(first[k].numpy(), second[k].numpy()) for k in first)
    assert [r["loss"] for r in progress(b)] == [r["loss"] for r in progress(a)]


def test_a_run_killed_with_sigkill_resumes_to_the_weights_of_an_unkilled_one(demos, tmp_path):
    killed = tmp_path / "killed"
    straight, command = straight_run_and_command(demos, tmp_path, steps=4, save_every=1, out=killed)
    run = subprocess.Popen(command, env=ONE_THREAD, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 300
    while run.poll() is None and time.monotonic() < deadline:
        if (killed / PROGRESS).is_file() and len(progress(killed)) >= 2:
            run.send_signal(signal.SIGKILL)  # somewhere in step 3 or its save
            break
        time.sleep(0.05)
    run.wait(timeout=60)
    assert run.returncode == -signal.SIGKILL, "the run ended before it could be killed"
    assert subprocess.run(command, env=ONE_THREAD, capture_output=True, timeout=600).returncode == 0
    assert_same_run(straight, killed)
    assert [r["step"] for r in progress(killed)] == ["1", "2", "3", "4"]


def test_sigterm_saves_the_step_just_taken_and_the_run_resumes_to_the_unstopped_weights(demos, tmp_path):
    stopped = tmp_path / "stopped"
    # save_every 100: no regular save before the end, so only the stop saves.
    straight, command = straight_run_and_command(demos, tmp_path, steps=12, save_every=100, out=stopped)
    run = subprocess.Popen(command, env=ONE_THREAD, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert run.stdout is not None
    for line in run.stdout:  # a line per step here (12 steps: every step is printed)
        if line.startswith("step 2/12"):
            run.send_signal(signal.SIGTERM)
            break
    _, err = run.communicate(timeout=300)
    assert run.returncode == 143, err
    assert "stopped: state saved at the last step" in err
    saved = json.loads((stopped / "state" / "counters.json").read_text())
    assert 2 <= saved["step"] < 12 and len(progress(stopped)) == saved["step"]  # nothing lost, nothing beyond
    assert subprocess.run(command, env=ONE_THREAD, capture_output=True, timeout=600).returncode == 0
    assert_same_run(straight, stopped)


def test_bad_input_is_one_line_naming_what_is_valid(tmp_path, capsys):
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "notes.txt").write_text("x")
    (tmp_path / "foreign" / "data").mkdir(parents=True)
    (tmp_path / "foreign" / "data" / "metadata.json").write_text("{}")
    (tmp_path / "other_run").mkdir()
    (tmp_path / "other_run" / "x.txt").write_text("x")
    out = ["--out", str(tmp_path / "run")]
    cases = [
        (["--baseline", "bc", *out], "--baseline bc needs --demos DIR: a dataset folder recorded by mpg-demos"),
        (["--baseline", "bc", "--demos", str(tmp_path / "junk"), "--env", "MPG-Stage2-v0", *out], "takes no --env"),
        (["--baseline", "bc", "--demos", str(tmp_path / "junk"), "--q-star", "1", *out], "takes no --q-star"),
        (["--baseline", "bc", "--demos", str(tmp_path / "none"), *out], "is not a dataset of mpg-demos (no such folder)"),
        (["--baseline", "bc", "--demos", str(tmp_path / "junk"), *out], "(no data/metadata.json in it)"),
        (["--baseline", "bc", "--demos", str(tmp_path / "foreign"), *out], "is not a dataset of mpg-demos"),
        (
            ["--baseline", "bc", "--demos", str(tmp_path / "junk"), "--steps", "0", *out],
            "steps (--steps) must be an integer >= 1",
        ),
        (["--baseline", "bc", "--demos", str(tmp_path / "junk"), "--demo-episodes", "-1", *out], "must be an integer >= 1"),
    ]
    for argv, says in cases:
        assert train_main(argv) == 2, argv
        err = capsys.readouterr().err
        assert says in err and err.count("\n") == 1, (argv, err)
    assert not (tmp_path / "run").exists()
    for argv, says in [
        (["--demos", str(tmp_path / "junk"), "--env", "MPG-Stage2-v0"], "--demos and --demo-episodes go with --baseline bc"),
        (["--out", str(tmp_path / "run")], "one of the arguments --env --pipeline is required"),
    ]:
        with pytest.raises(SystemExit) as stop:
            train_main(argv)
        assert stop.value.code == 2 and says in capsys.readouterr().err
