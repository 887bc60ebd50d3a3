"""Which heightmap rays can hit a moving geom (pure geometry on MuJoCo's arrays).

The ray caster (:class:`~mpg_envs.perception.heightmap.RaycastHeightmapper`) aims one nearly
vertical ray at each pixel centre. A geom can only be hit by the rays of the pixels under
its bounding box, so rays elsewhere see only the geoms that never move (the table), whose
result is the same in every scene. :func:`world_boxes` gives geoms' world-frame bounding
boxes from ``MjModel.geom_aabb`` (exact for meshes: the box of their vertices) and the geoms'
poses; :func:`pixels_under_boxes` the pixels whose rays may pass through any of them,
allowing for the rays' slant.
"""

from __future__ import annotations

import numpy as np

from mpg_envs.grid.workspace import Workspace

__all__ = ["pixels_under_boxes", "world_boxes"]


def world_boxes(aabb: np.ndarray, xpos: np.ndarray, xmat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-frame axis-aligned boxes ``(lo, hi)``, each ``(N, 3)``, that hold geoms whose
    local boxes are ``aabb`` (``(N, 6)``: centre then half-sizes, as ``MjModel.geom_aabb``)
    at positions ``xpos`` (``(N, 3)``) and orientations ``xmat`` (``(N, 9)`` or ``(N, 3, 3)``)."""
    aabb = np.asarray(aabb, np.float64).reshape(-1, 6)
    rot = np.asarray(xmat, np.float64).reshape(-1, 3, 3)
    centre = np.asarray(xpos, np.float64).reshape(-1, 3) + np.einsum("nij,nj->ni", rot, aabb[:, :3])
    half = np.einsum("nij,nj->ni", np.abs(rot), aabb[:, 3:])
    return centre - half, centre + half


def pixels_under_boxes(workspace: Workspace, lo: np.ndarray, hi: np.ndarray, slant: float) -> np.ndarray:
    """``(H, W)`` bool: the pixels whose rays may pass through a box ``[lo[k], hi[k]]``.

    A pixel's ray aims at its centre on the plane ``z = workspace.z_min``; at height ``z``
    above that plane it is off by at most ``slant * (z - z_min)`` (``slant``: the largest
    horizontal-to-vertical ratio of the rays), so each box is grown by that at its top and by
    one pixel besides, then every pixel whose cell meets it is marked (a superset of the
    pixels whose rays can reach the box).
    """
    rows, cols = workspace.shape
    mask = np.zeros((rows, cols), dtype=bool)
    lo, hi = np.asarray(lo, np.float64).reshape(-1, 3), np.asarray(hi, np.float64).reshape(-1, 3)
    if lo.shape[0] == 0:
        return mask
    grow = workspace.resolution + slant * np.maximum(np.abs(hi[:, 2] - workspace.z_min), np.abs(lo[:, 2] - workspace.z_min))
    res = workspace.resolution
    # Pixel k covers [min + k * res, min + (k + 1) * res): the cells meeting [a, b] are k in
    # [floor((a - min) / res), ceil((b - min) / res)).
    c0 = np.clip(np.floor((lo[:, 0] - grow - workspace.x_min) / res), 0, cols).astype(int)
    c1 = np.clip(np.ceil((hi[:, 0] + grow - workspace.x_min) / res), 0, cols).astype(int)
    r0 = np.clip(np.floor((lo[:, 1] - grow - workspace.y_min) / res), 0, rows).astype(int)
    r1 = np.clip(np.ceil((hi[:, 1] + grow - workspace.y_min) / res), 0, rows).astype(int)
    for a, b, c, d in zip(r0, r1, c0, c1):
        mask[a:b, c:d] = True
    return mask
