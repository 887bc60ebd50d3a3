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


@pytest.mark.parametrize("q_star, shown", [(float("nan"), "nan"), (float("inf"), "inf"), ("high", "'high'"), (-3, "-3"), (1e9, "1000000000.0")])
def test_a_q_star_out_of_range_in_the_header_is_refused(tmp_path, checkpoint, capsys, q_star, shown):
    from mpg_agents.cli import eval_main, export_main

    path = rewritten(checkpoint, tmp_path / "q.safetensors", header={"q_star": q_star})
    message = (f"q.safetensors: its header's Q*_g (q_star) is {shown}; valid: a number in (-1, 15] (a grasp's Q lies in "
               "what the rewards allow: at or below -1 every grasp passes, and no return exceeds 15), or null (never calibrated)")
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


def test_the_q_star_range_comes_from_the_rewards():
    from mpg_agents.acting.grasp_threshold import check_in_range, q_star_range
    from mpg_envs.tasks.rewards import RewardConfig

    # Grasps earn 1 or 0, a strict mis-pick -1; the longest stage (Stage I) has 15 motions.
    assert q_star_range() == (-1.0, 15.0)
    assert q_star_range(RewardConfig(success=2.0, wrong_object=-0.5)) == (-0.5, 30.0)
    assert check_in_range(0.6) == 0.6 and check_in_range(6.3) == 6.3 and check_in_range(15) == 15.0 and check_in_range(None) is None
    for bad in (-1, -3, 15.5, 1e9):
        with pytest.raises(ValueError, match=r"valid: a number in \(-1, 15\]"):
            check_in_range(bad)


def test_an_out_of_range_q_star_or_target_margin_flag_is_refused_before_any_work(tmp_path, checkpoint, capsys):
    from mpg_agents.cli import eval_main, export_main, train_main

    common = ["--policy", str(checkpoint), "--env", "MPG-Stage5-v0", "--episodes", "1", "--quiet"]
    assert eval_main([*common, "--q-star", "-1"]) == 2
    assert "error: --q-star is -1.0; valid: a number in (-1, 15]" in capsys.readouterr().err
    assert train_main(["--env", "MPG-Stage2-v0", "--out", str(tmp_path / "run"), "--q-star", "-1"]) == 2
    assert "error: --q-star is -1.0; valid: a number in (-1, 15]" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
    assert export_main([str(checkpoint), str(tmp_path / "copy.safetensors"), "--q-star", "16"]) == 2
    assert "error: --q-star is 16.0; valid: a number in (-1, 15]" in capsys.readouterr().err
    assert eval_main([*common, "--target-margin", "1000"]) == 2
    assert "error: --target-margin 1000: target_margin_px must be an integer in [-112, 223] pixels, got 1000" in capsys.readouterr().err
    assert export_main([str(checkpoint), str(tmp_path / "copy.safetensors"), "--target-margin", "-113"]) == 2
    assert "target_margin_px must be an integer in [-112, 223] pixels, got -113" in capsys.readouterr().err
    assert not (tmp_path / "copy.safetensors").exists()


def test_float_weights_resaved_as_integers_are_refused_naming_the_tensor(tmp_path, checkpoint, capsys):
    from mpg_agents.acting.weights import check_tensor_dtypes
    from mpg_agents.cli import eval_main

    state = load_file(str(checkpoint))
    key = next(k for k, v in state.items() if v.is_floating_point() and k.startswith("branches.grasp"))
    path = rewritten(checkpoint, tmp_path / "int.safetensors", tensors={key: state[key].to(torch.int32)})
    message = f"int.safetensors: tensor '{key}' is stored as int32, expected float32 (as training writes weights)"
    for check in (load_mpgnet, check_tensor_dtypes):
        with pytest.raises(ValueError) as info:
            check(path)
        assert message in str(info.value)
    assert eval_main(["--policy", str(path), "--env", "MPG-Stage5-v0", "--episodes", "1", "--quiet"]) == 2
    assert message in capsys.readouterr().err
    # An exported copy stores float16 and says so; its float32 re-save is refused too.
    copy = export_weights(checkpoint, tmp_path / "copy.safetensors")
    check_tensor_dtypes(copy)
    resaved = rewritten(copy, tmp_path / "f32.safetensors", tensors={key: load_file(str(copy))[key].float()})
    with pytest.raises(ValueError, match=rf"tensor '{key}' is stored as float32, expected float16 \(its header says float16: an exported copy\)"):
        load_mpgnet(resaved)


@pytest.mark.parametrize("header, message", [
    ({"config": None}, "its header has no 'config' (a JSON object of MPGNetConfig fields, the network's settings)"),
    ({"primitives": None}, "its header has no 'primitives' (a JSON list of the branches it holds"),
    ({"extra": ["a"]}, "its header's 'extra' is a list; valid: a JSON object (what training and export recorded), or none"),
    ({"config": [1]}, "its header's 'config' is a list; valid: a JSON object of MPGNetConfig fields"),
    ({"primitives": ["jump"]}, "its header's 'primitives': primitives must be a non-empty subset of"),
])
def test_a_header_missing_or_with_a_wrong_field_is_refused_naming_it(tmp_path, checkpoint, capsys, header, message):
    from mpg_agents.cli import eval_main

    path = tmp_path / "h.safetensors"
    with safe_open(str(checkpoint), framework="pt") as f:
        doc = json.loads(f.metadata()["mpgnet"])
    doc.update(header)
    doc = {k: v for k, v in doc.items() if v is not None}
    save_file(load_file(str(checkpoint)), str(path), metadata={"mpgnet": json.dumps(doc)})
    with pytest.raises(ValueError) as info:
        load_mpgnet(path)
    assert f"h.safetensors: {message}" in str(info.value)
    assert eval_main(["--policy", str(path), "--env", "MPG-Stage5-v0", "--episodes", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
