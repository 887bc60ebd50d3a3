"""Scene generators: where objects are dropped for each training stage.

A generator is a small hook ``(world, rng, config) -> target index`` over a :class:`World`
whose objects are all parked: it drops them one by one (each settles before the next) and
says which object is the target (``None`` when the mask covers every object, Stage I).
Whether the result is acceptable (e.g. the target really is occluded) is the stage's call,
which retries with fresh random draws.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from mpg_envs.world import World

SceneFn = Callable[[World, np.random.Generator, "SceneConfig"], Optional[int]]


@dataclass(frozen=True)
class SceneConfig:
    """Distances (metres) shaping the generated scenes."""

    edge_margin: float = 0.07  # drops stay this far inside the workspace edges
    apart_distance: float = 0.12  # Stage I: drop points at least this far apart
    isolation_distance: float = 0.14  # Stage II: the target this far from every other drop
    occluder_offset: float = 0.012  # Stage III: occluder lands within this of the target centre
    surround_gap: float = 0.012  # Stage IV: gap between the target and its neighbours
    cluster_radius: float = 0.06  # Stage V: "dropped close together"
    test_cluster_radius: float = 0.075  # test scenes (15 or 30 objects)
    max_point_tries: int = 200


def random_quat(rng: np.random.Generator) -> np.ndarray:
    """A uniformly random orientation (unit quaternion, w first)."""
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def yaw_quat(rng: np.random.Generator) -> np.ndarray:
    """A random rotation about z only (the object lands on its canonical base)."""
    a = rng.uniform(0, 2 * math.pi)
    return np.array([math.cos(a / 2), 0.0, 0.0, math.sin(a / 2)])


def _uniform_point(world: World, rng: np.random.Generator, margin: float) -> np.ndarray:
    ws = world.workspace
    return np.array([rng.uniform(ws.x_min + margin, ws.x_max - margin), rng.uniform(ws.y_min + margin, ws.y_max - margin)])


def _points_apart(world: World, rng: np.random.Generator, n: int, distance: float, cfg: SceneConfig) -> list[np.ndarray]:
    points: list[np.ndarray] = []
    for _ in range(cfg.max_point_tries):
        if len(points) == n:
            break
        p = _uniform_point(world, rng, cfg.edge_margin)
        if all(np.linalg.norm(p - q) >= distance for q in points):
            points.append(p)
    while len(points) < n:  # crowded workspace: accept the best spacing we can find
        candidates = [_uniform_point(world, rng, cfg.edge_margin) for _ in range(20)]
        points.append(max(candidates, key=lambda p: min(np.linalg.norm(p - q) for q in points)))
    return points


def _cluster_point(center: np.ndarray, radius: float, rng: np.random.Generator) -> np.ndarray:
    r = radius * math.sqrt(rng.uniform())
    a = rng.uniform(0, 2 * math.pi)
    return center + r * np.array([math.cos(a), math.sin(a)])


def scattered(world: World, rng: np.random.Generator, cfg: SceneConfig) -> None:
    """Stage I: every object dropped apart from the others; the mask shows them all."""
    for i, p in enumerate(_points_apart(world, rng, world.num_objects, cfg.apart_distance, cfg)):
        world.drop_object(i, p, random_quat(rng))
    return None


def isolated_target(world: World, rng: np.random.Generator, cfg: SceneConfig) -> int:
    """Stage II: the n-th dropped object is the target, kept clear of the others."""
    n = world.num_objects
    target = int(rng.integers(n))
    points = _points_apart(world, rng, n, cfg.apart_distance, cfg)
    # Give the target the drop point farthest from all the others.
    best = max(range(n), key=lambda k: min((np.linalg.norm(points[k] - q) for j, q in enumerate(points) if j != k), default=1.0))
    points[target], points[best] = points[best], points[target]
    for i, p in enumerate(points):
        world.drop_object(i, p, random_quat(rng))
    return target


def occluded_target(world: World, rng: np.random.Generator, cfg: SceneConfig) -> int:
    """Stage III: an occluder dropped onto the target, more objects nearby as they grow."""
    center = _uniform_point(world, rng, cfg.edge_margin + 0.03)
    world.drop_object(0, center, yaw_quat(rng))
    offset = _cluster_point(np.zeros(2), cfg.occluder_offset, rng)
    world.drop_object(1, center + offset, random_quat(rng), height=0.05)
    for i in range(2, world.num_objects):
        world.drop_object(i, _cluster_point(center, 2 * cfg.cluster_radius, rng), random_quat(rng))
    return 0


def surrounded_target(world: World, rng: np.random.Generator, cfg: SceneConfig) -> int:
    """Stage IV: the target boxed in by neighbours on all sides, none on top of it."""
    center = _uniform_point(world, rng, cfg.edge_margin + 0.05)
    world.drop_object(0, center, yaw_quat(rng), height=0.02)
    target_radius = 0.5 * float(np.max(world.assets[0].extents[:2]))
    n = world.num_objects - 1
    phase = rng.uniform(0, 2 * math.pi)
    for k in range(n):
        a = phase + 2 * math.pi * k / n
        radius = target_radius + 0.5 * float(np.min(world.assets[k + 1].extents[:2])) + cfg.surround_gap
        p = center + radius * np.array([math.cos(a), math.sin(a)])
        world.drop_object(k + 1, p, yaw_quat(rng), height=0.02)
    return 0


def clustered(world: World, rng: np.random.Generator, cfg: SceneConfig) -> int:
    """Stage V: all objects dropped close together; the target is the 1st or 2nd dropped."""
    center = _uniform_point(world, rng, cfg.edge_margin + cfg.cluster_radius)
    for i in range(world.num_objects):
        world.drop_object(i, _cluster_point(center, cfg.cluster_radius, rng), random_quat(rng))
    return int(rng.integers(2))


def test_scene(world: World, rng: np.random.Generator, cfg: SceneConfig) -> int:
    """Test scenes: 15 or 30 objects close together; the target one of the first five."""
    center = _uniform_point(world, rng, cfg.edge_margin + cfg.test_cluster_radius)
    for i in range(world.num_objects):
        world.drop_object(i, _cluster_point(center, cfg.test_cluster_radius, rng), random_quat(rng))
    return int(rng.integers(min(5, world.num_objects)))


SCENES: dict[str, SceneFn] = {
    "scattered": scattered,
    "isolated_target": isolated_target,
    "occluded_target": occluded_target,
    "surrounded_target": surrounded_target,
    "clustered": clustered,
    "test_scene": test_scene,
}
