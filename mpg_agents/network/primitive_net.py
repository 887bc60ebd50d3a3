"""One primitive's Q-network: colour and depth MobileNetV3 trunks and a Q head.

:class:`~mpg_agents.network.mpgnet.MPGNet` holds one :class:`PrimitiveNet` per primitive next to the
mask trunk they share. Every net reads its planes from one stacked, rotated input tensor
(:data:`PLANES`).
"""

from __future__ import annotations

from typing import Any, cast

import torch
from torch import Tensor, nn

from mpg_agents.network.mobilenet import MobileNetV3Features
from mpg_agents.network.mpgnet_config import MPGNetConfig

# The input planes, stacked on channels and rotated together; each trunk's stem reads its own
# channels from the stack (mobilenet.window_weight), so no plane is copied out of it (5 channels).
PLANES: dict[str, int] = {"color": 0, "depth": 3, "mask": 4}


class QHead(nn.Sequential):
    """Two 1x1 convolutions with batch norm and ReLU (VPG's pre-activation order), 1 output channel.

    BN -> ReLU -> conv(C -> hidden) -> BN -> ReLU -> conv(hidden -> 1): the last layer is
    linear so Q can be negative (the move and push rewards go down to -0.5). With
    ``dilation`` > 0 the first convolution is 3x3 with that dilation (padding keeps the size):
    each Q value then also reads the features ``dilation`` cells away on every side. Every
    convolution starts He-normal (VPG's); ``zero_output`` starts the last one at zero, so the
    untrained head answers Q = 0 everywhere (see ``MPGNetConfig.head_init``).
    """

    def __init__(self, in_channels: int, hidden: int, dilation: int = 0, zero_output: bool = False) -> None:
        first = (
            nn.Conv2d(in_channels, hidden, 3, padding=dilation, dilation=dilation, bias=False)
            if dilation
            else nn.Conv2d(in_channels, hidden, 1, bias=False)
        )
        super().__init__(
            nn.BatchNorm2d(in_channels),
            nn.ReLU(inplace=True),
            first,
            nn.BatchNorm2d(hidden),
            nn.ReLU(inplace=True),
            nn.Conv2d(hidden, 1, 1),
        )
        for module in self.modules():
            if isinstance(module, nn.Conv2d):
                nn.init.kaiming_normal_(module.weight)
        if zero_output:
            out = cast(nn.Conv2d, self[-1])
            assert out.bias is not None  # made with a bias above
            nn.init.zeros_(out.weight)
            nn.init.zeros_(out.bias)


class PrimitiveNet(nn.Module):
    """One primitive's Q-network: colour trunk (unless ``config.color_input`` is off), depth
    trunk and head (the mask trunk is shared)."""

    def __init__(self, config: MPGNetConfig, mask_channels: int) -> None:
        super().__init__()
        self.config = config
        self.color_trunk = (
            MobileNetV3Features(config.variant, 3, config.trunk_depth, config.bn_momentum) if config.color_input else None
        )
        # Depth and mask are single-channel: a 1-channel stem is equivalent to replicating them to
        # 3 channels (an ImageNet stem is loaded by summing its RGB kernels) and 3x cheaper.
        self.depth_trunk = MobileNetV3Features(config.variant, 1, config.trunk_depth, config.bn_momentum)
        color_channels = self.color_trunk.out_channels if self.color_trunk is not None else 0
        channels = color_channels + self.depth_trunk.out_channels + mask_channels
        self.head = QHead(channels, config.head_channels, config.head_dilation, zero_output=config.head_init == "zero")

    @property
    def trunks(self) -> tuple[MobileNetV3Features, ...]:
        """This net's own trunks (colour when it reads colour, depth)."""
        return tuple(t for t in (self.color_trunk, self.depth_trunk) if t is not None)

    def forward(self, planes: Tensor, mask_features: Tensor) -> Tensor:
        """Coarse Q map ``(N, 1, h, w)`` from rotated, padded input planes (:data:`PLANES`) and
        mask-trunk features."""
        size = trunk_chunk(self.config, self.training, planes)
        features = [run_in_batches(self.depth_trunk, planes, size, first_channel=PLANES["depth"]), mask_features]
        if self.color_trunk is not None:
            features.insert(0, run_in_batches(self.color_trunk, planes, size, first_channel=PLANES["color"]))
        return self.head(torch.cat(features, dim=1))


def trunk_chunk(config: MPGNetConfig, training: bool, planes: Tensor) -> int | None:
    """How many rotated images go through a trunk at once: all in training and on an
    accelerator (which wants one large batch), ``config.trunk_batch`` at inference on the CPU
    (where small batches keep the activations in cache)."""
    return None if training or planes.device.type != "cpu" else config.trunk_batch


def run_in_batches(module: nn.Module, x: Tensor, size: int | None, **kwargs: Any) -> Tensor:
    """``module(x, **kwargs)`` computed ``size`` samples at a time (all at once for ``None``)."""
    if size is None or x.shape[0] <= size:
        return module(x, **kwargs)
    return torch.cat([module(part, **kwargs) for part in x.split(size)], dim=0)
