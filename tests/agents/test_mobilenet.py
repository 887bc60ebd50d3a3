"""MobileNetV3 trunks: torchvision key names/shapes and the checkpoint loader."""

from __future__ import annotations

import pickle

import pytest
import torch
from safetensors.torch import save_file

from mpg_agents.mobilenet import MobileNetV3Features, full_depth, load_torchvision_features, make_divisible

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
