"""Scripted reference policies.

``OraclePolicy`` reads the simulator's state (object poses and shapes, which object is the
target), never pixels alone. It proves the suite is solvable and is the upper baseline of
evaluations: move the topmost object lying on the target; when the target is boxed in,
push the neighbour that blocks the fingers away; otherwise grasp the target across its
short axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import cv2
import gymnasium as gym
import numpy as np

from mpg_envs.workspace import NUM_ROTATIONS, Workspace, world_to_pixel


@runtime_checkable
class Policy(Protocol):
    """What every policy in the suite is: a name, a per-episode reset and ``act(obs) -> action``.

    ``act`` returns a flat action index of the env's action space (see
    :class:`mpg_envs.actions.MPGActionSpace`). Privileged policies (the oracle) may also read
    the env they were built with; learned ones read ``obs`` alone.
    """

    name: str

    def reset(self) -> None:
        """Forget per-episode memory; called at the start of every episode."""
        ...

    def act(self, obs: Any) -> int:
        """The flat action index to take for observation ``obs``."""
        ...


@dataclass(frozen=True)
class OracleConfig:
    """Geometry the oracle uses to judge grasps (metres)."""

    max_grasp_width: float = 0.075  # wider than this across the fingers: not graspable
    finger_thickness: float = 0.025  # room each finger needs beside the object
    finger_width: float = 0.024  # pad width, along the jaw
    finger_margin: float = 0.006  # gap between the object's side and the finger
    finger_clearance: float = 0.01  # a finger spot is free if nothing there is higher than the grasp height + this
    push_start_gap: float = 0.012  # a push starts this far outside the target's edge


def footprint_rect(points_xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Minimum-area rectangle of 2-D points: centre, (long, short) sizes, short-axis angle.

    The angle (radians, in [0, pi)) is the direction of the rectangle's short side, i.e.
    the direction the fingers should close along.
    """
    (cx, cy), (w, h), angle = cv2.minAreaRect(points_xy.astype(np.float32))
    a = math.radians(angle)
    # OpenCV's width runs along ``angle``; the short side is the one to close across.
    short_dir = a if w <= h else a + math.pi / 2
    return np.array([cx, cy]), np.array([max(w, h), min(w, h)]), short_dir % math.pi


