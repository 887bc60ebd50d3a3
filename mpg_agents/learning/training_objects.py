"""What a training stage's envs are built from: the ``env_options`` a stage may set, and the
object sets a run may train on (never a held-out test set or test seeds).

A stage's ``object_set`` is a set name or a list of sets pooled into one, each ``"name"`` or
``"name:seed"`` (``"procedural:3"``: the mix of every procedural family drawn with set seed 3).
Pooling gives a run more shapes than one 20-shape set holds; every seed comes from the
families' training split (:data:`~mpg_envs.simulation.families.FAMILY_SEED_RANGES`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.families import FAMILY_SEED_RANGES, PROCEDURAL_SETS
from mpg_envs.simulation.objects import load_object_set
from mpg_envs.tasks.config import EnvConfig, config_of

STAGE_ENV_OPTIONS = ("object_set", "visual_randomization", "obs_mode", "config", "arranged")
"""The ``gym.make`` keywords a stage's ``env_options`` may set (``arranged``: a share of resets
starting from drawn arrangements, :class:`~mpg_envs.scenes.arranged.ArrangedScenes`); ``config`` is a table of
:class:`~mpg_envs.tasks.config.EnvConfig` fields (e.g. ``scene_tries``, ``generator``) other
than ``reward``. The object count, the rewards and the discriminator are the stage's and the
run's own."""

OBS_MODES = ("raycast", "camera")


def object_set_entries(value: Any, what: str = "object_set") -> list[tuple[str, int | None]]:
    """A training object set as ``[(name, seed or None), ...]``: ``value`` is a set name or a list
    of ``"name"`` / ``"name:seed"`` strings (pooled). Names are ``"blocks"`` and the procedural
    sets; seeds must lie in the families' training split (below 500000).

    Raises:
        ValueError: not a name or list of names, an unknown or held-out set, a seed that is not
            a training seed (each names what is valid).
    """
    items = [value] if isinstance(value, str) else list(value) if isinstance(value, (list, tuple)) else None
    if not items or not all(isinstance(item, str) for item in items):
        raise ValueError(
            f"{what}: object_set must be a set name or a non-empty list of 'name' or 'name:seed' strings, got {value!r}"
        )
    valid = ("blocks", *PROCEDURAL_SETS)
    entries = []
    for item in items:
        name, _, seed_text = item.partition(":")
        if name not in valid:
            raise ValueError(
                f"{what}: object set {name!r} cannot be trained on; valid: {list(valid)} (held-out test sets are refused)"
            )
        seed = None
        if seed_text:
            if not seed_text.isdigit() or int(seed_text) not in FAMILY_SEED_RANGES["train"]:
                train = FAMILY_SEED_RANGES["train"]
                raise ValueError(
                    f"{what}: {item!r}: a training set's seed must be an integer "
                    f"in [{train.start}, {train.stop - 1}], got {seed_text!r}"
                )
            seed = int(seed_text)
        entries.append((name, seed))
    return entries


def stage_env_config(options: dict[str, Any], reward: Any = None) -> EnvConfig | None:
    """The training env's :class:`EnvConfig`: ``options``' ``config`` table with the stage's
    ``reward`` settings (a ``(field, value)`` tuple) on top; ``None`` when neither is set (the
    registered env's own config).

    Raises:
        ValueError: ``config`` is not a table of EnvConfig fields, or names ``reward``.
    """
    table = options.get("config", {})
    if not isinstance(table, dict) or "reward" in table:
        raise ValueError(
            "env_options config must be a table of EnvConfig fields other "
            f"than reward (a stage's reward is its own), got {table!r}"
        )
    if not table and not reward:
        return None
    base = config_of(dict(table))
    return replace(base, reward=replace(base.reward, **dict(reward))) if reward else base


def training_object_set(value: Any) -> str | list[ObjectAsset]:
    """The env's ``object_set`` for a stage's ``object_set`` option: a plain name passes through
    (the env loads it, with its config's set seed); a list, or a name with a seed, is loaded and
    pooled into one list of assets."""
    entries = object_set_entries(value)
    if len(entries) == 1 and entries[0][1] is None:
        return entries[0][0]
    assets: list[ObjectAsset] = []
    for name, seed in entries:
        assets.extend(load_object_set(name, seed=seed or 0))
    return assets
