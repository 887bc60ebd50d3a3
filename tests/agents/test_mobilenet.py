"""MobileNetV3 trunks: torchvision key names/shapes and the checkpoint loader."""

from __future__ import annotations

import pickle

import pytest
import torch
from safetensors.torch import save_file

from torch import nn

from mpg_agents.network.mobilenet import (
    MobileNetV3Features,
    full_depth,
    load_torchvision_features,
    make_divisible,
)

# Known entries of torchvision's mobilenet_v3_{large,small}().features state dicts.
LARGE_KEYS = {
    "features.0.0.weight": (16, 3, 3, 3),
    "features.0.1.running_var": (16,),
    "features.1.block.0.0.weight": (16, 1, 3, 3),  # first block has no expansion conv
    "features.2.block.0.0.weight": (64, 16, 1, 1),
    "features.4.block.1.0.weight": (72, 1, 5, 5),
    "features.4.block.2.fc1.weight": (24, 72, 1, 1),
    "features.4.block.2.fc2.bias": (72,),
    "features.15.block.3.1.weight": (160,),
    "features.16.0.weight": (960, 160, 1, 1),
}
SMALL_KEYS = {
    "features.1.block.1.fc1.weight": (8, 16, 1, 1),
    "features.1.block.2.0.weight": (16, 16, 1, 1),
    "features.9.block.2.fc1.weight": (72, 288, 1, 1),
    "features.12.0.weight": (576, 96, 1, 1),
}


@pytest.mark.parametrize(
    "variant, keys, params, n_keys",
    [("large", LARGE_KEYS, 2_971_952, 308), ("small", SMALL_KEYS, 927_008, 240)],
)
def test_state_dict_matches_torchvision(variant, keys, params, n_keys):
    trunk = MobileNetV3Features(variant)
    state = trunk.state_dict()
    for key, shape in keys.items():
        assert tuple(state[key].shape) == shape, key
    # torchvision's full model minus its classifier has exactly these parameter counts.
    assert sum(p.numel() for p in trunk.parameters()) == params
    assert len(state) == n_keys
    assert trunk.output_stride == 32


def test_forward_shapes_and_cut_trunk():
    x = torch.randn(2, 3, 64, 64)
    assert MobileNetV3Features("small").eval()(x).shape == (2, 576, 2, 2)
    cut = MobileNetV3Features("small", depth=9)
    assert (cut.out_channels, cut.output_stride) == (48, 16)
    assert cut.eval()(x).shape == (2, 48, 4, 4)
    one = MobileNetV3Features("large", in_channels=1, depth=4)
    assert one.eval()(torch.randn(1, 1, 32, 32)).shape == (1, 24, 8, 8)
    with pytest.raises(ValueError, match="depth"):
        MobileNetV3Features("small", depth=full_depth("small") + 1)
    with pytest.raises(ValueError, match="variant"):
        MobileNetV3Features("medium")


def reference_eval(trunk: MobileNetV3Features, x: torch.Tensor) -> torch.Tensor:
    """``trunk`` in eval mode computed as torchvision does (conv, then BN on running
    statistics), by an independent copy, so no folded weights are shared."""
    ref = MobileNetV3Features(trunk.variant, trunk.in_channels, trunk.depth)
    ref.load_state_dict(trunk.state_dict())
    ref.train()  # unfolded conv -> BN -> activation ...
    for module in ref.modules():
        if isinstance(module, nn.BatchNorm2d):
            module.eval()  # ... with BN on its running statistics
    return ref(x)


def train_a_little(trunk: MobileNetV3Features) -> None:
    """Move weights and BN statistics away from their initial values."""
    opt = torch.optim.SGD(trunk.parameters(), lr=0.1)
    for module in trunk.modules():
        if isinstance(module, nn.BatchNorm2d):
            module.momentum = None  # cumulative averages: realistic statistics after two passes
    trunk.train()
    for _ in range(2):
        opt.zero_grad()
        trunk(torch.randn(4, trunk.in_channels, 32, 32)).square().mean().backward()
        opt.step()
    trunk.eval()


