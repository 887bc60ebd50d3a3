"""mpg-bc-to-q: a behaviour-cloning net's logits mapped onto the return scale by one affine map
(hand-checked), written into the heads' last layers exactly, anchored on its demonstrations,
and the result starts reinforcement learning."""

from __future__ import annotations

import json
import os

import gymnasium as gym
import numpy as np
import pytest
import torch

import mpg_envs  # noqa: F401
from mpg_agents.acting.agent import batch_observation
from mpg_agents.acting.weights import read_checkpoint_header
from mpg_agents.evaluation.policy_zoo import shipped_checkpoint
from mpg_agents.imitation.logits_to_q import LogitAnchors, affine_map, logits_to_q, main, rescale_heads
from mpg_agents.network.mpgnet import MPGNet, flat_q
from mpg_agents.network.mpgnet_config import MPGNetConfig


def test_the_map_sends_the_typical_logit_to_zero_and_the_demonstrated_one_to_the_value():
    # typical -1, demonstrated 19: a spread of 20, so a = 1/20 and b = 1/20 (Q = (logit + 1) / 20).
    a, b = affine_map(-1.0, 19.0)
    assert a == pytest.approx(0.05) and b == pytest.approx(0.05)
    assert a * -1.0 + b == pytest.approx(0.0) and a * 19.0 + b == pytest.approx(1.0)
    a, b = affine_map(2.0, 6.0, value=2.0)  # spread 4, value 2: a = 0.5, b = -1
    assert (a, b) == pytest.approx((0.5, -1.0))


@pytest.mark.parametrize("demonstrated", [3.0, 2.0])
def test_a_net_that_does_not_prefer_its_demonstrations_gives_no_scale(demonstrated):
    with pytest.raises(ValueError, match="not above the median logit"):
        LogitAnchors(typical=3.0, demonstrated=demonstrated, samples=8).scale_offset()


def test_rescaled_heads_answer_the_affine_map_of_every_branch_at_every_pixel():
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.for_variant("small", primitives=("move", "push", "grasp"), color_input=False, rough_mask=False))
    env = gym.make("MPG-OccludedHard-v0", num_objects=8)
    obs, _ = env.reset(seed=700000)
    env.close()
    batch, _ = batch_observation(obs)
    net.eval()
    primitives = ("move", "push", "grasp")
    with torch.no_grad():
        before = flat_q(net(batch, primitives), primitives)
        rescale_heads(net, 0.25, -0.5)
        after = flat_q(net(batch, primitives), primitives)
    assert torch.allclose(after, 0.25 * before - 0.5, atol=1e-5)
    with pytest.raises(ValueError, match="scale must be > 0"):
        rescale_heads(net, -1.0, 0.0)


def test_a_checkpoint_not_made_by_behaviour_cloning_is_refused(tmp_path):
    with pytest.raises(ValueError, match="not a behaviour-cloning checkpoint"):
        logits_to_q(shipped_checkpoint(), tmp_path, tmp_path / "q.safetensors")


def test_a_cloned_net_becomes_a_starting_q_network_that_reinforcement_learning_trains(tmp_path, capsys):
    if not os.environ.get("CI"):  # the demos extra: .ci/install installs it
        pytest.importorskip("minari")
    from mpg_agents.acting.weights import load_mpgnet_weights  # noqa: PLC0415
    from mpg_agents.cli import train_main  # noqa: PLC0415
    from mpg_agents.demos.cli import main as demos_main  # noqa: PLC0415
    from mpg_agents.demos.dataset import dataset_digest  # noqa: PLC0415
    from mpg_agents.imitation.demo_samples import DemoSamples  # noqa: PLC0415
    from mpg_agents.imitation.logits_to_q import measure_anchors  # noqa: PLC0415

    demos = tmp_path / "demos"
    record = ["--policy", "oracle", "--env", "MPG-Stage2-v0", "--num-objects", "2", "--episodes", "3", "--seed", "5"]
    assert demos_main([*record, "--quiet", "--out", str(demos)]) == 0
    bc = tmp_path / "bc"
    config = tmp_path / "bc.toml"
    config.write_text("batch_size = 4\nlearning_rate = 0.001\nrotations_per_sample = 16\nquarter_turns = false\n")
    bc_command = ["--baseline", "bc", "--demos", str(demos), "--out", str(bc), "--steps", "4", "--config", str(config)]
    assert train_main(bc_command) == 0
    capsys.readouterr()
    start = tmp_path / "start.safetensors"
    assert main([str(bc / "weights.safetensors"), str(start), "--demos", str(demos), "--samples", "5"]) == 0
    printed = json.loads(capsys.readouterr().out.splitlines()[-1])
    header = read_checkpoint_header(start)
    assert header["extra"]["logits_to_q"] == printed and printed["demos_digest"] == dataset_digest(demos)
    assert printed["scale"] > 0 and printed["median_demonstrated_logit"] > printed["median_logit"]
    # Measured again on the written net: the same samples now give the anchors 0 and 1.
    net = MPGNet(MPGNetConfig.from_checkpoint(header["config"], grasp_fingers="any"))
    load_mpgnet_weights(net, start)
    samples = DemoSamples(demos)
    indices = np.unique(np.linspace(0, len(samples) - 1, min(5, len(samples))).round().astype(np.int64))
    again = measure_anchors(net, samples, ("grasp",), indices)
    assert again.typical == pytest.approx(0.0, abs=1e-4) and again.demonstrated == pytest.approx(1.0, abs=1e-4)
    # Reinforcement learning starts from it (the cloned net's mask input: no rough mask).
    rl_config = tmp_path / "rl.json"
    rl_config.write_text(json.dumps({"net_config": {"rough_mask": False, "color_input": False}, "torch_threads": 1}))
    run = tmp_path / "rl"
    command = ["--env", "MPG-Stage2-v0", "--init", str(start), "--config", str(rl_config), "--steps", "2", "--out", str(run)]
    assert train_main(command) == 0
    assert (run / "weights.safetensors").is_file()
    # Anchored on the dataset it was cloned from only.
    other = tmp_path / "other"
    assert demos_main([*record[:-1], "6", "--quiet", "--out", str(other)]) == 0
    assert main([str(bc / "weights.safetensors"), str(tmp_path / "x.safetensors"), "--demos", str(other)]) == 2
    assert "is not the dataset" in capsys.readouterr().err
    # Mapped once only: a second map would scale it again.
    assert main([str(start), str(tmp_path / "again.safetensors"), "--demos", str(demos)]) == 2
    assert "already mapped onto the return scale" in capsys.readouterr().err
    assert not (tmp_path / "again.safetensors").exists()
