"""Parallel actors: a tiny run with two actor processes learns, logs, saves and resumes; the
replay ratio; the settings' checks; Ray (skipped without it, slow)."""

import json
import os
import signal

import pytest
import torch

from mpg_agents.cli import train_main
from mpg_agents.learning.actor_feed import ActorLedger
from mpg_agents.learning.actor_pool import check_actor_backend
from mpg_agents.learning.actors import ActorStep, TakenAction
from mpg_agents.learning.learner import Learner, StopRequested
from mpg_agents.learning.train_config import TrainConfig
from .tiny import TINY


def _rows(folder):
    return [r.split(",") for r in (folder / "progress.csv").read_text().splitlines()[1:]]


def test_two_actor_processes_learn_log_save_and_resume(tmp_path):
    cfg = TrainConfig(steps=4, actors=2, actor_backend="processes", weights_refresh=1, **TINY)
    learner = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    original = learner.record

    def record_then_kill(*args):
        original(*args)
        if learner.counters.iteration == 2:
            os.kill(os.getpid(), signal.SIGTERM)  # the real signal path: save, stop the actors

    learner.record = record_then_kill
    with pytest.raises(StopRequested):
        learner.run()
    c = learner.counters
    assert (c.iteration, c.gradient_steps, learner.replay.size()) == (2, 2, 2)
    assert c.episode >= 2  # each actor was handed its own episode
    handed = c.episode

    resumed = Learner(cfg, "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    assert (resumed.counters.iteration, resumed.replay.size(), resumed.counters.episode) == (2, 2, handed)
    for a, b in zip(resumed.net.state_dict().values(), learner.net.state_dict().values()):
        assert torch.equal(a, b)
    summary = resumed.run()
    assert summary["iteration"] == resumed.counters.iteration == 4 and resumed.replay.size() == 4
    assert resumed.counters.gradient_steps == 4  # replay ratio 1: a gradient step per env step
    rows = _rows(tmp_path)
    assert [r[0] for r in rows] == ["1", "2", "3", "4"]
    episodes = [int(r[1]) for r in rows]
    assert min(episodes[2:]) >= handed  # the resumed actors started episodes the run had not handed out
    assert (tmp_path / "weights.safetensors").is_file()


def test_replay_ratio_sets_gradient_steps_per_env_step(tmp_path):
    learner = Learner(TrainConfig(steps=4, replay_ratio=0.5, **TINY), "MPG-Stage1-v0", tmp_path, log=lambda s: None)
    learner.run()
    assert learner.counters.iteration == 4 and learner.counters.gradient_steps == 2
    losses = [r[5] for r in _rows(tmp_path)]
    assert sum(loss in ("", "nan") for loss in losses) == 2, losses  # the iterations without a step log no loss


@pytest.mark.parametrize("setting, message", [
    ({"actors": 0}, "actors must be an integer >= 1"),
    ({"actors": 1.5}, "actors must be an integer >= 1"),
    ({"replay_ratio": 0.0}, "replay_ratio must be a positive"),
    ({"replay_ratio": float("inf")}, "replay_ratio must be a positive"),
    ({"weights_refresh": 0}, "weights_refresh must be an integer >= 1"),
    ({"actor_backend": "threads"}, "actor_backend must be one of auto, ray, processes"),
    ({"ray_address": "auto"}, "ray_address is the Ray cluster"),
    ({"actors": 2, "actor_backend": "processes", "ray_address": "auto"}, "ray_address is the Ray cluster"),
])
def test_bad_actor_settings_are_refused(setting, message):
    with pytest.raises(ValueError, match=message):
        TrainConfig(**setting)


def test_ray_backend_without_ray_names_the_extra(monkeypatch, tmp_path, capsys):
    import mpg_agents.learning.actor_pool as actor_pool

    monkeypatch.setattr(actor_pool, "ray_installed", lambda: False)
    assert check_actor_backend(TrainConfig(actors=2)) == "processes"  # auto: processes without Ray
    with pytest.raises(ValueError, match=r"pip install 'mpg-grasp\[ray\]'"):
        check_actor_backend(TrainConfig(actors=2, actor_backend="ray"))
    code = train_main(["--env", "MPG-Stage2-v0", "--actors", "2", "--actor-backend", "ray", "--out", str(tmp_path / "run")])
    assert code == 2 and "pip install 'mpg-grasp[ray]'" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()  # refused before anything was written


def test_ledger_sends_weights_once_per_version_and_hands_out_episodes():
    ledger = ActorLedger(actors=2, refresh=3)
    assert ledger.stale(0, None)
    ledger.publish({"w": torch.zeros(1).numpy()}, None, 0)
    handed = iter(range(10))
    first = ledger.request(0, 0.5, 4, lambda: next(handed))
    assert first.weights is not None and first.weights.version == 1 and first.episode == 0 and first.num_objects == 4
    ledger.received(ActorStep(0, 0, choice=TakenAction(1, "grasp", "greedy")), 50)  # the episode goes on
    again = ledger.request(0, 0.4, 4, lambda: next(handed))
    assert again.weights is None and again.episode is None
    assert ledger.request(1, 0.4, 4, lambda: next(handed)).episode == 1
    assert not ledger.stale(2, None) and ledger.stale(3, None) and ledger.stale(0, 1.5)  # refresh, or a new Q*_g
    ledger.publish({"w": torch.ones(1).numpy()}, 1.5, 3)
    assert ledger.request(0, 0.4, 4, lambda: next(handed)).weights.q_star == 1.5
    from mpg_envs.scenes.generators import InvalidSceneError

    ledger.received(ActorStep(1, 1, skipped="no scene"), 1)
    assert ledger.request(1, 0.4, 4, lambda: next(handed)).episode == 2  # a skipped seed: the next index
    with pytest.raises(InvalidSceneError, match="2 seeds in a row"):
        ledger.received(ActorStep(1, 2, skipped="no scene"), 1)


@pytest.mark.slow
def test_ray_actors_train_a_tiny_run(tmp_path):
    pytest.importorskip("ray")
    code = train_main(["--env", "MPG-Stage2-v0", "--steps", "3", "--actors", "2", "--actor-backend", "ray",
                       "--config", str(_tiny_config(tmp_path)), "--out", str(tmp_path / "run")])
    assert code == 0
    rows = _rows(tmp_path / "run")
    assert [r[0] for r in rows] == ["1", "2", "3"]
    assert json.loads((tmp_path / "run" / "state" / "counters.json").read_text())["gradient_steps"] == 3


def _tiny_config(tmp_path):
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps(TINY))
    return path


