"""The MPG envs for Ray RLlib: ``register()`` makes every registered id known to ``register_env``.

::

    from mpg_envs.integrations.rllib import register
    register()
    config = PPOConfig().environment(
        "MPG-Stage2-v0",
        env_config={"wrappers": ["grid", "image"], "seed": 0, "num_objects": 5},
    )

``env_config`` holds the env's constructor arguments (``num_objects``, ``max_motions``,
``obs_mode`` ...) plus three keys of its own:

- ``wrappers``: a list applied in order, innermost first; each item a name or a
  ``[name, kwargs]`` pair. Names: ``"grid"`` (:class:`~mpg_envs.integrations.wrappers.GridAction`),
  ``"continuous"`` (:class:`~mpg_envs.integrations.wrappers.ContinuousAction`) and ``"image"``
  (:class:`~mpg_envs.integrations.wrappers.ImageObservation`, channels-last by default because RLlib's
  CNN encoder expects ``(H, W, C)``, then cast to float32 in [0, 1] with Gymnasium's
  ``DtypeObservation`` and ``RescaleObservation``: RLlib does not cast uint8 images). The raw
  env's 802,816-way action and ``Dict`` of
  heightmaps have no default RLlib model: use ``["grid", "image"]`` or your own RLModule.
- ``seed`` (default 0): the base seed. Each env seeds its first reset with
  ``seed + 1000 * worker_index + vector_index``, so every env of every runner draws its own
  scenes and a run is repeatable. RLlib's new API stack builds a runner's envs from one
  ``EnvContext`` whose ``vector_index`` is 0, so there the vector index is the order in
  which that runner built its envs. A seed given to ``reset`` (RLlib passes
  ``config.debugging(seed=...)`` when set) takes precedence.
- ``num_envs``: set by RLlib for vectorised entry points; ignored.

This module imports Ray only inside :func:`register`, so ``mpg_envs`` never needs it.
"""

from __future__ import annotations

import itertools
from collections import defaultdict
from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.wrappers import DtypeObservation, RescaleObservation

from mpg_envs import ENV_IDS, make
from mpg_envs.integrations.wrappers import ContinuousAction, GridAction, ImageObservation

SEED_STRIDE = 1000
"""Seeds per env runner: ``seed + SEED_STRIDE * worker_index + vector_index``."""


def _image(env: gym.Env, **kwargs: Any) -> gym.Env:
    """ImageObservation, channels-last, as float32 in [0, 1]: RLlib's CNN encoder feeds the
    observation to its first convolution as it comes (no cast from uint8, no scaling)."""
    kwargs.setdefault("channels_last", True)
    image = ImageObservation(env, **kwargs)
    return RescaleObservation(DtypeObservation(image, np.float32), np.float32(0.0), np.float32(1.0))


WRAPPERS: dict[str, Callable[..., gym.Env]] = {"grid": GridAction, "continuous": ContinuousAction, "image": _image}
"""Wrapper names accepted in ``env_config["wrappers"]``."""

_OWN_KEYS = ("wrappers", "seed", "num_envs")
_built: defaultdict[int, itertools.count] = defaultdict(itertools.count)  # envs built per worker index


class InitialSeed(gym.Wrapper):
    """Seeds the first ``reset`` with ``seed`` unless the caller gives one."""

    def __init__(self, env: gym.Env, seed: int):
        super().__init__(env)
        self.initial_seed = int(seed)
        self._seeded = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        if seed is None and not self._seeded:
            seed = self.initial_seed
        self._seeded = True
        return self.env.reset(seed=seed, options=options)


def apply_wrappers(env: gym.Env, wrappers: Any) -> gym.Env:
    """Wrap ``env`` with ``wrappers`` (names or ``[name, kwargs]`` pairs), innermost first."""
    if isinstance(wrappers, (str, bytes)) or not isinstance(wrappers, (list, tuple)):
        raise ValueError(f"env_config['wrappers'] must be a list of names or [name, kwargs] pairs, got {wrappers!r}")
    for item in wrappers:
        name, kwargs = item, None
        if isinstance(item, str):
            kwargs = {}
        elif isinstance(item, (list, tuple)) and len(item) == 2:
            name, kwargs = item
        if not isinstance(name, str) or name not in WRAPPERS or not isinstance(kwargs, Mapping):
            raise ValueError(f"unknown wrapper {item!r}; use one of {sorted(WRAPPERS)} or [name, kwargs]")
        env = WRAPPERS[name](env, **dict(kwargs))
    return env


def make_env(env_id: str, env_config: Mapping[str, Any] | None = None) -> gym.Env:
    """Build ``env_id`` as :func:`register`'s creators do, from an RLlib ``EnvContext`` (or
    a plain dict: worker and vector index 0)."""
    if env_id not in ENV_IDS:
        raise ValueError(f"unknown MPG env {env_id!r}; valid: {list(ENV_IDS)}")
    env_config = env_config if env_config is not None else {}
    kwargs = {k: v for k, v in dict(env_config).items() if k not in _OWN_KEYS}
    base_seed = env_config.get("seed", 0)
    if not isinstance(base_seed, int) or isinstance(base_seed, bool) or base_seed < 0:
        raise ValueError(f"env_config['seed'] must be a non-negative integer, got {base_seed!r}")
    worker_index = int(getattr(env_config, "worker_index", 0) or 0)
    vector_index = int(getattr(env_config, "vector_index", 0) or 0)
    built = next(_built[worker_index])
    if vector_index == 0:
        vector_index = built  # new API stack: one EnvContext for all of a runner's envs
    env = apply_wrappers(make(env_id, **kwargs), env_config.get("wrappers", []))
    return InitialSeed(env, base_seed + SEED_STRIDE * worker_index + vector_index)


def register() -> tuple[str, ...]:
    """Register the MPG ids with ``ray.tune.registry.register_env``; returns them.

    Call it in the driver before building the algorithm (RLlib ships the creators to
    the env runners itself).
    """
    from ray.tune.registry import register_env  # noqa: PLC0415 - Ray is an optional extra

    for env_id in ENV_IDS:
        register_env(env_id, lambda config, env_id=env_id: make_env(env_id, config))
    return ENV_IDS


__all__ = ["InitialSeed", "SEED_STRIDE", "WRAPPERS", "apply_wrappers", "make_env", "register"]
