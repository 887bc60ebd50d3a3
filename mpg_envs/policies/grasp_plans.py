"""The oracle's plans by geometry (no trials): each grasp of an object at the 8 angles with how badly
the open fingers land (:func:`plan_grasps`, a :class:`GraspPlan` each) and the pushes that open a
finger gap beside the target (:func:`push_options`), on the simulator's view of a world (its depth
heightmap and which object each pixel shows)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from mpg_envs.grid.grasp_geometry import (
    GRASP_ROTATIONS,
    angle_gap,
    angle_to_rotation,
    extent_along,
    footprint_rect,
    jaw_strip_heights,
)
from mpg_envs.grid.workspace import Workspace, world_to_pixel

if TYPE_CHECKING:  # the world loads mujoco, which this module does not
    from mpg_envs.simulation.world import World

__all__ = ["GraspPlan", "PlanGeometry", "clip_pixel", "plan_grasps", "push_options"]


class PlanGeometry(Protocol):
    """The sizes the plans are made with, metres (e.g. :class:`mpg_envs.policies.oracle.OracleConfig`):
    read-only, so frozen dataclasses qualify."""

    @property
    def max_grasp_width(self) -> float:
        """Wider than this across the fingers: not graspable."""
        ...

    @property
    def finger_open_inner(self) -> float:
        """An open finger's inner face, from the jaw's centre."""
        ...

    @property
    def finger_thickness(self) -> float:
        """A finger's thickness along the closing direction."""
        ...

    @property
    def finger_half_width(self) -> float:
        """Half a pad's width across the jaw."""
        ...

    @property
    def offset_step(self) -> float:
        """The jaw slides along the closing direction in steps of this."""
        ...

    @property
    def finger_margin(self) -> float:
        """The swept strip starts this far off the object's side."""
        ...

    @property
    def pad_below_tcp(self) -> float:
        """The pads' lower edge lies this far below the TCP."""
        ...

    @property
    def finger_clearance(self) -> float:
        """A strip is free if nothing in it rises above the pads' lower edge + this."""
        ...

    @property
    def push_start_gap(self) -> float:
        """A push starts this far outside the target's edge."""
        ...


@dataclass(frozen=True)
class GraspPlan:
    """One grasp of one object: angle index (0..7), pixel, and how badly the fingers collide."""

    obj: int
    rotation: int
    row: int
    col: int
    blocked: float  # metres the highest thing under the open fingers rises above their lower edge (<= 0: free)
    blockers: tuple[tuple[int, int], ...]  # (side, object) pairs in the fingers' way
    angle_off: float  # radians from the object's short axis

    @property
    def free(self) -> bool:
        return self.blocked <= 0.0


def clip_pixel(workspace: Workspace, xy: np.ndarray) -> tuple[int, int]:
    """The pixel of world point ``xy``, clipped into ``workspace``'s grid."""
    rows, cols = workspace.shape
    r, c = world_to_pixel(workspace, float(xy[0]), float(xy[1]))
    return int(np.clip(r, 0, rows - 1)), int(np.clip(c, 0, cols - 1))


def plan_grasps(
    world: World,
    i: int,
    depth: np.ndarray,
    ids: np.ndarray,
    c: PlanGeometry,
    grasp_depth: float,
    grasp_min_height: float,
    require_fit: bool = True,
) -> list[GraspPlan]:
    """Grasps of object ``i`` of ``world`` at the 8 angles, best first: free ones nearest the short
    axis, then the least blocked. At each angle the jaw slides along the closing direction (the
    open fingers span 85 mm) to where both fingers come down on free space. ``depth`` and ``ids``:
    the view (heights, the object each pixel shows); ``grasp_depth``, ``grasp_min_height``: how the
    grasp primitive sets its height (:class:`~mpg_envs.simulation.primitives.PrimitiveConfig`);
    ``require_fit``: skip angles wider than ``max_grasp_width``."""
    ws = world.workspace
    verts = world.object_vertices(i)[:, :2]
    centre, _, short_dir = footprint_rect(verts)
    gx, gy = ws.pixel_centers()
    reach = c.finger_open_inner + c.finger_thickness
    plans = []
    for k in range(GRASP_ROTATIONS):
        theta = k * math.pi / GRASP_ROTATIONS
        d = np.array([math.cos(theta), math.sin(theta)])
        n = np.array([-d[1], d[0]])
        lo, hi = extent_along(verts, centre, d)
        width = hi - lo
        if require_fit and width > c.max_grasp_width:
            continue
        nlo, nhi = extent_along(verts, centre, n)
        mid = centre + d * (lo + hi) / 2 + n * (nlo + nhi) / 2
        max_offset = max(0.0, c.finger_open_inner - width / 2 - c.finger_margin)
        rel_x, rel_y = gx - mid[0], gy - mid[1]
        s, t = rel_x * d[0] + rel_y * d[1], rel_x * n[0] + rel_y * n[1]
        band = (np.abs(t) <= c.finger_half_width) & (np.abs(s) <= reach + max_offset)
        sb, hb, ib = s[band], depth[band], ids[band]
        best = None
        for offset in sorted(np.arange(-max_offset, max_offset + 1e-9, c.offset_step).tolist() + [0.0], key=abs):
            row, col = clip_pixel(ws, mid + offset * d)
            z = max(float(depth[row, col]) - grasp_depth, grasp_min_height)
            limit = z - c.pad_below_tcp + c.finger_clearance
            heights = jaw_strip_heights(sb, hb, width, offset, c.finger_open_inner, c.finger_thickness, c.finger_margin)
            blocked = max(heights) - limit
            if best is None or blocked < best[0] - 1e-4:
                best = (blocked, offset, row, col, limit)
            if blocked <= 0:
                break
        assert best is not None  # the offsets tried include 0.0: at least one
        blocked, offset, row, col, limit = best
        edge = width / 2 + c.finger_margin
        in_low = (sb <= -edge) & (sb >= offset - reach) & (hb > limit)
        in_high = (sb >= edge) & (sb <= offset + reach) & (hb > limit)
        blockers = [
            (side, int(j)) for side, sel in ((-1, in_low), (1, in_high)) for j in np.unique(ib[sel]) if j >= 0 and j != i
        ]
        plans.append(GraspPlan(i, k, row, col, blocked, tuple(blockers), angle_gap(theta, short_dir)))
    # Free first, nearest the short axis; then the least blocked.
    return sorted(plans, key=lambda p: (not p.free, p.angle_off if p.free else p.blocked, p.angle_off))


def push_options(world: World, target: int, plans: list[GraspPlan], c: PlanGeometry) -> list[tuple[int, np.ndarray, int]]:
    """Pushes that open a finger gap, as ``(side, start, rotation)``: each blocker of the target's
    grasp ``plans`` pushed straight out along the closing direction, from ``push_start_gap``
    outside the target's edge (both sides of a plan with no blocker); least blocked angles first."""
    verts = world.object_vertices(target)[:, :2]
    options = []
    for p in sorted(plans, key=lambda p: p.blocked):
        theta = p.rotation * math.pi / GRASP_ROTATIONS
        for side in sorted({s for s, _ in p.blockers}) or (-1, 1):
            d = side * np.array([math.cos(theta), math.sin(theta)])
            centre = verts.mean(axis=0)
            _, reach = extent_along(verts, centre, d)
            start = centre + d * (reach + c.push_start_gap)
            rotation = angle_to_rotation(math.atan2(d[1], d[0]) % (2 * math.pi), symmetric=False)
            options.append((side, start, rotation))
    return options
