"""Free space on the table as the primitives see it: the highest clutter under the gripper's
footprint around a pixel (what a motion's pre-pose clears), and the most open spot of the
workspace where a moved object is put down, clear of the target."""

from __future__ import annotations

import math

import cv2
import numpy as np

from mpg_envs.grid.workspace import pixel_to_world
from mpg_envs.perception.footprint import footprint_mask
from mpg_envs.simulation.world import World

__all__ = ["clutter_height", "disc_offsets", "free_spot"]


def disc_offsets(radius: float, resolution: float) -> np.ndarray:
    """The ``(row, col)`` offsets of the pixels within ``radius`` metres of a pixel, on a grid of
    ``resolution`` metres per pixel (the radius rounded up to whole pixels), shape ``(n, 2)``."""
    r = int(math.ceil(radius / resolution))
    dr, dc = np.mgrid[-r : r + 1, -r : r + 1]
    inside = dr**2 + dc**2 <= r**2
    return np.stack([dr[inside], dc[inside]], axis=1)


def clutter_height(depth: np.ndarray, row: int, col: int, offsets: np.ndarray) -> float:
    """Highest point of the ``depth`` heightmap under the footprint ``offsets``
    (:func:`disc_offsets`) around pixel ``(row, col)``; offsets past the edge read the edge."""
    rows = np.clip(row + offsets[:, 0], 0, depth.shape[0] - 1)
    cols = np.clip(col + offsets[:, 1], 0, depth.shape[1] - 1)
    return float(depth[rows, cols].max())


def free_spot(
    world: World, held: int, target: int | None, margin: float, clear_of_target: float
) -> tuple[float, float] | None:
    """The most open spot of the workspace (world ``(x, y)``) for the held object ``held``: the
    farthest from every other object's footprint and the workspace's edge, with ``margin`` metres
    free around the object's reach, and its centre ``clear_of_target`` metres beyond that from the
    target's centre; ``None`` when no spot is free."""
    ws = world.workspace
    others = [i for i in world.active_objects() if i != held]
    geoms = np.concatenate([world.object_geom_ids[i] for i in others]) if others else np.array([], dtype=int)
    occupied = footprint_mask(ws, world.model, world.data, geoms) if geoms.size else np.zeros(ws.shape, np.uint8)
    verts = world.assets[held].vertices
    radius = float(np.linalg.norm(verts[:, :2], axis=1).max()) + margin
    free = (occupied == 0).astype(np.uint8)
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = 0  # distances to the workspace edge too
    clearance = cv2.distanceTransform(free, cv2.DIST_L2, 5) * ws.resolution
    ok = clearance > radius
    if target is not None and world.active[target] and target != held:
        tx, ty = world.object_position(target)[:2]
        gx, gy = ws.pixel_centers()
        ok &= np.hypot(gx - tx, gy - ty) > clear_of_target + radius
    if not ok.any():
        return None
    row, col = np.unravel_index(np.argmax(np.where(ok, clearance, -1.0)), ok.shape)
    return pixel_to_world(ws, int(row), int(col))
