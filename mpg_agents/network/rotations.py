"""Rotation maths of MPGNet: the padded frame and the sampling grids of the 16 orientations.

Conventions of :mod:`mpg_envs.grid.workspace`: for rotation ``k`` the input is resampled so that
the world direction ``theta_k = 2 pi k / R`` (from +x = increasing column toward +y =
increasing row) becomes the +column direction of the rotated image. Pure functions (numpy in,
tensors out), used by :class:`mpg_agents.network.mpgnet.MPGNet` and unit-tested on small frames.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor


def padded_side(size: int, multiple: int = 32) -> int:
    """Side of the padded heightmap: ``ceil(size * sqrt 2)`` rounded up to ``multiple``, so no
    corner of a ``size`` square is cut off by any rotation about the centre."""
    return int(math.ceil(math.ceil(size * math.sqrt(2.0)) / float(multiple)) * multiple)


def rotation_grids(num_rotations: int, size: int, padded: int, kind: str, stride: int = 1) -> Tensor:
    """Sampling grids for ``F.grid_sample(..., align_corners=True)``.

    ``kind="in"``: ``(R, S, S, 2)``; rotated image pixel ``p`` samples the padded input at
    ``c + R(theta_k) (p - c)`` so world direction ``theta_k`` becomes +column.
    ``kind="out"``: ``(R, H, W, 2)``; heightmap pixel ``q`` (padded frame ``q + pad``) samples
    the coarse map of rotation ``k`` at ``(c + R(-theta_k)(q + pad - c)) / stride`` in cell units.
    Angles are computed in float64 so multiples of 90 degrees land exactly on pixel centres.
    """
    pad = (padded - size) // 2
    centre = (padded - 1) / 2.0
    k = np.arange(num_rotations)
    theta = k * 2.0 * np.pi / num_rotations
    cos, sin = np.cos(theta), np.sin(theta)
    # Snap the exact cases (cos/sin of multiples of 90 degrees) to remove 6e-17 residues.
    cos = np.where(np.abs(cos) < 1e-12, 0.0, cos)
    sin = np.where(np.abs(sin) < 1e-12, 0.0, sin)
    if kind == "in":
        coords = np.arange(padded, dtype=np.float64) - centre
        n_src, sign = padded, 1.0
    elif kind == "out":
        coords = np.arange(size, dtype=np.float64) + pad - centre
        n_src, sign = padded // stride, -1.0
    else:
        raise ValueError(f"kind must be 'in' or 'out', got {kind!r}")
    gy, gx = np.meshgrid(coords, coords, indexing="ij")  # rows = y, cols = x
    c, s = cos[:, None, None], sign * sin[:, None, None]
    src_x = c * gx - s * gy + centre
    src_y = s * gx + c * gy + centre
    if kind == "out":
        src_x, src_y = src_x / stride, src_y / stride
    # align_corners=True: index 0 -> -1, index n-1 -> +1.
    norm = lambda v: 2.0 * v / (n_src - 1) - 1.0  # noqa: E731
    grid = np.stack([norm(src_x), norm(src_y)], axis=-1)
    return torch.from_numpy(grid.astype(np.float32))
