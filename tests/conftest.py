"""Shared fixtures. Rendering tests need OpenGL: default to EGL on headless machines."""

import os
import sys
from pathlib import Path

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


PEERS_DIR = Path(os.environ.get("MPG_PEERS_DIR") or Path(__file__).resolve().parents[1].parent / "shared" / "peers")
"""The peers' published files, beside the repository (``<repo>/../shared/peers``) and never
copied into it; ``MPG_PEERS_DIR`` names another folder."""

PEER_FOLDERS = ("vpg/test-cases", "vpg/blocks", "gti")


def peers_or_stop(folder: Path, ci: bool) -> Path:
    """``folder`` if it holds the peers' files; else the test skips on a user's machine and
    fails under CI, where a skip would hide that the test never ran."""
    missing = [sub for sub in PEER_FOLDERS if not (folder / sub).is_dir()]
    if missing:
        message = f"the peers' files ({', '.join(missing)}) are not in {folder}; set MPG_PEERS_DIR to their folder"
        if ci:
            pytest.fail(message)
        pytest.skip(message)
    return folder


@pytest.fixture(scope="session")
def peers_dir() -> Path:
    """The one lookup of the peers' folder (:data:`PEERS_DIR`; fails when absent under ``CI=true``)."""
    return peers_or_stop(PEERS_DIR, os.environ.get("CI", "").lower() == "true")


@pytest.fixture(scope="session")
def vpg_dir(peers_dir: Path) -> Path:
    """The VPG peer files (meshes and test cases)."""
    return peers_dir / "vpg"


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


HEAVY_TESTS_FILE = Path(__file__).with_name("heavy.txt")


def pytest_collection_modifyitems(config, items):
    """Mark the tests listed in ``tests/heavy.txt`` ``heavy`` (deselected by default: the fast
    suite stays under 5 minutes; CI runs them after it). A listed id whose file was collected
    but which no longer exists is an error, so a renamed heavy test is never silently lost."""
    listed = {line.strip() for line in HEAVY_TESTS_FILE.read_text().splitlines() if line.strip() and not line.startswith("#")}
    root = Path(str(config.rootpath))
    seen = set()
    for item in items:
        node = Path(str(item.path)).relative_to(root).as_posix() + "::" + item.name
        if node in listed:
            item.add_marker(pytest.mark.heavy)
            seen.add(node)
    collected_files = {Path(str(item.path)).relative_to(root).as_posix() for item in items}
    missing = sorted(n for n in listed - seen if n.split("::")[0] in collected_files)
    if missing:
        raise pytest.UsageError(f"tests/heavy.txt lists tests that do not exist (renamed or removed?): {missing}")


def _load_script(folder: str, name: str, monkeypatch: pytest.MonkeyPatch):
    """``<folder>/<name>.py`` of the repository as a module under a test-only name, registered
    for the calling test alone."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / folder / f"{name}.py"
    spec = importlib.util.spec_from_file_location(f"{name}_under_test", path)
    module = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, module)
    spec.loader.exec_module(module)
    return module


@pytest.fixture()
def benchmark_script(monkeypatch):
    """A loader of a script of ``benchmarks/`` as a module: ``benchmark_script("keep_stages")``
    imports ``benchmarks/keep_stages.py`` under a test-only name, registered for this test alone."""
    return lambda name: _load_script("benchmarks", name, monkeypatch)


@pytest.fixture()
def docs_script(monkeypatch):
    """The same loader for the scripts of ``docs/``: ``docs_script("make_headline")``."""
    return lambda name: _load_script("docs", name, monkeypatch)
