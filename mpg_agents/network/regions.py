"""Where move and grasp may act: the rough target region (paper, Training Details).

Move and grasp Q maps are restricted to the axis-aligned bounding rectangle of the target mask
(:func:`target_region`). A grasp may further be kept on the target itself
(:func:`target_pixels`: the visible target pixels, dilated by a margin): inside the rectangle
of an L-shaped or partly covered target lie other objects, and a grasp there lifts the wrong
one. A grasp may instead be kept where the target itself shows, the lowest surface over its
footprint (:func:`footprint_bottom`), so it closes on the target and not on what lies on it. A
move may be kept on what lies highest over the target (:func:`footprint_top`): the
occluder's top, which is what a move must grasp to carry it away. A grasp may be kept to the
(pixel, angle) pairs whose open fingers land least blocked (:func:`least_blocked`).
:func:`region_max` is the best Q inside a region (the grasp score compared with Q*_g).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor
from torch.nn import functional as F


def _binary(mask: Tensor) -> Tensor:
    """``(B, H, W)`` bool from a 0/1 (or bool) mask, ``(B, H, W)`` or ``(B, 1, H, W)``."""
    if mask.dim() == 4:
        mask = mask[:, 0]
    return mask > 0.5 if mask.dtype != torch.bool else mask


def target_region(mask: Tensor) -> Tensor:
    """Rough target mask ``(B, H, W)`` bool: the mask's axis-aligned bounding rectangle.

    An empty mask (target not visible) gives an all-true region: there is nothing to
    localise, so Q is left unrestricted rather than zeroed everywhere.
    """
    mask = _binary(mask)
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

    Shrinking keeps a grasp off the rim, where closing fingers slip. It is done per connected
    part of the mask (a partly covered target shows several; Stage I's mask holds every
    object): a part too thin to shrink that far keeps its deepest pixels, so no part
    vanishes. An empty mask gives an all-true region, as :func:`target_region` does.
    """
    mask = _binary(mask)
    empty = ~mask.flatten(1).any(dim=1)
    if margin >= 0:
        grown = mask
        if margin:
            grown = F.max_pool2d(mask[:, None].float(), 2 * margin + 1, stride=1, padding=margin)[:, 0] > 0.5
        return grown | empty[:, None, None]
    shrunk = torch.stack([torch.from_numpy(_interior(m, -margin)) for m in mask.cpu().numpy()]).to(mask.device)
    return shrunk | empty[:, None, None]


def _interior(mask: np.ndarray, depth: int) -> np.ndarray:
    """Pixels of ``mask (H, W)`` bool that survive ``depth`` square erosions, per connected part
    (8-connected); a part that would vanish keeps its deepest pixels."""
    binary = np.pad(mask.astype(np.uint8), 1)  # the image border counts as background
    # Chessboard distance to the background: a pixel at distance d survives d - 1 erosions.
    distance = cv2.distanceTransform(binary, cv2.DIST_C, 3)[1:-1, 1:-1]
    parts, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    deepest = np.zeros(parts, dtype=np.float32)
    np.maximum.at(deepest, labels.ravel().astype(np.intp), distance.ravel())
    return mask & (distance >= np.minimum(depth + 1, deepest[labels]))


def grasp_pixels(mask: Tensor, depth: Tensor, margin: int, visible_band: float | None = None) -> Tensor:
    """Where a grasp kept on the target may act, ``(B, H, W)`` bool: the footprint ``mask``, or
    with ``visible_band`` only its part within that height of its lowest surface
    (:func:`footprint_bottom`, in ``depth``'s unit), grown or shrunk by ``margin`` pixels
    (:func:`target_pixels`). The network's grasp region and exploration's grasps both use it."""
    region = mask if visible_band is None else footprint_bottom(mask, depth, visible_band)
    return target_pixels(region, margin)


