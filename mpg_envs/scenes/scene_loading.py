"""Loading a scene file into a world: place every object at its file pose, let the peers'
hand-made poses settle, and check that nothing left the table.

Our own scene files were saved at rest and are placed exactly (bit for bit: the same
observations as when they were saved). The peers' files (``SceneFile.settle``) were made in
another simulator, whose shapes keep about 1 mm of contact margin: their objects float up
to a few millimetres above what holds them, so the physics runs until every object is at
rest. Loading is faithful: every object of every peer file then lies within
:data:`LOAD_TOLERANCE_M` and :data:`LOAD_TOLERANCE_DEG` of its file pose (the largest
measured settling is 5.5 mm, a block on the third layer of a stack, and 4.5 degrees, a
cylinder leaning across two others), stacks stand, and nothing leaves the table.
:func:`pose_errors` measures it.

Before anything is placed the scene's poses and count are checked
(:func:`~mpg_envs.scenes.scene_io.check_scene`); once placed, objects interpenetrating deeper than
:data:`~mpg_envs.scenes.scene_io.PENETRATION_TOLERANCE_M` raise naming the two and the depth
(:func:`interpenetrations`), and so do objects sunk that deep into the table
(:func:`sunk_into_table`), unless the scene is a state the physics itself reached
(``SceneFile.simulated``). :func:`place_scene` does the checks and the placing alone (no
settling): what checking a scene before running it needs.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.scene_file import (
    BELOW_TABLE,
    PENETRATION_TOLERANCE_M,
    SceneFile,
    SceneFileError,
    SceneObject,
    check_scene,
)
from mpg_envs.scenes.scene_io import kept_target, objects_outside, resolve_outside
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.world import World

LOAD_TOLERANCE_M = 0.006
"""How far (m) an object of a settled peer file may lie from its file position."""

LOAD_TOLERANCE_DEG = 6.0
"""How far (degrees) an object of a settled peer file may be turned from its file orientation."""

SETTLE_ROUNDS = 4
"""Settling of a peer file runs up to this many times the physics' usual settling cap."""


def load_scene(
    build_world: Callable[[Sequence[ObjectAsset]], World],
    scene: SceneFile,
    workspace: Workspace,
    drop_outside: bool,
) -> tuple[World, int | None]:
    """Build the world of ``scene`` with ``build_world`` and place its objects; returns the
    world and the target's index in it.

    Objects outside the workspace in the file, or off the table or outside it once
    settled, raise :class:`~mpg_envs.scenes.scene_io.SceneFileError` naming them or, with
    ``drop_outside``, are left out with a warning (the target then is the first kept object
    for a VPG test case, else it raises).
    """
    world, dropped = place_scene(build_world, scene, workspace, drop_outside)
    if scene.settle:
        world.settle(SETTLE_ROUNDS * world.physics.settle_max_steps)
        moved_out = sorted(set(world.objects_out_of_room().tolist()) | set(world.objects_outside_workspace().tolist()))
        positions = np.array([world.object_position(i) for i in moved_out]).reshape(-1, 3)
        resolve_outside(scene, moved_out, workspace, drop_outside, "after settling", positions)
        for i in moved_out:
            world.remove_object(i)
        world.forward()
        dropped = dropped + moved_out
    return world, kept_target(scene, set(dropped))


def place_scene(
    build_world: Callable[[Sequence[ObjectAsset]], World],
    scene: SceneFile,
    workspace: Workspace,
    drop_outside: bool,
) -> tuple[World, list[int]]:
    """Check ``scene``, build its world with ``build_world`` and place its objects at their
    file poses (no settling); returns the world and the objects left out (outside the workspace,
    with ``drop_outside``). What :func:`load_scene` does first, and all a scene needs to be
    checked without running it.

    Raises:
        SceneFileError: a malformed pose, too many objects, objects outside the workspace
            (without ``drop_outside``), or, unless the scene is a state the physics reached
            (``SceneFile.simulated``), objects interpenetrating or sunk into the table deeper
            than :data:`~mpg_envs.scenes.scene_io.PENETRATION_TOLERANCE_M`.
    """
    check_scene(scene)
    dropped = objects_outside(scene, workspace)
    resolve_outside(scene, dropped, workspace, drop_outside, "in the file")
    world = build_world([obj.asset for obj in scene.objects])
    for i, obj in enumerate(scene.objects):
        if obj.active and i not in dropped:
            world.set_object_pose(i, obj.position, obj.quat)
    world.forward()
    if scene.simulated:
        return world, dropped
    valid = f"at most {1000 * PENETRATION_TOLERANCE_M:g} mm is valid"
    deep = interpenetrations(world, PENETRATION_TOLERANCE_M)
    if deep:
        names = [f"{_label(scene, a)} and {_label(scene, b)} by {1000 * d:.1f} mm" for a, b, d in deep]
        raise SceneFileError(
            f"scene {scene.source!r}: objects interpenetrate: {'; '.join(names[:5])}"
            f"{f' (and {len(names) - 5} more pairs)' if len(names) > 5 else ''}; {valid}"
        )
    sunk = sunk_into_table(world, PENETRATION_TOLERANCE_M)
    if sunk:
        names = [f"{_label(scene, i)} by {1000 * d:.1f} mm" for i, d in sunk]
        raise SceneFileError(
            f"scene {scene.source!r}: objects sunk into the table (its top is z = 0): {'; '.join(names)}; {valid}"
        )
    return world, dropped


