"""The learner, the pipeline and the command lines, on tiny settings."""

import json
import math
import os
import signal
from pathlib import Path

import pytest
import torch

from mpg_agents.cli import eval_main, plot_main, train_main
from mpg_agents.learning.learner import Learner, StopRequested
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.pipeline import PipelineConfig, run_pipeline
from mpg_agents.learning.training_stages import TRAINING_STAGES, with_overrides
from .tiny import TINY

REPO = Path(__file__).resolve().parents[2]


def test_tiny_pipeline_runs_stages_one_to_five(tmp_path):
    stages = with_overrides(
        TRAINING_STAGES,
        {s.name: {"iterations": 2} for s in TRAINING_STAGES} | {"Stage3": {"iterations": 2, "objects": [2, 3]}, "Stage5": {"iterations": 2, "alternate_every": 1}},
    )
    cfg = PipelineConfig(base=TrainConfig(**TINY), stages=stages)
    summary = run_pipeline(cfg, tmp_path, log=lambda s: None)
    for i in range(1, 6):
        stage = tmp_path / f"Stage{i}"
        assert (stage / "weights.safetensors").is_file() and (stage / "done.json").is_file()
        assert summary[f"Stage{i}"]["iteration"] == 2
    assert summary["final_weights"].endswith("Stage5/weights.safetensors")
    # the record on disk names no machine path: it ships beside its weights
    assert json.loads((tmp_path / "pipeline.json").read_text())["final_weights"] == "Stage5/weights.safetensors"
    # A re-run skips finished stages.
    again = run_pipeline(cfg, tmp_path, log=lambda s: None)
    assert again["Stage5"] == summary["Stage5"]


def test_branch_init_starts_the_move_net_as_the_grasp_net(tmp_path):
    stage = with_overrides(TRAINING_STAGES, {"Stage3": {"branch_init": [["move", "grasp"]], "objects": [2, 2]}})[2]
    learner = Learner(TrainConfig(steps=1, **TINY), stage, tmp_path, log=lambda s: None)
    move, grasp = learner.net.branches["move"].state_dict(), learner.net.branches["grasp"].state_dict()
    assert move.keys() == grasp.keys() and all(torch.equal(move[k], grasp[k]) for k in move)
    target_move = learner.target.branches["move"].state_dict()
    assert all(torch.equal(target_move[k], move[k]) for k in move)
    learner.env.close()


def test_a_stage_reward_setting_reaches_its_env(tmp_path):
    stage = with_overrides(TRAINING_STAGES, {"Stage3": {"reward": {"move_needs_lift": True}, "objects": [2, 2]}})[2]
    learner = Learner(TrainConfig(steps=1, **TINY), stage, tmp_path, log=lambda s: None)
    assert learner.env.unwrapped.config.reward.move_needs_lift
    learner.env.close()
    plain = Learner(TrainConfig(steps=1, **TINY), TRAINING_STAGES[2], tmp_path / "plain", log=lambda s: None)
    assert not plain.env.unwrapped.config.reward.move_needs_lift
    plain.env.close()


def test_grasp_trials_store_other_orientations_at_the_grasp_pixel(tmp_path, monkeypatch):
    import mpg_agents.learning.learner as learner_module

    stage = with_overrides(TRAINING_STAGES, {"Stage5": {
        "env_id": "MPG-Occluded-v0", "objects": [6, 6], "coordination": "grasp_first", "grasp_trials": 2, "alternate_every": 1,
    }})[-1]
    steps = []
    real = learner_module.td_step
    monkeypatch.setattr(learner_module, "td_step", lambda *args: steps.append(1) or real(*args))
    learner = Learner(TrainConfig(steps=2, **TINY), stage, tmp_path, log=lambda s: None)
    # Every decision a grasp: a Q*_g below any Q this untrained net gives (below what a setting
    # may say, so it is set on the policy, as a test may).
    learner.policy.set_q_star(-10.0)
    summary = learner.run()
    env = learner.env.unwrapped
    assert summary["grasp_trials"] == learner.counters.grasp_trials == 4 and len(steps) == 4  # two steps per grasp
    actions = [env.action_space.decode(int(a)) for a in learner.replay.actions[:6, 0, 0]]
    for k in range(2):  # each iteration: its two trials, then the grasp taken
        (_, r1, *p1), (_, r2, *p2), (_, taken, *pixel) = actions[3 * k : 3 * k + 3]
        assert p1 == p2 == pixel and len({r1 % 8, r2 % 8, taken % 8}) == 3
    learner.env.close()


