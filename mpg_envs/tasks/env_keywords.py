"""The checks of ``MPGEnv``'s keywords that are no settings (``stage``, ``num_objects``, ``wrong_grasp``,
``visible_range``, ``use_test_set``, ``max_motions``, ``obs_mode``, ``render_mode``, ``grasp_scorer``):
each a ``ValueError`` naming the keyword and what is valid; a value left ``None`` takes the stage's.
The keywords that name settings (``config``, ``object_set``, ``camera_config``) are checked by
:mod:`mpg_envs.tasks.config`."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from mpg_envs.perception.occlusion import check_band
from mpg_envs.scenes.scene_file import MAX_OBJECTS
from mpg_envs.tasks.config import OBS_MODES
from mpg_envs.tasks.stages import STAGES, WRONG_GRASP_RULES, StageSpec

__all__ = [
    "GraspScorer",
    "check_grasp_scorer",
    "check_max_motions",
    "check_num_objects",
    "check_obs_mode",
    "check_render_mode",
    "check_use_test_set",
    "check_visible_range",
    "check_wrong_grasp",
    "stage_of",
]

GraspScorer = Callable[[dict[str, np.ndarray]], float]
"""What scores an observation for the move and push rewards (a frozen grasp net, for one)."""


def stage_of(stage: str | StageSpec) -> StageSpec:
    """The :class:`~mpg_envs.tasks.stages.StageSpec` of ``stage`` (a name of ``STAGES``, or a spec)."""
    spec = STAGES[stage] if isinstance(stage, str) and stage in STAGES else stage
    if not isinstance(spec, StageSpec):
        raise ValueError(f"unknown stage {stage!r}; valid: {sorted(STAGES)}")
    return spec


def check_num_objects(n: Any, stage: StageSpec) -> int:
    """``n`` as the object count of one of ``stage``'s scenes: an integer from the stage's least to
    the most a scene holds."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not stage.min_objects <= n <= MAX_OBJECTS:
        raise ValueError(f"num_objects must be an integer in {stage.min_objects}..{MAX_OBJECTS} for {stage.env_id}, got {n!r}")
    return int(n)


def check_wrong_grasp(wrong_grasp: str | None, stage: StageSpec) -> str:
    """What a mis-pick does (``None``: the stage's rule); strict retrieval needs a target."""
    rule = stage.wrong_grasp if wrong_grasp is None else wrong_grasp
    if rule not in WRONG_GRASP_RULES:
        raise ValueError(f"wrong_grasp must be one of {WRONG_GRASP_RULES}, got {wrong_grasp!r}")
    if rule == "fail" and stage.mask_all_objects:
        raise ValueError(f"wrong_grasp='fail' needs a target; {stage.env_id} has none (every object is a target)")
    return rule


def check_visible_range(visible_range: tuple[float, float] | None, stage: StageSpec) -> tuple[float, float] | None:
    """The band of the target's visible fraction at reset (``None``: the stage's); a band needs a target."""
    band = check_band(stage.visible_range if visible_range is None else visible_range)
    if band is not None and stage.mask_all_objects:
        raise ValueError(f"visible_range needs a target; {stage.env_id} has none (every object is a target)")
    return band


def check_use_test_set(use_test_set: Any) -> bool:
    """Whether the test seeds load their shipped scenes: True or False."""
    if not isinstance(use_test_set, (bool, np.bool_)):
        raise ValueError(f"use_test_set must be True or False, got {use_test_set!r}")
    return bool(use_test_set)


def check_max_motions(max_motions: Any, stage: StageSpec) -> int:
    """The motion cap (``None``: the stage's): a positive integer, returned as given."""
    cap = stage.max_motions if max_motions is None else max_motions
    if not isinstance(cap, (int, np.integer)) or cap < 1:
        raise ValueError(f"max_motions must be a positive integer, got {max_motions!r}")
    return cap  # type: ignore[return-value]  # a NumPy integer is kept as given


def check_obs_mode(obs_mode: Any) -> str:
    """The observation mode: one of :data:`~mpg_envs.tasks.config.OBS_MODES`."""
    if obs_mode not in OBS_MODES:
        raise ValueError(f"obs_mode must be one of {OBS_MODES}, got {obs_mode!r}")
    return obs_mode


def check_render_mode(render_mode: Any, render_modes: Sequence[str]) -> str | None:
    """``None`` or one of the env's ``render_modes``."""
    if render_mode is not None and render_mode not in render_modes:
        raise ValueError(f"render_mode must be None or one of {render_modes}, got {render_mode!r}")
    return render_mode


def check_grasp_scorer(grasp_scorer: Any) -> GraspScorer | None:
    """``None`` or a callable observation -> float (:data:`GraspScorer`)."""
    if grasp_scorer is not None and not callable(grasp_scorer):
        raise ValueError("grasp_scorer must be a callable obs -> float")
    return grasp_scorer
