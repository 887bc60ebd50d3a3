"""Scene generators: where objects are dropped for each training stage.

A generator is a small hook ``(world, rng, config) -> SceneLayout`` over a :class:`World`
whose objects are all parked: it drops them one by one (each settles before the next) and
says which objects may be the target, in the order to try them (none when the mask covers
every object, Stage I), and where an object that rolled out of the workspace is dropped
again (:func:`keep_inside`: same pile, same seed stream, so scenes stay deterministic).
Whether a candidate target is acceptable (e.g. it really is occluded) is the stage's call
(:class:`~mpg_envs.tasks.stages.StageSpec`), made by the env, which redraws the whole scene when
no candidate is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

from mpg_envs.simulation.world import World


class InvalidSceneError(RuntimeError):
    """A valid scene (every object resting inside the workspace, the stage's start
    condition met) could not be made in the bounded number of tries."""


@dataclass(frozen=True)
class SceneLayout:
    """What a generator made.

    Attributes:
        targets: candidate target indices in the order to try them (empty: no target, the
            mask shows every object).
        redrop: draws the ``(x, y)`` where an object that left the workspace is dropped again.
    """

    targets: tuple[int, ...]
    redrop: Callable[[], np.ndarray]


GeneratorFn = Callable[[World, np.random.Generator, "GeneratorConfig"], SceneLayout]


@dataclass(frozen=True)
class GeneratorConfig:
    """Distances (metres) shaping the generated scenes."""

    edge_margin: float = 0.07  # drops stay this far inside the workspace edges
    apart_distance: float = 0.12  # Stage I: drop points at least this far apart
    isolation_distance: float = 0.14  # Stage II: the target this far from every other drop
    occluder_offset: float = 0.012  # Stage III: occluder lands within this of the target centre
    surround_gap: float = 0.012  # Stage IV: gap between the target and its neighbours
    cluster_radius: float = 0.06  # Stage V: "dropped close together"
    test_cluster_radius: float = 0.075  # test scenes (15 or 30 objects)
    max_point_tries: int = 200
    redrop_rounds: int = 4  # rounds of re-dropping the objects that left the workspace
    buried_occluders: int = 3  # buried scenes: objects dropped right onto the target after it
    bury_offset: float = 0.015  # ... each landing within this of the target's centre
    bury_height: float | None = None  # ... dropped from this height above the pile (None: PhysicsConfig.drop_height)
    buried_candidates: int = 1  # buried scenes: the first k dropped may be the target (the buried one first)
    drop_settle_steps: int | None = None  # settling cap after each drop (None: PhysicsConfig.settle_max_steps)
    drop_timestep: float | None = None  # the physics' timestep while objects drop (None: PhysicsConfig.timestep)

    def __post_init__(self) -> None:
        if (
            isinstance(self.buried_candidates, bool)
            or not isinstance(self.buried_candidates, int)
            or self.buried_candidates < 1
        ):
            raise ValueError(f"GeneratorConfig.buried_candidates must be an integer >= 1, got {self.buried_candidates!r}")
        steps = self.drop_settle_steps
        if steps is not None and (isinstance(steps, bool) or not isinstance(steps, int) or steps < 1):
            raise ValueError(f"GeneratorConfig.drop_settle_steps must be None or an integer >= 1, got {steps!r}")


def _drop(world: World, cfg: GeneratorConfig, i: int, xy: np.ndarray, quat: np.ndarray, height: float | None = None) -> int:
    """Drop object ``i`` and let it settle for at most ``cfg.drop_settle_steps`` steps of ``cfg.drop_timestep``."""
    with world.stepping(cfg.drop_timestep):
        return world.drop_object(i, xy, quat, height=height, max_steps=cfg.drop_settle_steps)


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


def _points_apart(world: World, rng: np.random.Generator, n: int, distance: float, cfg: GeneratorConfig) -> list[np.ndarray]:
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


def scattered(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage I: every object dropped apart from the others; the mask shows them all."""
    for i, p in enumerate(_points_apart(world, rng, world.num_objects, cfg.apart_distance, cfg)):
        _drop(world, cfg, i, p, random_quat(rng))
    return SceneLayout((), lambda: _uniform_point(world, rng, cfg.edge_margin))


