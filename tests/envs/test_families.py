"""Tests of the procedural object families: the pure solids (hand-checked volumes), the
families' sizes, solidity and determinism, the cache, and how sets are named and read back."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from mpg_envs.scenes.scene_io import SceneFile, SceneObject, read_scene, save_scene
from mpg_envs.simulation.assets import MASS_RANGE, TABLEAU_10, WOOD_DENSITY, mesh_centroid, mesh_volume
from mpg_envs.simulation.families import (
    FAMILY_SEED_RANGES,
    FAMILY_SET_SIZE,
    PROCEDURAL_SETS,
    family_asset,
    family_object_set,
    seed_split,
)
from mpg_envs.simulation.family_shapes import FAMILY_NAMES, build_shape, draw_shape
from mpg_envs.simulation.objects import load_object_set
from mpg_envs.simulation.solids import (
    extrude_pieces,
    axis_fit_factors,
    ring_pieces,
    star_polygon_pieces,
    superquadric_part,
    superquadric_volume,
    sweep_pieces,
    union_mesh,
)

AXES = (0.03, 0.02, 0.015)


def _volume(parts) -> float:
    return sum(mesh_volume(v, f) for v, f in parts)


def _solid_bodies(parts) -> int:
    """Bodies of the parts' union with a volume (the boolean leaves zero-volume slivers where
    faces coincide exactly)."""
    return sum(1 for body in union_mesh(parts).split(only_watertight=False) if abs(body.volume) > 1e-9)


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("family_cache")


# ------------------------------------------------------------------ pure solids
def test_superquadric_with_exponents_two_is_the_ellipsoid() -> None:
    exact = 4.0 / 3.0 * math.pi * AXES[0] * AXES[1] * AXES[2]
    assert superquadric_volume(AXES, (2, 2)) == pytest.approx(exact, rel=1e-12)
    (part,) = superquadric_part(AXES, (2, 2))
    assert mesh_volume(*part) == pytest.approx(exact, rel=0.01)  # the hull of a 25 x 48 grid
    assert mesh_volume(*part) < exact  # inscribed
    np.testing.assert_allclose(np.ptp(part[0], axis=0), 2 * np.array(AXES), rtol=1e-9)


def test_superquadric_limits_are_the_octahedron_and_the_box() -> None:
    a, b, c = AXES
    assert superquadric_volume(AXES, (1, 1)) == pytest.approx(4.0 / 3.0 * a * b * c, rel=1e-12)
    (part,) = superquadric_part(AXES, (1, 1))
    assert mesh_volume(*part) == pytest.approx(4.0 / 3.0 * a * b * c, rel=1e-9)  # its 6 corners are sampled
    assert superquadric_volume(AXES, (400, 400)) == pytest.approx(8 * a * b * c, rel=0.01)
    with pytest.raises(ValueError, match="exponents >= 1"):
        superquadric_part(AXES, (0.5, 2))


def test_extruded_square_and_star() -> None:
    square = np.array([(1, 1), (-1, 1), (-1, -1), (1, -1)]) * 0.02
    parts = extrude_pieces(star_polygon_pieces(square), 0.03)
    assert _volume(parts) == pytest.approx(0.04 * 0.04 * 0.03, rel=1e-12)
    # A concave four-pointed star: area by the shoelace formula.
    angles = np.arange(8) * math.pi / 4
    radii = np.where(np.arange(8) % 2 == 0, 0.03, 0.01)
    star = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    x, y = star[:, 0], star[:, 1]
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    pieces = star_polygon_pieces(star)
    assert len(pieces) >= 4  # concave: at least one piece per point
    parts = extrude_pieces(pieces, 0.025)
    assert _volume(parts) == pytest.approx(area * 0.025, rel=1e-12)
    mesh = union_mesh(parts)
    assert mesh.is_watertight and mesh.volume == pytest.approx(area * 0.025, rel=1e-6)
    with pytest.raises(ValueError, match="star-shaped"):
        star_polygon_pieces(star[::-1])  # clockwise


def test_mitred_l_bar_and_ring() -> None:
    section = np.array([(-0.01, 0.0), (0.01, 0.0), (0.01, 0.02), (-0.01, 0.02)])
    parts = sweep_pieces(np.array([(0, 0), (0.05, 0), (0.05, 0.04)]), section)
    # A mitred bar's area is its width times its centre line: 2 cm x 9 cm, 2 cm high.
    assert _volume(parts) == pytest.approx(0.02 * 0.09 * 0.02, rel=1e-12)
    assert union_mesh(parts).is_watertight and _solid_bodies(parts) == 1
    with pytest.raises(ValueError, match="too short"):
        sweep_pieces(np.array([(0, 0), (0.05, 0), (0.05, 0.008)]), section)  # needs 1 cm
    with pytest.raises(ValueError, match="150 degrees"):
        sweep_pieces(np.array([(0, 0), (0.05, 0), (0.0, 0.01)]), section)
    n, inner, outer, height = 12, 0.01, 0.02, 0.03
    ring = ring_pieces(inner, outer, 0.0, height, n)
    polygon_area = n / 2 * math.sin(2 * math.pi / n)  # of unit circumradius
    assert _volume(ring) == pytest.approx(polygon_area * (outer**2 - inner**2) * height, rel=1e-12)
    assert union_mesh(ring).is_watertight and _solid_bodies(ring) == 1


def test_axis_fit_factors_hand_cases() -> None:
    np.testing.assert_allclose(axis_fit_factors([0.02, 0.05, 0.12]), [0.025 / 0.02, 1.0, 0.10 / 0.12])
    np.testing.assert_allclose(axis_fit_factors([0.07, 0.08, 0.09]), [0.06 / 0.07, 0.06 / 0.08, 1.0])
    assert np.all(axis_fit_factors([0.03, 0.05, 0.09]) == 1.0)  # in range: exactly as drawn
    with pytest.raises(ValueError, match="3 positive"):
        axis_fit_factors([0.0, 0.05, 0.09])


# ------------------------------------------------------------------ families
@pytest.mark.parametrize("family", FAMILY_NAMES)
def test_family_shapes_fit_the_gripper_and_are_solid(family: str) -> None:
    for index in range(6):
        params = draw_shape(family, 0, index)
        parts = build_shape(family, params)
        ext = np.sort(np.ptp(np.concatenate([v for v, _ in parts]), axis=0))
        assert ext[0] >= 0.025 - 1e-9 and ext[2] <= 0.10 + 1e-9 and ext[1] <= 0.06 + 1e-9, (family, index, ext)
        mesh = union_mesh(parts)
        # Disjoint parts meeting face to face: one closed solid with the parts' summed volume.
        assert mesh.is_watertight, (family, index)
        assert mesh.volume == pytest.approx(_volume(parts), rel=1e-6), (family, index)
        assert _solid_bodies(parts) == 1, (family, index)


def test_family_set_assets(cache_dir: Path) -> None:
    assets = family_object_set("hollow", 3, cache_dir, size=4)
    assert [a.name for a in assets] == ["hollow-00", "hollow-01", "hollow-02", "hollow-03"]
    for i, asset in enumerate(assets):
        assert asset.source == "hollow" and asset.rgba == TABLEAU_10[i]
        assert asset.mass == pytest.approx(float(np.clip(WOOD_DENSITY * asset.volume, *MASS_RANGE)))
        # The object frame's origin is the centre of mass of the parts.
        centroids = np.array([mesh_centroid(v, f) for v, f in asset.parts])
        np.testing.assert_allclose(asset.part_volumes @ centroids / asset.volume, 0.0, atol=1e-12)
    mix = family_object_set("procedural", 3, cache_dir, size=7)
    assert [a.name for a in mix] == ["superquadric-00", "compound-00", "extrusion-00", "bent-00", "hollow-00", "superquadric-01", "compound-01"]
    assert [a.source for a in mix][:5] == list(FAMILY_NAMES)
    # The mix's hollow-00 is the hollow set's (same seed): the same parts, bit for bit.
    for (v1, f1), (v2, f2) in zip(mix[4].parts, assets[0].parts):
        assert np.array_equal(v1, v2) and np.array_equal(f1, f2)


def test_same_seed_same_shapes_bit_for_bit(tmp_path: Path) -> None:
    first = family_object_set("procedural", 11, tmp_path / "a", size=5)
    second = family_object_set("procedural", 11, tmp_path / "b", size=5)  # a separate cold cache
    other = family_object_set("procedural", 12, tmp_path / "a", size=5)
    for a, b, c in zip(first, second, other):
        assert a.mass == b.mass and a.mesh_offset == b.mesh_offset
        assert all(np.array_equal(p[0], q[0]) and np.array_equal(p[1], q[1]) for p, q in zip(a.parts, b.parts))
        assert not np.array_equal(a.vertices, c.vertices)


def test_second_load_reads_the_cache(cache_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    first = family_object_set("compounds", 5, cache_dir, size=3)
    monkeypatch.setattr("mpg_envs.simulation.families.build_shape", lambda *a: pytest.fail("built although cached"))
    again = family_object_set("compounds", 5, cache_dir, size=3)
    assert [a.name for a in again] == ["compound-00", "compound-01", "compound-02"]
    assert all(np.array_equal(a.vertices, b.vertices) for a, b in zip(first, again))


def test_names_seeds_and_errors(cache_dir: Path) -> None:
    assert PROCEDURAL_SETS == ("superquadrics", "compounds", "extrusions", "bent", "hollow", "procedural")
    assert len(load_object_set("bent", seed=1, cache_dir=cache_dir)) == FAMILY_SET_SIZE
    with pytest.raises(ValueError, match="superquadrics"):
        load_object_set("superquadric")  # not a set name: the message lists them
    with pytest.raises(ValueError, match="size"):
        family_object_set("bent", 0, cache_dir, size=0)
    with pytest.raises(ValueError, match="expected bent-<index>"):
        family_asset("bent", "cube", 0, cache_dir)
    assert [seed_split(s) for s in (0, 499_999, 500_000, 699_999, 700_000, 999_999)] == ["train", "train", "test", "test", "tuning", "tuning"]
    with pytest.raises(ValueError, match="no split"):
        seed_split(1_000_000)
    assert FAMILY_SEED_RANGES["test"].start == 500_000 and FAMILY_SEED_RANGES["tuning"].start == 700_000


def test_scene_file_with_procedural_objects_reads_back(tmp_path: Path) -> None:
    assets = family_object_set("procedural", 700_000, size=6)
    objects = tuple(
        SceneObject(asset, np.array([0.3 + 0.06 * k, 0.0, 0.05]), np.array([1.0, 0.0, 0.0, 0.0])) for k, asset in enumerate(assets)
    )
    path = save_scene(SceneFile(objects, 0, "", "Stage5", 700_000), tmp_path / "scene.json")
    read = read_scene(path)
    assert read.object_set_seed == 700_000
    for written, loaded in zip(assets, (o.asset for o in read.objects)):
        assert loaded.name == written.name and loaded.rgba == written.rgba and loaded.mass == written.mass
        assert np.array_equal(loaded.vertices, written.vertices)


def test_env_takes_a_family_by_name(make_env) -> None:
    env = make_env("MPG-Stage1-v0", object_set="bent")
    assert [a.name for a in env.object_set] == [f"bent-{i:02d}" for i in range(FAMILY_SET_SIZE)]
    _, info = env.reset(seed=0)
    assert info["objects_left"] == 5
    assert all(asset.source == "bent" for asset in env.world.assets)
