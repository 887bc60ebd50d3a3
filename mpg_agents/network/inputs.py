"""MPGNet's inputs: raw observations validated, batched and normalised.

Colour uint8 ``(H, W, 3)`` or channels-first, depth in metres, mask 0/1; numpy arrays or
tensors, batched or not. Bad shapes and non-finite depth raise naming the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from torch import Tensor

from mpg_agents.network.mpgnet_config import MPGNetConfig


def batched_inputs(obs: Mapping[str, Any], size: int, device: torch.device) -> tuple[Tensor, Tensor, Tensor, Tensor | None]:
    """Validate and bring ``color``/``depth``/``mask`` to ``(B, C, H, W)`` tensors."""
    missing = [k for k in ("color", "depth", "mask") if k not in obs]
    if missing:
        raise KeyError(f"observation lacks {missing}; MPGNet needs 'color', 'depth' and 'mask'")
    color = torch.as_tensor(np.asarray(obs["color"]) if not isinstance(obs["color"], Tensor) else obs["color"])
    depth = torch.as_tensor(np.asarray(obs["depth"]) if not isinstance(obs["depth"], Tensor) else obs["depth"])
    mask = torch.as_tensor(np.asarray(obs["mask"]) if not isinstance(obs["mask"], Tensor) else obs["mask"])
    originals = {"color": tuple(color.shape), "depth": tuple(depth.shape), "mask": tuple(mask.shape)}
    expected = {
        "color": f"({size}, {size}, 3), (B, {size}, {size}, 3) or (B, 3, {size}, {size})",
        "depth": f"({size}, {size}), (B, {size}, {size}) or (B, 1, {size}, {size})",
        "mask": f"({size}, {size}), (B, {size}, {size}) or (B, 1, {size}, {size})",
    }

    def bad(key: str) -> ValueError:
        return ValueError(f"observation '{key}' has shape {originals[key]}; expected {expected[key]}")

    single = color.dim() == 3  # one unbatched observation: (H, W, 3) or (3, H, W)
    if single:
        color = color.unsqueeze(0)
    if color.dim() != 4:
        raise bad("color")
    if color.shape[-1] == 3 and color.shape[1] != 3:
        color = color.permute(0, 3, 1, 2)
    if tuple(color.shape[1:]) != (3, size, size):
        raise bad("color")
    planes = []
    for key, t in (("depth", depth), ("mask", mask)):
        if single and t.dim() == 2:
            t = t.unsqueeze(0)
        if t.dim() == 3:
            t = t.unsqueeze(1)
        if t.dim() != 4 or tuple(t.shape[1:]) != (1, size, size):
            raise bad(key)
        planes.append(t)
    depth, mask = planes
    if not color.shape[0] == depth.shape[0] == mask.shape[0]:
        raise ValueError(f"batch sizes differ: color {color.shape[0]}, depth {depth.shape[0]}, mask {mask.shape[0]}")
    occluded = None
    if "occluded" in obs:
        occ = obs["occluded"]
        occ = torch.as_tensor(np.asarray(occ) if not isinstance(occ, Tensor) else occ)
        occluded = occ.reshape(color.shape[0], -1)[:, 0].to(device) > 0.5
    return color.to(device), depth.to(device), mask.to(device), occluded


def normalize_inputs(
    obs: Mapping[str, Any], cfg: MPGNetConfig, color_mean: Tensor, color_std: Tensor
) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor | None]:
    """Normalised ``color (B,3,H,W)``, ``depth (B,1,H,W)``, ``mask (B,1,H,W)`` float tensors,
    the binary mask and the ``occluded`` flags (``None`` when absent).

    Colour: uint8 is divided by 255 (float input is taken to be on the same 0..255 scale,
    which is what SB3 hands over when ``normalize_images=False``), then ImageNet mean/std.
    Depth: clipped to ``[0, depth_max]`` m, then ``(d - depth_mean) / depth_std``.
    Mask: binarised at 0.5.
    """
    color, depth, mask, occluded = batched_inputs(obs, cfg.heightmap_size, color_mean.device)
    color = (color.float() / 255.0 - color_mean) / color_std
    depth = depth.float()
    if not torch.isfinite(depth).all():
        raise ValueError("observation 'depth' contains NaN or infinite values; fill holes before acting")
    depth = (depth.clamp(0.0, cfg.depth_max) - cfg.depth_mean) / cfg.depth_std
    binary = mask > 0.5 if mask.dtype != torch.bool else mask
    return color, depth, binary.float(), binary[:, 0], occluded
