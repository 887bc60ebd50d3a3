"""The rough target region (paper, Training Details): where move and grasp may act.

Move and grasp Q maps are restricted to the axis-aligned bounding rectangle of the target mask;
:func:`region_max` is the best Q inside it (the grasp score compared with Q*_g).
"""

from __future__ import annotations

import torch
from torch import Tensor


def target_region(mask: Tensor) -> Tensor:
    """Rough target mask ``(B, H, W)`` bool: the mask's axis-aligned bounding rectangle.

    An empty mask (target not visible) gives an all-true region: there is nothing to
    localise, so Q is left unrestricted rather than zeroed everywhere.
    """
    if mask.dim() == 4:
        mask = mask[:, 0]
    mask = mask > 0.5 if mask.dtype != torch.bool else mask
    rows, cols = mask.any(dim=2), mask.any(dim=1)
    h, w = mask.shape[1:]
    ar_h = torch.arange(h, device=mask.device)
    ar_w = torch.arange(w, device=mask.device)

    def span(any_: Tensor, ar: Tensor, n: int) -> Tensor:
        first = torch.where(any_, ar, n).amin(dim=1, keepdim=True)
        last = torch.where(any_, ar, -1).amax(dim=1, keepdim=True)
        inside = (ar >= first) & (ar <= last)
        empty = ~any_.any(dim=1, keepdim=True)
        return inside | empty

    return span(rows, ar_h, h)[:, :, None] & span(cols, ar_w, w)[:, None, :]


def region_max(q: Tensor, region: Tensor) -> Tensor:
    """Max of ``q (B, R, H, W)`` over rotations and the pixels where ``region (B, H, W)`` is true."""
    masked = q.masked_fill(~region[:, None], float("-inf"))
    return masked.flatten(1).amax(dim=1)

