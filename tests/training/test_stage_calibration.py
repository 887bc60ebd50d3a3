"""Q*_g calibration inside a training stage: in its own scenes, every N iterations, on resume."""

import json

import pytest

from mpg_agents.cli import eval_main
from mpg_agents.learning.learner import Learner
from mpg_agents.learning.stage_calibration import calibrate_in_scenes
from mpg_agents.learning.train_config import TrainConfig
from mpg_agents.learning.pipeline import PipelineConfig, run_pipeline
from mpg_agents.learning.training_stages import TRAINING_STAGES, with_overrides
from .tiny import TINY


def test_a_stage_calibrates_q_star_in_its_own_scenes_once(tmp_path):
    """calibration_episodes: greedy grasp-only episodes before training set Q*_g to the median
    Q of the grasps that took the target; the weights and the pipeline carry it, a resumed
    run does not calibrate again, and nothing of it enters the replay."""
    from mpg_agents.acting.weights import read_checkpoint_header

    net = {"trunk_depth": 2, "grasp_region": "target", "target_margin_px": -8}
    stages = with_overrides(
        TRAINING_STAGES, {"Stage2": {"iterations": 1, "calibration_episodes": 3, "calibrates_q_star": False}}
    )
    cfg = PipelineConfig(base=TrainConfig(**{**TINY, "net_config": net}), stages=stages[1:2])
    logged: list[str] = []
    summary = run_pipeline(cfg, tmp_path, log=logged.append)
    record = json.loads((tmp_path / "Stage2" / "calibration.json").read_text())
    assert record["episodes"] == 3 and record["target_grasps"] == len(record["target_grasp_q"]) >= 1
    values = sorted(record["target_grasp_q"])
    assert record["q_star"] == pytest.approx((values[(len(values) - 1) // 2] + values[len(values) // 2]) / 2)
    assert record["q_star_before"] is None  # nothing calibrated before
    assert summary["q_star"] == pytest.approx(record["q_star"])
    assert read_checkpoint_header(tmp_path / "Stage2" / "weights.safetensors")["q_star"] == pytest.approx(record["q_star"])
    assert sum("in its scenes" in line for line in logged) == 1
    # The state after calibration holds an empty replay; a resumed learner skips calibrating.
    # (steps 2 extends the finished stage of 1 iteration: a changed setting, asked for)
    resumed = Learner(TrainConfig(steps=2, **{**TINY, "net_config": net}), stages[1], tmp_path / "Stage2", log=logged.append,
                      resume_anyway=True)
    assert resumed.resumed and resumed.policy.q_star == pytest.approx(record["q_star"])
    resumed.run()
    assert sum("in its scenes" in line for line in logged) == 1
    resumed.env.close()
    # Another quantile of the same grasps (same seeds, same starting net): the lowest Q.
    low = with_overrides(stages, {"Stage2": {"calibration_quantile": 0.0}})[1]
    learner = Learner(TrainConfig(steps=1, **{**TINY, "net_config": net}), low, tmp_path / "low", log=lambda s: None)
    assert calibrate_in_scenes(learner, 3) == pytest.approx(min(record["target_grasp_q"]))
    learner.env.close()


def test_calibration_with_no_target_grasp_is_an_error(tmp_path, monkeypatch):
    stage = with_overrides(TRAINING_STAGES, {"Stage2": {"calibration_episodes": 1, "calibrates_q_star": False}})[1]
    learner = Learner(TrainConfig(steps=1, **TINY), stage, tmp_path, log=lambda s: None)
    learner.env.unwrapped.max_motions = 1
    real_step = learner.env.step

    def missing_step(action):
        obs, reward, terminated, truncated, info = real_step(action)
        return obs, reward, terminated, truncated, {**info, "target_grasped": False}

    monkeypatch.setattr(learner.env, "step", missing_step)
    with pytest.raises(RuntimeError, match="no grasp took the target in 1 calibration episodes"):
        calibrate_in_scenes(learner, 1)
    learner.env.close()


def test_calibrate_every_follows_the_grasp_net_and_ends_calibrated(tmp_path):
    """calibrate_every: Q*_g is measured again while the stage learns (at episode ends) and
    once at its end, on the same calibration scenes; the weights carry the last value."""
    from mpg_agents.acting.weights import read_checkpoint_header

    net = {"trunk_depth": 2, "grasp_region": "target", "target_margin_px": -8}
    stage = with_overrides(
        TRAINING_STAGES, {"Stage2": {"calibration_episodes": 1, "calibrate_every": 2, "calibrates_q_star": False}}
    )[1]
    learner = Learner(TrainConfig(steps=6, **{**TINY, "net_config": net}), stage, tmp_path, log=lambda s: None)
    learner.run()
    record = json.loads((tmp_path / "calibration.json").read_text())
    its = [h["iteration"] for h in record["history"]]
    assert its[0] == 0 and its[-1] == 6 and its == sorted(set(its)) and record["iteration"] == 6
    assert record["q_star"] == record["history"][-1]["q_star"] == pytest.approx(learner.policy.q_star)
    assert read_checkpoint_header(tmp_path / "weights.safetensors")["q_star"] == pytest.approx(record["q_star"])
    assert learner.counters.calibrated_at == 6
    learner.env.close()


def test_mpg_eval_q_star_overrides_the_checkpoint(tmp_path, capsys):
    import gymnasium as gym

    from mpg_agents.evaluation.policy_zoo import NetworkPolicy
    from mpg_agents.acting.weights import save_mpgnet

    cfg = TrainConfig(steps=1, **TINY)
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path / "run", log=lambda s: None)
    path = tmp_path / "net.safetensors"
    save_mpgnet(learner.net, path, q_star=1.5)
    learner.env.close()
    env = gym.make("MPG-Occluded-v0", num_objects=5)
    assert NetworkPolicy(path, env).policy.q_star == 1.5
    policy = NetworkPolicy(path, env, q_star=0.5)
    assert policy.policy.q_star == 0.5 and policy.name.endswith("[Q*_g: 0.5]")
    with pytest.raises(ValueError, match=r"q_star is nan; valid: a number in \(-1, 15\]"):
        NetworkPolicy(path, env, q_star=float("nan"))
    env.close()
    assert eval_main(["--policy", str(path), "--env", "MPG-Stage2-v0", "--episodes", "1", "--q-star", "0.25", "--quiet"]) == 0
    assert "[Q*_g: 0.25]" in capsys.readouterr().out
