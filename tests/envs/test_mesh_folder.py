"""Tests of loading a folder of meshes: one failing or slow mesh is skipped (or stands in as its
hull when that is close to it) while the others load, in parallel worker processes."""

from __future__ import annotations

import re
import textwrap
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import trimesh

from mpg_envs.simulation import mesh_folder, meshes
from mpg_envs.simulation.assets import convex_part
from mpg_envs.simulation.decomposition import HULL_FALLBACK_RATIO, hull_close_enough
from mpg_envs.simulation.isolated_call import IsolatedWorker, WorkerPool
from mpg_envs.simulation.objects import MeshFolderObjects, MeshLoadError, SkippedMesh, load_mesh_folder


@pytest.fixture()
def injected(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A module the worker can import (it takes the caller's sys.path): the real mesh pipeline
    with coacd replaced by one that fails or hangs, so only meshes that need coacd are hit."""
    module = tmp_path / "mesh_injected.py"
    module.write_text(textwrap.dedent("""
        import time

        from mpg_envs.simulation import decomposition

        def _run(replacement, args):
            real = decomposition.decompose
            decomposition.decompose = replacement
            try:
                return decomposition.solid_from_mesh_file(*args)
            finally:
                decomposition.decompose = real

        def _fail(*args, **kwargs):
            raise RuntimeError("injected coacd failure")

        def coacd_fails(*args):
            return _run(_fail, args)

        def coacd_hangs(*args):
            return _run(lambda *a, **k: time.sleep(60), args)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    return "mesh_injected"


def _folder(root: Path, shapes: dict[str, trimesh.Trimesh]) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    for name, mesh in shapes.items():
        mesh.export(root / name)
    return root


def _ring(r_min: float) -> trimesh.Trimesh:
    """A tube 3 cm tall, 3 cm outer radius: its hull (the solid cylinder) is 0.03^2 / (0.03^2 - r_min^2) x its volume."""
    return trimesh.creation.annulus(r_min=r_min, r_max=0.03, height=0.03)


GOOD = {"a_box.obj": trimesh.creation.box((0.04, 0.03, 0.02)), "b_cylinder.stl": trimesh.creation.cylinder(0.02, 0.05)}


def test_hull_close_enough_hand_checked() -> None:
    assert HULL_FALLBACK_RATIO == 1.1
    assert hull_close_enough(1.0, 1.0) and hull_close_enough(1.0, 1.1) and not hull_close_enough(1.0, 1.1001)
    # Rings of outer radius 30 mm: a hole of 8 mm leaves 836/900 of the cylinder (hull 1.077 x), 20 mm 500/900 (1.8 x).
    assert hull_close_enough(836.0, 900.0) and not hull_close_enough(500.0, 900.0)
    assert not hull_close_enough(0.0, 1.0) and not hull_close_enough(-1.0, -1.0)


def test_a_failing_mesh_is_skipped_a_near_convex_one_becomes_its_hull(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, injected: str
) -> None:
    folder = _folder(tmp_path / "m", {**GOOD, "c_ring.obj": _ring(0.02), "d_near.obj": _ring(0.008)})
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{injected}:coacd_fails")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        objects = load_mesh_folder(folder, cache_dir=tmp_path / "c", workers=1)
    messages = [str(w.message) for w in caught]
    assert isinstance(objects, MeshFolderObjects)
    assert [o.name for o in objects] == ["a_box", "b_cylinder", "d_near"]
    # The concave ring (hull 1.8 x its volume) is skipped, named with the failure and why no fallback.
    (skipped,) = objects.skipped
    assert skipped == SkippedMesh(str(folder / "c_ring.obj"), skipped.reason)
    assert "convex decomposition failed (RuntimeError: injected coacd failure)" in skipped.reason
    assert "no fallback applies: a concave solid needs convex decomposition (its convex hull is 1.80 x its volume, over the 1.1" in skipped.reason
    # The near-convex ring (hull 900/836 = 1.077 x) is its hull: one part, the ring's own volume for the mass.
    near = objects[2]
    assert near.num_parts == 1 and near.volume == pytest.approx(0.03**2 * 3.14 * 0.03, rel=0.05)
    assert near.mass == pytest.approx(meshes.WOOD_DENSITY * _ring(0.008).volume, rel=1e-6)
    assert near.rgba == meshes.TABLEAU_10[3]  # colours follow the files, skipped ones included
    assert len(messages) == 2
    assert messages[0].startswith(f"skipping a mesh of folder {str(folder)!r}: mesh file {str(folder / 'c_ring.obj')!r}: ")
    assert messages[1] == (
        f"mesh file {str(folder / 'd_near.obj')!r}: convex decomposition failed (RuntimeError: injected coacd failure); "
        "using its convex hull instead (1.077 x its volume, within the 1.1 allowed)"
    )


def test_a_slow_mesh_is_skipped_naming_its_time_limit(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, injected: str) -> None:
    folder = _folder(tmp_path / "m", {**GOOD, "c_ring.obj": _ring(0.02)})
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{injected}:coacd_fails")
    with pytest.warns(RuntimeWarning, match=r"c_ring\.obj': convex decomposition failed"):
        first = load_mesh_folder(folder, cache_dir=tmp_path / "c", workers=1)  # the good ones are cached
    assert [o.name for o in first] == ["a_box", "b_cylinder"]
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{injected}:coacd_hangs")
    with pytest.warns(RuntimeWarning) as caught:
        objects = load_mesh_folder(folder, cache_dir=tmp_path / "c", workers=1, time_limit_s=0.3)
    assert [o.name for o in objects] == ["a_box", "b_cylinder"]
    (message,) = [str(w.message) for w in caught]
    assert message.startswith(
        f"skipping a mesh of folder {str(folder)!r}: mesh file {str(folder / 'c_ring.obj')!r}: convex decomposition "
        "did not finish within the time limit of 0.3 s (time_limit_s), and "
    )
    assert message.endswith("; a larger time_limit_s may let it finish")
    assert objects.skipped == (SkippedMesh(str(folder / "c_ring.obj"), message.split(": ", 1)[1]),)


def test_a_folder_where_every_mesh_fails_is_an_error_naming_it(tmp_path: Path) -> None:
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "a.obj").write_text("v 0 0 0\n")
    (folder / "b.stl").write_bytes(b"not a mesh")
    with pytest.warns(RuntimeWarning) as caught, pytest.raises(
        MeshLoadError,
        match=rf"^mesh folder {re.escape(repr(str(folder)))}: none of its 2 meshes could be loaded \(a\.obj, b\.stl\); "
        rf"the first: mesh file {re.escape(repr(str(folder / 'a.obj')))}: empty or unreadable mesh",
    ):
        load_mesh_folder(folder, cache_dir=tmp_path / "c", fit="gripper")  # the fit reads the vertices first
    assert [str(w.message).split("': ")[1].rsplit("/", 1)[1] for w in caught] == ["a.obj", "b.stl"]
    with pytest.raises(ValueError, match="workers must be a positive integer or None"):
        load_mesh_folder(folder, workers=0)
    with pytest.raises(ValueError, match="density must be a positive number"):
        load_mesh_folder(folder, density=-1.0)


def test_parallel_load_gives_the_serial_result(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, injected: str) -> None:
    folder = _folder(tmp_path / "m", {**GOOD, "c_ring.obj": _ring(0.02), "d_near.obj": _ring(0.008)})
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{injected}:coacd_fails")
    pools: list[WorkerPool] = []

    class RecordedPool(WorkerPool):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            pools.append(self)

    monkeypatch.setattr(mesh_folder, "WorkerPool", RecordedPool)
    monkeypatch.setattr(mesh_folder, "GROW_AFTER_S", 0.0)  # a worker process per mesh at once

    def load(workers: int) -> tuple[MeshFolderObjects, list[str]]:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            objects = load_mesh_folder(folder, cache_dir=tmp_path / f"cache{workers}", workers=workers)
        return objects, [str(w.message) for w in caught]

    serial, serial_messages = load(1)
    parallel, parallel_messages = load(2)
    assert len(pools) == 1 and pools[0].workers == 2  # the serial load used no pool, the parallel one 2 workers
    assert [o.name for o in parallel] == [o.name for o in serial] == ["a_box", "b_cylinder", "d_near"]
    assert parallel.skipped == serial.skipped and len(serial.skipped) == 1
    assert parallel_messages == serial_messages  # in file order, whichever worker finished first
    for a, b in zip(serial, parallel, strict=True):
        assert [v.tobytes() + f.tobytes() for v, f in a.parts] == [v.tobytes() + f.tobytes() for v, f in b.parts]
        assert (a.mass, a.rgba, a.mesh_offset) == (b.mass, b.rgba, b.mesh_offset)


def test_worker_pool_grows_only_when_calls_wait() -> None:
    with WorkerPool(2) as pool:  # grows at once
        assert pool.size == 2 and pool.workers == 0 and pool.starts == 0
        assert pool.call("math:hypot", (3.0, 4.0), time_limit_s=30) == 5.0
        assert pool.workers == 1 and pool.starts == 1  # workers start on first use
    first = IsolatedWorker()
    try:
        with WorkerPool(3, first=first, grow_after_s=5.0) as pool:
            with ThreadPoolExecutor(3) as threads:  # three quick calls: the first worker serves them all
                assert list(threads.map(lambda x: pool.call("math:sqrt", (x,), 30), [1.0, 4.0, 9.0])) == [1.0, 2.0, 3.0]
            assert pool.workers == 1 and first.starts == 1
        with WorkerPool(3, first=first, grow_after_s=0.2) as pool, ThreadPoolExecutor(2) as threads:
            # A call that waits 0.2 s for the busy worker gets a new one.
            assert list(threads.map(lambda x: pool.call("time:sleep", (x,), 30), [0.6, 0.0])) == [None, None]
            assert pool.workers == 2
        assert first.call("math:hypot", (6.0, 8.0), time_limit_s=30) == 10.0  # not stopped by the pool
        assert first.starts == 1
    finally:
        first.close()
    with pytest.raises(ValueError, match="size must be a positive integer"):
        WorkerPool(0)


def test_a_fallback_after_a_time_out_is_cached_for_that_time_limit_only(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = _folder(tmp_path / "m", {"near.obj": _ring(0.008)}) / "near.obj"
    hull = convex_part(_ring(0.008).vertices)
    calls: list[float] = []

    def timed_out_then_hull(path, scale, seed, params, time_limit_s, worker):  # what a time-out gives
        calls.append(time_limit_s)
        return [hull], 7.8e-5, f"convex decomposition did not finish within {time_limit_s:g} s; using its convex hull", True

    monkeypatch.setattr(meshes, "_isolated_solid", timed_out_then_hull)
    for limit in (1.0, 1.0, 2.0, 2.0, 1.0):
        job = meshes.MeshJob.prepare(path, cache_dir=tmp_path / "c", time_limit_s=limit)
        assert job.solid(worker=None).note.startswith(f"convex decomposition did not finish within {limit:g} s")
    assert calls == [1.0, 2.0]  # each limit tries once; the same limit reads the cache