def test_move_trials_store_the_move_nets_next_places(tmp_path, monkeypatch):
    import mpg_agents.learning.learner as learner_module
    from mpg_agents.learning.trials import MOVE_TRIAL_SPACING_PX

    stage = with_overrides(TRAINING_STAGES, {"Stage5": {
        "env_id": "MPG-OccludedHard-v0", "objects": [6, 6], "move_trials": 2, "alternate_every": 1,
    }})[-1]
    steps = []
    real = learner_module.td_step
    monkeypatch.setattr(learner_module, "td_step", lambda *args: steps.append(1) or real(*args))
    learner = Learner(TrainConfig(steps=1, **TINY), stage, tmp_path, log=lambda s: None)
    summary = learner.run()  # the hard track's target starts covered: the workflow moves
    env = learner.env.unwrapped
    assert summary["move_trials"] == learner.counters.move_trials == 2 and len(steps) == 2
    assert 0 <= summary["move_trial_successes"] <= 2
    actions = [env.action_space.decode(int(a)) for a in learner.replay.actions[:3, 0, 0]]
    assert [a[0] for a in actions] == ["move"] * 3  # its two trials, then the move taken
    pixels = [a[2:] for a in actions]
    for i in range(3):
        for j in range(i):
            assert math.dist(pixels[i], pixels[j]) >= MOVE_TRIAL_SPACING_PX
    learner.env.close()


def _one_covered_step(tmp_path, monkeypatch, trial: str):
    """One Stage V iteration on the hard track (its target starts covered: a move or a push is
    taken) with the trial switch ``trial`` on; returns the learner, its summary and the TD steps."""
    import mpg_agents.learning.learner as learner_module

    stage = with_overrides(TRAINING_STAGES, {"Stage5": {
        "env_id": "MPG-OccludedHard-v0", "objects": [6, 6], trial: True, "alternate_every": 1,
        "coordination": "uncover_max_q", "reward": {"push_uncovers": True},
    }})[-1]
    steps = []
    real = learner_module.td_step
    monkeypatch.setattr(learner_module, "td_step", lambda *args: steps.append(1) or real(*args))
    learner = Learner(TrainConfig(steps=1, **TINY), stage, tmp_path, log=lambda s: None)
    assert learner.env.unwrapped.config.reward.push_uncovers
    return learner, learner.run(), steps


def test_rival_trials_label_the_push_a_covered_move_replaces(tmp_path, monkeypatch):
    learner, summary, steps = _one_covered_step(tmp_path, monkeypatch, "rival_trials")
    env = learner.env.unwrapped
    assert summary["rival_trials"] == learner.counters.rival_trials == 1 and len(steps) == 2
    assert summary["rival_trial_clears"] in (0, 1)
    tried, taken = (env.action_space.decode(int(a))[0] for a in learner.replay.actions[:2, 0, 0])
    assert {tried, taken} == {"move", "push"}  # the trial is the primitive not taken
    learner.env.close()


def test_rival_trials_is_a_switch():
    with pytest.raises(ValueError, match="rival_trials must be true or false"):
        with_overrides(TRAINING_STAGES, {"Stage5": {"rival_trials": 1}})
    with pytest.raises(ValueError, match="covered_grasp_trials must be true or false"):
        with_overrides(TRAINING_STAGES, {"Stage5": {"covered_grasp_trials": "yes"}})


def test_covered_grasp_trials_label_the_grasp_a_covered_step_skips(tmp_path, monkeypatch):
    learner, summary, steps = _one_covered_step(tmp_path, monkeypatch, "covered_grasp_trials")
    env = learner.env.unwrapped
    assert summary["covered_grasp_trials"] == learner.counters.covered_grasp_trials == 1 and len(steps) == 2
    assert summary["covered_grasp_trial_targets"] in (0, 1)
    tried, taken = (env.action_space.decode(int(a))[0] for a in learner.replay.actions[:2, 0, 0])
    assert tried == "grasp" and taken in ("move", "push")  # the trial is stored first, then the step
    assert env.num_motions == 1  # the trial was undone: only the step taken counts
    learner.env.close()


