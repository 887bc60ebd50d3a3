"""The episode's simulation as one public handle (``env.sim``), and test sets that know the
generator that made them."""

from __future__ import annotations

import ast
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import mpg_envs
from mpg_envs.scenes.test_sets import StaleTestSetError, find_test_set
from mpg_envs.tasks import scene_source
from mpg_envs.tasks.config import EnvConfig
from mpg_envs.tasks.scene_source import code_fingerprint, generator_digest

ROOT = Path(mpg_envs.__file__).resolve().parent


def _same_obs(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)


def test_env_and_scene_source_do_not_import_each_other():
    def imported(path: Path) -> set[str]:
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
            elif isinstance(node, ast.Import):
                names.update(alias.name for alias in node.names)
        return names

    assert "mpg_envs.tasks.env" not in imported(ROOT / "tasks" / "scene_source.py")
    assert "mpg_envs.tasks.scene_source" in imported(ROOT / "tasks" / "env.py")  # one way only


def test_a_reset_on_the_same_objects_reuses_the_world_and_gives_a_fresh_worlds_scene(make_env):
    env = make_env("MPG-OccludedHard-v0")
    obs, info = env.reset(seed=500000)
    world, executor = env.sim.world, env.sim.executor
    env.step(env.action_space.encode("grasp", 0, 100, 100))  # the world moves on
    again, info_again = env.reset(seed=500000)
    assert env.sim.world is world and env.sim.executor is executor  # same objects: not compiled again
    assert _same_obs(obs, again) and info_again == info
    fresh = make_env("MPG-OccludedHard-v0")
    first, _ = fresh.reset(seed=500000)
    assert _same_obs(first, again)  # a reused world starts as a fresh one, bit for bit
    env.reset(seed=500001)
    assert env.sim.world is not world  # other objects: another world


def test_a_dropped_scene_in_a_reused_world_is_the_fresh_ones(make_env):
    env = make_env("MPG-Stage2-v0")
    env.reset(seed=7)
    obs, info = env.reset(seed=7)
    fresh, fresh_info = make_env("MPG-Stage2-v0").reset(seed=7)
    assert _same_obs(obs, fresh) and info == fresh_info


def test_a_trial_undoes_the_world_and_the_generator(make_env):
    env = make_env("MPG-Stage2-v0")
    obs, _ = env.reset(seed=3)
    sim = env.sim
    qpos = sim.world.data.qpos.copy()
    state = sim.random.bit_generator.state
    rows, cols = np.nonzero(obs["mask"])
    with sim.trial():
        sim.random.integers(10, size=5)
        sim.executor.execute("grasp", 0, int(rows.mean()), int(cols.mean()), obs["depth"], env.target)
        assert not np.array_equal(sim.world.data.qpos, qpos)
    np.testing.assert_array_equal(sim.world.data.qpos, qpos)
    assert sim.random.bit_generator.state == state


def test_shipped_test_sets_record_this_codes_generator(make_env):
    for env_id in ("MPG-Occluded-v0", "MPG-OccludedHard-v0"):
        for n in (15, 30):
            env = make_env(env_id, num_objects=n)
            test_set = find_test_set(env.stage.test_set, n)
            test_set.check_made_by(generator_digest(env.scene_request))


def test_a_changed_generator_fails_the_test_set_check_saying_how_to_regenerate(make_env, monkeypatch):
    env = make_env("MPG-OccludedHard-v0")
    monkeypatch.setattr(scene_source, "generator_digest", lambda request: "a changed generator")
    with pytest.raises(StaleTestSetError, match=r"python benchmarks/make_test_sets.py --envs MPG-OccludedHard-v0 --objects 15"):
        env.reset(seed=500000)
    env.reset(seed=123)  # a dropped seed needs no test set


def test_the_generator_digest_follows_code_and_parameters_not_docs(make_env):
    request = make_env("MPG-OccludedHard-v0").scene_request
    digest = generator_digest(request)
    assert generator_digest(request) == digest
    assert generator_digest(replace(request, num_objects=30)) != digest
    config = EnvConfig(generator=replace(EnvConfig().generator, test_cluster_radius=0.08))
    assert generator_digest(replace(request, config=config)) != digest
    code = 'def f(x):\n    """Doc."""\n    return x + 1  # comment\n'
    assert code_fingerprint(code) == code_fingerprint('def f(x):\n    """Other doc."""\n    return x + 1\n')
    assert code_fingerprint(code) != code_fingerprint("def f(x):\n    return x + 2\n")
    # the fingerprint is source written back from the tree (the same text on every Python from
    # 3.11 on, where ast.dump differs), so a set made under one Python is valid under another
    assert code_fingerprint("def f(x) :\n  '''Doc.'''\n  return (x+1)  # c\n") == "def f(x):\n    return x + 1"
