"""Arranged scenes: blocks placed by design (a target boxed in, walled, ringed, at the edge,
under a tower or a bridge), not dropped.

An :class:`Arrangement` lists blocks (a shape of the ``blocks`` set, a position in millimetres
from the workspace centre, a yaw) and says which is the target; :func:`arrangement_scene`
stacks them in order into a :class:`~mpg_envs.scenes.scene_io.SceneFile` to settle (each block
just above whatever is already under its footprint). The shipped challenge set is written
this way by hand (``benchmarks/make_challenge.py``).

:mod:`mpg_envs.scenes.arrangement_draw` draws arrangements from a seed;
:func:`settle_arrangement` checks that one stands as designed once the physics settles it, and
:class:`ArrangedScenes` (the env's ``arranged`` option) starts a share of an env's resets from
drawn arrangements.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.scene_file import SceneFile, SceneObject
from mpg_envs.scenes.scene_loading import LOAD_TOLERANCE_DEG, LOAD_TOLERANCE_M, pose_errors
from mpg_envs.simulation.blocks import blocks_object_set

GAP = 0.0005
"""A stacked block is placed this far (m) above what it rests on, then settles."""

ARRANGEMENT_KINDS: tuple[str, ...] = (
    "boxed-in",
    "wall",
    "ring",
    "twin",
    "edge",
    "corner",
    "crowd",
    "tower",
    "cover",
    "bridge",
)
"""The kinds :func:`mpg_envs.scenes.arrangement_draw.draw_arrangement` draws, each with probability 1/10."""


@dataclass(frozen=True)
class Block:
    """One block: ``shape`` from the blocks set at ``(x, y)`` mm from the workspace centre,
    turned ``yaw`` degrees about z; ``side=True`` lays it on its side first (turned 90 degrees
    about its own x axis)."""

    shape: str
    x: float
    y: float
    yaw: float = 0.0
    side: bool = False


@dataclass(frozen=True)
class Arrangement:
    """An arranged scene: its blocks (stacked in this order), which one is the target, what
    makes it hard, and the band the target's visible fraction must lie in once settled."""

    name: str
    note: str
    target: int
    blocks: tuple[Block, ...]
    visible: tuple[float, float] = (0.0, 1.0)


@functools.cache
def block_assets() -> dict:
    """The blocks set (seed 0) by shape name: what arrangements are built from."""
    return {a.name: a for a in blocks_object_set()}


def half_extents(shape: str) -> tuple[float, float]:
    """Half extents (mm) of a blocks-set shape along its own x and y, standing as built."""
    if shape not in block_assets():
        raise ValueError(f"unknown block shape {shape!r}; valid: {sorted(block_assets())}")
    v = block_assets()[shape].vertices
    return float(1000 * v[:, 0].max()), float(1000 * v[:, 1].max())


def block_quat(block: Block) -> np.ndarray:
    """Orientation of a block: on its side if asked, then turned by its yaw."""
    quat = np.array([1.0, 0.0, 0.0, 0.0])
    if block.side:
        quat = np.array([math.cos(math.pi / 4), math.sin(math.pi / 4), 0.0, 0.0])
    yaw = np.array([math.cos(math.radians(block.yaw) / 2), 0.0, 0.0, math.sin(math.radians(block.yaw) / 2)])
    out = np.empty(4)
    mujoco.mju_mulQuat(out, yaw, quat)
    return out


def _world_vertices(vertices: np.ndarray, position: np.ndarray, quat: np.ndarray) -> np.ndarray:
    rot = np.empty(9)
    mujoco.mju_quat2Mat(rot, quat)
    return position + vertices @ rot.reshape(3, 3).T


