"""The package tops' public names: every name ``mpg_envs`` and ``mpg_agents`` export stays
importable from the top, wherever the module that defines it lives."""

from __future__ import annotations

import importlib

import pytest

PUBLIC = {
    "mpg_envs": (
        "__version__", "ContinuousAction", "ENV_IDS", "GridAction", "ImageObservation", "NUM_ROTATIONS",
        "PRIMITIVES", "PixelAction", "PixelActionSpace", "STAGES", "StageSpec", "Workspace", "decode_action",
        "encode_action", "env_primitives", "make",
    ),
    "mpg_agents": (
        "__version__", "COORDINATIONS", "Decision", "Discriminator", "GraspThreshold", "MPGAgent", "MPGDQN",
        "MPGNet", "MPGNetConfig", "MPGNetPolicy", "MPGQFunction", "MPGQNetwork", "MobileNetV3Features",
        "PrioritizedHeightmapReplayBuffer", "TDStepConfig", "TRAINING_STAGES", "TrainConfig", "TrainingStage",
        "calibrate_q_star", "choose_primitive", "flat_q", "load_mpgnet", "load_torchvision_features",
        "recompute_batch_norm_statistics", "save_mpgnet", "save_qmap_png", "td_step", "td_targets",
    ),
}
"""Each package's ``__all__``, pinned: a name leaves or joins it only on purpose."""


@pytest.mark.parametrize("package", sorted(PUBLIC))
def test_the_top_exports_the_same_names(package):
    module = importlib.import_module(package)
    assert tuple(module.__all__) == PUBLIC[package]
    assert set(PUBLIC[package]) <= set(dir(module))


@pytest.mark.parametrize("package, name", [(p, n) for p, names in sorted(PUBLIC.items()) for n in names])
def test_every_public_name_imports_from_the_top(package, name):
    namespace: dict = {}
    exec(f"from {package} import {name}", namespace)
    assert namespace[name] is getattr(importlib.import_module(package), name)


@pytest.mark.parametrize("package", sorted(PUBLIC))
def test_no_public_name_is_a_module(package):
    """``from mpg_agents import td_step`` is the function, whichever modules were imported first
    (while ``td_step.py`` lay at the package top, importing it rebound the name to the module)."""
    module = importlib.import_module(package)
    importlib.import_module("mpg_agents.learning.learner")  # imports the module td_step, among others
    for name in PUBLIC[package]:
        assert not isinstance(getattr(module, name), type(importlib)), f"{package}.{name} is a module"
