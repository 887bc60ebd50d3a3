"""Weight files under bad input: non-finite weights or Q*_g are refused on load and export, and an
export never overwrites its own source."""

from __future__ import annotations

import json
import warnings

import pytest
import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from mpg_agents.acting.weights import export_weights, load_mpgnet, read_checkpoint_header, save_mpgnet


def rewritten(src, dst, tensors=None, header=None):
    """A copy of ``src`` with some tensors or header fields replaced (as a corrupted file would be)."""
    with safe_open(str(src), framework="pt") as f:
        meta = f.metadata()
    state = load_file(str(src))
    state.update(tensors or {})
    doc = json.loads(meta["mpgnet"])
    doc.update(header or {})
    save_file(state, str(dst), metadata={"mpgnet": json.dumps(doc)})
    return dst


@pytest.fixture
def checkpoint(tmp_path, small_net):
    path = tmp_path / "net.safetensors"
    save_mpgnet(small_net, path, q_star=1.25)
    return path


def test_nan_weights_are_refused_on_load_export_and_eval(tmp_path, checkpoint, capsys):
    from mpg_agents.cli import eval_main, export_main

    key = next(k for k, v in load_file(str(checkpoint)).items() if v.is_floating_point() and k.startswith("branches.grasp"))
    bad = load_file(str(checkpoint))[key].clone()
    bad.view(-1)[0] = float("nan")
    path = rewritten(checkpoint, tmp_path / "nan.safetensors", tensors={key: bad})
    message = rf"checkpoint .*nan\.safetensors has NaN or infinite values in 1 tensor\(s\): {key}; weights must be finite"
    with pytest.raises(ValueError, match=message):
        load_mpgnet(path)
    with pytest.raises(ValueError, match=message):
        export_weights(path, tmp_path / "copy.safetensors")
    assert not (tmp_path / "copy.safetensors").exists()
    assert export_main([str(path), str(tmp_path / "copy.safetensors")]) == 2
    assert eval_main(["--policy", str(path), "--env", "MPG-Stage5-v0", "--episodes", "1", "--quiet"]) == 2
    assert capsys.readouterr().err.count("has NaN or infinite values") == 2


def test_nan_weights_are_never_written(tmp_path, small_net):
    net = type(small_net)(small_net.config)
    with torch.no_grad():
        next(net.parameters()).view(-1)[0] = float("inf")
    with pytest.raises(ValueError, match=r"the MPGNet to be written to .*w\.safetensors has NaN or infinite values"):
        save_mpgnet(net, tmp_path / "w.safetensors")
    assert not (tmp_path / "w.safetensors").exists()


@pytest.mark.parametrize("q_star, shown", [(float("nan"), "nan"), (float("inf"), "inf"), ("high", "'high'")])
def test_a_non_finite_q_star_in_the_header_is_refused(tmp_path, checkpoint, capsys, q_star, shown):
    from mpg_agents.cli import eval_main, export_main

    path = rewritten(checkpoint, tmp_path / "q.safetensors", header={"q_star": q_star})
    message = f"q.safetensors: its header's Q*_g (q_star) is {shown}; valid: a finite number, or null (never calibrated)"
    with pytest.raises(ValueError) as info:
        read_checkpoint_header(path)
    assert message in str(info.value)
    assert export_main([str(path), str(tmp_path / "copy.safetensors")]) == 2
    assert eval_main(["--policy", str(path), "--env", "MPG-Stage5-v0", "--episodes", "1", "--quiet"]) == 2
    assert capsys.readouterr().err.count(message) == 2


def test_null_q_star_stays_the_uncalibrated_record_and_evaluating_it_warns(tmp_path, checkpoint):
    """``null`` is how a checkpoint says it was never calibrated (the next stage reads it); a
    policy that would compare grasp Q with it says what it does instead."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401
    from mpg_agents.evaluation.policy_zoo import make_policy

    path = rewritten(checkpoint, tmp_path / "null.safetensors", header={"q_star": None})
    assert read_checkpoint_header(path)["q_star"] is None
    env = gym.make("MPG-Stage5-v0")
    with pytest.warns(UserWarning, match=r"null\.safetensors carries no Q\*_g \(null: never calibrated\): its 'workflow' "
                                         r"coordination compares the best grasp and push Q instead; pass --q-star"):
        make_policy(str(path), env)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        make_policy(str(path), env, q_star=0.5)
    env.close()


def test_export_never_overwrites_its_source(tmp_path, checkpoint, capsys):
    from mpg_agents.cli import export_main

    before = checkpoint.read_bytes()
    (tmp_path / "sub").mkdir()
    link = tmp_path / "link.safetensors"
    link.symlink_to(checkpoint)
    for dst in (checkpoint, tmp_path / "sub" / ".." / "net.safetensors", link):
        with pytest.raises(ValueError, match=r"the copy .* is the source checkpoint .*; write it to another file"):
            export_weights(checkpoint, dst, primitives=("grasp",))
        assert export_main([str(checkpoint), str(dst), "--primitives", "grasp"]) == 2
        assert "is the source checkpoint" in capsys.readouterr().err
    assert checkpoint.read_bytes() == before
    assert export_main([str(checkpoint), str(tmp_path / "missing" / "copy.safetensors")]) == 2
    assert "missing' does not exist; create it first" in capsys.readouterr().err