def isolated_target(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage II: the n-th dropped object is the target, kept clear of the others."""
    n = world.num_objects
    target = int(rng.integers(n))
    points = _points_apart(world, rng, n, cfg.apart_distance, cfg)
    # Give the target the drop point farthest from all the others.
    best = max(
        range(n), key=lambda k: min((np.linalg.norm(points[k] - q) for j, q in enumerate(points) if j != k), default=1.0)
    )
    points[target], points[best] = points[best], points[target]
    for i, p in enumerate(points):
        _drop(world, cfg, i, p, random_quat(rng))
    return SceneLayout((target,), lambda: _uniform_point(world, rng, cfg.edge_margin))


def occluded_target(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage III: an occluder dropped onto the target, more objects nearby as they grow."""
    center = _uniform_point(world, rng, cfg.edge_margin + 0.03)
    _drop(world, cfg, 0, center, yaw_quat(rng))
    offset = _cluster_point(np.zeros(2), cfg.occluder_offset, rng)
    _drop(world, cfg, 1, center + offset, random_quat(rng), height=0.05)
    for i in range(2, world.num_objects):
        _drop(world, cfg, i, _cluster_point(center, 2 * cfg.cluster_radius, rng), random_quat(rng))
    return SceneLayout((0,), lambda: _cluster_point(center, 2 * cfg.cluster_radius, rng))


def surrounded_target(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage IV: the target boxed in by neighbours on all sides, none on top of it."""
    center = _uniform_point(world, rng, cfg.edge_margin + 0.05)
    _drop(world, cfg, 0, center, yaw_quat(rng), height=0.02)
    target_radius = 0.5 * float(np.max(world.assets[0].extents[:2]))
    n = world.num_objects - 1
    phase = rng.uniform(0, 2 * math.pi)
    for k in range(n):
        a = phase + 2 * math.pi * k / n
        radius = target_radius + 0.5 * float(np.min(world.assets[k + 1].extents[:2])) + cfg.surround_gap
        p = center + radius * np.array([math.cos(a), math.sin(a)])
        _drop(world, cfg, k + 1, p, yaw_quat(rng), height=0.02)
    # A neighbour that rolled away can't be put back in the ring: the stage's surround check decides.
    return SceneLayout((0,), lambda: _cluster_point(center, 3 * target_radius, rng))


def clustered(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage V: all objects dropped close together; the target is the 1st or 2nd dropped."""
    center = _uniform_point(world, rng, cfg.edge_margin + cfg.cluster_radius)
    for i in range(world.num_objects):
        _drop(world, cfg, i, _cluster_point(center, cfg.cluster_radius, rng), random_quat(rng))
    return SceneLayout(tuple(int(k) for k in rng.permutation(2)), lambda: _cluster_point(center, cfg.cluster_radius, rng))


def test_cluster(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Test scenes: 15 or 30 objects close together; the target one of the first five."""
    center = _uniform_point(world, rng, cfg.edge_margin + cfg.test_cluster_radius)
    for i in range(world.num_objects):
        _drop(world, cfg, i, _cluster_point(center, cfg.test_cluster_radius, rng), random_quat(rng))
    first = rng.permutation(min(5, world.num_objects))
    return SceneLayout(tuple(int(k) for k in first), lambda: _cluster_point(center, cfg.test_cluster_radius, rng))


def _buried(world: World, rng: np.random.Generator, cfg: GeneratorConfig, radius: float) -> SceneLayout:
    """The target (object 0) dropped flat at a cluster's centre, ``cfg.buried_occluders``
    objects dropped onto it, the rest around it within ``radius``."""
    center = _uniform_point(world, rng, cfg.edge_margin + radius)
    _drop(world, cfg, 0, center, yaw_quat(rng))
    for i in range(1, world.num_objects):
        if i <= cfg.buried_occluders:
            _drop(world, cfg, i, center + _cluster_point(np.zeros(2), cfg.bury_offset, rng), random_quat(rng), cfg.bury_height)
        else:
            _drop(world, cfg, i, _cluster_point(center, radius, rng), random_quat(rng))
    # Later candidates (the occluders, then the next drop) are tried in random order after the buried one.
    k = min(cfg.buried_candidates, world.num_objects)
    others = tuple(int(j) for j in 1 + rng.permutation(k - 1)) if k > 1 else ()
    return SceneLayout((0, *others), lambda: _cluster_point(center, radius, rng))


def buried_cluster(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """Stage V's cluster with the target buried: occluders dropped onto it by construction."""
    return _buried(world, rng, cfg, cfg.cluster_radius)


def buried_test_cluster(world: World, rng: np.random.Generator, cfg: GeneratorConfig) -> SceneLayout:
    """The test scenes' cluster with the target buried: occluders dropped onto it by construction."""
    return _buried(world, rng, cfg, cfg.test_cluster_radius)


def objects_astray(world: World) -> np.ndarray:
    """Objects that make a scene invalid: inactive, left the room, or centre outside the workspace."""
    astray = set(np.flatnonzero(~world.active).tolist())
    astray.update(world.objects_out_of_room().tolist())
    astray.update(world.objects_outside_workspace().tolist())
    return np.array(sorted(astray), dtype=int)


def keep_inside(world: World, rng: np.random.Generator, layout: SceneLayout, cfg: GeneratorConfig) -> tuple[int, ...] | None:
    """Re-drop, at ``layout.redrop`` points, every object that is not resting inside the
    workspace, for up to ``cfg.redrop_rounds`` rounds.

    Returns the indices that were re-dropped (they land on top of the pile, so they are no
    longer candidate targets), or ``None`` when objects are still astray after the last
    round or the pile does not come to rest.
    """
    redropped: set[int] = set()
    for round_ in range(cfg.redrop_rounds + 1):
        astray = objects_astray(world)
        if astray.size == 0 and not world.objects_at_rest():
            world.settle()  # a pile still creeping after the capped settle of the last drop
            astray = objects_astray(world)
        if astray.size == 0:
            return tuple(sorted(redropped)) if world.objects_at_rest() else None
        if round_ == cfg.redrop_rounds:
            return None
        for i in astray:
            world.remove_object(int(i))
        for i in astray:
            _drop(world, cfg, int(i), layout.redrop(), random_quat(rng))
        redropped.update(int(i) for i in astray)
    return None  # not reached: the last round returns


GENERATORS: dict[str, GeneratorFn] = {
    "scattered": scattered,
    "isolated_target": isolated_target,
    "occluded_target": occluded_target,
    "surrounded_target": surrounded_target,
    "clustered": clustered,
    "test_cluster": test_cluster,
    "buried_cluster": buried_cluster,
    "buried_test_cluster": buried_test_cluster,
}

SceneConfig = GeneratorConfig
"""The former name of :class:`GeneratorConfig` (kept for code that sets it)."""

BURIED: dict[str, str] = {"clustered": "buried_cluster", "test_cluster": "buried_test_cluster"}
"""A generator -> its variant that buries the target (for bands of low visibility)."""