def test_stem_reads_a_channel_window_of_a_stacked_input():
    """A depth trunk reading plane 3 of a 5-plane stack equals it on that plane alone."""
    trunk = MobileNetV3Features("small", in_channels=1, depth=4)
    train_a_little(trunk)
    stack = torch.randn(2, 5, 48, 48)
    with torch.no_grad():
        alone = trunk(stack[:, 3:4])
        torch.testing.assert_close(trunk(stack, first_channel=3), alone, rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(alone, reference_eval(trunk, stack[:, 3:4]), rtol=1e-4, atol=1e-5)
    trunk.train()  # training path (BN on batch statistics): the same equality
    torch.testing.assert_close(trunk(stack, first_channel=3), trunk(stack[:, 3:4]), rtol=1e-4, atol=1e-5)
    for bad in (-1, 5):
        with pytest.raises(ValueError, match="channels"):
            trunk(stack, first_channel=bad)


def test_folded_batch_norm_follows_every_change_of_the_weights():
    """Eval mode folds BN into the convolutions: it equals conv -> BN on running statistics
    after every kind of change (optimiser steps in eval mode as in SB3's polyak update of a
    target net, train-mode passes that only move BN statistics, load_state_dict)."""
    trunk = MobileNetV3Features("small", in_channels=3, depth=4)
    train_a_little(trunk)
    x = torch.randn(2, 3, 48, 48)

    def check(mode=torch.no_grad) -> None:
        with mode():
            expected = reference_eval(trunk, x)
            scale = float(expected.abs().max())
            assert scale > 1e-2  # activations of a realistic size, so a stale fold would show
            torch.testing.assert_close(trunk(x), expected, rtol=1e-4, atol=1e-5 * scale)

    check()
    check(torch.inference_mode)
    with torch.no_grad():
        for p in trunk.parameters():
            p.mul_(1.5).add_(0.05)  # in place, still in eval mode
    check()
    train_a_little(trunk)
    check()
    trunk.train()
    with torch.no_grad():
        trunk(3.0 * torch.randn(4, 3, 48, 48))  # new BN statistics only, no weight update
    trunk.eval()
    check()
    other = MobileNetV3Features("small", in_channels=3, depth=4)
    train_a_little(other)
    trunk.load_state_dict(other.state_dict())
    check()
    # With autograd on, eval-mode gradients reach the convolution weights through the fold.
    trunk(x).sum().backward()
    assert trunk.features[0][0].weight.grad is not None and trunk.features[0][0].weight.grad.abs().sum() > 0


def test_make_divisible():
    assert make_divisible(72 // 4) == 24
    assert make_divisible(16 // 4) == 8
    assert make_divisible(960 // 4) == 240


def _torchvision_like_checkpoint(variant: str) -> dict[str, torch.Tensor]:
    """A full torchvision-style state dict (features + classifier) with random values."""
    torch.manual_seed(3)
    ref = MobileNetV3Features(variant)
    state = {
        k: (torch.randn_like(v.float()).to(v.dtype) if v.is_floating_point() else v)
        for k, v in ref.state_dict().items()
    }
    width = ref.out_channels
    state.update({"classifier.0.weight": torch.randn(1280, width), "classifier.3.bias": torch.randn(1000)})
    return state


@pytest.mark.parametrize("suffix", [".pth", ".safetensors"])
def test_loader_reads_torchvision_checkpoint(tmp_path, suffix):
    state = _torchvision_like_checkpoint("small")
    path = tmp_path / f"mobilenet_v3_small{suffix}"
    if suffix == ".pth":
        torch.save(state, path)
    else:
        save_file(state, str(path))
    trunk = MobileNetV3Features("small")
    ignored = load_torchvision_features(trunk, path)
    assert ignored == ["classifier.0.weight", "classifier.3.bias"]
    for key, value in trunk.state_dict().items():
        assert torch.equal(value, state[key]), key
    # A 1-channel (depth/mask) trunk takes the stem's RGB kernels summed.
    grey = MobileNetV3Features("small", in_channels=1, depth=5)
    load_torchvision_features(grey, path)
    assert torch.allclose(grey.state_dict()["features.0.0.weight"], state["features.0.0.weight"].sum(1, keepdim=True))


def test_loader_rejects_other_architectures(tmp_path):
    path = tmp_path / "large.pth"
    torch.save(_torchvision_like_checkpoint("large"), path)
    with pytest.raises(ValueError, match=r"does not match MobileNetV3-small: features\.\S+ has shape"):
        load_torchvision_features(MobileNetV3Features("small"), path)
    torch.save({"features.0.0.weight": torch.zeros(16, 3, 3, 3)}, tmp_path / "partial.pth")
    with pytest.raises(ValueError, match="missing"):
        load_torchvision_features(MobileNetV3Features("small"), tmp_path / "partial.pth")


class _Exploit:
    def __reduce__(self):
        return (print, ("unpickled!",))


@pytest.mark.filterwarnings("ignore:Detected pickle protocol")
def test_loader_never_unpickles_objects(tmp_path):
    path = tmp_path / "evil.pth"
    with open(path, "wb") as f:
        pickle.dump({"features.0.0.weight": _Exploit()}, f)
    with pytest.raises(ValueError, match="weights_only"):
        load_torchvision_features(MobileNetV3Features("small"), path)
