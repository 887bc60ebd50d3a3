"""MPG environments: target-oriented grasping in clutter on MuJoCo.

Importing the package registers the six Gymnasium ids (``MPG-Stage1-v0`` ...
``MPG-Stage5-v0`` and ``MPG-Occluded-v0``); ``gymnasium.make("mpg_envs:MPG-Stage5-v0")``
imports it on demand.
"""

from mpg_envs.render import choose_gl_backend

choose_gl_backend()  # before anything imports mujoco: EGL (or OSMesa) on headless Linux

import gymnasium as gym  # noqa: E402

from mpg_envs.actions import PRIMITIVES, PixelAction, PixelActionSpace, decode_action, encode_action
from mpg_envs.stages import STAGES, StageSpec
from mpg_envs.workspace import NUM_ROTATIONS, Workspace
from mpg_envs.wrappers import ContinuousAction, GridAction, ImageObservation

ENV_IDS: tuple[str, ...] = tuple(spec.env_id for spec in STAGES.values())


def _register() -> None:
    for name, stage in STAGES.items():
        if stage.env_id not in gym.registry:
            gym.register(id=stage.env_id, entry_point="mpg_envs.env:MPGEnv", kwargs={"stage": name})


def env_primitives(env: gym.Env) -> tuple[str, ...]:
    """The primitives an env allows, in action order (works through wrappers)."""
    return tuple(env.unwrapped.primitives)


_register()

__all__ = [
    "ContinuousAction",
    "ENV_IDS",
    "GridAction",
    "ImageObservation",
    "NUM_ROTATIONS",
    "PRIMITIVES",
    "PixelAction",
    "PixelActionSpace",
    "STAGES",
    "StageSpec",
    "Workspace",
    "decode_action",
    "encode_action",
    "env_primitives",
]
