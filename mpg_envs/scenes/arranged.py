"""Arranged scenes: blocks placed by design (a target boxed in, walled, ringed, at the edge,
under a tower or a bridge), not dropped.

An :class:`Arrangement` lists blocks (a shape of the ``blocks`` set, a position in millimetres
from the workspace centre, a yaw) and says which is the target; :func:`arrangement_scene`
stacks them in order into a :class:`~mpg_envs.scenes.scene_io.SceneFile` to settle (each block
just above whatever is already under its footprint). The shipped challenge set is written
this way by hand (``benchmarks/make_challenge.py``).

:func:`draw_arrangement` draws one from a seed: one of :data:`ARRANGEMENT_KINDS`, its shapes,
gaps (1-3 mm for the tight kinds), turn and place in the workspace, and a few loose blocks
elsewhere. It is pure and deterministic per seed; whether a drawn arrangement stands once
the physics settles it is the builder's check (``benchmarks/make_arranged.py``). Seeds
follow the project's convention: training and calibration use a run's own seeds, tuning
700000-; the peers' arranged cases and the challenge set are the tests and are never drawn
from.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.spatial import ConvexHull

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.scene_io import SceneFile, SceneObject
from mpg_envs.simulation.blocks import blocks_object_set

GAP = 0.0005
"""A stacked block is placed this far (m) above what it rests on, then settles."""

ARRANGEMENT_KINDS: tuple[str, ...] = ("boxed-in", "wall", "ring", "twin", "edge", "corner", "crowd", "tower", "cover", "bridge")
"""What :func:`draw_arrangement` can draw, each with probability 1/10."""

_STREAM = 0x41524E47  # keeps these draws apart from every other use of the same seed
_TIGHT_GAP_MM = (1.0, 3.0)
_COMPACT = ("cube", "cylinder", "disc", "tall_box")
_POSTS = ("tall_box", "cube", "cylinder")


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
def _assets() -> dict:
    return {a.name: a for a in blocks_object_set()}


def half_extents(shape: str) -> tuple[float, float]:
    """Half extents (mm) of a blocks-set shape along its own x and y, standing as built."""
    if shape not in _assets():
        raise ValueError(f"unknown block shape {shape!r}; valid: {sorted(_assets())}")
    v = _assets()[shape].vertices
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
    assets = _assets()
    placed: list[np.ndarray] = []
    objects = []
    for k, block in enumerate(arrangement.blocks):
        if block.shape not in assets:
            raise ValueError(f"arrangement {arrangement.name!r} block {k}: unknown shape {block.shape!r}; valid: {sorted(assets)}")
        asset = assets[block.shape]
        quat = block_quat(block)
        xy = np.array([workspace.center[0] + block.x / 1000, workspace.center[1] + block.y / 1000])
        verts = _world_vertices(asset.vertices, np.array([*xy, 0.0]), quat)
        below = [p[:, 2].max() for p in placed if footprints_overlap(p[:, :2], verts[:, :2])]
        position = np.array([*xy, max(below, default=0.0) + GAP - verts[:, 2].min()])
        placed.append(_world_vertices(asset.vertices, position, quat))
        objects.append(SceneObject(asset, position, quat, True, f"object {k} ({block.shape!r})"))
    return SceneFile(tuple(objects), arrangement.target, arrangement.name, None, 0, settle=True)


# ------------------------------------------------------------------------------ drawing
# Layouts are made in a local frame (mm, the target at the origin, yaws multiples of 90 so
# footprints are axis-aligned rectangles), then turned and moved into the workspace.


@dataclass
class _Layout:
    blocks: list[tuple[str, float, float, float]]  # shape, x, y, yaw (local)
    note: str
    visible: tuple[float, float]
    anchor: str = "free"  # free | edge | corner: how it is put in the workspace

    def rect(self, i: int) -> tuple[float, float, float, float]:
        shape, x, y, yaw = self.blocks[i]
        hx, hy = half_extents(shape)
        return (x, y, hy, hx) if round(yaw / 90) % 2 else (x, y, hx, hy)

    def clear(self, shape: str, x: float, y: float, yaw: float, gap: float = 1.0) -> bool:
        hx, hy = half_extents(shape)
        if round(yaw / 90) % 2:
            hx, hy = hy, hx
        return all(abs(x - cx) >= hx + ax + gap or abs(y - cy) >= hy + ay + gap for cx, cy, ax, ay in map(self.rect, range(len(self.blocks))))

    def put_beside(self, shape: str, direction: tuple[float, float], gap: float, yaw: float, along: float = 0.0) -> bool:
        """Put ``shape`` ``gap`` mm beyond the target's side or corner in ``direction`` (unit
        steps in x and y), moved ``along`` mm sideways, pushed outward until clear of every
        block placed; False when it would not fit within 150 mm."""
        dx, dy = direction
        hx, hy = half_extents(shape)
        if round(yaw / 90) % 2:
            hx, hy = hy, hx
        _, _, tx, ty = self.rect(0)
        x = dx * (tx + gap + hx) + (along if dx == 0 else 0.0)
        y = dy * (ty + gap + hy) + (along if dy == 0 else 0.0)
        for _ in range(150):
            if self.clear(shape, x, y, yaw, gap=min(gap, 1.0)):
                self.blocks.append((shape, x, y, yaw))
                return True
            x, y = x + dx, y + dy
        return False


def _gap(rng: np.random.Generator) -> float:
    return float(rng.uniform(*_TIGHT_GAP_MM))


def _pick(rng: np.random.Generator, names: tuple[str, ...]) -> str:
    return names[int(rng.integers(len(names)))]


def _boxed_in(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, _COMPACT), 0.0, 0.0, 0.0)], "boxed in by blocks 1-3 mm away on every side", (0.9, 1.0))
    sides = [(1, 0), (-1, 0), (0, 1), (0, -1)] + ([(1, 1), (-1, 1), (1, -1), (-1, -1)] if rng.random() < 0.5 else [])
    for d in sides:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 90.0 * int(rng.integers(2)))
    return lay


def _wall(rng: np.random.Generator) -> _Layout:
    target = _pick(rng, ("long_box", "flat_box", "triangular_prism"))
    yaw = 90.0 if target == "triangular_prism" else 0.0  # its long side along x
    lay = _Layout([(target, 0.0, 0.0, yaw)], "along a wall of blocks: a grasp across it puts a finger in the wall", (0.9, 1.0))
    _, _, tx, _ = lay.rect(0)
    for along in np.linspace(-tx, tx, int(rng.integers(2, 4))):
        lay.put_beside(_pick(rng, _POSTS), (0, 1), _gap(rng), 0.0, along=float(along))
    if rng.random() < 0.4:
        lay.put_beside(_pick(rng, _POSTS), (0, -1), _gap(rng), 0.0)
    return lay


def _ring(rng: np.random.Generator) -> _Layout:
    target = _pick(rng, ("cylinder", "cube", "disc"))
    post = _pick(rng, ("cylinder", "disc"))
    r_post = half_extents(post)[0]
    r_target = math.hypot(*half_extents(target)) if target == "cube" else half_extents(target)[0]
    gap = _gap(rng)
    radius = r_target + gap + r_post
    count = int(math.pi / math.asin((r_post + gap / 2) / radius) + 1e-9)  # as many as fit: a closed ring
    start = float(rng.uniform(0.0, 360.0))
    angles = [math.radians(start + 360.0 * k / count) for k in range(count)]
    blocks = [(target, 0.0, 0.0, 0.0)] + [(post, radius * math.cos(a), radius * math.sin(a), 0.0) for a in angles]
    return _Layout(blocks, f"in a closed ring of {count} round blocks", (0.9, 1.0))


def _twin(rng: np.random.Generator) -> _Layout:
    shape = _pick(rng, _COMPACT)
    lay = _Layout([(shape, 0.0, 0.0, 0.0)], "beside an identical block (same shape and colour): only the mask tells them apart", (0.9, 1.0))
    lay.put_beside(shape, (0, 1), _gap(rng), 0.0)
    for d in [(1, 0), (-1, 0), (0, -1)][: int(rng.integers(1, 4))]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _edge(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, _COMPACT), 0.0, 0.0, 0.0)], "at the workspace's edge behind blocks: a push outward loses it", (0.9, 1.0), "edge")
    for d in [(-1, 0), (0, 1), (0, -1)]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _corner(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, _COMPACT), 0.0, 0.0, 0.0)], "in a corner of the workspace behind blocks", (0.9, 1.0), "corner")
    for d in [(-1, 0), (0, -1), (-1, -1)]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _crowd(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, _COMPACT + ("long_box", "flat_box")), 0.0, 0.0, 0.0)], "in a tight crowd of blocks", (0.85, 1.0))
    for _ in range(int(rng.integers(6, 10))):
        d = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1)][int(rng.integers(8))]
        lay.put_beside(_pick(rng, tuple(_assets())), d, _gap(rng), 90.0 * int(rng.integers(2)), along=float(rng.uniform(-30, 30)))
    return lay


def _tower(rng: np.random.Generator) -> _Layout:
    blocks = [(_pick(rng, ("cube", "disc", "flat_box", "long_box")), 0.0, 0.0, 0.0)]
    for _ in range(int(rng.integers(1, 3))):
        blocks.append((_pick(rng, ("cube", "flat_box", "disc")), float(rng.uniform(-5, 5)), float(rng.uniform(-5, 5)), 90.0 * int(rng.integers(2))))
    return _Layout(blocks, "under a tower of blocks: take it down first", (0.0, 0.35))


def _cover(rng: np.random.Generator) -> _Layout:
    blocks = [(_pick(rng, ("disc", "cube", "flat_box")), 0.0, 0.0, 0.0), ("flat_box", 0.0, 0.0, 0.0)]
    if rng.random() < 0.5:
        blocks.append(("flat_box", 0.0, 0.0, 90.0))
    return _Layout(blocks, "under flat boxes laid on it", (0.0, 0.3))


def _bridge(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, ("disc", "cube", "flat_box")), 0.0, 0.0, 0.0)], "under a bridge: two posts and a span stop the gripper coming down", (0.1, 0.95))
    gap = float(rng.uniform(3.0, 8.0))
    lay.put_beside("tall_box", (0, 1), gap, 0.0)
    lay.put_beside("tall_box", (0, -1), gap, 0.0)
    lay.blocks.append(("long_box", 0.0, 0.0, 90.0))
    return lay


_DRAW = {"boxed-in": _boxed_in, "wall": _wall, "ring": _ring, "twin": _twin, "edge": _edge, "corner": _corner,
         "crowd": _crowd, "tower": _tower, "cover": _cover, "bridge": _bridge}  # fmt: skip


def draw_arrangement(seed: int, workspace: Workspace = Workspace(), kind: str | None = None, loose: tuple[int, int] = (0, 5)) -> Arrangement:
    """The arrangement of ``seed``: a kind (``kind``, or one of :data:`ARRANGEMENT_KINDS`
    drawn), laid out, turned and placed in ``workspace`` (the edge and corner kinds against
    its edge, 4-12 mm in), and ``loose`` (inclusive range) loose blocks elsewhere, at least
    10 mm from everything. Every block's footprint lies inside the workspace.

    Raises:
        ValueError: an unknown ``kind`` (the message lists the kinds), a negative seed, or a
            bad ``loose`` range.
    """
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    if kind is not None and kind not in _DRAW:
        raise ValueError(f"unknown arrangement kind {kind!r}; valid: {', '.join(ARRANGEMENT_KINDS)}")
    if len(loose) != 2 or not 0 <= loose[0] <= loose[1]:
        raise ValueError(f"loose must be (low, high) with 0 <= low <= high, got {loose!r}")
    rng = np.random.default_rng([_STREAM, int(seed)])
    kind = kind if kind is not None else ARRANGEMENT_KINDS[int(rng.integers(len(ARRANGEMENT_KINDS)))]
    half = 500 * np.array([workspace.x_max - workspace.x_min, workspace.y_max - workspace.y_min])  # mm
    for _ in range(100):
        lay = _DRAW[kind](rng)
        blocks = _place(lay, rng, half)
        if blocks is not None:
            break
    else:  # pragma: no cover - every kind fits the default workspace in a few tries
        raise RuntimeError(f"arrangement {kind!r} of seed {seed} does not fit the workspace")
    blocks += _loose(blocks, rng, half, int(rng.integers(loose[0], loose[1] + 1)))
    return Arrangement(f"{kind}-{seed}", lay.note, 0, tuple(blocks), lay.visible)


def _corners(shape: str, x: float, y: float, yaw: float) -> np.ndarray:
    hx, hy = half_extents(shape)
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    local = np.array([[hx, hy], [hx, -hy], [-hx, hy], [-hx, -hy]])
    return local @ np.array([[c, s], [-s, c]]) + [x, y]


def _place(lay: _Layout, rng: np.random.Generator, half: np.ndarray) -> list[Block] | None:
    """The layout turned and moved into the workspace (``half``: its half sizes, mm), or None
    when the draw leaves a footprint outside."""
    if lay.anchor == "free":
        turn = float(rng.uniform(0.0, 360.0))
    else:  # local +x (and +y for a corner) faces the edge: a quarter turn picks which
        turn = 90.0 * int(rng.integers(4))
    c, s = math.cos(math.radians(turn)), math.sin(math.radians(turn))
    rot = np.array([[c, s], [-s, c]])
    turned = [(shape, *(np.array([x, y]) @ rot), yaw + turn) for shape, x, y, yaw in lay.blocks]
    pts = np.concatenate([_corners(*b) for b in turned])
    lo, hi = -half - pts.min(axis=0), half - pts.max(axis=0)  # allowed shifts
    if np.any(lo > hi):
        return None
    shift = lo + rng.random(2) * (hi - lo)
    if lay.anchor != "free":
        target = _corners(*turned[0])
        inward = float(rng.uniform(4.0, 12.0))
        for axis, local_axis in ((0, np.array([1.0, 0.0])), (1, np.array([0.0, 1.0])))[: 1 if lay.anchor == "edge" else 2]:
            out = local_axis @ rot  # the layout's outward direction, a world axis
            k = int(np.argmax(np.abs(out)))
            sign = float(np.sign(out[k]))
            shift[k] = sign * (half[k] - inward) - (target[:, k].max() if sign > 0 else target[:, k].min())
        placed = pts + shift
        if np.any(placed < -half) or np.any(placed > half):
            return None
    return [Block(shape, float(x + shift[0]), float(y + shift[1]), float(yaw % 360.0)) for shape, x, y, yaw in turned]


def _loose(blocks: list[Block], rng: np.random.Generator, half: np.ndarray, count: int) -> list[Block]:
    """``count`` loose blocks (fewer where no room is found), 10 mm clear of the rest."""
    out: list[Block] = []
    for _ in range(count):
        for _try in range(50):
            shape = _pick(rng, tuple(_assets()))
            r = math.hypot(*half_extents(shape))
            x, y = rng.uniform(-1, 1, 2) * (half - r)
            if all(math.hypot(x - b.x, y - b.y) >= r + math.hypot(*half_extents(b.shape)) + 10.0 for b in blocks + out):
                out.append(Block(shape, float(x), float(y), float(rng.uniform(0.0, 360.0))))
                break
    return out


# ------------------------------------------------------------------------------ settling
class ArrangementError(RuntimeError):
    """An arrangement that does not stand as designed once settled (a block toppled or slid,
    or the target's visible fraction is outside the arrangement's band)."""


def settle_arrangement(env, arrangement: Arrangement) -> tuple[SceneFile, float]:
    """Load ``arrangement`` into ``env`` (an :class:`~mpg_envs.tasks.env.MPGEnv`; the episode
    it had is lost), let it settle, and check it: every block within the loading tolerance of
    its designed pose, the target's visible fraction in the arrangement's band. Returns the
    settled scene (``env.current_scene()``, ready to save) and the visible fraction.

    Raises:
        ArrangementError: what moved and by how much, or the visible fraction and the band.
    """
    from mpg_envs.scenes.scene_loading import LOAD_TOLERANCE_DEG, LOAD_TOLERANCE_M, pose_errors

    scene = arrangement_scene(arrangement, env.config.workspace)
    _, info = env.reset(options={"scene": scene})
    distance, angle = pose_errors(env.world, scene)
    if np.nanmax(distance) > LOAD_TOLERANCE_M or np.nanmax(angle) > LOAD_TOLERANCE_DEG:
        k = int(np.nanargmax(distance / LOAD_TOLERANCE_M + angle / LOAD_TOLERANCE_DEG))
        raise ArrangementError(f"{arrangement.name}: {scene.objects[k].label} moved {1000 * distance[k]:.1f} mm, {angle[k]:.1f} deg while settling")
    visible = float(info["visible_fraction"])
    low, high = arrangement.visible
    if not low <= visible <= high:
        raise ArrangementError(f"{arrangement.name}: the target is {visible:.2f} visible, outside the band [{low:g}, {high:g}]")
    return env.current_scene(), visible
