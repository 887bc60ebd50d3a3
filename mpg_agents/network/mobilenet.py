"""MobileNetV3 feature trunks (Howard et al., 2019, Tables 1 and 2), written in plain torch.

The module tree mirrors torchvision's ``mobilenet_v3_large`` / ``mobilenet_v3_small``
``features`` submodule so its state-dict keys and shapes are identical
(``features.0.0.weight`` for the stem conv, ``features.N.block.M...`` for the inverted
residual blocks, ``fc1``/``fc2`` inside squeeze-excitation). That lets
:func:`load_torchvision_features` read an ImageNet checkpoint saved from torchvision
without torchvision being installed. Only the convolutional ``features`` are built: MPGNet
is fully convolutional and never uses the classifier.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import cast

import torch
from safetensors.torch import load_file
from torch import Tensor, nn

VARIANTS: tuple[str, ...] = ("large", "small")
"""MobileNetV3 sizes this module builds."""


def make_divisible(value: float, divisor: int = 8) -> int:
    """Round a channel count to a multiple of ``divisor`` without losing more than 10%.

    This is the rounding rule of the reference implementation; the squeeze-excitation widths
    depend on it, so checkpoints only load when it is reproduced exactly.
    """
    rounded = max(divisor, int(value + divisor / 2) // divisor * divisor)
    if rounded < 0.9 * value:
        rounded += divisor
    return rounded


@dataclass(frozen=True)
class BlockSpec:
    """One inverted-residual ("bneck") row of the MobileNetV3 architecture tables."""

    in_channels: int
    kernel: int
    expanded: int
    out_channels: int
    squeeze_excite: bool
    hard_swish: bool
    stride: int


# Rows of Table 1 (large) and Table 2 (small) of the MobileNetV3 paper:
# input channels, kernel, expansion size, output channels, SE, non-linearity (HS/RE), stride.
LARGE_BLOCKS: tuple[BlockSpec, ...] = (
    BlockSpec(16, 3, 16, 16, False, False, 1),
    BlockSpec(16, 3, 64, 24, False, False, 2),
    BlockSpec(24, 3, 72, 24, False, False, 1),
    BlockSpec(24, 5, 72, 40, True, False, 2),
    BlockSpec(40, 5, 120, 40, True, False, 1),
    BlockSpec(40, 5, 120, 40, True, False, 1),
    BlockSpec(40, 3, 240, 80, False, True, 2),
    BlockSpec(80, 3, 200, 80, False, True, 1),
    BlockSpec(80, 3, 184, 80, False, True, 1),
    BlockSpec(80, 3, 184, 80, False, True, 1),
    BlockSpec(80, 3, 480, 112, True, True, 1),
    BlockSpec(112, 3, 672, 112, True, True, 1),
    BlockSpec(112, 5, 672, 160, True, True, 2),
    BlockSpec(160, 5, 960, 160, True, True, 1),
    BlockSpec(160, 5, 960, 160, True, True, 1),
)
SMALL_BLOCKS: tuple[BlockSpec, ...] = (
    BlockSpec(16, 3, 16, 16, True, False, 2),
    BlockSpec(16, 3, 72, 24, False, False, 2),
    BlockSpec(24, 3, 88, 24, False, False, 1),
    BlockSpec(24, 5, 96, 40, True, True, 2),
    BlockSpec(40, 5, 240, 40, True, True, 1),
    BlockSpec(40, 5, 240, 40, True, True, 1),
    BlockSpec(40, 5, 120, 48, True, True, 1),
    BlockSpec(48, 5, 144, 48, True, True, 1),
    BlockSpec(48, 5, 288, 96, True, True, 2),
    BlockSpec(96, 5, 576, 96, True, True, 1),
    BlockSpec(96, 5, 576, 96, True, True, 1),
)
_BLOCKS = {"large": LARGE_BLOCKS, "small": SMALL_BLOCKS}

# The reference batch norm eps (1e-3, the TF default the ImageNet weights were trained with).
_BN_EPS = 1e-3
DEFAULT_BN_MOMENTUM = 0.1
"""PyTorch's default. The ImageNet recipe uses 0.01, which makes the running statistics of a
network trained from scratch lag for hundreds of updates; momentum is not stored in
checkpoints, so either value loads the same weights."""


def full_depth(variant: str) -> int:
    """Number of ``features`` modules of the complete trunk (stem + blocks + last 1x1 conv)."""
    return len(_blocks(variant)) + 2


def _blocks(variant: str) -> tuple[BlockSpec, ...]:
    if variant not in _BLOCKS:
        raise ValueError(f"MobileNetV3 variant must be one of {VARIANTS}, got {variant!r}")
    return _BLOCKS[variant]


class ConvBNAct(nn.Sequential):
    """Conv (no bias) -> BatchNorm -> optional activation; children named ``0``, ``1``, ``2``."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int,
        stride: int = 1,
        groups: int = 1,
        activation: type[nn.Module] | None = nn.Hardswish,
        bn_momentum: float = DEFAULT_BN_MOMENTUM,
    ) -> None:
        layers: list[nn.Module] = [
            nn.Conv2d(
                in_channels,
                out_channels,
                kernel_size,
                stride=stride,
                padding=(kernel_size - 1) // 2,
                groups=groups,
                bias=False,
            ),
            nn.BatchNorm2d(out_channels, eps=_BN_EPS, momentum=bn_momentum),
        ]
        if activation is not None:
            layers.append(activation(inplace=True))
        super().__init__(*layers)

    def forward(self, x: Tensor, first_channel: int = 0) -> Tensor:
        """Conv -> BN -> activation of ``x``; the convolution reads channels
        ``first_channel .. first_channel + in_channels - 1`` of ``x`` (see :func:`window_weight`)."""
        conv, bn = cast(nn.Conv2d, self[0]), cast(nn.BatchNorm2d, self[1])
        window = x.shape[1] != conv.in_channels or first_channel != 0
        if self.training:
            if not window:
                return super().forward(x)
            weight = window_weight(conv.weight, x.shape[1], first_channel)
            y = bn(torch.nn.functional.conv2d(x, weight, None, conv.stride, conv.padding, conv.dilation, conv.groups))
        else:
            weight, bias = self.folded(x.shape[1], first_channel)
            y = torch.nn.functional.conv2d(x, weight, bias, conv.stride, conv.padding, conv.dilation, conv.groups)
        return self[2](y) if len(self) > 2 else y

    def folded(self, channels: int, first_channel: int = 0) -> tuple[Tensor, Tensor]:
        """Inference weight and bias with the batch norm folded into the convolution.

        Exact up to rounding, and it skips a full pass over the activations (BN was ~60% of a
        decision's CPU time). Recomputed on every call: caching it saved nothing measurable on
        the batched path (a few small tensor ops per layer against its convolutions) and would
        have to track every in-place change of weights and statistics.
        """
        conv, bn = cast(nn.Conv2d, self[0]), cast(nn.BatchNorm2d, self[1])
        assert bn.running_var is not None and bn.running_mean is not None  # tracked (the default)
        scale = bn.weight * torch.rsqrt(bn.running_var + bn.eps)
        weight = conv.weight * scale.view(-1, 1, 1, 1)
        bias = bn.bias - bn.running_mean * scale
        if channels != conv.in_channels or first_channel != 0:
            weight = window_weight(weight, channels, first_channel)
            if conv.weight.is_contiguous(memory_format=torch.channels_last):
                weight = weight.contiguous(memory_format=torch.channels_last)  # as the model's own
        return weight, bias