def angle_to_rotation(theta: float, symmetric: bool = True) -> int:
    """Nearest rotation index to ``theta`` (radians); grasp angles are taken mod 180 deg."""
    step = 2 * math.pi / NUM_ROTATIONS
    k = int(round(theta / step)) % NUM_ROTATIONS
    return k % (NUM_ROTATIONS // 2) if symmetric else k


class OraclePolicy:
    """The scripted reference policy for any MPG env (a :class:`Policy`); also SB3's ``predict``."""

    name = "oracle"

    def __init__(self, env: gym.Env, config: OracleConfig = OracleConfig()):
        self.env = env
        self.config = config
        self._last: tuple[int, str, int] | None = None  # (motion count, primitive, rotation) of our last action
        self._failed_rotations: set[int] = set()  # target grasp angles that failed this episode

    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        """SB3-style: ``(action, state)`` for the env's current state (``obs`` unused)."""
        return self.act(obs), state

    def reset(self) -> None:
        """Forget the failed actions remembered in the last episode."""
        self._last = None
        self._failed_rotations = set()

    def act(self, obs: Any = None) -> int:
        """The flat action index the oracle chooses now (it reads the env's state; ``obs`` is unused)."""
        env = self.env.unwrapped
        world, depth = env.world, env._obs["depth"]
        allowed = env.primitives
        target = env.target
        self._remember_failures(env)
        action = self._choose(env, world, depth, allowed, target)
        primitive, rotation, _, _ = env.action_space.decode(action)
        self._last = (env.num_motions, primitive, rotation)
        return action

    def _remember_failures(self, env) -> None:
        if env.num_motions == 0:
            self._failed_rotations = set()
        elif self._last is not None and self._last[0] == env.num_motions - 1 and self._last[1] == "grasp":
            # Our grasp did not end the episode, so it failed: try another angle next time.
            self._failed_rotations.add(self._last[2] % (NUM_ROTATIONS // 2))

    def _choose(self, env, world, depth, allowed, target) -> int:
        if target is None or env.spec_stage.mask_all_objects or not world.active[target]:
            return self._grasp_any(env, depth)
        if "move" in allowed:
            occluder = self._top_occluder(world, target)
            if occluder is not None and ("grasp" not in allowed or env._obs["occluded"][0]):
                return self._grasp_object(env, occluder, depth, primitive="move")
        rotation, blocker = self._best_grasp(env, target, depth)
        if blocker is None or "push" not in allowed or "grasp" not in allowed:
            if "grasp" in allowed:
                return self._encode(env, "grasp", rotation, *self._pixel(world, target))
            # Stage III with nothing on top: move the nearest neighbour away from the target.
            neighbour = blocker if blocker is not None else self._nearest(world, target)
            return self._grasp_object(env, neighbour if neighbour is not None else target, depth, primitive="move")
        return self._push_away(env, target, blocker)

    # ------------------------------------------------------------ pieces
    def _grasp_any(self, env, depth) -> int:
        world = env.world
        inside = set(world.active_objects().tolist()) - set(world.objects_outside_workspace().tolist())
        candidates = sorted(inside, key=lambda i: -world.object_top(i))
        if not candidates:
            candidates = world.active_objects().tolist() or [0]
        return self._grasp_object(env, candidates[0], depth, primitive="grasp")

    def _grasp_object(self, env, i: int, depth, primitive: str) -> int:
        world = env.world
        _, _, short_dir = footprint_rect(world.object_vertices(i)[:, :2])
        return self._encode(env, primitive, angle_to_rotation(short_dir), *self._pixel(world, i))

    def _pixel(self, world, i: int) -> tuple[int, int]:
        centre, _, _ = footprint_rect(world.object_vertices(i)[:, :2])
        rows, cols = world.workspace.shape
        r, c = world_to_pixel(world.workspace, centre[0], centre[1])
        return int(np.clip(r, 0, rows - 1)), int(np.clip(c, 0, cols - 1))

    def _top_occluder(self, world, target: int) -> int | None:
        """The highest object overlapping the target's footprint and rising above it."""
        hull = _hull_mm(world.object_vertices(target)[:, :2])
        t_top = world.object_top(target)
        best, best_top = None, t_top + 0.005
        for j in world.active_objects():
            if j == target:
                continue
            v = world.object_vertices(j)
            top = float(v[:, 2].max())
            if top <= best_top:
                continue
            overlap, _ = cv2.intersectConvexConvex(hull, _hull_mm(v[:, :2]))
            if overlap > 1.0:  # mm^2
                best, best_top = j, top
        return best

    def _finger_spots(self, centre, width: float, theta: float) -> list[np.ndarray]:
        c = self.config
        d = np.array([math.cos(theta), math.sin(theta)])
        offset = width / 2 + c.finger_margin + c.finger_thickness / 2
        return [centre + s * offset * d for s in (-1.0, 1.0)]

    def _spot_height(self, world, depth, spot: np.ndarray, theta: float) -> tuple[float, int | None]:
        """Highest scene point under one finger (and which object is there)."""
        c = self.config
        d = np.array([math.cos(theta), math.sin(theta)])
        n = np.array([-d[1], d[0]])
        corners = [spot + a * d * c.finger_thickness / 2 + b * n * c.finger_width / 2 for a in (-1, 1) for b in (-1, 1)]
        ws: Workspace = world.workspace
        pix = np.array([world_to_pixel(ws, x, y)[::-1] for x, y in corners], dtype=np.int32)  # (col, row)
        region = np.zeros(depth.shape, np.uint8)
        cv2.fillConvexPoly(region, cv2.convexHull(pix), 1)
        inside = region > 0
        if not inside.any():
            return 0.0, None
        height = float(depth[inside].max())
        owner = None
        best = 0.0
        for j in world.active_objects():
            v = world.object_vertices(j)
            near = np.linalg.norm(v[:, :2].mean(axis=0) - spot)
            if near < 0.08 and float(v[:, 2].max()) > best and _polygon_hits(v[:, :2], corners):
                best, owner = float(v[:, 2].max()), int(j)
        return height, owner

    def _best_grasp(self, env, target: int, depth) -> tuple[int, int | None]:
        """Grasp rotation for the target, and the object blocking the fingers (or None)."""
        world, c = env.world, self.config
        verts = world.object_vertices(target)
        centre, _, short_dir = footprint_rect(verts[:, :2])
        z_grasp = max(float(verts[:, 2].max()) - env.config.primitives.grasp_depth, env.config.primitives.grasp_min_height)
        first_blocker = None
        # Try the short axis first, then the other angles from nearest to farthest.
        order = sorted(range(NUM_ROTATIONS // 2), key=lambda k: _angle_gap(k * math.pi / 8, short_dir))
        order = [k for k in order if k not in self._failed_rotations] or order
        for k in order:
            theta = k * math.pi / 8
            d = np.array([math.cos(theta), math.sin(theta)])
            proj = (verts[:, :2] - centre) @ d
            width = float(proj.max() - proj.min())
            if width > c.max_grasp_width:
                continue
            blocked = None
            for spot in self._finger_spots(centre + d * (proj.max() + proj.min()) / 2, width, theta):
                h, owner = self._spot_height(world, depth, spot, theta)
                if h > z_grasp + c.finger_clearance:
                    blocked = owner if owner is not None and owner != target else blocked
                    if blocked is None:
                        blocked = -1
                    break
            if blocked is None:
                return k, None
            if first_blocker is None:
                first_blocker = (k, blocked)
        if first_blocker is None:
            return order[0], None  # nothing fits the fingers: the best untried angle
        k, blocker = first_blocker
        if blocker == -1:
            blocker = self._nearest(world, target)
        return k, blocker

    def _nearest(self, world, target: int) -> int | None:
        t = world.object_position(target)[:2]
        others = [j for j in world.active_objects() if j != target]
        if not others:
            return None
        return int(min(others, key=lambda j: np.linalg.norm(world.object_position(j)[:2] - t)))

    def _push_away(self, env, target: int, blocker: int) -> int:
        """Push ``blocker`` straight away from the target, starting in the gap between them."""
        world, c = env.world, self.config
        t_verts = world.object_vertices(target)[:, :2]
        t_centre = t_verts.mean(axis=0)
        d = world.object_position(blocker)[:2] - t_centre
        d = d / (np.linalg.norm(d) + 1e-9)
        reach = float(((t_verts - t_centre) @ d).max())
        start = t_centre + d * (reach + c.push_start_gap)
        theta = math.atan2(d[1], d[0]) % (2 * math.pi)
        rotation = int(round(theta / (2 * math.pi / NUM_ROTATIONS))) % NUM_ROTATIONS
        rows, cols = world.workspace.shape
        r, col = world_to_pixel(world.workspace, start[0], start[1])
        return self._encode(env, "push", rotation, int(np.clip(r, 0, rows - 1)), int(np.clip(col, 0, cols - 1)))

    @staticmethod
    def _encode(env, primitive: str, rotation: int, row: int, col: int) -> int:
        return env.action_space.encode(primitive, rotation, row, col)


def _angle_gap(a: float, b: float) -> float:
    """Distance between two grasp angles modulo pi."""
    d = (a - b) % math.pi
    return min(d, math.pi - d)


def _hull_mm(points_xy: np.ndarray) -> np.ndarray:
    """Convex hull in millimetres: OpenCV's polygon intersection loses areas in m^2."""
    return cv2.convexHull((1000.0 * np.asarray(points_xy)).astype(np.float32))


def _polygon_hits(points: np.ndarray, corners: list[np.ndarray]) -> bool:
    area, _ = cv2.intersectConvexConvex(_hull_mm(points), _hull_mm(np.array(corners)))
    return area > 1.0  # mm^2
