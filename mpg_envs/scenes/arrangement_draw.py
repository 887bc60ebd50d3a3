"""Drawing an arrangement from a seed: one of
:data:`~mpg_envs.scenes.arranged.ARRANGEMENT_KINDS`, its shapes, gaps (1-3 mm for the tight
kinds), turn and place in the workspace, and a few loose blocks elsewhere.

:func:`draw_arrangement` is pure and deterministic per seed; whether a drawn arrangement
stands once the physics settles it is :func:`~mpg_envs.scenes.arranged.settle_arrangement`'s
check. Seeds follow the project's convention: training and calibration use a run's own seeds,
tuning 700000-; the peers' arranged cases and the challenge set are the tests and are never
drawn from.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.arranged import ARRANGEMENT_KINDS, Arrangement, Block, block_assets, half_extents

_STREAM = 0x41524E47  # keeps these draws apart from every other use of the same seed
_TIGHT_GAP_MM = (1.0, 3.0)
_COMPACT = ("cube", "cylinder", "disc", "tall_box")
_POSTS = ("tall_box", "cube", "cylinder")

# ------------------------------------------------------------------------------ drawing
# Layouts are made in a local frame (mm, the target at the origin, yaws multiples of 90 so
# footprints are axis-aligned rectangles), then turned and moved into the workspace.


def _turned_extents(shape: str, yaw: float) -> tuple[float, float]:
    """Half extents (mm) along local x and y of ``shape`` turned ``yaw`` (a multiple of 90)."""
    hx, hy = half_extents(shape)
    return (hy, hx) if round(yaw / 90) % 2 else (hx, hy)


@dataclass
class _Layout:
    blocks: list[tuple[str, float, float, float]]  # shape, x, y, yaw (local)
    note: str
    visible: tuple[float, float]
    anchor: str = "free"  # free | edge | corner: how it is put in the workspace

    def rect(self, i: int) -> tuple[float, float, float, float]:
        shape, x, y, yaw = self.blocks[i]
        return (x, y, *_turned_extents(shape, yaw))

    def clear(self, shape: str, x: float, y: float, yaw: float, gap: float = 1.0) -> bool:
        hx, hy = _turned_extents(shape, yaw)
        return all(
            abs(x - cx) >= hx + ax + gap or abs(y - cy) >= hy + ay + gap
            for cx, cy, ax, ay in map(self.rect, range(len(self.blocks)))
        )

    def put_beside(self, shape: str, direction: tuple[float, float], gap: float, yaw: float, along: float = 0.0) -> bool:
        """Put ``shape`` ``gap`` mm beyond the target's side or corner in ``direction`` (unit
        steps in x and y), moved ``along`` mm sideways, pushed outward until clear of every
        block placed; False when it would not fit within 150 mm."""
        dx, dy = direction
        hx, hy = _turned_extents(shape, yaw)
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
    lay = _Layout(
        [(shape, 0.0, 0.0, 0.0)],
        "beside an identical block (same shape and colour): only the mask tells them apart",
        (0.9, 1.0),
    )
    lay.put_beside(shape, (0, 1), _gap(rng), 0.0)
    for d in [(1, 0), (-1, 0), (0, -1)][: int(rng.integers(1, 4))]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _edge(rng: np.random.Generator) -> _Layout:
    lay = _Layout(
        [(_pick(rng, _COMPACT), 0.0, 0.0, 0.0)],
        "at the workspace's edge behind blocks: a push outward loses it",
        (0.9, 1.0),
        "edge",
    )
    for d in [(-1, 0), (0, 1), (0, -1)]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _corner(rng: np.random.Generator) -> _Layout:
    lay = _Layout([(_pick(rng, _COMPACT), 0.0, 0.0, 0.0)], "in a corner of the workspace behind blocks", (0.9, 1.0), "corner")
    for d in [(-1, 0), (0, -1), (-1, -1)]:
        lay.put_beside(_pick(rng, _POSTS), d, _gap(rng), 0.0)
    return lay


def _crowd(rng: np.random.Generator) -> _Layout:
    lay = _Layout(
        [(_pick(rng, _COMPACT + ("long_box", "flat_box")), 0.0, 0.0, 0.0)], "in a tight crowd of blocks", (0.85, 1.0)
    )
    for _ in range(int(rng.integers(6, 10))):
        d = [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, 1), (1, -1), (-1, -1)][int(rng.integers(8))]
        lay.put_beside(
            _pick(rng, tuple(block_assets())), d, _gap(rng), 90.0 * int(rng.integers(2)), along=float(rng.uniform(-30, 30))
        )
    return lay


def _tower(rng: np.random.Generator) -> _Layout:
    blocks = [(_pick(rng, ("cube", "disc", "flat_box", "long_box")), 0.0, 0.0, 0.0)]
    for _ in range(int(rng.integers(1, 3))):
        blocks.append(
            (
                _pick(rng, ("cube", "flat_box", "disc")),
                float(rng.uniform(-5, 5)),
                float(rng.uniform(-5, 5)),
                90.0 * int(rng.integers(2)),
            )
        )
    return _Layout(blocks, "under a tower of blocks: take it down first", (0.0, 0.35))


def _cover(rng: np.random.Generator) -> _Layout:
    blocks = [(_pick(rng, ("disc", "cube", "flat_box")), 0.0, 0.0, 0.0), ("flat_box", 0.0, 0.0, 0.0)]
    if rng.random() < 0.5:
        blocks.append(("flat_box", 0.0, 0.0, 90.0))
    return _Layout(blocks, "under flat boxes laid on it", (0.0, 0.3))


def _bridge(rng: np.random.Generator) -> _Layout:
    lay = _Layout(
        [(_pick(rng, ("disc", "cube", "flat_box")), 0.0, 0.0, 0.0)],
        "under a bridge: two posts and a span stop the gripper coming down",
        (0.1, 0.95),
    )
    gap = float(rng.uniform(3.0, 8.0))
    lay.put_beside("tall_box", (0, 1), gap, 0.0)
    lay.put_beside("tall_box", (0, -1), gap, 0.0)
    lay.blocks.append(("long_box", 0.0, 0.0, 90.0))
    return lay


_DRAW = {"boxed-in": _boxed_in, "wall": _wall, "ring": _ring, "twin": _twin, "edge": _edge, "corner": _corner,
         "crowd": _crowd, "tower": _tower, "cover": _cover, "bridge": _bridge}  # fmt: skip


def draw_arrangement(
    seed: int, workspace: Workspace = Workspace(), kind: str | None = None, loose: tuple[int, int] = (0, 5)
) -> Arrangement:
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
        for _axis, local_axis in ((0, np.array([1.0, 0.0])), (1, np.array([0.0, 1.0])))[: 1 if lay.anchor == "edge" else 2]:
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
            shape = _pick(rng, tuple(block_assets()))
            r = math.hypot(*half_extents(shape))
            x, y = rng.uniform(-1, 1, 2) * (half - r)
            if all(math.hypot(x - b.x, y - b.y) >= r + math.hypot(*half_extents(b.shape)) + 10.0 for b in blocks + out):
                out.append(Block(shape, float(x), float(y), float(rng.uniform(0.0, 360.0))))
                break
    return out
