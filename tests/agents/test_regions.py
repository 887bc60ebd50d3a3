"""Where move and grasp may act: hand-checked cases of the region functions."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mpg_agents.network.mpgnet import MPGNet
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_agents.network.regions import footprint_bottom, footprint_top, grasp_pixels, least_blocked, region_max, target_pixels, target_region

from .conftest import calibrate_bn


def _mask(*pixels: tuple[int, int], size: int = 8) -> torch.Tensor:
    m = torch.zeros((1, size, size), dtype=torch.uint8)
    for r, c in pixels:
        m[0, r, c] = 1
    return m


def test_target_region_is_the_bounding_rectangle():
    region = target_region(_mask((2, 1), (4, 3)))[0]
    expected = torch.zeros((8, 8), dtype=torch.bool)
    expected[2:5, 1:4] = True
    assert torch.equal(region, expected)


def test_target_pixels_grow_by_the_margin_only():
    # An L of three pixels: its rectangle has a fourth corner (2, 3) that is not the target.
    mask = _mask((2, 1), (3, 1), (3, 3), (3, 2))
    assert torch.equal(target_pixels(mask, 0)[0], mask[0].bool())
    assert not target_pixels(mask, 0)[0, 2, 3]
    grown = target_pixels(mask, 1)[0]
    expected = torch.zeros((8, 8), dtype=torch.bool)
    expected[1:5, 0:3] = True  # around (2,1) and (3,1)
    expected[2:5, 1:5] = True  # around (3,2) and (3,3)
    assert torch.equal(grown, expected)
    # Growth stops at the image border (no wrap-around).
    corner = target_pixels(_mask((0, 0)), 2)[0]
    assert corner[:3, :3].all() and corner.sum() == 9


def test_empty_mask_leaves_everything_actable():
    empty = _mask()
    assert target_pixels(empty, 3).all() and target_region(empty).all() and target_pixels(empty, -2).all()


def test_negative_margin_keeps_the_interior():
    block = _mask(*[(r, c) for r in range(1, 6) for c in range(1, 7)])  # rows 1-5, cols 1-6
    one = target_pixels(block, -1)[0]
    expected = torch.zeros((8, 8), dtype=torch.bool)
    expected[2:5, 2:6] = True
    assert torch.equal(one, expected)
    two = target_pixels(block, -2)[0]
    expected = torch.zeros((8, 8), dtype=torch.bool)
    expected[3, 3:5] = True  # a 1 x 2 core
    assert torch.equal(two, expected)
    # Too thin to shrink further: the deepest non-empty erosion stays.
    assert torch.equal(target_pixels(block, -5)[0], two)
    line = _mask((4, 2), (4, 3), (4, 4))
    assert torch.equal(target_pixels(line, -3)[0], line[0].bool())


def test_each_part_of_the_mask_shrinks_on_its_own():
    # A 5 x 5 block and, apart from it, a 1-pixel-wide bar: shrinking by 1 keeps the block's
    # 3 x 3 centre and the whole bar (its deepest pixels), not the block alone.
    pixels = [(r, c) for r in range(1, 6) for c in range(1, 6)] + [(r, 8) for r in range(1, 6)]
    shrunk = target_pixels(_mask(*pixels, size=10), -1)[0]
    expected = torch.zeros((10, 10), dtype=torch.bool)
    expected[2:5, 2:5] = True
    expected[1:6, 8] = True
    assert torch.equal(shrunk, expected)


def test_footprint_top_is_what_lies_highest_over_the_target():
    mask = _mask(*[(r, c) for r in range(1, 4) for c in range(1, 4)], size=5)
    depth = torch.zeros((1, 5, 5))
    depth[0, 1:4, 1:4] = 0.03  # the target's top
    depth[0, 2, 2:4] = 0.06  # an occluder over two of its pixels
    depth[0, 0, 0] = 0.20  # higher, but outside the footprint
    expected = torch.zeros((5, 5), dtype=torch.bool)
    expected[2, 2:4] = True
    assert torch.equal(footprint_top(mask, depth, 0.015)[0], expected)
    # A band reaching down to the target's top takes the whole footprint; nothing on top: all of it.
    assert torch.equal(footprint_top(mask, depth, 0.03)[0], mask[0].bool())
    assert torch.equal(footprint_top(mask, torch.where(mask > 0, 0.03, 0.0), 0.0)[0], mask[0].bool())
    # Channel dims are accepted; an empty mask leaves the move unrestricted, as the rectangle does.
    assert torch.equal(footprint_top(mask[:, None], depth[:, None], 0.015)[0], expected)
    assert footprint_top(torch.zeros_like(mask), depth, 0.015).all()


def test_footprint_bottom_is_where_the_target_itself_shows():
    mask = _mask(*[(r, c) for r in range(1, 4) for c in range(1, 4)], size=5)
    depth = torch.zeros((1, 5, 5))
    depth[0, 1:4, 1:4] = 0.03  # the target's top
    depth[0, 2, 2:4] = 0.06  # an occluder over two of its pixels
    depth[0, 0, 0] = 0.0  # lower, but outside the footprint (table)
    expected = mask[0].bool().clone()
    expected[2, 2:4] = False
    assert torch.equal(footprint_bottom(mask, depth, 0.01)[0], expected)
    # A band reaching up to the occluder takes the whole footprint; nothing on top: all of it.
    assert torch.equal(footprint_bottom(mask, depth, 0.03)[0], mask[0].bool())
    assert torch.equal(footprint_bottom(mask, torch.where(mask > 0, 0.03, 0.0), 0.0)[0], mask[0].bool())
    # Covered entirely: the lowest thing over the footprint is the lower occluder.
    covered = torch.where(mask > 0, 0.06, 0.0)
    covered[0, 1, 1:4] = 0.09
    expected = mask[0].bool().clone()
    expected[1, 1:4] = False
    assert torch.equal(footprint_bottom(mask, covered, 0.01)[0], expected)
    assert torch.equal(footprint_bottom(mask[:, None], depth[:, None], 0.01)[0], footprint_bottom(mask, depth, 0.01)[0])
    assert footprint_bottom(torch.zeros_like(mask), depth, 0.01).all()


def test_grasp_pixels_is_the_footprint_or_where_the_target_shows_then_the_margin():
    mask = _mask(*[(r, c) for r in range(1, 6) for c in range(1, 6)], size=7)
    depth = torch.where(mask > 0, 0.03, 0.0)
    depth[0, 1:3, 1:6] = 0.07  # an occluder over the footprint's first two rows
    assert torch.equal(grasp_pixels(mask, depth, 0), target_pixels(mask, 0))
    assert torch.equal(grasp_pixels(mask, depth, -1), target_pixels(mask, -1))
    shows = torch.zeros((7, 7), dtype=torch.bool)
    shows[3:6, 1:6] = True
    assert torch.equal(grasp_pixels(mask, depth, 0, 0.01)[0], shows)
    core = torch.zeros((7, 7), dtype=torch.bool)
    core[4, 2:5] = True  # the visible 3 x 5 part, one pixel off its rim
    assert torch.equal(grasp_pixels(mask, depth, -1, 0.01)[0], core)


@pytest.mark.parametrize("band_region", [footprint_top, footprint_bottom])
def test_footprint_bands_bad_input_is_named(band_region):
    mask = _mask((1, 1))
    with pytest.raises(ValueError, match="band"):
        band_region(mask, torch.zeros((1, 8, 8)), -0.01)
    with pytest.raises(ValueError, match="same shape"):
        band_region(mask, torch.zeros((1, 4, 4)), 0.01)


def test_footprint_top_bad_input_is_named():
    mask = _mask((1, 1))
    with pytest.raises(ValueError, match="band"):
        footprint_top(mask, torch.zeros((1, 8, 8)), -0.01)
    with pytest.raises(ValueError, match="same shape"):
        footprint_top(mask, torch.zeros((1, 4, 4)), 0.01)


def test_region_max_ignores_pixels_outside():
    q = torch.zeros((1, 2, 8, 8))
    q[0, 1, 0, 0] = 9.0  # outside
    q[0, 0, 3, 2] = 0.5  # inside
    assert float(region_max(q, target_pixels(_mask((3, 2)), 0))[0]) == 0.5


def test_region_max_per_rotation():
    q = torch.zeros((1, 2, 8, 8))
    q[0, 1, 3, 2] = 9.0  # barred at rotation 1
    q[0, 0, 3, 2] = 0.5
    where = torch.zeros((1, 2, 8, 8), dtype=torch.bool)
    where[0, 0, 3, 2] = True
    assert float(region_max(q, where)[0]) == 0.5
    assert float(region_max(q, where[:, :1].expand(1, 2, 8, 8).clone())[0]) == 9.0


def _blocked(values: list[list[float]]) -> torch.Tensor:
    """(1, R, 1, W) finger blocking from rows of metres, one row per rotation."""
    return torch.tensor(values)[None, :, None, :]


def test_least_blocked_keeps_the_free_grasps_when_the_target_has_one():
    blocked = _blocked([[-0.01, 0.02, 0.004, 0.006], [0.03, 0.001, -0.02, 0.0]])
    region = torch.tensor([[[True, True, False, False]]])  # the target: the first two pixels
    kept = least_blocked(blocked, region, tolerance=0.005)[0, :, 0]
    # A free grasp exists on the target (-0.01): everything blocked by at most 5 mm is kept.
    assert kept.tolist() == [[True, False, True, False], [False, True, True, True]]


def test_least_blocked_keeps_the_least_blocked_when_none_is_free():
    blocked = _blocked([[0.03, 0.02, -0.05], [0.024, 0.026, 0.0]])
    region = torch.tensor([[[True, True, False]]])
    kept = least_blocked(blocked, region, tolerance=0.005)[0, :, 0]
    # The least blocked on the target is 0.02: kept up to 0.025 (outside the region too).
    assert kept.tolist() == [[False, True, True], [True, False, True]]
    assert least_blocked(blocked, region, tolerance=0.0)[0, :, 0].tolist() == [[False, True, True], [False, False, True]]
    with pytest.raises(ValueError, match="tolerance"):
        least_blocked(blocked, region, tolerance=-0.001)
    with pytest.raises(ValueError, match=r"\(B, R, H, W\)"):
        least_blocked(blocked[0], region, tolerance=0.0)


def test_grasp_region_target_zeroes_grasp_off_the_target(scene):
    mask = np.zeros((224, 224), np.uint8)
    mask[100:140, 90:100] = 1  # an L: its rectangle's far corner is not the target
    mask[130:140, 90:130] = 1
    scene = dict(scene, mask=mask)
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(grasp_region="target", target_margin_px=1))
    calibrate_bn(net, scene)
    with torch.inference_mode():
        maps = net(scene)
    allowed = target_pixels(torch.as_tensor(scene["mask"])[None], 1)[0].numpy()
    rectangle = target_region(torch.as_tensor(scene["mask"])[None])[0].numpy()
    assert (rectangle & ~allowed).any(), "the scene's target fills its rectangle; the test would be vacuous"
    grasp, move = maps["grasp"][0].numpy(), maps["move"][0].numpy()
    assert np.all(grasp[:, ~allowed] == 0) and np.count_nonzero(grasp[:, allowed]) > 0.9 * grasp[:, allowed].size
    # Move keeps the paper's rectangle: it acts on what covers the target.
    assert np.count_nonzero(move[:, rectangle & ~allowed]) > 0
    with pytest.raises(ValueError, match="grasp_region"):
        MPGNetConfig.small(grasp_region="disc")


def _covered_target(scene: dict, net: MPGNet) -> tuple[dict, dict]:
    """``scene`` with a 8 x 8 cm target, an occluder lying on part of it, and ``net``'s Q maps there."""
    mask = np.zeros((224, 224), np.uint8)
    mask[100:140, 90:130] = 1
    depth = np.where(mask > 0, 0.03, 0.0).astype(np.float32)
    depth[110:125, 100:120] = 0.07  # an occluder on the target
    scene = dict(scene, mask=mask, depth=depth)
    calibrate_bn(net, scene)
    with torch.inference_mode():
        return scene, net(scene)