def window_weight(weight: Tensor, channels: int, first_channel: int) -> Tensor:
    """``weight (O, I, k, k)`` zero-padded to ``channels`` inputs, its own at ``first_channel``.

    Lets several trunks read their planes out of one stacked input (colour, depth and mask
    rotated together) without copying channel slices; the extra input channels meet zero
    weights, so the result equals the convolution of the slice. On a CPU it is also the fast
    path: oneDNN's batched convolution of a single-channel input runs 4-8x slower than the
    same convolution of a multi-channel one.
    """
    inputs = weight.shape[1]
    if not 0 <= first_channel <= channels - inputs:
        raise ValueError(
            f"a {inputs}-channel convolution cannot read channels {first_channel}..{first_channel + inputs - 1} "
            f"of a {channels}-channel input"
        )
    return torch.nn.functional.pad(weight, (0, 0, 0, 0, first_channel, channels - inputs - first_channel))


class SqueezeExcite(nn.Module):
    """Channel attention: global pool -> 1x1 reduce -> ReLU -> 1x1 expand -> hard sigmoid."""

    def __init__(self, channels: int, squeezed: int) -> None:
        super().__init__()
        self.fc1 = nn.Conv2d(channels, squeezed, 1)
        self.fc2 = nn.Conv2d(squeezed, channels, 1)

    def forward(self, x: Tensor) -> Tensor:
        scale = torch.nn.functional.adaptive_avg_pool2d(x, 1)
        scale = torch.relu(self.fc1(scale))
        scale = torch.nn.functional.hardsigmoid(self.fc2(scale))
        return x * scale


