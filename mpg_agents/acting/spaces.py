"""The env MPGNet acts on: which primitives an action space indexes, the observation check, and
the env's grasp geometry (what the finger masks are made with)."""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_envs.grid.actions import HEIGHTMAP_SIZE, PRIMITIVES, check_primitives
from mpg_envs.grid.primitive_specs import GRASP, PUSH
from mpg_envs.grid.workspace import NUM_ROTATIONS


def finger_geometry(env: gym.Env | None = None) -> FingerGeometry:
    """The grasp geometry of ``env`` (read from its ``config``, an ``mpg_envs.tasks.config.EnvConfig``:
    the workspace and the grasp primitive's depth and lowest height), or of an env made with the
    default ``EnvConfig`` when ``env`` is ``None``.

    Raises:
        TypeError: ``env`` is not an MPG env (it has no ``EnvConfig``).
    """
    if env is None:
        from mpg_envs.tasks.config import EnvConfig  # noqa: PLC0415 - start-up time: it loads the simulation

        return geometry_of_config(EnvConfig())
    config = getattr(env.unwrapped, "config", None)
    if config is None or not hasattr(config, "workspace") or not hasattr(config, "primitives"):
        raise TypeError(f"{env.unwrapped!r} is no MPG env: it has no EnvConfig to read the grasp geometry from")
    return geometry_of_config(config)


def geometry_of_config(config: Any) -> FingerGeometry:
    """The grasp geometry an ``EnvConfig`` makes its envs with."""
    return FingerGeometry(config.workspace, config.primitives.grasp_depth, config.primitives.grasp_min_height)


def resolve_primitives(action_space: spaces.Space, primitives: Sequence[str] | None = None) -> tuple[str, ...]:
    """The primitives an action space indexes, in canonical order.

    Read from ``action_space.primitives`` (``mpg_envs.grid.actions.PixelActionSpace``), else from the
    ``primitives`` argument, else inferred from the size: 3 -> all, 2 -> push and grasp; a
    one-primitive space is ambiguous and raises.
    """
    if not isinstance(action_space, spaces.Discrete):
        raise TypeError(f"MPGNet needs a Discrete pixel action space, got {action_space}")
    declared = getattr(action_space, "primitives", None)
    if declared is not None:
        found = check_primitives(declared)
        if primitives is not None and tuple(primitives) != found:
            raise ValueError(f"primitives={tuple(primitives)} contradicts the action space's primitives {found}")
        return found
    if primitives is not None:
        return check_primitives(primitives)
    per = NUM_ROTATIONS * HEIGHTMAP_SIZE * HEIGHTMAP_SIZE  # one primitive's actions on the default grid
    n = int(action_space.n)
    if n % per:
        raise ValueError(
            f"action space Discrete({n}) is not P * {NUM_ROTATIONS} * {HEIGHTMAP_SIZE} * {HEIGHTMAP_SIZE} pixel actions"
        )
    count = n // per
    if count == 3:
        return PRIMITIVES
    if count == 2:
        return (PUSH, GRASP)
    raise ValueError(
        f"cannot tell which primitive a {count}-primitive action space Discrete({n}) uses; "
        f"pass primitives=(...) in policy_kwargs, one of {PRIMITIVES}"
    )


def check_observation_space(space: spaces.Space, size: int) -> None:
    """Fail early, naming the key, when an env's observation space is not MPG-shaped."""
    if not isinstance(space, spaces.Dict):
        raise TypeError(f"MPGNet needs a Dict observation space with color/depth/mask, got {space}")
    shapes = {
        "color": ((size, size, 3), (3, size, size)),
        "depth": ((size, size),),
        "mask": ((size, size),),
    }
    for key, allowed in shapes.items():
        if key not in space.spaces:
            raise ValueError(f"observation space lacks {key!r}; MPGNet needs keys {sorted(shapes)}")
        if tuple(space.spaces[key].shape or ()) not in allowed:
            raise ValueError(f"observation space {key!r} has shape {space.spaces[key].shape}; expected one of {allowed}")
    if space.spaces["color"].dtype != np.uint8:
        warnings.warn("colour observations are not uint8; MPGNet reads them on the 0..255 scale", stacklevel=3)
