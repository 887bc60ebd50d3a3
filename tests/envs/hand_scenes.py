"""Hand-made MuJoCo scenes for the perception tests: compiling a spec, turning a geom, and the
camera tests' clutter scene (table, boxes, one stacked, convex prisms and a robot stand-in
that no heightmap may see)."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mpg_envs.perception.camera import CameraConfig, CameraHeightmapper

BOX = mujoco.mjtGeom.mjGEOM_BOX


def yaw_quat(deg: float) -> list[float]:
    half = math.radians(deg) / 2
    return [math.cos(half), 0.0, 0.0, math.sin(half)]


def tetra_prism(radius: float, height: float) -> np.ndarray:
    """Vertices of a triangular prism with its base on z = 0 (convex)."""
    angles = np.radians([90.0, 210.0, 330.0])
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    return np.concatenate([np.c_[ring, np.zeros(3)], np.c_[ring, np.full(3, height)]])


def clutter_spec() -> mujoco.MjSpec:
    """Table, six boxes (one stacked, some rotated), three convex mesh prisms and a
    robot-like group-2 geom hovering over the clutter."""
    spec = mujoco.MjSpec()
    world = spec.worldbody
    world.add_geom(
        name="table", type=BOX, size=[0.5, 0.5, 0.05], pos=[0.5, 0.0, -0.05], rgba=[0.6, 0.5, 0.4, 1], group=0
    )
    boxes = [  # (centre x, y, half sizes, yaw deg, rgba)
        (0.40, -0.12, (0.025, 0.025, 0.025), 0.0, (0.12, 0.47, 0.71, 1)),
        (0.52, 0.05, (0.05, 0.0125, 0.0125), 30.0, (1.0, 0.5, 0.05, 1)),
        (0.62, -0.08, (0.03, 0.02, 0.01), 75.0, (0.17, 0.63, 0.17, 1)),
        (0.35, 0.12, (0.0125, 0.0125, 0.04), 10.0, (0.84, 0.15, 0.16, 1)),
        (0.66, 0.15, (0.04, 0.03, 0.015), -20.0, (0.58, 0.4, 0.74, 1)),
    ]
    for i, (x, y, half, yaw, rgba) in enumerate(boxes):
        world.add_geom(
            name=f"box{i}",
            type=BOX,
            size=list(half),
            pos=[x, y, half[2]],
            quat=yaw_quat(yaw),
            rgba=list(rgba),
            group=1,
        )
    # A box resting on box 4 (top at 0.03).
    world.add_geom(
        name="stacked",
        type=BOX,
        size=[0.02, 0.02, 0.015],
        pos=[0.67, 0.16, 0.045],
        quat=yaw_quat(40.0),
        rgba=[0.55, 0.34, 0.29, 1],
        group=1,
    )
    for i, (x, y, r, h, yaw) in enumerate(
        [(0.45, 0.16, 0.035, 0.03, 15.0), (0.58, -0.17, 0.03, 0.05, 70.0), (0.33, -0.02, 0.04, 0.02, -35.0)]
    ):
        spec.add_mesh(name=f"prism{i}", uservert=tetra_prism(r, h).ravel().tolist())
        body = world.add_body(name=f"obj{i}", pos=[x, y, 0.0], quat=yaw_quat(yaw))
        body.add_geom(
            name=f"prism{i}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=f"prism{i}",
            rgba=[0.9, 0.75, 0.1 * i, 1],
            group=1,
        )
    # Robot stand-in: visible to neither heightmap.
    world.add_geom(
        name="robot",
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        size=[0.04, 0.15],
        pos=[0.5, 0.0, 0.25],
        quat=[0.7071068, 0.0, 0.7071068, 0.0],
        rgba=[0.3, 0.3, 0.3, 1],
        group=2,
    )
    return spec


def compile_forward(spec: mujoco.MjSpec) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


def make_cameras(model: mujoco.MjModel, config: CameraConfig) -> CameraHeightmapper:
    """A CameraHeightmapper, or skip the test when no OpenGL context can be created."""
    try:
        return CameraHeightmapper(model, config)
    except RuntimeError as exc:
        pytest.skip(f"no OpenGL context for camera observations: {exc}")
