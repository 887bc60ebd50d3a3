"""The oracle's plans by geometry (``mpg_envs.policies.grasp_plans``) on a hand-made view: a box on
the table, and a tall neighbour in the fingers' way."""

import numpy as np
import pytest

from mpg_envs.grid.workspace import Workspace, world_to_pixel
from mpg_envs.policies.grasp_plans import clip_pixel, plan_grasps, push_options
from mpg_envs.policies.oracle import OracleConfig

WS = Workspace()
CENTRE = np.array([0.5, 0.0])
BOX = CENTRE + np.array([[-0.03, -0.015], [0.03, -0.015], [0.03, 0.015], [-0.03, 0.015]])  # 6 x 3 cm, long along x


class BoxWorld:
    """What the plans read of a world: the workspace and each object's vertices."""

    workspace = WS

    def object_vertices(self, i: int) -> np.ndarray:
        assert i == 0
        return np.column_stack([np.vstack([BOX, BOX]), [0.0] * 4 + [0.03] * 4])


def view(neighbour_at: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Depth and ids: the box 3 cm high; a 10 cm high neighbour 1 cm wide, ``neighbour_at`` metres
    beyond the box's side along +y."""
    gx, gy = WS.pixel_centers()
    depth, ids = np.zeros(WS.shape, np.float32), np.full(WS.shape, -1)
    box = (np.abs(gx - CENTRE[0]) < 0.03) & (np.abs(gy - CENTRE[1]) < 0.015)
    depth[box], ids[box] = 0.03, 0
    if neighbour_at is not None:
        y0 = CENTRE[1] + 0.015 + neighbour_at
        wall = (np.abs(gx - CENTRE[0]) < 0.04) & (gy > y0) & (gy < y0 + 0.01)
        depth[wall], ids[wall] = 0.1, 1
    return depth, ids


def test_clip_pixel_keeps_points_on_the_grid():
    assert clip_pixel(WS, np.array([0.5, 0.0])) == world_to_pixel(WS, 0.5, 0.0)
    rows, cols = WS.shape
    assert clip_pixel(WS, np.array([-5.0, 5.0])) == (rows - 1, 0)
    assert clip_pixel(WS, np.array([5.0, -5.0])) == (0, cols - 1)


def test_a_free_box_is_grasped_across_its_short_side_first():
    plans = plan_grasps(BoxWorld(), 0, *view(), OracleConfig(), 0.04, 0.02)
    best = plans[0]
    assert best.free and best.blockers == () and best.obj == 0
    assert best.rotation == 4 and best.angle_off == pytest.approx(0.0)  # closing along y: pi/2
    assert (best.row, best.col) == world_to_pixel(WS, *CENTRE)
    # Every angle fits the 7.5 cm jaw (the widest, 6.7 cm at 22.5 degrees from x); the short axis first.
    assert len(plans) == 8
    assert [p.rotation for p in plans if p.free][:3] in ([4, 3, 5], [4, 5, 3])
    assert all(p.angle_off >= best.angle_off for p in plans)
    wide = plan_grasps(BoxWorld(), 0, *view(), OracleConfig(max_grasp_width=0.035), 0.04, 0.02)
    # Across the fingers: 6 cm |cos| + 3 cm |sin| of the angle from x; only pi/2 (3 cm) is under 3.5 cm.
    assert [p.rotation for p in wide] == [4]
    assert len(plan_grasps(BoxWorld(), 0, *view(), OracleConfig(max_grasp_width=0.035), 0.04, 0.02, require_fit=False)) == 8


def test_a_neighbour_in_the_fingers_way_blocks_and_is_named():
    depth, ids = view(neighbour_at=0.005)
    plans = plan_grasps(BoxWorld(), 0, depth, ids, OracleConfig(), 0.04, 0.02)
    across = next(p for p in plans if p.rotation == 4)
    assert not across.free and across.blockers == ((1, 1),)  # on the +y side, object 1
    # Least blocked where the jaw's centre slid onto the 10 cm neighbour: the TCP 4 cm below that,
    # the pads' edge 0.5 cm lower, plus 0.4 cm clearance; the wall rises 4.1 cm above it.
    assert across.blocked == pytest.approx(0.1 - (0.1 - 0.04 - 0.005 + 0.004), abs=1e-6)
    assert ids[across.row, across.col] == 1
    assert plans[0].free and plans[0].rotation != 4  # a free angle comes before a blocked one


def test_push_options_push_the_blocker_out_along_the_closing_direction():
    plans = plan_grasps(BoxWorld(), 0, *view(neighbour_at=0.005), OracleConfig(), 0.04, 0.02)
    across = next(p for p in plans if p.rotation == 4)
    config = OracleConfig()
    [(side, start, rotation)] = push_options(BoxWorld(), 0, [across], config)
    assert side == 1 and rotation == 4  # +y is pi/2: rotation 4 of 16
    assert start == pytest.approx(CENTRE + [0.0, 0.015 + config.push_start_gap])
    free = plan_grasps(BoxWorld(), 0, *view(), config, 0.04, 0.02)[0]
    both = push_options(BoxWorld(), 0, [free], config)  # nothing in the way: from both sides
    assert [(s, r) for s, _, r in both] == [(-1, 12), (1, 4)]  # -y is 3 pi / 2: rotation 12
    assert both[0][1] == pytest.approx(CENTRE - [0.0, 0.015 + config.push_start_gap])