def test_the_finish_trains_only_its_branches(tmp_path, monkeypatch):
    import mpg_agents.learning.learner as learner_module

    stage = with_overrides(TRAINING_STAGES, {"Stage5": {
        "iterations": 4, "alternate_every": 1, "finish_iterations": 2, "finish_trainable": ["grasp"], "objects": [3, 3],
    }})[-1]
    trained: list[tuple[str, ...]] = []
    real = learner_module.td_step
    monkeypatch.setattr(learner_module, "td_step", lambda *args: trained.append(tuple(args[-2])) or real(*args))
    learner = Learner(TrainConfig(**TINY), stage, tmp_path, log=lambda s: None)
    learner.run()
    assert trained == [("move",), ("push",), ("grasp",), ("grasp",)]


def test_a_push_grasp_baseline_trains_and_acts_without_move(tmp_path):
    from mpg_agents.evaluation.policy_zoo import make_policy
    from mpg_agents.learning.stage_variants import target_vpg_baseline
    from mpg_agents.acting.weights import read_checkpoint_header

    stages = with_overrides(TRAINING_STAGES, {s.name: {"iterations": 2} for s in TRAINING_STAGES})
    table = target_vpg_baseline(stages)
    summary = run_pipeline(PipelineConfig(base=TrainConfig(**TINY), stages=table), tmp_path, log=lambda s: None)
    final = summary["final_weights"]
    assert read_checkpoint_header(final)["primitives"] == ["push", "grasp"]
    import gymnasium as gym

    env = gym.make("MPG-Occluded-v0", num_objects=6)
    policy = make_policy(final, env)
    assert policy.primitives == ("push", "grasp") and policy.name.endswith("(push+grasp net)")
    env.close()


def test_killed_run_resumes_with_its_counters_and_replay(tmp_path):
    cfg = TrainConfig(steps=5, **TINY)
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    original = learner.learn_from

    def iteration_then_kill(step):
        out = original(step)
        if learner.counters.iteration == 3:
            os.kill(os.getpid(), signal.SIGTERM)  # the real signal path
        return out

    learner.learn_from = iteration_then_kill
    with pytest.raises(StopRequested):
        learner.run()
    killed = (learner.counters.iteration, learner.counters.episode, learner.replay.size())
    assert killed[0] == 3 and killed[2] == 3

    resumed = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    assert (resumed.counters.iteration, resumed.counters.episode, resumed.replay.size()) == killed
    assert resumed.replay.priorities[:3].tolist() == learner.replay.priorities[:3].tolist()
    for a, b in zip(resumed.net.state_dict().values(), learner.net.state_dict().values()):
        assert torch.equal(a, b)
    resumed.run()
    assert resumed.counters.iteration == 5 and resumed.replay.size() == 5
    rows = (tmp_path / "progress.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == ["1", "2", "3", "4", "5"]


def test_learning_steps_shrink_the_surprise_of_a_transition(tmp_path):
    # One stored transition; repeated steps on it must shrink |Q - y| (its priority). At the
    # paper's learning rate (1e-4) it shrinks steadily; at 1e-3 Adam's first steps overshoot.
    cfg = TrainConfig(steps=1, learning_rate=1e-4, weight_decay=0.0, **{**TINY, "target_update_every": 1000})
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    learner.run()
    assert learner.replay.size() == 1
    errors = []
    for _ in range(12):
        learner.learn()
        errors.append(float(learner.replay.priorities[0, 0]) - learner.replay.priority_eps)
    assert errors[-1] < 0.5 * errors[0], errors


def test_mpg_eval_oracle_gives_the_same_json_twice(tmp_path, capsys):
    paths = [tmp_path / "a.json", tmp_path / "b.json"]
    for p in paths:
        code = eval_main(["--policy", "oracle", "--env", "MPG-Stage2-v0", "--episodes", "2", "--seed", "4", "--json", str(p), "--quiet"])
        assert code == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()
    data = json.loads(paths[0].read_text())
    assert data["task_success_rate"] == 1.0 and data["episodes"] == 2
    assert "task success rate" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--env", "MPG-Stage9-v0", "--steps", "1"], "unknown env id"),
        (["--env", "MPG-Stage2-v0", "--init", "missing.safetensors"], "does not exist"),
        (["--env", "MPG-Stage2-v0", "--config", "missing.json"], "does not exist"),
    ],
)
def test_mpg_train_rejects_bad_input(tmp_path, capsys, argv, message):
    assert train_main([*argv, "--out", str(tmp_path / "run")]) == 2
    assert message in capsys.readouterr().err


