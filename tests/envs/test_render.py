"""env.render(): EGL chosen without the user's help; without GL one clean error, never an abort."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import mujoco
import numpy as np
import pytest

import mpg_envs.perception.render as render_module
from mpg_envs.perception.render import RenderUnavailableError, default_gl_backend, gl_library_loads, make_renderer


def _loads(*available: str):
    return lambda backend: backend in available


@pytest.mark.parametrize(
    ("environ", "platform", "available", "expected"),
    [
        ({}, "linux", ("egl", "osmesa"), "egl"),  # headless Linux with EGL: pick it
        ({}, "linux", ("osmesa",), "osmesa"),  # no EGL: OSMesa as the fallback
        ({}, "linux", (), None),  # neither: leave it (render() will explain)
        ({"MUJOCO_GL": "osmesa"}, "linux", ("egl",), None),  # the user's choice stands
        ({"MUJOCO_GL": ""}, "linux", ("egl",), None),
        ({"DISPLAY": ":0"}, "linux", ("egl",), None),  # a display: MuJoCo's GLFW works
        ({"WAYLAND_DISPLAY": "wayland-0"}, "linux", ("egl",), None),
        ({"DISPLAY": ""}, "linux", ("egl",), "egl"),  # an empty DISPLAY is no display
        ({}, "darwin", ("egl",), None),  # macOS and Windows: MuJoCo's defaults
        ({}, "win32", ("egl",), None),
    ],
)
def test_default_gl_backend(environ, platform, available, expected):
    assert default_gl_backend(environ, platform, _loads(*available)) == expected


def _run(code: str, **env_changes: str | None) -> subprocess.CompletedProcess:
    env = dict(os.environ, OMP_NUM_THREADS="1")
    for key, value in env_changes.items():
        if value is None:
            env.pop(key, None)
        else:
            env[key] = value
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, capture_output=True, text=True, timeout=600
    )


def test_importing_mpg_envs_picks_a_headless_backend():
    proc = _run(
        "import os, mpg_envs; print('MUJOCO_GL', os.environ.get('MUJOCO_GL'))", MUJOCO_GL=None, DISPLAY=None,
        WAYLAND_DISPLAY=None,
    )
    assert proc.returncode == 0, proc.stderr
    expected = default_gl_backend({}, sys.platform, gl_library_loads)
    assert f"MUJOCO_GL {expected}" in proc.stdout


def test_without_gl_render_raises_once_cleanly_and_the_next_env_works():
    """GLFW without a display used to abort the interpreter on the second env's render."""
    code = """
        import gymnasium as gym
        from gymnasium.utils.env_checker import check_env
        import mpg_envs
        from mpg_envs.perception.render import RenderUnavailableError

        env = gym.make("MPG-Stage1-v0", render_mode="rgb_array")
        try:
            check_env(env.unwrapped)  # the user's way in: reset, step, then render
        except RenderUnavailableError:
            print("check_env: RenderUnavailableError")
        env.close()
        for attempt in range(2):  # the second render is the one that used to abort
            env = gym.make("MPG-Stage1-v0", render_mode="rgb_array")
            env.reset(seed=attempt)
            try:
                env.render()
            except RenderUnavailableError as exc:
                print("render:", exc)
            env.close()
        env = gym.make("MPG-Stage1-v0")
        obs, _ = env.reset(seed=0)
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        check_env(env.unwrapped, skip_render_check=True)
        env.close()
        print("next env: reset, step and check_env work")
    """
    proc = _run(code, MUJOCO_GL="glfw", DISPLAY=None, WAYLAND_DISPLAY=None)
    assert proc.returncode == 0, f"rc {proc.returncode}\n{proc.stdout}\n{proc.stderr[-3000:]}"
    renders = [line for line in proc.stdout.splitlines() if line.startswith("render:")]
    assert len(renders) == 2 and renders[0] == renders[1]
    for needle in ("MUJOCO_GL=glfw", "libegl1", "libosmesa6", "env.render()"):
        assert needle in renders[0]
    assert "check_env: RenderUnavailableError" in proc.stdout
    assert "next env: reset, step and check_env work" in proc.stdout


def test_make_renderer_never_retries_after_a_failure(monkeypatch):
    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1' type='sphere'/></worldbody></mujoco>")
    monkeypatch.setattr(render_module, "_gl_failure", None)  # as in a fresh process (restored after)
    calls = []

    def no_gl(*args, **kwargs):
        calls.append(1)
        raise mujoco.FatalError("gladLoadGL error")

    monkeypatch.setattr(mujoco, "Renderer", no_gl)
    for _ in range(3):
        with pytest.raises(RenderUnavailableError, match="gladLoadGL error") as info:
            make_renderer(model, 32, 32, purpose="A test picture")
        assert str(info.value).startswith("A test picture needs OpenGL")
    assert isinstance(info.value, RuntimeError) and len(calls) == 1


@pytest.mark.gl
def test_render_draws_the_scene():
    import gymnasium as gym

    env = gym.make("MPG-Stage2-v0", render_mode="rgb_array")
    env.reset(seed=0)
    try:
        image = env.render()
    except RenderUnavailableError as exc:
        pytest.skip(str(exc))
    finally:
        env.close()
    assert image.shape == (480, 640, 3) and image.dtype == np.uint8
    assert image.std() > 10  # a scene, not a blank frame