class InvertedResidual(nn.Module):
    """Expand (1x1) -> depthwise (k x k) -> optional SE -> project (1x1), residual when shapes match."""

    def __init__(self, spec: BlockSpec, bn_momentum: float = DEFAULT_BN_MOMENTUM) -> None:
        super().__init__()
        act: type[nn.Module] = nn.Hardswish if spec.hard_swish else nn.ReLU
        m = bn_momentum
        layers: list[nn.Module] = []
        if spec.expanded != spec.in_channels:
            layers.append(ConvBNAct(spec.in_channels, spec.expanded, 1, activation=act, bn_momentum=m))
        layers.append(
            ConvBNAct(
                spec.expanded,
                spec.expanded,
                spec.kernel,
                spec.stride,
                groups=spec.expanded,
                activation=act,
                bn_momentum=m,
            )
        )
        if spec.squeeze_excite:
            layers.append(SqueezeExcite(spec.expanded, make_divisible(spec.expanded // 4)))
        layers.append(ConvBNAct(spec.expanded, spec.out_channels, 1, activation=None, bn_momentum=m))
        self.block = nn.Sequential(*layers)
        self.residual = spec.stride == 1 and spec.in_channels == spec.out_channels

    def forward(self, x: Tensor) -> Tensor:
        out = self.block(x)
        return out + x if self.residual else out


class MobileNetV3Features(nn.Module):
    """The convolutional trunk of MobileNetV3 (torchvision's ``model.features``).

    Args:
        variant: ``"large"`` or ``"small"``.
        in_channels: channels of the input image (3 for colour; 1 for depth or mask,
            where an ImageNet stem is loaded by summing its RGB kernels).
        depth: how many ``features`` modules to keep, counted from the stem. ``None`` keeps
            the whole trunk (output stride 32). Cutting it earlier gives a cheaper trunk with a
            finer output (e.g. ``small`` with depth 9: output stride 16, 48 channels).
        bn_momentum: batch-norm momentum (:data:`DEFAULT_BN_MOMENTUM`).
    """

    def __init__(
        self,
        variant: str = "large",
        in_channels: int = 3,
        depth: int | None = None,
        bn_momentum: float = DEFAULT_BN_MOMENTUM,
    ) -> None:
        super().__init__()
        blocks = _blocks(variant)
        total = len(blocks) + 2
        if depth is None:
            depth = total
        if not isinstance(depth, int) or not 1 <= depth <= total:
            raise ValueError(f"depth for MobileNetV3-{variant} must be an integer in 1..{total}, got {depth!r}")
        if in_channels < 1:
            raise ValueError(f"in_channels must be positive, got {in_channels}")
        self.variant = variant
        self.in_channels = in_channels
        self.depth = depth
        m = bn_momentum
        layers: list[nn.Module] = [ConvBNAct(in_channels, blocks[0].in_channels, 3, stride=2, bn_momentum=m)]
        layers += [InvertedResidual(spec, bn_momentum=m) for spec in blocks]
        layers.append(ConvBNAct(blocks[-1].out_channels, 6 * blocks[-1].out_channels, 1, bn_momentum=m))
        self.features = nn.Sequential(*layers[:depth])
        self.out_channels = _out_channels(blocks, depth)
        self.output_stride = 2 * math.prod(spec.stride for spec in blocks[: max(0, depth - 1)])
        self._init_weights()

    def _init_weights(self) -> None:
        # The reference initialisation, so training from scratch behaves like torchvision's.
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight, mode="fan_out")
                if module.bias is not None:
                    nn.init.zeros_(module.bias)
            elif isinstance(module, nn.BatchNorm2d):
                nn.init.ones_(module.weight)
                nn.init.zeros_(module.bias)

    def forward(self, x: Tensor, first_channel: int = 0) -> Tensor:
        """Features of ``x (N, C, H, W)``; the stem reads ``in_channels`` planes of ``x`` from
        ``first_channel`` on (``C`` may be larger: e.g. a depth trunk reading plane 3 of a
        stacked colour/depth/mask input)."""
        if x.dim() != 4:
            raise ValueError(f"input must be (N, C, H, W), got shape {tuple(x.shape)}")
        stem, *rest = self.features  # the stem checks the channel window (window_weight)
        x = stem(x, first_channel)
        for layer in rest:
            x = layer(x)
        return x


def _out_channels(blocks: tuple[BlockSpec, ...], depth: int) -> int:
    if depth == 1:
        return blocks[0].in_channels
    if depth <= len(blocks) + 1:
        return blocks[depth - 2].out_channels
    return 6 * blocks[-1].out_channels


def read_state_dict(path: str | Path) -> dict[str, Tensor]:
    """Read a tensor dict from a ``.safetensors`` file or a torch checkpoint, never unpickling code.

    Torch checkpoints are read with ``torch.load(weights_only=True)``, which refuses arbitrary
    pickled objects. A checkpoint wrapping the weights as ``{"state_dict": ...}`` or
    ``{"model": ...}`` is unwrapped.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"checkpoint file not found: {path}")
    if path.suffix == ".safetensors":
        return load_file(str(path))
    try:
        obj = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - re-raised with the file named
        raise ValueError(
            f"cannot read {path} as a torch state_dict with weights_only=True (only tensors are allowed): {exc}"
        ) from exc
    for key in ("state_dict", "model"):
        if isinstance(obj, Mapping) and key in obj and isinstance(obj[key], Mapping):
            obj = obj[key]
    if not isinstance(obj, Mapping) or not all(isinstance(v, Tensor) for v in obj.values()):
        raise ValueError(f"{path} does not hold a state_dict (a mapping of names to tensors)")
    return dict(obj)


def load_torchvision_features(
    trunk: MobileNetV3Features, source: str | Path | Mapping[str, Tensor], prefix: str = "features."
) -> list[str]:
    """Load the ``features.*`` weights of a torchvision MobileNetV3 checkpoint into ``trunk``.

    ``source`` is a path (torch ``state_dict`` file or safetensors) or an in-memory state dict.
    Keys of layers the trunk does not have (a cut trunk, the classifier) are ignored. When the
    trunk's stem takes 1 channel and the checkpoint's takes 3, the RGB kernels are summed,
    which is the same as feeding the grey value replicated to 3 channels.

    Returns:
        The checkpoint keys that were ignored.

    Raises:
        ValueError: a key the trunk needs is missing, or a shape differs (names both).
    """
    state = read_state_dict(source) if isinstance(source, (str, Path)) else dict(source)
    own = trunk.state_dict()
    wanted = {"features." + k[len("features.") :]: v for k, v in own.items()}
    loaded: dict[str, Tensor] = {}
    missing: list[str] = []
    for key, target in wanted.items():
        src_key = prefix + key[len("features.") :]
        if src_key not in state:
            missing.append(src_key)
            continue
        value = state[src_key]
        if key == "features.0.0.weight" and value.shape[1] != target.shape[1] and target.shape[1] == 1:
            value = value.sum(dim=1, keepdim=True)
        if tuple(value.shape) != tuple(target.shape):
            raise ValueError(
                f"checkpoint does not match MobileNetV3-{trunk.variant}: {src_key} has shape "
                f"{tuple(value.shape)}, the trunk needs {tuple(target.shape)} (a checkpoint of the "
                f"other variant, or of another architecture?)"
            )
        loaded[key[len("features.") :]] = value.to(target.dtype)
    if missing:
        raise ValueError(
            f"checkpoint is missing {len(missing)} key(s) MobileNetV3-{trunk.variant} needs, "
            f"e.g. {missing[:3]}; a torchvision mobilenet_v3_{trunk.variant} state_dict has them"
        )
    trunk.features.load_state_dict(loaded, strict=True)
    used = {prefix + k for k in loaded}
    return sorted(k for k in state if k not in used)
