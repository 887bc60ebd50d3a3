"""Behaviour cloning's loss and settings, checked by hand."""

from __future__ import annotations

import math

import pytest
import torch

from mpg_agents.acting.weights import read_checkpoint_header, save_mpgnet
from mpg_agents.imitation.bc_config import BCConfig, bc_acting_config, bc_net_config
from mpg_agents.imitation.bc_loss import imitation_loss, top1_accuracy
from mpg_agents.imitation.bc_training import refuse_held_out
from mpg_agents.imitation.demo_samples import DemoSource
from mpg_agents.network.mpgnet import MPGNet, flat_q
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_envs.simulation.objects import HeldOutObjectsError


def test_the_loss_is_the_cross_entropy_of_the_recorded_action_computed_by_hand():
    # Row 0: logits log 1, log 2, log 3 -> softmax 1/6, 2/6, 3/6; the recorded action 1 costs -log(2/6) = log 3.
    # Row 1: four equal logits -> 1/4 each; action 3 costs log 4.
    logits = torch.tensor([[0.0, math.log(2), math.log(3), -math.inf], [5.0, 5.0, 5.0, 5.0]])
    loss = imitation_loss(logits, torch.tensor([1, 3]))
    assert loss.item() == pytest.approx((math.log(3) + math.log(4)) / 2, abs=1e-6)
    # One row, the recorded action the certain one: no loss.
    assert imitation_loss(torch.tensor([[0.0, -math.inf]]), torch.tensor([0])).item() == pytest.approx(0.0, abs=1e-7)


def test_the_gradient_is_the_softmax_less_the_recorded_one_hot():
    logits = torch.tensor([[0.0, math.log(2), math.log(3)]], requires_grad=True)
    imitation_loss(logits, torch.tensor([2])).backward()
    assert logits.grad is not None
    assert torch.allclose(logits.grad, torch.tensor([[1 / 6, 2 / 6, 3 / 6 - 1]]), atol=1e-6)


def test_top1_accuracy_counts_the_rows_whose_argmax_is_the_recorded_action():
    logits = torch.tensor([[0.0, 1.0, 0.5], [2.0, 1.0, 0.0], [0.0, 0.0, 3.0], [1.0, 0.0, 0.0]])
    assert top1_accuracy(logits, torch.tensor([1, 0, 0, 2])) == pytest.approx(0.5)


def test_bad_logits_or_actions_are_named():
    with pytest.raises(ValueError, match=r"logits must be \(batch, actions\)"):
        imitation_loss(torch.zeros(3), torch.tensor([0]))
    with pytest.raises(ValueError, match="2 rows of logits but 1 actions"):
        imitation_loss(torch.zeros(2, 4), torch.tensor([0]))
    with pytest.raises(ValueError, match=r"actions must lie in 0\.\.3"):
        imitation_loss(torch.zeros(2, 4), torch.tensor([0, 4]))
    with pytest.raises(ValueError, match=r"actions must lie in 0\.\.3"):
        top1_accuracy(torch.zeros(1, 4), torch.tensor([-1]))


def test_settings_are_checked_by_name_and_range():
    assert BCConfig.from_dict({"steps": 5, "batch_size": 2}).steps == 5
    cases = [
        ({"steps": 0}, "steps \\(--steps\\) must be an integer >= 1"),
        ({"demo_episodes": 0}, "demo_episodes \\(--demo-episodes\\) must be an integer >= 1"),
        ({"batch_size": 1.5}, "batch_size must be an integer >= 1"),
        ({"learning_rate": 0}, "learning_rate must be a number > 0"),
        ({"seed": -1}, "seed \\(--seed\\) must be >= 0"),
        ({"variant": "tiny"}, "variant must be 'small' or 'large'"),
        ({"color_input": "yes"}, "color_input must be true or false"),
        ({"quarter_turns": 1}, "quarter_turns must be true or false"),
        ({"grasp_fingers": "free"}, r"grasp_fingers must be one of \('any', 'clear'\)"),
        ({"rotations_per_sample": 0}, "rotations_per_sample must be an integer >= 1"),
        ({"rotations_per_sample": 17}, r"rotations_per_sample must lie in 1..16"),
        ({"device": "tpu"}, "device must be one of"),
        ({"epochs": 3}, r"unknown BCConfig fields \['epochs'\]; valid: \[.*'batch_size'"),
    ]
    for settings, says in cases:
        with pytest.raises(ValueError, match=says):
            BCConfig.from_dict(settings)
    # What a resume must share leaves out where it runs, how often it saves and how long.
    assert set(BCConfig().run_record()) == {
        "demo_episodes",
        "batch_size",
        "learning_rate",
        "seed",
        "variant",
        "color_input",
        "rotations_per_sample",
        "quarter_turns",
    }


