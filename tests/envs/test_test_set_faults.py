"""Shipped test sets under faults: a scene changed in its file is refused at its reset, a file
that is no set (a Git LFS pointer, a truncated download) is a ValueError naming it and costs no
seed outside the test seeds, and a stale set is one line from mpg-eval."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mpg_envs.scenes import test_sets
from mpg_envs.scenes.test_sets import ChangedTestSetError, TEST_SEEDS, find_test_set, load_test_set, shipped_set_path
from mpg_envs.tasks import scene_source

LFS_POINTER = (
    "version https://git-lfs.github.com/spec/v1\n"
    "oid sha256:4d7a214614ab2935c943f9e0ff69d22eadbb8f32b1258daaa5e2ca24d17e2393\nsize 414289\n"
)


@pytest.fixture
def shipped_as(monkeypatch):
    """``shipped_as(name, objects, path)``: the shipped set ``name_objects`` read from ``path`` instead."""
    real = test_sets.shipped_set_path

    def use(name: str, objects: int, path) -> None:
        monkeypatch.setattr(test_sets, "shipped_set_path", lambda n, k: path if (n, k) == (name, objects) else real(n, k))
        find_test_set.cache_clear()

    yield use
    find_test_set.cache_clear()


def moved_target(name: str, shift: tuple[float, float, float], path) -> object:
    """The first two scenes of the shipped set ``name``_15 written to ``path``, the first
    one's target moved by ``shift`` metres."""
    made = find_test_set(name, 15)
    first = {f: getattr(made, f)[:2] for f in ("seeds", "assets", "positions", "quats", "targets", "visible_fraction")}
    first["positions"] = first["positions"].copy()
    first["positions"][0, made.targets[0]] += shift
    return dataclasses.replace(made, **first).save(path)


def test_a_target_moved_1_cm_in_a_shipped_set_is_refused_at_its_reset(tmp_path, shipped_as, make_env):
    shipped_as("occluded_hard", 15, moved_target("occluded_hard", (-0.01, 0.0, 0.0), tmp_path / "occluded_hard_15.npz"))
    env = make_env("MPG-OccludedHard-v0")
    tolerance = find_test_set("occluded_hard", 15).visible_fraction_tolerance()  # wider on another MuJoCo major version
    message = (r"test set occluded_hard_15: the scene of seed 500000 is not the one the set was made with \(the "
               rf"target's visible fraction at reset is 0\.143187, the set records 0\.184758, tolerance {tolerance:g}\); restore "
               r"the file occluded_hard_15\.npz \(reinstall the package, or `git checkout -- "
               r"mpg_envs/test_scenes/occluded_hard_15\.npz`\) or regenerate it with `python benchmarks/make_test_sets\.py "
               r"--envs MPG-OccludedHard-v0 --objects 15` \(the set was made with MuJoCo [0-9.]+, this is MuJoCo [0-9.]+\)$")
    with pytest.raises(ChangedTestSetError, match=message):
        env.reset(seed=500000)
    _, info = env.reset(seed=500001)  # its other scenes are as made
    assert info["visible_fraction"] == pytest.approx(float(find_test_set("occluded_hard", 15).visible_fraction[1]),
                                                abs=1e-6 if tolerance == test_sets.VISIBLE_FRACTION_TOLERANCE else tolerance)


def test_the_unseen_shapes_set_with_a_target_moved_1_cm_is_refused(tmp_path, shipped_as, make_env):
    name = "occluded_hard_novel"
    shipped_as(name, 15, moved_target(name, (0.01, 0.0, 0.0), tmp_path / f"{name}_15.npz"))
    with pytest.raises(ChangedTestSetError, match=r"seed 500000 .* at reset is 0\.167266, the set records 0\.251799"):
        make_env("MPG-OccludedHardNovel-v0").reset(seed=500000)


def test_the_check_passes_the_shipped_scenes_exactly(make_env):
    """The sample of each shipped set checked here (every scene of every set passed when the
    check was written) measures its recorded fraction to float32 rounding."""
    for env_id, name in (("MPG-Occluded-v0", "occluded"), ("MPG-OccludedHard-v0", "occluded_hard")):
        env = make_env(env_id)
        made = find_test_set(name, 15)
        for k in (0, len(made) - 1):
            _, info = env.reset(seed=int(made.seeds[k]))
            assert abs(info["visible_fraction"] - float(made.visible_fraction[k])) < 1e-6


def test_a_git_lfs_pointer_is_named_and_costs_no_seed_outside_the_test_seeds(tmp_path, shipped_as, make_env):
    path = tmp_path / "occluded_hard_15.npz"
    path.write_text(LFS_POINTER)
    with pytest.raises(ValueError, match=rf"^{path}: a Git LFS pointer, not the test set itself; fetch the file with `git lfs pull`"):
        load_test_set(path)
    shipped_as("occluded_hard", 15, path)
    env = make_env("MPG-OccludedHard-v0")
    with pytest.raises(ValueError, match="a Git LFS pointer"):
        env.reset(seed=500000)
    for seed in (TEST_SEEDS.stop, 700000, 123):  # tuning and training seeds never read the file
        assert scene_source.scene_from_test_set(env.scene_request, seed) is None


def test_a_truncated_or_foreign_set_is_a_value_error_naming_the_file(tmp_path):
    data = shipped_set_path("occluded_hard", 15).read_bytes()
    truncated = tmp_path / "truncated.npz"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=rf"^{truncated}: not a readable mpg-test-set file \(truncated or damaged: "):
        load_test_set(truncated)
    text = tmp_path / "text.npz"
    text.write_text("not a set")
    with pytest.raises(ValueError, match=rf"^{text}: not an mpg-test-set file \("):
        load_test_set(text)
    other = tmp_path / "other.npz"
    np.savez(other, seeds=np.arange(3))
    with pytest.raises(ValueError, match=rf"^{other}: not an mpg-test-set file \(no assets, positions, "):
        load_test_set(other)


def test_a_stale_test_set_is_one_line_from_mpg_eval(monkeypatch, capsys):
    from mpg_agents.cli import eval_main

    monkeypatch.setattr(scene_source, "generator_digest", lambda request: "a changed generator")
    code = eval_main(["--policy", "random", "--env", "MPG-OccludedHard-v0", "--episodes", "1", "--seed", "500000", "--quiet"])
    err = capsys.readouterr().err
    assert code != 0 and err.count("\n") == 1 and "Traceback" not in err
    assert "test set occluded_hard_15 was made by another scene generator" in err


def test_a_stale_test_set_raised_from_the_run_is_a_user_error(monkeypatch, capsys):
    from mpg_agents import cli
    from mpg_agents.evaluation import eval_runner
    from mpg_envs.scenes.test_sets import StaleTestSetError

    def stale(*args, **kwargs):
        raise StaleTestSetError("test set occluded_hard_15 was made by another scene generator")

    monkeypatch.setattr(eval_runner, "evaluate_parallel", stale)
    assert cli.eval_main(["--policy", "random", "--env", "MPG-OccludedHard-v0", "--episodes", "1", "--quiet"]) == 2
    assert capsys.readouterr().err == "error: test set occluded_hard_15 was made by another scene generator\n"
