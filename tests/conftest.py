"""Shared fixtures. Rendering tests need OpenGL: default to EGL on headless machines."""

import os
import sys

if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
    os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mpg_envs.simulation.objects import blocks_object_set  # noqa: E402


EXPECTED_PRIMITIVES = {
    "MPG-Stage1-v0": ("grasp",),
    "MPG-Stage2-v0": ("grasp",),
    "MPG-Stage3-v0": ("move",),
    "MPG-Stage4-v0": ("push", "grasp"),
    "MPG-Stage5-v0": ("move", "push", "grasp"),
    "MPG-Occluded-v0": ("move", "push", "grasp"),
    "MPG-OccludedHard-v0": ("move", "push", "grasp"),
}
"""The contract (ENV.md): each registered id and its primitives in action order."""


@pytest.fixture(scope="session")
def expected_primitives() -> dict[str, tuple[str, ...]]:
    """Env id -> the primitives ENV.md gives it, in action order (stated once for all tests)."""
    return EXPECTED_PRIMITIVES


@pytest.fixture(scope="session")
def blocks():
    """The blocks object set, by name."""
    return {asset.name: asset for asset in blocks_object_set()}


@pytest.fixture(scope="session")
def vpg_dir():
    """The VPG peer files (meshes and test cases), outside the repo; skip if absent."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "shared" / "peers" / "vpg"
    if not path.is_dir():
        pytest.skip(f"VPG peer files not found at {path}")
    return path


@pytest.fixture
def make_env():
    """Factory ``make_env(env_id, wrapped=False, **kwargs)``: ``gym.make(env_id, **kwargs)``
    (its unwrapped ``MPGEnv`` unless ``wrapped``), closed when the test ends. Shared by the
    env tests and the agents' integration tests."""
    import gymnasium as gym

    import mpg_envs  # noqa: F401  (registers the ids)

    made = []

    def make(env_id: str, wrapped: bool = False, **kwargs):
        env = gym.make(env_id, **kwargs)
        made.append(env)
        return env if wrapped else env.unwrapped

    yield make
    for env in made:
        env.close()


def flat_quat(yaw: float = 0.0) -> np.ndarray:
    return np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
