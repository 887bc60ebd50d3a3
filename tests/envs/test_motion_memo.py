"""The motion memo: a motion asked again from a state it ran from ends in the same bits, unsimulated."""

import dataclasses

import mujoco
import numpy as np
import pytest
from conftest import flat_quat

import mpg_envs
from mpg_envs.grid.workspace import world_to_pixel
from mpg_envs.perception.heightmap import RaycastHeightmapper
from mpg_envs.policies.registry import make_baseline
from mpg_envs.simulation.motion_memo import MotionMemo
from mpg_envs.simulation.primitives import PrimitiveExecutor
from mpg_envs.simulation.robot import ArmIK
from mpg_envs.simulation.world import World, WorldCheckpoint


@pytest.fixture(scope="module")
def ik():
    return ArmIK()


def stacked_scene(blocks, ik, memo=True):
    """A flat box under a cube: the cube is the one to move, the box the target."""
    world = World([blocks["flat_box"], blocks["cube"]])
    world.drop_object(0, (0.5, 0.0), flat_quat())
    world.drop_object(1, (0.5, 0.005), flat_quat())
    cam = RaycastHeightmapper(world.model, world.workspace, num_threads=1)
    return world, PrimitiveExecutor(world, ik=ik, memo=memo), cam


def pixel_of(world, i):
    x, y, _ = world.object_position(i)
    return world_to_pixel(world.workspace, x, y)


def snapshot(world):
    """Every array a later step or observation reads, as bytes."""
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    state = np.empty(mujoco.mj_stateSize(world.model, spec))
    mujoco.mj_getState(world.model, world.data, state, spec)
    d = world.data
    return [state.tobytes(), d.xpos.tobytes(), d.geom_xpos.tobytes(), d.geom_xmat.tobytes(), world.active.tobytes()]


def outcome(result):
    """A result without its wall times and IK count (what was measured, not what happened)."""
    return dataclasses.replace(result, physics_seconds=0.0, seconds=0.0, ik_solves=0)


def test_a_motion_asked_again_is_restored_bit_for_bit_not_simulated(blocks, ik):
    world, prims, cam = stacked_scene(blocks, ik)
    depth = cam(world.data).depth
    args = ("move", 0, *pixel_of(world, 1), depth)
    before = WorldCheckpoint(world)
    first = prims.execute(*args, target=0)
    after_first = snapshot(world)
    steps_after = world.counter.steps
    assert first.lifted and first.grasped_object == 1 and first.physics_steps > 0
    assert (prims.memo.hits, prims.memo.misses, len(prims.memo)) == (0, 1, 1)

    before.restore()
    seconds = world.counter.seconds
    again = prims.execute(*args, target=0)
    assert prims.memo.hits == 1
    assert snapshot(world) == after_first
    assert outcome(again) == outcome(first) and again.physics_seconds == 0.0
    assert world.counter.steps == steps_after and world.counter.seconds == seconds

    # The same motion on a twin world without a memo, simulated, ends in the same bits.
    twin, plain, twin_cam = stacked_scene(blocks, ik, memo=False)
    assert plain.memo is None
    simulated = plain.execute("move", 0, *pixel_of(twin, 1), twin_cam(twin.data).depth, target=0)
    assert snapshot(twin) == after_first and outcome(simulated) == outcome(first)
    assert np.array_equal(cam(world.data).depth, twin_cam(twin.data).depth)


def test_the_key_changes_with_everything_a_motion_reads(blocks, ik):
    world, _, cam = stacked_scene(blocks, ik)
    depth = cam(world.data).depth
    row, col = pixel_of(world, 1)
    key = MotionMemo.key(world, "grasp", 2, row, col, depth, 0)
    assert MotionMemo.key(world, "grasp", 2, row, col, depth.copy(), 0) == key  # content, not identity
    others = [
        MotionMemo.key(world, "push", 2, row, col, depth, 0),
        MotionMemo.key(world, "grasp", 3, row, col, depth, 0),
        MotionMemo.key(world, "grasp", 2, row + 1, col, depth, 0),
        MotionMemo.key(world, "grasp", 2, row, col + 1, depth, 0),
        MotionMemo.key(world, "grasp", 2, row, col, depth, 1),
        MotionMemo.key(world, "grasp", 2, row, col, depth, None),
    ]
    nudged = depth.copy()
    nudged[0, 0] += 1e-6
    others.append(MotionMemo.key(world, "grasp", 2, row, col, nudged, 0))
    checkpoint = WorldCheckpoint(world)
    world.remove_object(1)
    others.append(MotionMemo.key(world, "grasp", 2, row, col, depth, 0))
    checkpoint.restore()
    assert MotionMemo.key(world, "grasp", 2, row, col, depth, 0) == key
    world.data.qvel[world.object_dof_adr[0]] = 1e-9
    others.append(MotionMemo.key(world, "grasp", 2, row, col, depth, 0))
    checkpoint.restore()
    world.step()
    others.append(MotionMemo.key(world, "grasp", 2, row, col, depth, 0))
    assert len({key, *others}) == len(others) + 1


def test_the_memo_forgets_the_least_recently_used_and_refuses_a_bad_capacity(blocks, ik):
    world, prims, cam = stacked_scene(blocks, ik)
    memo = MotionMemo(capacity=2)
    result = prims.execute("push", 0, *pixel_of(world, 0), cam(world.data).depth)
    end = WorldCheckpoint(world)
    memo.remember(b"a", result, end)
    memo.remember(b"b", result, end)
    assert memo.recall(b"a") is not None  # "a" is now the most recent
    memo.remember(b"c", result, end)
    assert memo.recall(b"b") is None and memo.recall(b"a") is not None and memo.recall(b"c") is not None
    assert (memo.hits, memo.misses, len(memo)) == (3, 1, 2)
    kept, _ = memo.recall(b"a")
    assert kept == result and kept is not result  # a copy: the caller's result is the caller's
    memo.clear()
    assert len(memo) == 0 and memo.recall(b"a") is None
    for bad in (0, -1, 1.5, True):
        with pytest.raises(ValueError, match="capacity must be a positive integer"):
            MotionMemo(capacity=bad)


def test_an_oracle_episode_is_the_same_with_and_without_the_memo():
    def episode(memo):
        env = mpg_envs.make("MPG-OccludedHard-v0", num_objects=8)
        try:
            obs, _ = env.reset(seed=2)
            executor = env.unwrapped.sim.executor
            if not memo:
                executor.memo = None
            policy = make_baseline("oracle", env, seed=2)
            trace, done = [], False
            while not done:
                action = policy.act(obs)
                obs, reward, terminated, truncated, info = env.step(action)
                trace.append((int(action), reward, obs["depth"].tobytes(), obs["color"].tobytes(), info["end_reason"]))
                done = terminated or truncated
            return trace, executor.memo
        finally:
            env.close()

    with_memo, memo = episode(True)
    without, _ = episode(False)
    assert with_memo == without
    assert memo is not None and memo.hits > 0  # the oracle's tried actions were not simulated twice
