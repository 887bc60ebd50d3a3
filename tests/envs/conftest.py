"""Fixtures shared by the env tests."""

from __future__ import annotations

import pytest

from mpg_envs.perception.camera import CameraConfig, add_cameras

from .hand_scenes import clutter_spec, compile_forward


@pytest.fixture(scope="module")
def clutter():
    """The clutter scene with the default cameras: ``(model, data, camera names)``."""
    spec = clutter_spec()
    names = add_cameras(spec, CameraConfig())
    model, data = compile_forward(spec)
    return model, data, names