def footprints_overlap(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two point sets' convex footprints (their xy) overlap (separating axis test;
    touching counts as apart)."""
    for points in (a, b):
        hull = points[ConvexHull(points).vertices]
        edges = np.roll(hull, -1, axis=0) - hull
        for normal in np.stack([-edges[:, 1], edges[:, 0]], axis=1):
            pa, pb = a @ normal, b @ normal
            if pa.max() <= pb.min() + 1e-6 or pb.max() <= pa.min() + 1e-6:
                return False
    return True


def arrangement_scene(arrangement: Arrangement, workspace: Workspace = Workspace()) -> SceneFile:
    """The arrangement's blocks stacked in order (each :data:`GAP` above what is under its
    footprint), as a scene to settle.

    Raises:
        ValueError: a block of an unknown shape (the message lists the valid ones).
    """
    assets = block_assets()
    placed: list[np.ndarray] = []
    objects = []
    for k, block in enumerate(arrangement.blocks):
        if block.shape not in assets:
            raise ValueError(
                f"arrangement {arrangement.name!r} block {k}: unknown shape {block.shape!r}; valid: {sorted(assets)}"
            )
        asset = assets[block.shape]
        quat = block_quat(block)
        xy = np.array([workspace.center[0] + block.x / 1000, workspace.center[1] + block.y / 1000])
        verts = _world_vertices(asset.vertices, np.array([*xy, 0.0]), quat)
        below = [p[:, 2].max() for p in placed if footprints_overlap(p[:, :2], verts[:, :2])]
        position = np.array([*xy, max(below, default=0.0) + GAP - verts[:, 2].min()])
        placed.append(_world_vertices(asset.vertices, position, quat))
        objects.append(SceneObject(asset, position, quat, True, f"object {k} ({block.shape!r})"))
    return SceneFile(tuple(objects), arrangement.target, arrangement.name, None, 0, settle=True)


# ------------------------------------------------------------------------------ settling
class ArrangementError(RuntimeError):
    """An arrangement that does not stand as designed once settled (a block toppled or slid,
    or the target's visible fraction is outside the arrangement's band)."""


def check_settled(world, scene: SceneFile, arrangement: Arrangement, visible: float) -> None:
    """Check a settled ``world`` built from ``scene`` (``arrangement_scene(arrangement)``):
    every block within the loading tolerance of its designed pose, and the target's
    ``visible`` fraction in the arrangement's band.

    Raises:
        ArrangementError: what moved and by how much, or the visible fraction and the band.
    """
    distance, angle = pose_errors(world, scene)
    if np.nanmax(distance) > LOAD_TOLERANCE_M or np.nanmax(angle) > LOAD_TOLERANCE_DEG:
        k = int(np.nanargmax(distance / LOAD_TOLERANCE_M + angle / LOAD_TOLERANCE_DEG))
        raise ArrangementError(
            f"{arrangement.name}: {scene.objects[k].label} moved "
            f"{1000 * distance[k]:.1f} mm, {angle[k]:.1f} deg while settling"
        )
    low, high = arrangement.visible
    if not low <= visible <= high:
        raise ArrangementError(
            f"{arrangement.name}: the target is {visible:.2f} visible, outside the band [{low:g}, {high:g}]"
        )


def settle_arrangement(env, arrangement: Arrangement) -> tuple[SceneFile, float]:
    """Load ``arrangement`` into ``env`` (an :class:`~mpg_envs.tasks.env.MPGEnv`; the episode
    it had is lost), let it settle, and check it: every block within the loading tolerance of
    its designed pose, the target's visible fraction in the arrangement's band. Returns the
    settled scene (``env.current_scene()``, ready to save) and the visible fraction.

    Raises:
        ArrangementError: what moved and by how much, or the visible fraction and the band.
    """
    scene = arrangement_scene(arrangement, env.config.workspace)
    _, info = env.reset(options={"scene": scene})
    visible = float(info["visible_fraction"])
    check_settled(env.world, scene, arrangement, visible)
    return env.current_scene(), visible


# ------------------------------------------------------------------------------ env option
@dataclass(frozen=True)
class ArrangedScenes:
    """The env's ``arranged`` option: a share of its generated resets start from an
    arrangement drawn from the episode's generator instead of a drop (training on arranged
    scenes beside dropped ones; test seeds and scene files are unaffected).

    Such a reset starts as its arrangement is designed: its own blocks and object count, the
    target in its kind's visible band, not the env's start condition or band (an arrangement
    that does not stand is drawn again, up to ``tries`` times, then the reset drops a scene as
    usual).

    Attributes:
        share: the probability, in (0, 1], that a generated reset is arranged.
        kinds: the kinds drawn from (default all of :data:`ARRANGEMENT_KINDS`).
        tries: arrangements drawn before falling back to a drop.
    """

    share: float
    kinds: tuple[str, ...] = ARRANGEMENT_KINDS
    tries: int = 20

    def __post_init__(self) -> None:
        if isinstance(self.share, bool) or not isinstance(self.share, (int, float)) or not 0.0 < self.share <= 1.0:
            raise ValueError(f"arranged share must be a number in (0, 1], got {self.share!r}")
        kinds = (self.kinds,) if isinstance(self.kinds, str) else tuple(self.kinds)
        unknown = [k for k in kinds if k not in ARRANGEMENT_KINDS]
        if not kinds or unknown:
            raise ValueError(f"arranged kinds must be a non-empty list of {', '.join(ARRANGEMENT_KINDS)}; got {self.kinds!r}")
        if isinstance(self.tries, bool) or not isinstance(self.tries, int) or self.tries < 1:
            raise ValueError(f"arranged tries must be a positive integer, got {self.tries!r}")
        object.__setattr__(self, "share", float(self.share))
        object.__setattr__(self, "kinds", kinds)

    @classmethod
    def from_option(cls, value: Any) -> ArrangedScenes | None:
        """The option from an env keyword: ``None``, ``False`` or 0 (off), a share, a table of
        the fields (``{"share": 0.3, "kinds": ["ring", "wall"]}``) or an instance.

        Raises:
            ValueError: anything else, or a field out of range (the message says what is valid).
        """
        if value is None or value is False or (isinstance(value, (int, float)) and not isinstance(value, bool) and value == 0):
            return None
        if isinstance(value, cls):
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return cls(float(value))
        if isinstance(value, Mapping):
            unknown = sorted(set(value) - {"share", "kinds", "tries"})
            if unknown or "share" not in value:
                raise ValueError(f"arranged takes a table of share (required), kinds and tries; got {dict(value)!r}")
            return cls(**value)
        raise ValueError(f"arranged must be None, a share in (0, 1] or a table of share, kinds and tries; got {value!r}")