def test_move_region_top_zeroes_move_off_the_occluder(scene):
    torch.manual_seed(0)
    _, maps = _covered_target(scene, MPGNet(MPGNetConfig.small(move_region="top", move_band_m=0.015)))
    occluder = np.zeros((224, 224), bool)
    occluder[110:125, 100:120] = True
    move = maps["move"][0].numpy()
    assert np.all(move[:, ~occluder] == 0) and np.count_nonzero(move[:, occluder]) > 0.9 * move[:, occluder].size
    with pytest.raises(ValueError, match="move_region"):
        MPGNetConfig.small(move_region="disc")
    with pytest.raises(ValueError, match="move_band_m"):
        MPGNetConfig.small(move_band_m=-0.01)


def test_grasp_region_visible_zeroes_grasp_on_what_lies_on_the_target(scene):
    torch.manual_seed(0)
    net = MPGNet(MPGNetConfig.small(grasp_region="visible", target_margin_px=-2, visible_band_m=0.01))
    scene, maps = _covered_target(scene, net)
    shows = torch.as_tensor(scene["mask"] > 0) & torch.as_tensor(scene["depth"] < 0.05)
    allowed = target_pixels(shows[None], -2)[0].numpy()
    assert not allowed[110:125, 100:120].any() and allowed[104, 94] and not allowed[100, 90]  # off the occluder and the rim
    grasp = maps["grasp"][0].numpy()
    assert np.all(grasp[:, ~allowed] == 0) and np.count_nonzero(grasp[:, allowed]) > 0.9 * grasp[:, allowed].size
    with pytest.raises(ValueError, match="visible_band_m"):
        MPGNetConfig.small(visible_band_m=-0.01)
