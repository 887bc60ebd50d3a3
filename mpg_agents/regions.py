"""Where move and grasp may act: the rough target region (paper, Training Details).

Move and grasp Q maps are restricted to the axis-aligned bounding rectangle of the target mask
(:func:`target_region`). A grasp may further be kept on the target itself
(:func:`target_pixels`: the visible target pixels, dilated by a margin): inside the rectangle
of an L-shaped or partly covered target lie other objects, and a grasp there lifts the wrong
one. :func:`region_max` is the best Q inside a region (the grasp score compared with Q*_g).
"""

from __future__ import annotations

import torch
from torch import Tensor
from torch.nn import functional as F


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


def target_pixels(mask: Tensor, margin: int) -> Tensor:
    """The target's visible pixels grown (``margin > 0``) or shrunk (``margin < 0``) by
    ``|margin|`` pixels (square neighbourhood), ``(B, H, W)`` bool.

    Shrinking keeps a grasp off the target's rim: a grasp whose fingers close on an edge
    slips. A target too thin to shrink that far keeps its deepest non-empty erosion (at
    least one pixel). An empty mask gives an all-true region, as :func:`target_region` does.
    """
    if mask.dim() == 4:
        mask = mask[:, 0]
    mask = mask > 0.5 if mask.dtype != torch.bool else mask
    empty = ~mask.flatten(1).any(dim=1)
    if margin >= 0:
        grown = mask
        if margin:
            grown = F.max_pool2d(mask[:, None].float(), 2 * margin + 1, stride=1, padding=margin)[:, 0] > 0.5
        return grown | empty[:, None, None]
    region = mask
    for _ in range(-margin):
        # One pixel of erosion: a pixel stays if its 3 x 3 neighbourhood is all target.
        eroded = -F.max_pool2d(-region[:, None].float(), 3, stride=1, padding=1)[:, 0] > 0.5
        keep = eroded.flatten(1).any(dim=1)
        region = torch.where(keep[:, None, None], eroded, region)
    return region | empty[:, None, None]


def region_max(q: Tensor, region: Tensor) -> Tensor:
    """Max of ``q (B, R, H, W)`` over rotations and the pixels where ``region (B, H, W)`` is true."""
    masked = q.masked_fill(~region[:, None], float("-inf"))
    return masked.flatten(1).amax(dim=1)

