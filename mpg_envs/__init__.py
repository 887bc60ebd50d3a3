"""MPG environments: target-oriented grasping in clutter on MuJoCo.

Importing the package registers one Gymnasium id per stage of
:data:`mpg_envs.tasks.stages.STAGES` (:data:`ENV_IDS`: ``MPG-Stage1-v0`` ... ``MPG-Stage5-v0``,
``MPG-Occluded-v0``, ...) and one per track of :data:`mpg_envs.tasks.tracks.TRACKS`
(``MPG-OccludedHardCamera-v0``); ``gymnasium.make("mpg_envs:MPG-Stage5-v0")`` imports it on demand.
Each id carries its stage's motion cap as ``max_episode_steps``, so ``gymnasium.make`` wraps
the env in Gymnasium's ``TimeLimit`` at the same cap the env enforces itself.

Importing the package also picks an OpenGL backend for rendering when none is chosen
(``MUJOCO_GL``; see :func:`mpg_envs.perception.render.choose_gl_backend`). It imports no deep-learning
library.
"""

from mpg_envs._version import __version__
from mpg_envs.perception.render import choose_gl_backend

choose_gl_backend()  # before anything imports mujoco: EGL (or OSMesa) on headless Linux

from typing import Any

import gymnasium as gym

from mpg_envs.grid.actions import PRIMITIVES, PixelAction, PixelActionSpace, decode_action, encode_action
from mpg_envs.grid.workspace import NUM_ROTATIONS, Workspace
from mpg_envs.integrations.wrappers import ContinuousAction, GridAction, ImageObservation
from mpg_envs.tasks.stages import STAGES, StageSpec
from mpg_envs.tasks.tracks import TRACKS

ENV_IDS: tuple[str, ...] = tuple(spec.env_id for spec in STAGES.values())


def _register() -> None:
    """Register every stage's id (once), with ``max_episode_steps`` = the stage's motion cap.

    A cap passed to ``gymnasium.make(env_id, max_motions=n)`` changes the env's own cap; pass
    ``max_episode_steps=n`` with it when ``n`` is larger than the stage's (or use :func:`make`),
    or the ``TimeLimit`` wrapper truncates at the stage's cap first.
    """
    for name, stage in STAGES.items():
        if stage.env_id not in gym.registry:
            gym.register(
                id=stage.env_id,
                entry_point="mpg_envs.tasks.env:MPGEnv",
                kwargs={"stage": name},
                max_episode_steps=stage.max_motions,
            )
    for track in TRACKS.values():  # a stage with fixed keywords (mpg_envs.tasks.tracks)
        if track.env_id not in gym.registry:
            kwargs = {"stage": track.stage, **track.options}
            gym.register(
                id=track.env_id, entry_point="mpg_envs.tasks.env:MPGEnv", kwargs=kwargs, max_episode_steps=track.max_motions
            )


def make(env_id: str, **kwargs) -> gym.Env:
    """``gymnasium.make(env_id, **kwargs)`` whose ``TimeLimit`` follows a ``max_motions`` given
    here (unless ``max_episode_steps`` is given too), so it never cuts an episode short of the
    env's own cap."""
    if "max_motions" in kwargs:
        kwargs.setdefault("max_episode_steps", kwargs["max_motions"])
    return gym.make(env_id, **kwargs)


def env_primitives(env: gym.Env) -> tuple[str, ...]:
    """The primitives an env allows, in action order (works through wrappers)."""
    unwrapped: Any = env.unwrapped  # an MPG env (gym.Env does not declare its attributes)
    return tuple(unwrapped.primitives)


_register()

__all__ = [
    "__version__",
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
    "make",
]
