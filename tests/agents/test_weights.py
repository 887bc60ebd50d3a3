"""The MPGNet weight file (mpg_agents.acting.weights): round trip, architecture checks, no unpickling."""

from __future__ import annotations

import pytest
import torch

from mpg_agents.network.mpgnet import MPGNet
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.acting.weights import load_mpgnet, load_mpgnet_weights, save_mpgnet


def test_checkpoint_roundtrip_and_mismatch(tmp_path, small_net, scene):
    path = tmp_path / "net.safetensors"
    save_mpgnet(small_net, path, q_star=1.25)
    net, header = load_mpgnet(path)
    net.eval()
    assert header["q_star"] == 1.25 and header["variant"] == "small"
    with torch.inference_mode():
        assert torch.equal(net(scene)["grasp"], small_net(scene)["grasp"])
    # Another architecture: a clear error naming the difference.
    with pytest.raises(ValueError, match="variant='small' but this network has variant='large'"):
        load_mpgnet_weights(MPGNet(MPGNetConfig.large(primitives=("grasp",))), path)
    with pytest.raises(ValueError, match="trunk_depth"):
        load_mpgnet_weights(MPGNet(MPGNetConfig.small(trunk_depth=9, primitives=("grasp",))), path)
    # A grasp-only file cannot fill a push branch unless asked to.
    grasp_only = tmp_path / "grasp.safetensors"
    save_mpgnet(MPGNet(MPGNetConfig.small(primitives=("grasp",))), grasp_only)
    target = MPGNet(MPGNetConfig.small(primitives=("push", "grasp")))
    with pytest.raises(ValueError, match=r"missing \['push'\]"):
        load_mpgnet_weights(target, grasp_only)
    load_mpgnet_weights(target, grasp_only, strict_branches=False)
    # Not a safetensors file at all (e.g. a pickle): refused without unpickling.
    bogus = tmp_path / "bogus.safetensors"
    torch.save({"x": torch.zeros(1)}, bogus)
    with pytest.raises(ValueError, match="not a safetensors file"):
        load_mpgnet(bogus)


def test_weights_file_mode_follows_the_umask(tmp_path, small_net):
    """safetensors writes 0600 through a temporary file; the weights get 0666 less the umask."""
    import os

    old = os.umask(0o022)
    try:
        save_mpgnet(small_net, tmp_path / "w.safetensors")
    finally:
        os.umask(old)
    assert (tmp_path / "w.safetensors").stat().st_mode & 0o777 == 0o644


def test_export_keeps_the_weights_and_records_changed_settings(tmp_path, small_net):
    from safetensors.torch import load_file

    from mpg_agents.acting.weights import export_weights, read_checkpoint_header

    src = tmp_path / "net.safetensors"
    save_mpgnet(small_net, src, q_star=1.25)
    dst = export_weights(src, tmp_path / "lean.safetensors", settings={"move_region": "top"})
    header = read_checkpoint_header(dst)
    assert header["config"]["move_region"] == "top" and header["q_star"] == 1.25
    assert header["extra"]["settings_after_training"] == {"move_region": "top"} and header["extra"]["float16"]
    before, after = load_file(str(src)), load_file(str(dst))
    assert before.keys() == after.keys()
    assert all(torch.equal(before[k].half() if before[k].is_floating_point() else before[k], after[k]) for k in before)
    with pytest.raises(ValueError, match=r"\['head_channels'\] change the architecture"):
        export_weights(src, tmp_path / "bad.safetensors", settings={"head_channels": 32})
    # A finger mask set after training, with Q*_g measured under it: training's Q*_g stays on record.
    masked = export_weights(src, tmp_path / "masked.safetensors", settings={"grasp_fingers": "clear"}, q_star=0.5)
    header = read_checkpoint_header(masked)
    assert header["config"]["grasp_fingers"] == "clear" and header["q_star"] == 0.5
    assert header["extra"]["q_star_from_training"] == 1.25
    with pytest.raises(ValueError, match="q_star"):
        export_weights(src, tmp_path / "nan.safetensors", q_star=float("nan"))


def test_a_checkpoint_acts_with_the_coordination_it_records(tmp_path, small_net):
    """The header's coordination (the learner writes its stage's; export may set it) is what a
    loaded policy coordinates with; a header without one gets the paper's workflow."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401
    from mpg_agents.sb3 import MPGNetPolicy
    from mpg_agents.acting.weights import export_weights, read_checkpoint_header

    env = gym.make("MPG-Occluded-v0", num_objects=5)
    src = tmp_path / "net.safetensors"
    save_mpgnet(small_net, src, q_star=0.8)
    assert MPGNetPolicy.from_weights(src, env.observation_space, env.action_space).coordination == "workflow"
    dst = export_weights(src, tmp_path / "gf.safetensors", coordination="grasp_first")
    assert read_checkpoint_header(dst)["extra"]["coordination"] == "grasp_first"
    assert MPGNetPolicy.from_weights(dst, env.observation_space, env.action_space).coordination == "grasp_first"
    given = MPGNetPolicy.from_weights(dst, env.observation_space, env.action_space, coordination="max_q")
    assert given.coordination == "max_q"
    with pytest.raises(ValueError, match="coordination must be one of"):
        export_weights(src, tmp_path / "bad.safetensors", coordination="vote")
    env.close()


def test_mpg_export_cli(tmp_path, small_net, capsys):
    from mpg_agents.cli import export_main
    from mpg_agents.acting.weights import read_checkpoint_header

    src = tmp_path / "net.safetensors"
    save_mpgnet(small_net, src, q_star=0.9)
    dst = tmp_path / "grasp.safetensors"
    assert export_main([str(src), str(dst), "--primitives", "grasp", "--grasp-fingers", "clear", "--q-star", "0"]) == 0
    header = read_checkpoint_header(dst)
    assert header["primitives"] == ["grasp"] and header["q_star"] == 0.0
    assert header["config"]["grasp_fingers"] == "clear" and header["extra"]["q_star_from_training"] == 0.9
    assert "Q*_g 0.0000" in capsys.readouterr().out
    assert export_main([str(tmp_path / "missing.safetensors"), str(dst)]) == 2
    assert export_main([str(src), str(dst), "--q-star", "nan"]) == 2
    assert "--q-star is nan; valid: a number in (-1, 15]" in capsys.readouterr().err
    # A net trained by the largest Q never calibrates Q*_g: its copy says so.
    save_mpgnet(small_net, src)
    assert export_main([str(src), str(dst), "--grasp-fingers", "clear"]) == 0
    assert read_checkpoint_header(dst)["q_star"] is None
    assert "Q*_g none (never calibrated)" in capsys.readouterr().out
