"""Tests of mesh loading under faults and odd input: the worker process, bodies and unions, the gripper fit, random_urdfs."""

from __future__ import annotations

import importlib.util
import textwrap
from pathlib import Path

import numpy as np
import pytest

from mpg_envs.simulation import meshes, random_urdfs
from mpg_envs.simulation.assets import MIN_PART_VOLUME, WOOD_DENSITY
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange, FitError, fit_scale, scale_bounds
from mpg_envs.simulation.isolated_call import IsolatedWorker, WorkerCallError, WorkerCrashedError, WorkerTimeoutError
from mpg_envs.simulation.objects import MeshLoadError, load_mesh_file, load_mesh_folder, load_random_urdfs, random_urdf_entries

HAS_PYBULLET_DATA = importlib.util.find_spec("pybullet_data") is not None

BOX_FACES = [(1, 3, 4), (1, 4, 2), (5, 6, 8), (5, 8, 7), (1, 2, 6), (1, 6, 5),
             (3, 7, 8), (3, 8, 4), (1, 5, 7), (1, 7, 3), (2, 4, 8), (2, 8, 6)]  # fmt: skip
"""Outward faces (1-based) of the 8 corners ordered as ``(x, y, z) for x for y for z``."""


def _boxes_obj(boxes: list[tuple[tuple[float, float, float], tuple[float, float, float]]], drop_faces: int = 0) -> str:
    """OBJ text of closed boxes ``(low corner, high corner)``, each its own body, in one mesh."""
    lines, faces = [], []
    for k, (lo, hi) in enumerate(boxes):
        lines += [f"v {x} {y} {z}" for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
        faces += [tuple(i + 8 * k for i in f) for f in BOX_FACES]
    faces = faces[drop_faces:]
    return "\n".join(lines + [f"f {a} {b} {c}" for a, b, c in faces]) + "\n"


def _write(folder: Path, name: str, text: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(text)
    return path


def _inside_any_part(parts, points: np.ndarray) -> np.ndarray:
    inside = np.zeros(len(points), dtype=bool)
    for vertices, faces in parts:  # convex and outward-oriented: inside = behind every face
        a, b, c = (vertices[faces[:, k]] for k in range(3))
        normals = np.cross(b - a, c - a)
        inside |= np.all(np.einsum("fk,pfk->pf", normals, points[:, None, :] - a[None]) <= 1e-12, axis=1)
    return inside


# ---------------------------------------------------------------------------- the worker process
def test_worker_turns_crashes_and_hangs_into_exceptions() -> None:
    worker = IsolatedWorker()
    try:
        assert worker.starts == 0  # started on first use only
        assert worker.call("math:hypot", (3.0, 4.0), time_limit_s=30) == 5.0
        with pytest.raises(WorkerCrashedError, match="ctypes:string_at.*SIGSEGV"):
            worker.call("ctypes:string_at", (0,), time_limit_s=30)  # reads address 0: a segfault
        with pytest.raises(WorkerCrashedError, match="SIGABRT"):
            worker.call("os:abort", (), time_limit_s=30)
        with pytest.raises(WorkerTimeoutError, match=r"time:sleep ran past its time limit of 0\.5 s"):
            worker.call("time:sleep", (60,), time_limit_s=0.5)
        with pytest.raises(WorkerCallError, match="math:sqrt raised ValueError") as info:
            worker.call("math:sqrt", (-1.0,), time_limit_s=30)
        assert info.value.exc_type == "ValueError"
        assert worker.call("math:hypot", (6.0, 8.0), time_limit_s=30) == 10.0  # a fresh worker
        assert worker.starts == 4  # the first, then one after each crash and the timeout
        with pytest.raises(ValueError, match="time_limit_s"):
            worker.call("math:hypot", (1.0, 1.0), time_limit_s=0)
    finally:
        worker.close()


@pytest.fixture()
def crashers(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> str:
    """A module the worker can import (it takes the caller's sys.path) whose functions crash or hang."""
    module = tmp_path / "mesh_crashers.py"
    module.write_text(textwrap.dedent("""
        import ctypes, time

        def segfault(*args):
            ctypes.string_at(0)

        def hang(*args):
            time.sleep(60)

        def crash_in_coacd(path, scale, seed, params, use_coacd):
            if use_coacd:  # as coacd does on some meshes; the fallback (no coacd) works
                ctypes.string_at(0)
            from mpg_envs.simulation.decomposition import solid_from_mesh_file

            return solid_from_mesh_file(path, scale, seed, params, use_coacd)
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    return "mesh_crashers"


L_SHAPE = [((0, 0, 0), (60, 20, 20)), ((0, 20, 0), (20, 60, 20))]
"""Two boxes touching on a face (24,000 + 16,000 mm^3): together a concave L."""


def test_native_crash_or_hang_in_decomposition_is_an_error_naming_the_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, crashers: str
) -> None:
    # An overlapping pair needs decomposition of its union: no fallback to its bodies.
    path = _write(tmp_path / "m", "overlap.obj", _boxes_obj([((0, 0, 0), (40, 40, 20)), ((20, 20, 0), (60, 60, 20))]))
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{crashers}:segfault")
    with pytest.raises(MeshLoadError, match=r"overlap\.obj.*crashed.*SIGSEGV"):
        load_mesh_file(path, cache_dir=tmp_path / "c", scale=0.001)
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{crashers}:hang")
    with pytest.raises(MeshLoadError, match=r"overlap\.obj.*time limit of 0\.5 s \(time_limit_s\)"):
        load_mesh_file(path, cache_dir=tmp_path / "c", scale=0.001, time_limit_s=0.5)

    # Separate convex bodies fall back to one part per body, with a warning naming the file.
    two = _write(tmp_path / "m", "two.obj", _boxes_obj([((0, 0, 0), (30, 30, 30)), ((50, 0, 0), (80, 30, 30))]))
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{crashers}:crash_in_coacd")
    with pytest.warns(RuntimeWarning, match=r"two\.obj.*crashed.*hulls of its 2 convex bodies"):
        asset = load_mesh_file(two, cache_dir=tmp_path / "c", scale=0.001)
    assert asset.num_parts == 2 and asset.volume == pytest.approx(2 * 27e-6)
    with pytest.warns(RuntimeWarning, match=r"two\.obj.*crashed"):  # said again when read from the cache
        load_mesh_file(two, cache_dir=tmp_path / "c", scale=0.001)


def test_warm_cache_needs_no_decomposition(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, crashers: str) -> None:
    folder = tmp_path / "m"
    _write(folder, "l.obj", _boxes_obj(L_SHAPE))
    (cold,) = load_mesh_folder(folder, cache_dir=tmp_path / "c", scale=0.001)
    monkeypatch.setattr(meshes, "SOLID_ENTRY", f"{crashers}:segfault")  # would crash if it ran
    (warm,) = load_mesh_folder(folder, cache_dir=tmp_path / "c", scale=0.001)
    assert [v.tobytes() for v, _ in warm.parts] == [v.tobytes() for v, _ in cold.parts]
    assert warm.mass == cold.mass


# ---------------------------------------------------------------------------- odd meshes
def test_overlapping_closed_parts_get_the_union_volume_not_the_hull(tmp_path: Path) -> None:
    """Two 40 x 40 x 20 mm boxes overlapping on a 20 x 20 mm corner, written as one mesh.

    By hand: union = 2 * 32,000 - 8,000 = 56,000 mm^3; their hull (an octagonal prism of
    area 3,600 - 2 * 200 mm^2 corners cut) = 64,000 mm^3, which the summed volume equals.
    """
    path = _write(tmp_path / "m", "pair.obj", _boxes_obj([((0, 0, 0), (40, 40, 20)), ((20, 20, 0), (60, 60, 20))]))
    asset = load_mesh_file(path, cache_dir=tmp_path / "c", scale=0.001)
    assert asset.mass == pytest.approx(WOOD_DENSITY * 56e-6, rel=1e-5)  # not 600 * 64e-6
    assert asset.volume == pytest.approx(56e-6, rel=0.03)  # the parts approximate the union
    np.testing.assert_allclose(asset.extents, (0.06, 0.06, 0.02), atol=2e-4)
    # The hull's corners outside both boxes stay empty.
    offset = np.asarray(asset.mesh_offset)
    corners = np.array([[0.005, 0.055, 0.01], [0.055, 0.005, 0.01], [0.004, 0.050, 0.01]]) - offset
    assert not _inside_any_part(asset.parts, corners).any()
    inside = np.array([[0.01, 0.01, 0.01], [0.05, 0.05, 0.01], [0.03, 0.03, 0.01]]) - offset
    assert _inside_any_part(asset.parts, inside).all()


def test_multi_body_non_manifold_open_mesh_kinds(tmp_path: Path) -> None:
    folder = tmp_path / "m"
    # Separate closed bodies: one exact part each, no coacd.
    two = load_mesh_file(
        _write(folder, "two.obj", _boxes_obj([((0, 0, 0), (30, 30, 30)), ((50, 0, 0), (80, 30, 30))])),
        cache_dir=tmp_path / "c", scale=0.001,
    )  # fmt: skip
    assert two.num_parts == 2 and two.volume == pytest.approx(54e-6) and two.mass == pytest.approx(WOOD_DENSITY * 54e-6)
    # Touching along one edge: four faces share it (non-manifold as a whole), each body closed.
    edge = load_mesh_file(
        _write(folder, "edge.obj", _boxes_obj([((0, 0, 0), (30, 30, 30)), ((30, 30, 0), (60, 60, 30))])),
        cache_dir=tmp_path / "c", scale=0.001,
    )  # fmt: skip
    assert edge.num_parts == 2 and edge.volume == pytest.approx(54e-6)
    # Touching along a face: the two boxes of a concave L stay its two exact parts.
    l_shape = load_mesh_file(_write(folder, "l.obj", _boxes_obj(L_SHAPE)), cache_dir=tmp_path / "c", scale=0.001)
    assert l_shape.num_parts == 2 and l_shape.volume == pytest.approx(40e-6)
    assert l_shape.mass == pytest.approx(WOOD_DENSITY * 40e-6, rel=1e-5)
    # An open box (one face missing): coacd's manifold preprocess closes it.
    open_box = load_mesh_file(
        _write(folder, "open.obj", _boxes_obj([((0, 0, 0), (40, 30, 20))], drop_faces=1)), cache_dir=tmp_path / "c", scale=0.001
    )
    np.testing.assert_allclose(open_box.extents, (0.04, 0.03, 0.02), atol=2e-3)


def test_flat_tiny_and_empty_meshes_are_errors_naming_the_file(tmp_path: Path) -> None:
    folder = tmp_path / "m"
    flat = _write(folder, "flat.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    with pytest.raises(MeshLoadError, match=r"flat\.obj.*zero volume.*a solid"):
        load_mesh_file(flat, cache_dir=tmp_path / "c")
    # Zero thickness but closed: a box squashed flat.
    sheet = _write(folder, "sheet.obj", _boxes_obj([((0, 0, 0), (40, 30, 0))]))
    with pytest.raises(MeshLoadError, match=r"sheet\.obj.*zero volume"):
        load_mesh_file(sheet, cache_dir=tmp_path / "c", scale=0.001)
    tiny = _write(folder, "tiny.obj", _boxes_obj([((0, 0, 0), (0.5, 0.5, 0.5))]))  # 0.5 mm cube
    with pytest.raises(MeshLoadError, match=rf"tiny\.obj.*zero volume.*at least {MIN_PART_VOLUME:g} m\^3"):
        load_mesh_file(tiny, cache_dir=tmp_path / "c", scale=0.001)
    nan = _write(folder, "nan.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 2 3\nf 1 2 4\nf 2 3 4\nf 1 3 4\n")
    with pytest.raises(MeshLoadError, match=r"nan\.obj"):
        load_mesh_file(nan, cache_dir=tmp_path / "c")
    with pytest.raises(MeshLoadError, match=r"missing\.obj.*cannot read"):
        load_mesh_file(folder / "missing.obj", cache_dir=tmp_path / "c")
    with pytest.raises(ValueError, match="fit must be 'none', 'gripper' or an ExtentRange"):
        load_mesh_file(sheet, fit="blocks")  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- the gripper fit
def test_fit_scale_hand_checked() -> None:
    assert fit_scale([0.05, 0.04, 0.03]) == 1.0  # already in range: unchanged
    # Sorted 5, 10, 20 cm: at least 0.025/0.05 = 0.5, at most min(0.10/0.20, 0.06/0.10) = 0.5.
    assert scale_bounds([0.2, 0.1, 0.05], BLOCKS_EXTENTS) == pytest.approx((0.5, 0.5))
    assert fit_scale([0.2, 0.1, 0.05]) == pytest.approx(0.5)
    assert fit_scale([0.01, 0.01, 0.01]) == pytest.approx(2.5)  # grows to 2.5 cm
    assert fit_scale([5.0, 3.0, 2.0]) == pytest.approx(0.02)  # 5 x 3 x 2 m -> 10 x 6 x 4 cm
    with pytest.raises(FitError, match=r"too slender or too flat"):
        fit_scale([0.01, 0.01, 0.2])  # needs >= 2.5, allows <= 0.5
    with pytest.raises(FitError, match=r"the two smallest at most 6 cm"):
        fit_scale([0.01, 0.10, 0.10])  # flat: needs >= 2.5, allows <= 0.6
    assert fit_scale([0.01, 0.10, 0.10], ExtentRange(0.005, 0.12, 0.12)) == 1.0
    assert BLOCKS_EXTENTS.contains([0.10, 0.06, 0.025]) and not BLOCKS_EXTENTS.contains([0.07, 0.07, 0.03])
    with pytest.raises(ValueError, match="min_extent <= max_two_smallest <= max_extent"):
        ExtentRange(0.05, 0.04, 0.06)
    with pytest.raises(ValueError, match="three positive finite"):
        fit_scale([0.0, 0.05, 0.05])


def test_fit_to_gripper_tiny_huge_and_unfittable(tmp_path: Path) -> None:
    folder = tmp_path / "m"
    tiny = _write(folder, "tiny.obj", _boxes_obj([((0, 0, 0), (2, 2, 2))]))  # 2 mm cube, in mm
    small = load_mesh_file(tiny, cache_dir=tmp_path / "c", scale=0.001, fit="gripper")
    np.testing.assert_allclose(small.extents, 0.025, rtol=1e-9)
    assert small.scale == pytest.approx(0.001 * 12.5)
    # Under the smallest-part volume at its own size (0.8 mm cube: 5e-10 m^3), but fitted first.
    speck = _write(folder, "speck.obj", _boxes_obj([((0, 0, 0), (0.8, 0.8, 0.8))]))
    with pytest.raises(MeshLoadError, match=r"speck\.obj.*zero volume"):
        load_mesh_file(speck, cache_dir=tmp_path / "c", scale=0.001)
    grown = load_mesh_file(speck, cache_dir=tmp_path / "c", scale=0.001, fit="gripper")
    np.testing.assert_allclose(grown.extents, 0.025, rtol=1e-9)
    huge = _write(folder, "huge.obj", _boxes_obj([((0, 0, 0), (5, 3, 2))]))  # 5 x 3 x 2 m
    big = load_mesh_file(huge, cache_dir=tmp_path / "c", fit="gripper")
    np.testing.assert_allclose(big.extents, (0.10, 0.06, 0.04), rtol=1e-9)
    assert big.scale == pytest.approx(0.02) and BLOCKS_EXTENTS.contains(big.extents)
    assert big.mass == pytest.approx(WOOD_DENSITY * 0.10 * 0.06 * 0.04)  # from the fitted volume
    unfit = load_mesh_file(huge, cache_dir=tmp_path / "c")  # no fit: loads, mass clamped
    assert unfit.scale == 1.0 and unfit.mass == 0.3
    # Loading again at the recorded scale gives the same object (what a scene file needs).
    again = load_mesh_file(huge, cache_dir=tmp_path / "c", scale=big.scale)
    np.testing.assert_allclose(again.extents, big.extents, rtol=1e-12)
    stick = _write(folder, "stick.obj", _boxes_obj([((0, 0, 0), (1, 1, 30))]))
    with pytest.raises(MeshLoadError, match=r"stick\.obj' \(scale 0\.001\).*cannot be scaled into the range"):
        load_mesh_file(stick, cache_dir=tmp_path / "c", scale=0.001, fit="gripper")


# ---------------------------------------------------------------------------- pybullet's random_urdfs
def _fake_random_urdfs(root: Path) -> Path:
    """A random_urdfs-like folder: 000 (test) and 001 (train), boxes in the set's units."""
    for number, size in ((0, (4, 3, 2)), (1, (8, 4, 3))):
        sub = root / f"{number:03d}"
        _write(sub, f"{number:03d}.obj", _boxes_obj([((0, 0, 0), size)]))
        (sub / f"{number:03d}.urdf").write_text(
            f'<robot name="blob{number:03d}"><link name="l"><collision><origin rpy="0 0 0" xyz="0 0 0"/>'
            f'<geometry><mesh filename="{number:03d}.obj" scale="0.015 0.015 0.015"/></geometry></collision></link></robot>'
        )
    return root


def test_random_urdfs_from_a_named_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    root = _fake_random_urdfs(tmp_path / "random_urdfs")
    assert [e.number for e in random_urdf_entries(root, "test")] == [0]
    assert [e.number for e in random_urdf_entries(root, "train")] == [1]
    (entry,) = random_urdf_entries(root, "test")
    assert entry.scale == 0.015 and entry.mesh == root / "000" / "000.obj" and entry.is_test
    (obj,) = load_random_urdfs(root, "test", cache_dir=tmp_path / "c", fit="none")
    assert obj.name == "random_urdf_000" and obj.licence == random_urdfs.RANDOM_URDFS_LICENCE == "zlib"
    assert obj.source == str(root / "000" / "000.obj") and obj.scale == 0.015
    np.testing.assert_allclose(obj.extents, (0.06, 0.045, 0.03), rtol=1e-9)
    (fitted,) = load_random_urdfs(root, "train", cache_dir=tmp_path / "c")  # 12 x 6 x 4.5 cm: 10 cm at most
    np.testing.assert_allclose(fitted.extents, (0.10, 0.05, 0.0375), rtol=1e-9)
    assert fitted.scale == pytest.approx(0.015 * 0.10 / 0.12)
    with pytest.raises(ValueError, match="split must be one of"):
        random_urdf_entries(root, "val")  # type: ignore[arg-type]
    # Without pybullet and without a folder: say how to get it.
    monkeypatch.setattr(random_urdfs.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(ModuleNotFoundError, match=r"pip install 'mpg-grasp\[novel\]'.*or pass folder="):
        random_urdf_entries()


@pytest.mark.skipif(not HAS_PYBULLET_DATA, reason="pybullet (the 'novel' extra) is not installed")
def test_installed_random_urdfs_split_and_a_multi_body_mesh(tmp_path: Path) -> None:
    entries = random_urdf_entries(split="all")
    assert len(entries) == random_urdfs.RANDOM_URDFS_COUNT
    test = random_urdf_entries(split="test")
    assert len(test) == 100 and all(e.number % 10 == 0 for e in test)
    assert len(random_urdf_entries(split="train")) == 900
    # 008.obj: 8 closed convex bodies; coacd with preprocess off segfaults on it as one mesh.
    # Loaded as its bodies, it needs no coacd at all.
    e008 = entries[8]
    asset = load_mesh_file(e008.mesh, cache_dir=tmp_path, scale=e008.scale, fit="gripper", name=e008.name)
    assert asset.num_parts == 8 and BLOCKS_EXTENTS.contains(asset.extents)


@pytest.mark.slow
@pytest.mark.skipif(not HAS_PYBULLET_DATA, reason="pybullet (the 'novel' extra) is not installed")
def test_raw_coacd_crash_on_a_multi_body_mesh_stays_in_the_worker() -> None:
    """The crash the loader avoids, reproduced in the worker: coacd on all of 008.obj at once."""
    import trimesh

    entry = random_urdf_entries(split="all")[8]
    mesh = trimesh.load(str(entry.mesh), force="mesh")
    mesh.apply_scale(entry.scale)
    worker = IsolatedWorker()
    try:
        with pytest.raises(WorkerCrashedError, match="SIGSEGV"):
            worker.call(
                "mpg_envs.simulation.decomposition:decompose",
                (mesh, 0, meshes.CoacdParams(), False),
                time_limit_s=300,
            )
    finally:
        worker.close()
