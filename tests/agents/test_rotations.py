"""Rotation maths (mpg_agents.network.rotations): the padded frame and the sampling grids."""

from __future__ import annotations

import math

import pytest
import torch
from torch.nn import functional as F

from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.network.rotations import padded_side, rotation_grids


def test_padded_side_fits_the_diagonal_in_multiples_of_32():
    assert padded_side(224) == 320  # ceil(224 * sqrt 2) = 317 -> 320
    assert padded_side(32) == 64  # 46 -> 64
    assert padded_side(10, multiple=1) == 15  # ceil(14.14)
    assert MPGNetConfig.small().padded_size == padded_side(224)


def test_grids_of_quarter_turns_land_on_pixel_centres():
    """A 4-pixel frame padded to 4: rotation 0 is the identity, rotation 4 of 16 is a 90-degree turn."""
    grids = rotation_grids(16, 4, 4, "in")
    assert grids.shape == (16, 4, 4, 2)
    img = torch.arange(16.0).view(1, 1, 4, 4)
    same = F.grid_sample(img, grids[0:1], align_corners=True)[0, 0]
    assert torch.allclose(same, img[0, 0], atol=1e-5)
    turned = F.grid_sample(img, grids[4:5], align_corners=True)[0, 0]
    # Output pixel p samples c + R(90 deg)(p - c): (row, col) <- (col, n - 1 - row) in matrix terms.
    assert torch.allclose(turned, torch.rot90(img[0, 0], 1, dims=(0, 1)), atol=1e-5)


def test_out_grids_are_in_coarse_cell_units():
    """Rotation 0 with stride 2: heightmap pixel q (padded frame q + pad) samples cell (q + pad) / 2."""
    size, padded, stride = 4, 8, 2
    grid = rotation_grids(1, size, padded, "out", stride=stride)[0]
    cells = padded // stride
    # Normalised x of the first column: (0 + pad) / stride = 1 cell -> 2 * 1 / (cells - 1) - 1.
    assert grid[0, 0, 0].item() == pytest.approx(2.0 * 1.0 / (cells - 1) - 1.0)
    with pytest.raises(ValueError, match="kind"):
        rotation_grids(1, size, padded, "sideways")


def test_input_rotation_puts_action_direction_along_columns():
    """Rotation k resamples the input so world direction theta_k lies along +column."""
    cfg = MPGNetConfig.small()
    grids = rotation_grids(16, 224, cfg.padded_size, "in")
    centre = (cfg.padded_size - 1) / 2
    for k in (0, 1, 3, 4, 6, 11):
        theta = k * math.pi / 8
        img = torch.zeros(1, 1, cfg.padded_size, cfg.padded_size)
        # A dot 60 px from the centre in direction theta: col = x, row = y.
        row, col = round(centre + 60 * math.sin(theta)), round(centre + 60 * math.cos(theta))
        img[0, 0, row - 1 : row + 2, col - 1 : col + 2] = 1.0
        out = F.grid_sample(img, grids[k : k + 1], align_corners=True)[0, 0]
        r, c = divmod(int(out.argmax()), cfg.padded_size)
        assert abs(r - centre) <= 2 and abs(c - (centre + 60)) <= 2, (k, r, c)


def test_unrotation_inverts_rotation():
    """'out' grids (stride 1) map every heightmap pixel back to where 'in' grids sent it."""
    cfg = MPGNetConfig.small()
    pad = (cfg.padded_size - 224) // 2
    yy, xx = torch.meshgrid(torch.arange(224.0), torch.arange(224.0), indexing="ij")
    img = (torch.sin(xx / 9.0) + torch.cos(yy / 13.0))[None, None]
    padded = F.pad(img, (pad, pad, pad, pad))
    g_in = rotation_grids(16, 224, cfg.padded_size, "in")
    g_out = rotation_grids(16, 224, cfg.padded_size, "out", stride=1)
    for k in range(16):
        rotated = F.grid_sample(padded, g_in[k : k + 1], align_corners=True)
        back = F.grid_sample(rotated, g_out[k : k + 1], align_corners=True)[0, 0]
        err = (back - img[0, 0]).abs()[8:-8, 8:-8].max()
        assert err < (1e-5 if k % 4 == 0 else 0.02), (k, float(err))