def _label(scene: SceneFile, i: int) -> str:
    return scene.objects[i].label or f"object {i}"


def sunk_into_table(world: World, tolerance: float = 0.0) -> list[tuple[int, float]]:
    """``(object, depth in m)`` for each active object of ``world`` whose lowest point lies
    deeper than ``tolerance`` below the table top (the plane z = 0), deepest first. An object
    whose centre lies off the table's footprint (fallen to the floor) is not in it."""
    sunk = []
    for i in world.active_objects():
        depth = -float(world.object_vertices(int(i))[:, 2].min())
        if depth > tolerance and world.object_position(int(i))[2] >= BELOW_TABLE:
            sunk.append((int(i), depth))
    return sorted(sunk, key=lambda t: -t[1])


def interpenetrations(world: World, tolerance: float = 0.0) -> list[tuple[int, int, float]]:
    """``(object a, object b, depth in m)`` for each pair of objects of ``world`` whose deepest
    contact goes deeper than ``tolerance``, deepest first (MuJoCo's contacts of the last
    ``forward``). MuJoCo finds no contact between two shapes placed exactly on each other, so
    active objects whose centres lie within 1 mm count too, as deep as the smaller of their
    smallest extents."""
    deepest: dict[tuple[int, int], float] = {}
    for c in world.data.contact[: world.data.ncon]:
        a, b = int(world.object_of_geom(int(c.geom1))), int(world.object_of_geom(int(c.geom2)))
        if a >= 0 and b >= 0 and a != b and -float(c.dist) > tolerance:
            key = (min(a, b), max(a, b))
            deepest[key] = max(deepest.get(key, 0.0), -float(c.dist))
    active = world.active_objects()
    centres = np.array([world.object_position(i) for i in active]).reshape(-1, 3)
    for k, m in np.argwhere(np.triu(np.linalg.norm(centres[:, None] - centres[None], axis=2) < 1e-3, 1)):
        a, b = int(active[k]), int(active[m])
        extent = min(float(np.ptp(world.object_vertices(i), axis=0).min()) for i in (a, b))
        if (a, b) not in deepest and extent > tolerance:
            deepest[(a, b)] = extent
    return sorted(((a, b, d) for (a, b), d in deepest.items()), key=lambda t: -t[2])


def pose_errors(world: World, scene: SceneFile) -> tuple[np.ndarray, np.ndarray]:
    """How far each object of ``world`` lies from its pose in ``scene``: ``(distance in
    metres, angle in degrees)`` per object, NaN for objects not in the world."""
    distance = np.full(len(scene.objects), np.nan)
    angle = np.full(len(scene.objects), np.nan)
    for i, obj in enumerate(scene.objects):
        if i >= world.num_objects or not world.active[i]:
            continue
        position, quat = world.object_pose(i)
        distance[i] = float(np.linalg.norm(position - np.asarray(obj.position, float)))
        target = np.asarray(obj.quat, float) / np.linalg.norm(obj.quat)
        relative = np.empty(4)
        mujoco.mju_mulQuat(relative, quat, target * np.array([1.0, -1.0, -1.0, -1.0]))
        angle[i] = float(np.degrees(2.0 * np.arctan2(np.linalg.norm(relative[1:]), abs(relative[0]))))
    return distance, angle


def scene_of(world: World, target: int | None, stage: str | None = None, object_set_seed: int = 0) -> SceneFile:
    """A world's current scene (every object's asset, pose and state, the target), as
    :func:`mpg_envs.scenes.scene_io.save_scene` writes it."""
    objects = tuple(
        SceneObject(asset, *world.object_pose(i), active=bool(world.active[i]), label=f"object {i} ({asset.name!r})")
        for i, asset in enumerate(world.assets)
    )
    return SceneFile(objects, target, "", stage, object_set_seed, simulated=True)