def test_an_actor_steps_its_env_with_the_weights_and_trials_it_is_given():
    from mpg_agents.learning.actors import Actor, ActorSpec, ActRequest, Weights, weights_of
    from mpg_agents.learning.training_stages import TRAINING_STAGES, with_overrides

    stage = with_overrides(TRAINING_STAGES, {"Stage5": {
        "env_id": "MPG-Occluded-v0", "objects": [6, 6], "coordination": "grasp_first", "grasp_trials": 2, "alternate_every": 1,
    }})[-1]
    actor = Actor.from_spec(ActorSpec(TrainConfig(**TINY), stage, index=1, start_iteration=0, num_objects=6))
    try:
        with pytest.raises(RuntimeError, match="before it was given weights"):
            actor.step(ActRequest(0.0, 6, 0))
        weights = Weights(1, weights_of(actor.policy), -10.0)  # Q*_g -10: every decision a grasp
        step = actor.step(ActRequest(0.0, 6, 7, weights))
        assert actor.policy.q_star == -10.0 and step.episode == 7 and step.skipped is None
        assert step.choice.primitive == "grasp" and step.choice.chosen_by == "greedy"
        assert len(step.trials) == step.trial_counts.grasp_trials == 2  # its two other orientations, tried and undone
        assert step.info["num_motions"] == 1
        if not step.done:  # the episode goes on: no new index is needed
            again = actor.step(ActRequest(1.0, 6, None))
            assert again.episode == 7 and again.info["num_motions"] == 2
    finally:
        actor.close()


def test_interleaved_episodes_of_actors_end_at_their_last_rows():
    import numpy as np

    from mpg_agents.learning.plotting import window_episode_success

    # Two actors: episodes 0 and 1 interleave; 0 ends (success) at row 3, 1 (failure) at row 4, 2 runs on.
    data = {k: np.array(v, dtype=float) for k, v in {
        "iteration": [1, 2, 3, 4, 5, 6], "episode": [0, 1, 0, 1, 2, 2], "is_success": [0, 0, 1, 0, 0, 0],
    }.items()}
    x, y = window_episode_success(data, 6)
    assert x.tolist() == [6] and y.tolist() == [0.5]
