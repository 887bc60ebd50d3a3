"""Heightmap geometry without OpenGL: ray casting and footprint masks (RGB-D: test_rgbd.py).

Every expected pixel index below is worked out by hand from the ENV.md convention
``row = floor((y + 0.224) / 0.002)``, ``col = floor((x - 0.276) / 0.002)``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from mpg_envs.perception.footprint import fill_convex_hull, footprint_mask, geom_world_vertices, world_to_pixel_coords
from mpg_envs.perception.heightmap import RaycastHeightmapper, geom_colors, geomgroup_mask, heights_from_world_z
from mpg_envs.grid.workspace import Workspace, pixel_to_world, world_to_pixel

from .hand_scenes import compile_forward, yaw_quat

WS = Workspace()
BOX = mujoco.mjtGeom.mjGEOM_BOX
TABLE_RGBA = [0.6, 0.5, 0.4, 1.0]
TABLE_RGB = np.array([153, 128, 102], dtype=np.uint8)  # round(rgba * 255)


# ----------------------------------------------------------------------------------------
# Scene helpers
# ----------------------------------------------------------------------------------------


def table_spec(half_xy: tuple[float, float] = (0.4, 0.4)) -> mujoco.MjSpec:
    """A table box (group 0) whose top face is z = 0, centred under the workspace."""
    spec = mujoco.MjSpec()
    spec.worldbody.add_geom(
        name="table",
        type=BOX,
        size=[half_xy[0], half_xy[1], 0.05],
        pos=[0.5, 0.0, -0.05],
        rgba=TABLE_RGBA,
        group=0,
    )
    return spec


def add_geom(spec: mujoco.MjSpec, name: str, pos, size, rgba, group: int = 1, gtype=BOX, quat=None):
    kwargs = dict(name=name, type=gtype, size=list(size), pos=list(pos), rgba=list(rgba), group=group)
    if quat is not None:
        kwargs["quat"] = list(quat)
    return spec.worldbody.add_geom(**kwargs)


def gid(model: mujoco.MjModel, name: str) -> int:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, name)


def prism_vertices(radius: float, height: float) -> np.ndarray:
    """A triangular prism (convex), base on z = 0."""
    angles = np.array([90.0, 210.0, 330.0]) * math.pi / 180
    ring = np.stack([radius * np.cos(angles), radius * np.sin(angles)], axis=1)
    return np.concatenate([np.c_[ring, np.zeros(3)], np.c_[ring, np.full(3, height)]])


@pytest.fixture(scope="module")
def box_scene():
    """A 5 cm box at x in [0.58, 0.62], y in [-0.08, -0.02] (edges on pixel borders), with
    robot-like geoms of groups 2 and 3 hovering right above it."""
    spec = table_spec()
    add_geom(spec, "box", [0.60, -0.05, 0.025], [0.02, 0.03, 0.025], [1.0, 0.0, 0.2, 1.0])
    add_geom(
        spec,
        "arm",
        [0.60, -0.05, 0.20],
        [0.05, 0.10],
        [0.2, 0.2, 0.2, 1.0],
        group=2,
        gtype=mujoco.mjtGeom.mjGEOM_CAPSULE,
        quat=[0.7071068, 0.7071068, 0.0, 0.0],
    )
    add_geom(spec, "hand", [0.60, -0.05, 0.12], [0.08, 0.08, 0.03], [0.1, 0.9, 0.1, 1.0], group=3)
    model, data = compile_forward(spec)
    return model, data


# ----------------------------------------------------------------------------------------
# Small pure helpers
# ----------------------------------------------------------------------------------------


def test_geomgroup_mask_shows_only_given_groups():
    np.testing.assert_array_equal(geomgroup_mask((0, 1)), [1, 1, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="geom group"):
        geomgroup_mask((6,))


def test_heights_from_world_z_clips_to_observation_range():
    got = heights_from_world_z(np.array([-0.1, 0.0, 0.2, 0.5]), WS)
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, [0.0, 0.0, 0.2, 0.4], atol=1e-7)


def test_world_to_pixel_coords_matches_pixel_convention():
    rng = np.random.default_rng(3)
    xy = np.c_[rng.uniform(WS.x_min, WS.x_max, 200), rng.uniform(WS.y_min, WS.y_max, 200)]
    coords = world_to_pixel_coords(WS, xy)
    for (x, y), (c, r) in zip(xy, coords, strict=True):
        assert world_to_pixel(WS, x, y) == (math.floor(r + 0.5), math.floor(c + 0.5))
    # A pixel centre maps to integer coordinates.
    np.testing.assert_allclose(
        world_to_pixel_coords(WS, np.array(pixel_to_world(WS, 7, 9))), [9.0, 7.0], atol=1e-9
    )


def test_fill_convex_hull_uses_pixel_centres():
    mask = np.zeros((6, 6), dtype=np.uint8)
    # Right triangle (col, row) = (0,0), (4,0), (0,4), given with an interior point and
    # shuffled: the hull is taken. Centres with c + r <= 4 are inside (edge included).
    fill_convex_hull(mask, np.array([[4.0, 0.0], [1.0, 1.0], [0.0, 4.0], [0.0, 0.0]]))
    expected = np.array([[1 if c + r <= 4 else 0 for c in range(6)] for r in range(6)], dtype=np.uint8)
    np.testing.assert_array_equal(mask, expected)

    # A square whose sides lie half a pixel off the centres covers exactly its pixels.
    mask[:] = 0
    fill_convex_hull(mask, np.array([[0.6, 1.6], [3.4, 1.6], [3.4, 3.4], [0.6, 3.4]]))
    assert mask.sum() == 6 and mask[2:4, 1:4].all()

    # Collinear points: no area, their own pixels are marked; off-grid parts are dropped.
    mask[:] = 0
    fill_convex_hull(mask, np.array([[0.0, 0.0], [2.0, 2.0], [9.0, 9.0]]))
    assert mask.sum() == 2 and mask[0, 0] == 1 and mask[2, 2] == 1


def test_geom_colors_follow_material_rule():
    spec = table_spec()
    spec.add_material(name="mat", rgba=[0.0, 1.0, 0.0, 1.0])
    g_default = add_geom(spec, "mat_default", [0.4, 0.0, 0.01], [0.01, 0.01, 0.01], [0.5, 0.5, 0.5, 1.0])
    g_default.material = "mat"
    g_own = add_geom(spec, "mat_own", [0.45, 0.0, 0.01], [0.01, 0.01, 0.01], [0.0, 0.0, 1.0, 1.0])
    g_own.material = "mat"
    model, _ = compile_forward(spec)
    colors = geom_colors(model)
    np.testing.assert_array_equal(colors[gid(model, "table")], TABLE_RGB)
    np.testing.assert_array_equal(colors[gid(model, "mat_default")], [0, 255, 0])  # material wins
    np.testing.assert_array_equal(colors[gid(model, "mat_own")], [0, 0, 255])  # own rgba wins


# ----------------------------------------------------------------------------------------
# Ray-cast heightmaps
# ----------------------------------------------------------------------------------------


def test_box_height_pixels_colour_and_invisible_robot(box_scene):
    model, data = box_scene
    with RaycastHeightmapper(model) as mapper:
        maps = mapper(data)
    assert maps.depth.shape == (224, 224) and maps.depth.dtype == np.float32
    assert maps.color.shape == (224, 224, 3) and maps.color.dtype == np.uint8
    assert maps.geom_id is not None and maps.geom_id.dtype == np.int32

    # x in [0.58, 0.62] -> cols (0.58 - 0.276) / 0.002 = 152 .. 171;
    # y in [-0.08, -0.02] -> rows (-0.08 + 0.224) / 0.002 = 72 .. 101.
    assert world_to_pixel(WS, 0.5801, -0.0799) == (72, 152)
    assert world_to_pixel(WS, 0.6199, -0.0201) == (101, 171)
    inside = np.zeros((224, 224), dtype=bool)
    inside[72:102, 152:172] = True

    assert np.all(np.abs(maps.depth[inside] - 0.05) < 1e-3)
    np.testing.assert_allclose(maps.depth[inside], 0.05, atol=1e-6)  # in fact exact
    assert np.all(maps.depth[~inside] == 0.0)
    np.testing.assert_array_equal(maps.color[inside], np.broadcast_to([255, 0, 51], (inside.sum(), 3)))
    np.testing.assert_array_equal(maps.color[~inside], np.broadcast_to(TABLE_RGB, ((~inside).sum(), 3)))
    assert np.all(maps.geom_id[inside] == gid(model, "box"))
    assert np.all(maps.geom_id[~inside] == gid(model, "table"))
    # The group 2/3 geoms above the box were never hit.
    assert not np.isin(maps.geom_id, [gid(model, "arm"), gid(model, "hand")]).any()


def test_raycast_is_deterministic_and_thread_count_independent(box_scene):
    model, data = box_scene
    qpos_before = data.qpos.copy()
    xpos_before = data.geom_xpos.copy()
    with RaycastHeightmapper(model, num_threads=1) as one, RaycastHeightmapper(model, num_threads=3) as three:
        a, b, c = one.heightmaps(data), one(data), three(data)
    for x, y in ((a, b), (a, c)):
        np.testing.assert_array_equal(x.depth, y.depth)
        np.testing.assert_array_equal(x.color, y.color)
        np.testing.assert_array_equal(x.geom_id, y.geom_id)
    # The caller's data is left alone.
    np.testing.assert_array_equal(data.qpos, qpos_before)
    np.testing.assert_array_equal(data.geom_xpos, xpos_before)


def test_missed_rays_holes_and_tall_objects():
    # A narrow table (x in [0.45, 0.55]); left of it a smaller "floor" 10 cm lower, right of
    # it nothing at all; a 50 cm pillar is taller than the workspace.
    spec = table_spec(half_xy=(0.05, 0.2))
    add_geom(spec, "floor", [0.35, 0.0, -0.12], [0.08, 0.1, 0.02], [0.0, 0.0, 1.0, 1.0], group=0)
    add_geom(spec, "pillar", [0.501, 0.001, 0.25], [0.004, 0.004, 0.25], [1.0, 1.0, 0.0, 1.0])
    model, data = compile_forward(spec)
    with (
        RaycastHeightmapper(model) as mapper,
        RaycastHeightmapper(model, background_color=(1, 2, 3)) as custom,
    ):
        maps, maps_custom = mapper(data), custom(data)
    floor, table, pillar = gid(model, "floor"), gid(model, "table"), gid(model, "pillar")

    row, col = world_to_pixel(WS, 0.30, 0.05)  # over the floor only
    assert maps.geom_id[row, col] == floor and maps.depth[row, col] == 0.0  # -0.1 m clipped to 0
    np.testing.assert_array_equal(maps.color[row, col], [0, 0, 255])

    row, col = world_to_pixel(WS, 0.70, 0.10)  # over nothing
    assert maps.geom_id[row, col] == -1 and maps.depth[row, col] == 0.0
    # By default the colour of the largest group-0 geom, the table.
    np.testing.assert_array_equal(maps.color[row, col], TABLE_RGB)
    np.testing.assert_array_equal(maps_custom.color[row, col], [1, 2, 3])

    row, col = world_to_pixel(WS, 0.501, 0.001)
    assert maps.geom_id[row, col] == pillar
    assert maps.depth[row, col] == np.float32(WS.z_max)  # 0.5 m clipped to the 0.4 m range
    assert maps.depth.max() == np.float32(WS.z_max)
    assert (maps.geom_id == table).sum() > 0


def test_raycaster_rejects_bad_arguments(box_scene):
    model, data = box_scene
    with pytest.raises(ValueError, match="source_height"):
        RaycastHeightmapper(model, source_height=1.0)
    with pytest.raises(ValueError, match="num_threads"):
        RaycastHeightmapper(model, num_threads=0)
    with pytest.raises(ValueError, match="background_color"):
        RaycastHeightmapper(model, background_color=(0, 0, 300))
    other = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='1'/></worldbody></mujoco>")
    with RaycastHeightmapper(model, num_threads=1) as mapper, pytest.raises(ValueError, match="geoms"):
        mapper(mujoco.MjData(other))


# ----------------------------------------------------------------------------------------
# Footprints and geom vertices
# ----------------------------------------------------------------------------------------


def test_footprint_of_box_under_another_box_is_complete():
    spec = table_spec()
    # Lower box A: x in [0.37, 0.43] -> cols 47..76; y in [0.08, 0.12] -> rows 152..171.
    add_geom(spec, "lower", [0.40, 0.10, 0.02], [0.03, 0.02, 0.02], [1.0, 0.0, 0.0, 1.0])
    # Upper box B on top of A, covering its right/top part: x in [0.39, 0.45], y in [0.09, 0.13].
    add_geom(spec, "upper", [0.42, 0.11, 0.05], [0.03, 0.02, 0.01], [0.0, 1.0, 0.0, 1.0])
    model, data = compile_forward(spec)
    lower, upper = gid(model, "lower"), gid(model, "upper")

    mask = footprint_mask(WS, model, data, [lower])
    assert mask.dtype == np.uint8 and mask.shape == (224, 224)
    expected = np.zeros((224, 224), dtype=np.uint8)
    expected[152:172, 47:77] = 1
    np.testing.assert_array_equal(mask, expected)

    with RaycastHeightmapper(model) as mapper:
        maps = mapper(data)
    seen_lower = maps.geom_id == lower
    # Part of A is hidden under B in the heightmap, yet the mask still has all of A.
    assert seen_lower.sum() < mask.sum() and np.all(mask[seen_lower] == 1)
    hidden = (mask == 1) & ~seen_lower
    assert np.all(maps.geom_id[hidden] == upper)
    np.testing.assert_allclose(maps.depth[hidden], 0.06, atol=1e-6)
    # Both geoms together: the union of the two rectangles (B: rows 157..176, cols 57..86).
    both = footprint_mask(WS, model, data, np.array([lower, upper]))
    expected[157:177, 57:87] = 1
    np.testing.assert_array_equal(both, expected)


def test_footprint_of_rotated_box_is_exact():
    spec = table_spec()
    centre, half, yaw = np.array([0.5013, 0.0071]), np.array([0.03, 0.01]), 30.0
    add_geom(spec, "rotated", [*centre, 0.02], [*half, 0.02], [1, 0, 0, 1], quat=yaw_quat(yaw))
    model, data = compile_forward(spec)
    mask = footprint_mask(WS, model, data, [gid(model, "rotated")])
    gx, gy = WS.pixel_centers()
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    local_x = c * (gx - centre[0]) + s * (gy - centre[1])
    local_y = -s * (gx - centre[0]) + c * (gy - centre[1])
    expected = (np.abs(local_x) <= half[0]) & (np.abs(local_y) <= half[1])
    np.testing.assert_array_equal(mask.astype(bool), expected)
    assert abs(mask.sum() - 4 * half[0] * half[1] / WS.resolution**2) < 20  # ~area, edge effects only


def test_footprint_of_mesh_matches_raycast_footprint():
    spec = table_spec()
    verts = prism_vertices(0.035, 0.03)
    spec.add_mesh(name="prism", uservert=verts.ravel().tolist())
    body = spec.worldbody.add_body(name="obj", pos=[0.4437, -0.1021, 0.0], quat=yaw_quat(17.0))
    body.add_geom(name="prism", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="prism", rgba=[0, 1, 1, 1], group=1)
    model, data = compile_forward(spec)
    g = gid(model, "prism")
    world = geom_world_vertices(model, data, g)
    # Same points as the mesh we gave, moved by the body pose (MuJoCo re-centres meshes).
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.array(yaw_quat(17.0)))
    given = verts @ rot.reshape(3, 3).T + [0.4437, -0.1021, 0.0]
    dists = np.linalg.norm(world[:, None] - given[None], axis=2)
    assert world.shape == (6, 3) and dists.min(axis=1).max() < 1e-6 and dists.min(axis=0).max() < 1e-6

    mask = footprint_mask(WS, model, data, [g])
    with RaycastHeightmapper(model) as mapper:
        maps = mapper(data)
    seen = maps.geom_id == g
    assert seen.sum() > 200
    np.testing.assert_array_equal(mask.astype(bool), seen)
    np.testing.assert_allclose(maps.depth[seen], 0.03, atol=1e-6)


def test_geom_world_vertices_of_primitives():
    spec = table_spec()
    add_geom(spec, "sphere", [0.4, 0.0, 0.03], [0.03], [1, 1, 1, 1], gtype=mujoco.mjtGeom.mjGEOM_SPHERE)
    add_geom(
        spec, "capsule", [0.5, 0.1, 0.07], [0.02, 0.05], [1, 1, 1, 1], gtype=mujoco.mjtGeom.mjGEOM_CAPSULE
    )
    # A cylinder lying on its side (axis along world y).
    add_geom(
        spec,
        "cylinder",
        [0.6, -0.1, 0.02],
        [0.02, 0.05],
        [1, 1, 1, 1],
        gtype=mujoco.mjtGeom.mjGEOM_CYLINDER,
        quat=[0.7071068, 0.7071068, 0.0, 0.0],
    )
    add_geom(spec, "box", [0.5, -0.1, 0.01], [0.01, 0.02, 0.01], [1, 1, 1, 1])
    spec.worldbody.add_geom(name="plane", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1], group=3)
    model, data = compile_forward(spec)

    sphere = geom_world_vertices(model, data, gid(model, "sphere"))
    assert sphere[:, 2].max() == pytest.approx(0.06, abs=1e-12)
    assert sphere[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    capsule = geom_world_vertices(model, data, gid(model, "capsule"))
    assert capsule[:, 2].max() == pytest.approx(0.07 + 0.05 + 0.02, abs=1e-9)
    cylinder = geom_world_vertices(model, data, gid(model, "cylinder"))
    # Top of a lying cylinder = centre + radius; the polygon may overshoot by < 0.5 % of r.
    assert 0.04 - 1e-9 <= cylinder[:, 2].max() <= 0.04 + 0.005 * 0.02
    assert cylinder[:, 1].max() == pytest.approx(-0.1 + 0.05, abs=1e-6)
    box = geom_world_vertices(model, data, gid(model, "box"))
    np.testing.assert_allclose(
        np.sort(box, axis=0)[[0, -1]], [[0.49, -0.12, 0.0], [0.51, -0.08, 0.02]], atol=1e-9
    )

    # The disk footprint of the sphere covers every pixel centre within its radius.
    mask = footprint_mask(WS, model, data, [gid(model, "sphere")])
    gx, gy = WS.pixel_centers()
    in_disk = np.hypot(gx - 0.4, gy) <= 0.03
    assert np.all(mask[in_disk] == 1)
    assert mask.sum() - in_disk.sum() < 0.01 * in_disk.sum()

    with pytest.raises(ValueError, match="PLANE"):
        geom_world_vertices(model, data, gid(model, "plane"))
    with pytest.raises(ValueError, match="geom_id"):
        geom_world_vertices(model, data, model.ngeom)
