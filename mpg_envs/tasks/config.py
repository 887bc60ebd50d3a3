"""Settings shared by every MPG env and the observation space they all have; the checks of the
env's keywords that name settings (``config``, ``object_set``, ``camera_config``), each a
``ValueError`` naming the keyword and what is valid."""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, fields, is_dataclass, replace
from numbers import Integral
from typing import Any, cast

import numpy as np
from gymnasium import spaces

from mpg_envs.grid.workspace import Workspace
from mpg_envs.perception.camera import CameraConfig
from mpg_envs.perception.occlusion import ChangeConfig, OcclusionConfig
from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.settings_fields import check_known_fields
from mpg_envs.simulation.objects import ObjectAsset, load_object_set
from mpg_envs.simulation.primitives import PrimitiveConfig
from mpg_envs.simulation.robot import RobotConfig
from mpg_envs.simulation.world import PhysicsConfig
from mpg_envs.tasks.rewards import RewardConfig

OBS_MODES = ("raycast", "camera")
"""``raycast``: GL-free heightmaps (default); ``camera``: rendered RGB-D back-projected."""


@dataclass(frozen=True)
class EnvConfig:
    """Settings shared by every stage (the paper's values by default)."""

    workspace: Workspace = Workspace()
    robot: RobotConfig = RobotConfig()
    physics: PhysicsConfig = PhysicsConfig()
    primitives: PrimitiveConfig = PrimitiveConfig()
    generator: GeneratorConfig = GeneratorConfig()
    reward: RewardConfig = RewardConfig()
    occlusion: OcclusionConfig = OcclusionConfig()
    change: ChangeConfig = ChangeConfig()
    scene_tries: int = 20  # whole-scene redraws allowed to make a valid scene, then InvalidSceneError
    raycast_threads: int | None = None  # threads per env for the heightmap; None: up to 2 (set 1 with one env per core)
    object_set_seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if is_dataclass(f.default) and not isinstance(value, type(f.default)):
                raise ValueError(
                    f"config {f.name} must be a {type(f.default).__name__} or a dict of its fields, got {value!r}"
                )
        _integer("scene_tries", self.scene_tries, 1, "draws of a whole scene before InvalidSceneError")
        if self.raycast_threads is not None:
            _integer("raycast_threads", self.raycast_threads, 1, "threads per env for the heightmap, or None: automatic")
        _integer("object_set_seed", self.object_set_seed, 0, "which procedural object set")


def _integer(name: str, value: Any, low: int, meaning: str) -> None:
    """``ValueError`` naming the config field ``name`` unless ``value`` is an integer >= ``low``."""
    if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
        raise ValueError(f"config {name} must be an integer >= {low} ({meaning}), got {value!r}")


def observation_space(workspace: Workspace = Workspace()) -> spaces.Dict:
    """The observation space of every MPG env (see the Environments page of the documentation):
    colour, depth and mask heightmaps and the occlusion flag."""
    size = workspace.shape
    return spaces.Dict(
        {
            "color": spaces.Box(0, 255, (*size, 3), np.uint8),
            "depth": spaces.Box(0.0, workspace.z_max, size, np.float32),
            "mask": spaces.Box(0, 1, size, np.uint8),
            "occluded": spaces.MultiBinary(1),
        }
    )


def config_of(config: EnvConfig | dict[str, Any]) -> EnvConfig:
    """``config`` as an :class:`EnvConfig`: itself, or a dict of field overrides (how a
    registered track names its settings without importing the simulator at registration);
    a field that is a settings dataclass (``generator``, ``physics``, ...) may be a dict of
    its own field overrides."""
    if isinstance(config, EnvConfig):
        return config
    if isinstance(config, dict):
        check_known_fields(EnvConfig, config, "config")
        default = EnvConfig()
        # A nested settings dataclass may be named as a dict of its fields too (``{"generator": {...}}``).
        return replace(default, **{k: _fields_of(getattr(default, k), v, k) for k, v in config.items()})
    raise TypeError(
        f"config must be an EnvConfig or a dict of its fields (e.g. {{'scene_tries': 40}}; valid fields: "
        f"{', '.join(f.name for f in fields(EnvConfig))}), got {config!r}"
    )


def _fields_of(default: Any, value: Any, name: str) -> Any:
    """``value`` for the field ``name`` whose default is ``default``: a dict becomes ``default``
    with those fields replaced when ``default`` is a dataclass."""
    if not (isinstance(value, dict) and is_dataclass(default)):
        return value
    check_known_fields(type(default), value, f"config[{name!r}]")
    return replace(cast(Any, default), **value)  # a dataclass instance (checked above)


def object_assets(object_set: str | os.PathLike[str] | Sequence[ObjectAsset], seed: int = 0) -> list[ObjectAsset]:
    """The objects of the env keyword ``object_set``: a set by name or a mesh folder's path
    (:func:`~mpg_envs.simulation.objects.load_object_set`, with ``seed``), or a list of
    :class:`~mpg_envs.simulation.assets.ObjectAsset`; else a ``ValueError`` naming what it got."""
    if isinstance(object_set, (str, os.PathLike)):
        assets = load_object_set(object_set, seed=seed)
    elif isinstance(object_set, (list, tuple)) and all(isinstance(a, ObjectAsset) for a in object_set):
        assets = list(object_set)
    else:
        held = ""
        if isinstance(object_set, (list, tuple)):
            bad = next(a for a in object_set if not isinstance(a, ObjectAsset))
            held = f" (it holds {bad!r} of type {type(bad).__name__})"
        raise ValueError(
            f"object_set must be an object set's name (e.g. 'blocks'), a mesh folder's path or a list of "
            f"ObjectAsset, got {object_set!r}"[:300]
            + held
        )
    if not assets:
        raise ValueError("object_set is empty")
    return assets


def check_camera_config(camera_config: Any) -> CameraConfig | None:
    """The env keyword ``camera_config``: ``None`` (the default cameras) or a
    :class:`~mpg_envs.perception.camera.CameraConfig`; else a ``ValueError`` naming what it got."""
    if camera_config is not None and not isinstance(camera_config, CameraConfig):
        raise ValueError(f"camera_config must be None (the default cameras) or a CameraConfig, got {camera_config!r}")
    return camera_config