def test_the_untrained_net_gives_every_action_the_same_probability():
    """The last layer starts at zero: the first loss is log of the number of actions, whatever is recorded."""
    torch.manual_seed(0)
    net = MPGNet(bc_net_config(BCConfig(), ("grasp",)))
    assert net.primitives == ("grasp",) and not net.config.rough_mask and not net.config.color_input
    net.train()
    obs = {"color": torch.zeros(1, 224, 224, 3, dtype=torch.uint8), "depth": torch.rand(1, 224, 224) * 0.05}
    obs["mask"] = (obs["depth"] > 0.04).to(torch.uint8)
    with torch.no_grad():
        maps = net(obs)
    logits = flat_q(maps, ("grasp",))
    assert logits.shape == (1, 16 * 224 * 224)
    assert imitation_loss(logits, torch.tensor([12345])).item() == pytest.approx(math.log(16 * 224 * 224), abs=1e-5)


def test_the_maps_of_listed_rotations_are_those_of_the_all_rotation_pass():
    """``encode(obs, rotations=(B, K))`` runs just the listed rotations of each sample, in order; their
    maps are the all-rotation pass's at those rotations (up to float rounding of the resampling)."""
    torch.manual_seed(0)
    net = MPGNet(bc_net_config(BCConfig(), ("push", "grasp")))
    for p in net.parameters():  # a head that is not zero, so the maps differ by rotation
        p.data.add_(0.05 * torch.randn_like(p))
    obs = {"color": torch.zeros(2, 224, 224, 3, dtype=torch.uint8), "depth": torch.rand(2, 224, 224) * 0.05}
    obs["mask"] = (obs["depth"] > 0.04).to(torch.uint8)
    net.eval()
    listed = torch.tensor([[5, 0, 12], [3, 15, 8]])
    with torch.no_grad():
        every = net(obs)
        some = net.maps_from(net.encode(obs, rotations=listed), ("push", "grasp"))
    for name in ("push", "grasp"):
        assert some[name].shape == (2, 3, 224, 224)
        for b in range(2):
            assert torch.allclose(some[name][b], every[name][b, listed[b]], atol=1e-4)
    with pytest.raises(ValueError, match=r"rotations must be \(2,\) or \(2, K\) indices in 0..15"):
        net.encode(obs, rotations=torch.tensor([[0, 16], [1, 2]]))


def test_the_checkpoint_acts_with_its_finger_setting_and_nothing_with_weights_may_differ(tmp_path):
    net = MPGNet(bc_net_config(BCConfig(), ("grasp",)))
    assert net.config.grasp_fingers == "any"  # training: every action is a class
    acting = bc_acting_config(BCConfig(), net.config)
    assert acting.grasp_fingers == "clear"
    assert bc_acting_config(BCConfig(grasp_fingers="any"), net.config).grasp_fingers == "any"
    save_mpgnet(net, tmp_path / "w.safetensors", config=acting)
    header = read_checkpoint_header(tmp_path / "w.safetensors")
    assert header["config"]["grasp_fingers"] == "clear" and header["config"]["color_input"] is False
    other = MPGNetConfig.from_checkpoint(net.config.to_dict(), color_input=True)
    with pytest.raises(ValueError, match=r"differs from the net in \['color_input'\]"):
        save_mpgnet(net, tmp_path / "x.safetensors", config=other)
    assert not (tmp_path / "x.safetensors").exists()


def test_demonstrations_of_objects_held_out_for_testing_are_refused():
    """As mpg-train refuses to train on the unseen-object track, behaviour cloning refuses its demonstrations."""
    source = DemoSource(
        folder="d",
        dataset_id="d-v0",
        digest="0",
        env_id="MPG-OccludedHardNovel-v0",
        env_kwargs={"num_objects": 15},
        policy="oracle",
        action_primitives=("move", "push", "grasp"),
        episodes=1,
        total_episodes=1,
        samples=1,
    )
    with pytest.raises(HeldOutObjectsError, match="behaviour cloning on demonstrations recorded on MPG-OccludedHardNovel-v0"):
        refuse_held_out(source)
    on_stage2 = {**source.to_dict(), "env_id": "MPG-Stage2-v0", "env_kwargs": {"object_set": "random_urdfs_test"}}
    with pytest.raises(HeldOutObjectsError, match="held out for testing"):
        refuse_held_out(DemoSource(**on_stage2))
    refuse_held_out(DemoSource(**{**on_stage2, "env_kwargs": {}}))  # the blocks: allowed
