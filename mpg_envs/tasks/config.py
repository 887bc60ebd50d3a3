"""Settings shared by every MPG env and the observation space they all have."""

from __future__ import annotations

from dataclasses import dataclass, is_dataclass, replace
from typing import Any

import numpy as np
from gymnasium import spaces

from mpg_envs.perception.occlusion import ChangeConfig, OcclusionConfig
from mpg_envs.simulation.primitives import PrimitiveConfig
from mpg_envs.tasks.rewards import RewardConfig
from mpg_envs.simulation.robot import RobotConfig
from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.grid.workspace import Workspace
from mpg_envs.settings_fields import check_known_fields
from mpg_envs.simulation.world import PhysicsConfig

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


def observation_space(workspace: Workspace = Workspace()) -> spaces.Dict:
    """The observation space of every MPG env (see the Environments page of the documentation): colour, depth and mask heightmaps
    and the occlusion flag."""
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
    raise TypeError(f"config must be an EnvConfig or a dict of its fields, got {type(config).__name__}")


def _fields_of(default: Any, value: Any, name: str) -> Any:
    """``value`` for the field ``name`` whose default is ``default``: a dict becomes ``default``
    with those fields replaced when ``default`` is a dataclass."""
    if not (isinstance(value, dict) and is_dataclass(default)):
        return value
    check_known_fields(type(default), value, f"config[{name!r}]")
    return replace(default, **value)
