"""Where the open fingers land: hand-checked cases of the finger-strip geometry."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpg_envs.grid.grasp_geometry import JawGeometry, finger_landing_kernel, fingers_blocked
from mpg_envs.policies.oracle import OracleConfig

RES = 0.002  # 2 mm pixels, the default workspace's
# A grasp over the table: the tool centre stays at grasp_min_height 0.02, the pads' lower edge
# 5 mm below it, and a strip is free up to 4 mm above that edge: 0.019 m.
TABLE_LIMIT = 0.02 - 0.005 + 0.004


def test_kernel_of_a_jaw_closing_along_x():
    k = finger_landing_kernel(0.0, RES)
    assert k.shape == (55, 55)  # radius ceil(hypot(0.052, 0.013) / 0.002) = 27
    rows, cols = np.nonzero(k)
    # Strips 0.0425..0.052 m along x (pixel centres 22..26 px), 0.013 m to each side (6 px).
    assert sorted(set((cols - 27).tolist())) == [-26, -25, -24, -23, -22, 22, 23, 24, 25, 26]
    assert sorted(set((rows - 27).tolist())) == list(range(-6, 7))
    assert k.sum() == 2 * 5 * 13
    assert np.array_equal(k, k[::-1, ::-1])  # a parallel jaw turned by half a turn is itself
    assert np.array_equal(finger_landing_kernel(math.pi / 2, RES), k.T)  # closing along y: rows and columns swap


def test_free_table_everywhere():
    b = fingers_blocked(np.zeros((40, 60), np.float32), RES, grasp_depth=0.04, grasp_min_height=0.02)
    assert b.shape == (16, 40, 60)
    assert np.allclose(b, -TABLE_LIMIT)


def test_a_neighbour_under_one_finger_blocks_that_angle_only():
    depth = np.zeros((80, 80), np.float32)
    depth[38:43, 62:65] = 0.05  # 24 px to the right (+x) of pixel (40, 40)
    b = fingers_blocked(depth, RES, grasp_depth=0.04, grasp_min_height=0.02)
    assert b[0, 40, 40] == pytest.approx(0.05 - TABLE_LIMIT)  # closing along x: a finger lands on it
    assert b[8, 40, 40] == pytest.approx(0.05 - TABLE_LIMIT)  # the same jaw half a turn later
    assert b[4, 40, 40] == pytest.approx(-TABLE_LIMIT)  # closing along y: both fingers on the table
    assert b[0, 40, 20] == pytest.approx(-TABLE_LIMIT)  # 44 px away: beyond the open fingers


def test_a_tall_target_lifts_the_fingers_above_a_low_neighbour():
    depth = np.zeros((80, 80), np.float32)
    depth[30:51, 30:51] = 0.08  # the target: the tool centre comes down to 0.08 - 0.04 = 0.04
    depth[38:43, 62:65] = 0.03  # a low neighbour under the +x finger
    b = fingers_blocked(depth, RES, grasp_depth=0.04, grasp_min_height=0.02)
    assert b[0, 40, 40] == pytest.approx(0.03 - (0.04 - 0.005 + 0.004))  # -0.009: free
    custom = JawGeometry(finger_clearance=0.0)
    assert fingers_blocked(depth, RES, 0.04, 0.02, jaw=custom)[0, 40, 40] == pytest.approx(0.03 - 0.035)


def test_oracle_plans_with_the_same_jaw():
    jaw, oracle = JawGeometry(), OracleConfig()
    for name in ("finger_open_inner", "finger_thickness", "finger_half_width", "pad_below_tcp", "finger_clearance"):
        assert getattr(oracle, name) == getattr(jaw, name)


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match=r"\(H, W\) heightmap"):
        fingers_blocked(np.zeros((2, 8, 8)), RES, 0.04, 0.02)
    with pytest.raises(ValueError, match="resolution"):
        finger_landing_kernel(0.0, 0.0)
    with pytest.raises(ValueError, match="finger_thickness"):
        JawGeometry(finger_thickness=0.0)
    with pytest.raises(ValueError, match="num_rotations"):
        fingers_blocked(np.zeros((8, 8)), RES, 0.04, 0.02, num_rotations=0)
