"""The device option: auto | cpu | cuda, checked with clear errors; the learner keeps its
networks and batches on it and its replay's storage on the host (run on CPU here)."""

from __future__ import annotations

import pytest
import torch

from mpg_agents.acting.device import DEVICES, resolve_device
from mpg_agents.cli import eval_main, train_main
from mpg_agents.learning.learner import Learner
from mpg_agents.learning.train_config import TrainConfig

TINY = dict(steps=2, batch_size=1, replay_capacity=8, checkpoint_every=2, net_config={"trunk_depth": 2}, torch_threads=1)


def test_devices_resolve_and_bad_ones_say_what_is_valid(monkeypatch):
    assert DEVICES == ("auto", "cpu", "cuda")
    assert resolve_device("cpu") == torch.device("cpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert resolve_device("auto") == torch.device("cpu")  # CPU without CUDA
    with pytest.raises(ValueError, match="no CUDA"):
        resolve_device("cuda")
    with pytest.raises(ValueError, match=r"one of \('auto', 'cpu', 'cuda'\)"):
        resolve_device("gpu")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert resolve_device("auto") == torch.device("cuda")


def test_the_command_lines_refuse_cuda_without_it_and_unknown_devices(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert train_main(["--env", "MPG-Stage2-v0", "--steps", "1", "--device", "cuda", "--out", str(tmp_path)]) == 2
    assert "no CUDA" in capsys.readouterr().err
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "1", "--device", "cuda"]) == 2
    assert "no CUDA" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        eval_main(["--policy", "random", "--device", "tpu"])


def test_the_learner_trains_on_its_device_with_the_replay_on_the_host(tmp_path):
    learner = Learner(TrainConfig(device="cpu", **TINY), "MPG-Stage2-v0", tmp_path, log=lambda s: None)
    assert learner.device == torch.device("cpu") == learner.policy.device == learner.replay.device
    assert {p.device for p in learner.target_q.parameters()} == {torch.device("cpu")}
    assert learner.run()["iteration"] == 2
    batch = learner.replay.sample(1)
    assert batch.observations["depth"].device == learner.device
    assert isinstance(learner.replay.obs_frames[0, 0].planes["depth"][1], bytes)  # stored compressed, on the host
