"""``benchmarks/make_test_sets.py`` resumes: finished blocks of seeds are kept as shards, a
run started again makes only the rest (from the shards, or from a set it wrote), ``--partial``
writes the sets made so far, and a shard made by another generator is refused. The drops are stubbed (only the bookkeeping is tested)."""

from __future__ import annotations

import shutil
from concurrent.futures import Future

import numpy as np
import pytest

from mpg_envs.scenes.generators import GeneratorConfig
from mpg_envs.scenes.test_sets import load_test_set

ENV, N = "MPG-OccludedHard-v0", 5


@pytest.fixture()
def script(monkeypatch, benchmark_script):
    module = benchmark_script("make_test_sets")
    module.made, module.fail_at = [], set()

    def fake_scene(task):
        _, n, seed = task
        if seed in module.fail_at:
            raise RuntimeError(f"killed at seed {seed}")
        module.made.append(seed)
        return {"seed": seed, "assets": [f"cube{seed}"] * n, "positions": np.full((n, 3), seed / 1e6), "quats": np.tile([1.0, 0, 0, 0], (n, 1)),
                "target": seed % n, "visible_fraction": 0.25, "seconds": 0.5}  # fmt: skip

    class SerialPool:  # the pool's interface, in this process (the stub is not seen by child processes)
        def __init__(self, workers):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def submit(self, fn, *args):
            future = Future()
            try:
                future.set_result(fn(*args))
            except Exception as error:  # noqa: BLE001  (handed to the caller, as a pool does)
                future.set_exception(error)
            return future

    monkeypatch.setattr(module, "make_scene", fake_scene)
    monkeypatch.setattr(module, "ProcessPoolExecutor", SerialPool)
    return module


def run(script, tmp_path, *extra):
    return script.main(["--envs", ENV, "--objects", str(N), "--count", "5", "--block", "2", "--workers", "1",
                        "--out", str(tmp_path / "out"), "--work", str(tmp_path / "work"), *extra])  # fmt: skip


def test_a_killed_run_resumes_from_its_finished_blocks(script, tmp_path, capsys):
    script.fail_at = {500002}
    with pytest.raises(RuntimeError, match="killed at seed 500002"):
        run(script, tmp_path)
    shards = sorted(p.name for p in (tmp_path / "work").iterdir())
    assert shards == ["occluded_hard_5_500000-500001.npz", "occluded_hard_5_500004-500004.npz"]  # whole blocks only, no temporary file
    assert not (tmp_path / "out" / "occluded_hard_5.npz").exists()

    assert run(script, tmp_path, "--partial") == 0  # the sets so far: the first block (the third is not contiguous)
    partial = load_test_set(tmp_path / "out" / "occluded_hard_5.npz")
    assert partial.seeds.tolist() == [500000, 500001] and partial.generator_config == GeneratorConfig()
    assert "2 of 5 scenes made" in capsys.readouterr().out

    script.fail_at, script.made = set(), []
    assert run(script, tmp_path) == 0
    assert script.made == [500002, 500003]  # only the missing block
    full = load_test_set(tmp_path / "out" / "occluded_hard_5.npz")
    assert full.seeds.tolist() == list(range(500000, 500005)) and full.targets.tolist() == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal(full.positions[:, 0, 0], np.arange(500000, 500005) / 1e6)
    out = capsys.readouterr().out
    assert "3/5 scenes already made" in out and "ETA" in out and "scenes/min" in out
    assert full.meta["generator_digest"] and full.meta["generator_config"]

    # Without the work folder, the written set itself is what was made (a shipped partial set resumes).
    shutil.rmtree(tmp_path / "work")
    script.made = []
    assert run(script, tmp_path) == 0 and script.made == []
    assert "5/5 scenes already made" in capsys.readouterr().out
    again = load_test_set(tmp_path / "out" / "occluded_hard_5.npz")
    for field in ("seeds", "assets", "positions", "quats", "targets", "visible_fraction"):
        np.testing.assert_array_equal(getattr(again, field), getattr(full, field))


def test_a_shard_of_another_generator_is_refused(script, tmp_path):
    assert run(script, tmp_path) == 0
    shard = tmp_path / "work" / "occluded_hard_5_500000-500001.npz"
    with np.load(shard) as data:
        arrays = dict(data)
    np.savez_compressed(shard, **{**arrays, "digest": np.array("another generator")})
    with pytest.raises(SystemExit, match="occluded_hard_5_500000-500001.npz: made by another generator"):
        run(script, tmp_path)
