"""The scripted baselines by name: the one registry of the policies that need no learning.

Each entry is a name, a factory ``(env, seed, **kwargs) -> Policy`` and a one-line
description (:class:`ScriptedBaseline`); :func:`make_baseline` builds one by name. Every
scripted baseline lives in this layer (numpy, OpenCV and the simulator only, no torch), one
module each, so a plain install of the envs has them all; ``mpg_agents``' ``make_policy`` reads
this registry and adds its learned policies. A name a baseline had before stays accepted
(``old_names``), with one ``DeprecationWarning``.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import gymnasium as gym

from mpg_envs.policies.exemplar_matcher import ExemplarMatcher
from mpg_envs.policies.oracle import OraclePolicy
from mpg_envs.policies.pixel_heuristic import PixelHeuristic
from mpg_envs.policies.policy import Policy
from mpg_envs.policies.random_policy import RandomPolicy

__all__ = [
    "SCRIPTED_BASELINES",
    "ScriptedBaseline",
    "baseline_name",
    "make_baseline",
    "register_baseline",
    "scripted_baseline_names",
]

BaselineFactory = Callable[..., Policy]
"""``factory(env, seed, **kwargs) -> Policy``."""


@dataclass(frozen=True)
class ScriptedBaseline:
    """One scripted baseline: its name, how to build it, what it does in a line, its former names,
    and whether its actions depend on how the env names the target (``target_spec``).

    ``reads_target_spec=False`` is a promise: the baseline reads the simulator's target and
    geometry (the oracle) or nothing (random), not the colours or the mask the env shows, so on
    two envs that differ only in ``target_spec`` (the visible mask; the exemplar, which recolours
    the scene) it plays the same episodes action for action (tested in
    ``tests/envs/test_target_blind_baselines.py``) and a table may reuse its mask-track cells for
    those tracks (:mod:`mpg_agents.evaluation.reused_cells`, ``scenes_of``)."""

    name: str
    factory: BaselineFactory
    description: str
    old_names: tuple[str, ...] = ()
    reads_target_spec: bool = True


SCRIPTED_BASELINES: dict[str, ScriptedBaseline] = {}
"""The registered baselines by name, in registration order."""
_OLD_NAMES: dict[str, str] = {}
_WARNED: set[str] = set()


def register_baseline(
    name: str,
    factory: BaselineFactory,
    description: str,
    old_names: tuple[str, ...] = (),
    reads_target_spec: bool = True,
) -> ScriptedBaseline:
    """Register a scripted baseline under ``name`` (and its former ``old_names``); raises
    ``ValueError`` for a name, or former name, already taken. ``reads_target_spec``: see
    :class:`ScriptedBaseline`."""
    for taken in (name, *old_names):
        if taken in SCRIPTED_BASELINES or taken in _OLD_NAMES:
            raise ValueError(f"the baseline name {taken!r} is already registered")
    baseline = ScriptedBaseline(name, factory, description, tuple(old_names), reads_target_spec)
    SCRIPTED_BASELINES[name] = baseline
    for old in old_names:
        _OLD_NAMES[old] = name
    return baseline


def scripted_baseline_names() -> tuple[str, ...]:
    """The registered baselines' names (former names aside), in registration order."""
    return tuple(SCRIPTED_BASELINES)


def baseline_name(name: str) -> str | None:
    """The registered name ``name`` says (itself, or the current name of a former one), else ``None``."""
    if name in SCRIPTED_BASELINES:
        return name
    return _OLD_NAMES.get(name)


def make_baseline(name: str, env: gym.Env, seed: int = 0, **kwargs: Any) -> Policy:
    """The scripted baseline ``name`` (or a former name of one) for ``env``.

    Raises:
        ValueError: ``name`` is no registered baseline (the message lists them).
    """
    current = baseline_name(name)
    if current is None:
        raise ValueError(f"unknown scripted baseline {name!r}; valid: {', '.join(SCRIPTED_BASELINES)}")
    if current != name and name not in _WARNED:
        _WARNED.add(name)
        warnings.warn(f"the policy name {name!r} is now {current!r}", DeprecationWarning, stacklevel=2)
    return SCRIPTED_BASELINES[current].factory(env, seed, **kwargs)


def _oracle(env: gym.Env, seed: int) -> Policy:
    return OraclePolicy(env)


def _random(env: gym.Env, seed: int) -> Policy:
    return RandomPolicy(env, seed)


def _pixel_heuristic(env: gym.Env, seed: int) -> Policy:
    return PixelHeuristic(env)


def _matcher(env: gym.Env, seed: int) -> Policy:
    return ExemplarMatcher(env)


register_baseline(
    "oracle", _oracle, "reads the simulator and tries actions in a copy (upper baseline)", reads_target_spec=False
)
register_baseline("random", _random, "uniform over the whole action space (seeded)", reads_target_spec=False)
register_baseline(
    "pixel-heuristic",
    _pixel_heuristic,
    "the heuristic grasp at the target mask, every step",
    old_names=("grasp-only",),
)
register_baseline(
    "matcher",
    _matcher,
    "finds an exemplar's match by colour and shape, uncovers it, grasps it (exemplar envs)",
)