def footprint_top(mask: Tensor, depth: Tensor, band: float) -> Tensor:
    """The pixels of the target's footprint ``mask`` that lie within ``band`` of the highest
    point of ``depth`` over it, ``(B, H, W)`` bool.

    On an occluded target (something in its footprint stands above it) these are the
    occluder's top: where a move's fingers close around it rather than on the target below or
    on the air beside it. On an uncovered target they are the target's own top. ``depth`` is in
    any unit of height (``band`` in the same unit), ``(B, H, W)`` or ``(B, 1, H, W)``. An empty
    mask gives an all-true region, as :func:`target_region` does.
    """
    return _footprint_band(mask, depth, band, highest=True)


def footprint_bottom(mask: Tensor, depth: Tensor, band: float) -> Tensor:
    """The pixels of the target's footprint ``mask`` that lie within ``band`` of the lowest
    point of ``depth`` over it, ``(B, H, W)`` bool.

    The target lies under what occludes it, so the lowest surface over its footprint is its
    own visible top: where a grasp closes on the target and not on an object lying on it
    (which rises by its own thickness, above ``band``). On an uncovered target these are its
    whole top; on a target covered entirely, the lowest occluder's top. Units, shapes and the
    empty mask as :func:`footprint_top`.
    """
    return _footprint_band(mask, depth, band, highest=False)


def _footprint_band(mask: Tensor, depth: Tensor, band: float, highest: bool) -> Tensor:
    """The footprint's pixels within ``band`` of the highest (or lowest) ``depth`` over it."""
    if band < 0:
        raise ValueError(f"band must be >= 0 (a height range from the footprint's extreme), got {band}")
    mask = _binary(mask)
    if depth.dim() == 4:
        depth = depth[:, 0]
    if depth.shape != mask.shape:
        raise ValueError(f"depth {tuple(depth.shape)} and mask {tuple(mask.shape)} must have the same shape")
    empty = ~mask.flatten(1).any(dim=1)
    if highest:
        top = depth.masked_fill(~mask, float("-inf")).flatten(1).amax(dim=1)
        near = depth >= (top - band)[:, None, None]
    else:
        bottom = depth.masked_fill(~mask, float("inf")).flatten(1).amin(dim=1)
        near = depth <= (bottom + band)[:, None, None]
    return (mask & near) | empty[:, None, None]


def least_blocked(blocked: Tensor, region: Tensor, tolerance: float) -> Tensor:
    """The grasps whose open fingers land least blocked, ``(B, R, H, W)`` bool.

    ``blocked (B, R, H, W)``: how far each grasp's finger strips are blocked (metres, ``<= 0``
    free; :func:`mpg_envs.grid.grasp_geometry.fingers_blocked`); ``region (B, H, W)``: where the
    grasp must land (the target). Kept: every grasp at most ``tolerance`` more blocked than
    the least blocked grasp in the region, counting a free one as 0 -- so the free grasps
    (within ``tolerance``) when the region has one, else the region's least blocked. Pixels
    outside the region are kept or not by the same rule; the region restricts them apart.
    """
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0 metres, got {tolerance}")
    if blocked.dim() != 4 or region.shape != (blocked.shape[0], *blocked.shape[2:]):
        raise ValueError(
            f"blocked must be (B, R, H, W) and region (B, H, W), got {tuple(blocked.shape)} and {tuple(region.shape)}"
        )
    inside = blocked.masked_fill(~region[:, None], float("inf")).flatten(1).amin(dim=1)
    least = inside.clamp(min=0.0) + tolerance
    return blocked <= least[:, None, None, None]


def region_max(q: Tensor, region: Tensor) -> Tensor:
    """Max of ``q (B, R, H, W)`` where ``region`` is true: ``(B, H, W)`` (every rotation at
    those pixels) or ``(B, R, H, W)`` / ``(B, 1, H, W)`` (per rotation)."""
    allowed = region[:, None] if region.dim() == 3 else region
    masked = q.masked_fill(~allowed, float("-inf"))
    return masked.flatten(1).amax(dim=1)