def test_checkpoint_of_another_architecture_is_refused(tmp_path, capsys):
    from mpg_agents.network.mpgnet import MPGNet
    from mpg_agents.network.mpgnet_config import MPGNetConfig
    from mpg_agents.acting.weights import save_mpgnet

    other = tmp_path / "other.safetensors"
    save_mpgnet(MPGNet(MPGNetConfig.small(trunk_depth=3, primitives=("grasp",))), other)
    config = tmp_path / "tiny.json"
    config.write_text(json.dumps({k: v for k, v in TINY.items()}))
    code = train_main(["--env", "MPG-Stage2-v0", "--steps", "1", "--init", str(other), "--config", str(config), "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 2 and "trunk" in err.lower()
    garbage = tmp_path / "garbage.safetensors"
    garbage.write_bytes(b"not a checkpoint")
    assert eval_main(["--policy", str(garbage), "--env", "MPG-Stage2-v0", "--episodes", "1"]) == 2
    assert "is not a safetensors file" in capsys.readouterr().err
    assert eval_main(["--policy", "oracle", "--env", "Nope-v0"]) == 2


def test_mpg_plot_draws_curves(tmp_path):
    cfg = TrainConfig(steps=4, window=2, **TINY)
    Learner(cfg, "MPG-Stage1-v0", tmp_path, log=lambda s: None).run()
    assert plot_main([str(tmp_path), "--window", "2"]) == 0
    png = tmp_path / "curves.png"
    assert png.is_file() and png.read_bytes()[:4] == b"\x89PNG"
    # Several runs, one stage each, on one axis (the ablation figure).
    pipeline = tmp_path / "pipe"
    (pipeline / "Stage1").mkdir(parents=True)
    (pipeline / "Stage1" / "progress.csv").write_bytes((tmp_path / "progress.csv").read_bytes())
    both = tmp_path / "both.png"
    argv = [str(tmp_path), str(pipeline), "--stage", "Stage1", "--window", "2", "--out", str(both)]
    assert plot_main(argv + ["--labels", "run,pipeline"]) == 0 and both.read_bytes()[:4] == b"\x89PNG"
    assert plot_main(argv[:-2]) == 2  # comparing needs --out
    assert plot_main(argv + ["--labels", "one"]) == 2


def test_stage4_grasps_after_five_pushes(tmp_path):
    cfg = TrainConfig(steps=1, epsilon_start=0.0, epsilon_end=0.0, **TINY)
    learner = Learner(cfg, "MPG-Stage4-v0", tmp_path, log=lambda s: None)
    assert learner.stage.push_budget == 5  # from the stage table, not the env
    obs, _ = learner.env.reset(seed=0)
    learner.counters.pushes_in_episode = 5
    choice = learner.act(obs)
    assert choice.primitive == "grasp" and choice.chosen_by == "greedy"
    assert learner.env.unwrapped.action_space.decode(choice.action).primitive == "grasp"
    with pytest.raises(ValueError, match="not allowed"):
        learner.policy.decide(obs, "move")


@pytest.mark.parametrize("name", ["stage12_train.toml", "mpgnet_train.toml"])
def test_shipped_training_configs_load(name):
    from importlib.resources import files

    from mpg_agents.cli import training_settings
    from mpg_agents.network.mpgnet_config import MPGNetConfig

    path = files("mpg_agents") / "checkpoints" / name
    base, stages = training_settings(str(path))
    assert base.variant == "small" and [s.name for s in stages] == [s.name for s in TRAINING_STAGES]
    MPGNetConfig.for_variant(base.variant, **base.net_config)  # the net it describes builds


@pytest.mark.parametrize(
    "path",
    sorted(
        str(p.relative_to(REPO))
        for p in [*(REPO / "benchmarks" / "results").glob("*/train*.toml"), *(REPO / "benchmarks" / "checkpoints").glob("*.toml")]
    ),
)
def test_recorded_training_configs_still_load(path):
    """Every recorded run's config is still a valid stage table (its README command must run)."""
    from mpg_agents.cli import training_settings

    base, stages = training_settings(str(REPO / path))
    assert [s.name for s in stages] == [s.name for s in TRAINING_STAGES], path
