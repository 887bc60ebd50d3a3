"""A primitive added from this one file: a ``poke`` (the closed fingers pressed at a pixel and
slid 3 cm) registered as a record, a motion and a reward rule, then run in a full episode of
a stage that offers it beside push and grasp."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mpg_envs.grid.actions import PRIMITIVES, check_primitives
from mpg_envs.grid.primitive_specs import (
    GRASP,
    PUSH,
    PrimitiveSpec,
    primitive_spec,
    register_primitive,
    registered_primitives,
    unregister_primitive,
)
from mpg_envs.grid.workspace import NUM_ROTATIONS, pixel_to_world, rotation_angle
from mpg_envs.simulation.motions import register_motion, unregister_motion
from mpg_envs.simulation.primitives import PrimitiveExecutor, PrimitiveResult
from mpg_envs.tasks.env import MPGEnv
from mpg_envs.tasks.rewards import RewardConfig, StepOutcome, register_reward_rule, unregister_reward_rule
from mpg_envs.tasks.stages import StageSpec, reward_per_primitive

POKE = "poke"
POKE_LENGTH = 0.03  # metres the closed fingers slide after pressing in


def poke(executor: PrimitiveExecutor, rotation: int, row: int, col: int, depth: np.ndarray, target: int | None):
    """Closed fingers down to just below the local height at the pixel, a short slide along
    the rotation's direction, back up: the push's motion pieces over a third of its length."""
    cfg = executor.config
    x, y = pixel_to_world(executor.world.workspace, row, col)
    h = float(depth[row, col])
    z = max(h - cfg.push_depth, cfg.push_min_height) if h > cfg.occupied_height else cfg.push_table_height
    direction = rotation_angle(rotation)
    end = (x + POKE_LENGTH * math.cos(direction), y + POKE_LENGTH * math.sin(direction), z)
    theta = direction + math.pi / 2
    z_pre = executor.pre_height(depth, row, col, z)
    q = executor.teleport((x, y, z_pre), theta, closed=True)
    q = executor.linear((x, y, z_pre), (x, y, z), theta, q, cfg.approach_speed)
    q = executor.linear((x, y, z), end, theta, q, cfg.push_speed)
    executor.linear(end, (end[0], end[1], z_pre), theta, q, cfg.lift_speed)
    executor.finish()
    return PrimitiveResult(POKE, rotation, (row, col), (x, y, z))


def reward_poke(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """``improved`` for a poke that changed the scene, the penalty for one that did not."""
    return c.improved if o.change_detected else c.penalty


@pytest.fixture
def poke_registered():
    spec = register_primitive(PrimitiveSpec(POKE, reward_rule="poke_contact"))
    register_motion(POKE, poke)
    register_reward_rule("poke_contact", reward_poke)
    try:
        yield spec
    finally:
        unregister_reward_rule("poke_contact")
        unregister_motion(POKE)
        unregister_primitive(POKE)


def test_a_registered_primitive_comes_after_the_papers_three(poke_registered):
    assert registered_primitives() == (*PRIMITIVES, POKE)
    assert primitive_spec(POKE) is poke_registered and not poke_registered.half_turn_symmetric
    assert check_primitives((PUSH, GRASP, POKE)) == (PUSH, GRASP, POKE)
    with pytest.raises(ValueError, match="order"):
        check_primitives((POKE, GRASP))
    with pytest.raises(ValueError, match="already registered"):
        register_primitive(PrimitiveSpec(POKE, reward_rule="poke_contact"))
    with pytest.raises(ValueError, match="cannot be unregistered"):
        unregister_primitive(GRASP)


def test_unregistered_it_is_unknown_again():
    assert registered_primitives() == PRIMITIVES  # the fixture took it out after the tests above
    with pytest.raises(ValueError, match="unknown primitive 'poke'"):
        primitive_spec(POKE)
    with pytest.raises(ValueError, match="must be a non-empty subset"):
        check_primitives((GRASP, POKE))


def test_an_episode_with_a_poke(poke_registered):
    stage = StageSpec("PokeClutter", (PUSH, GRASP, POKE), "clustered", 4, 5, reward_per_primitive, min_objects=2)
    env = MPGEnv(stage=stage)
    try:
        obs, info = env.reset(seed=3)
        space = env.action_space
        assert space.primitives == (PUSH, GRASP, POKE) and space.n == 3 * NUM_ROTATIONS * 224 * 224
        # The codec's layout: poke's block comes after push's and grasp's.
        assert space.encode(POKE, 0, 0, 0) == 2 * NUM_ROTATIONS * 224 * 224

        # A push somewhere on the table, away from everything: the paper's rule pays it.
        _, reward, terminated, truncated, info = env.step(space.encode(PUSH, 0, 5, 5))
        assert info["primitive"] == PUSH and not (terminated or truncated)

        # The poke at the top of the tallest object, sliding along +x.
        world = env.world
        assert world is not None
        depth = env.last_observation["depth"]
        row, col = np.unravel_index(int(np.argmax(depth)), depth.shape)
        positions = {i: world.object_position(i).copy() for i in world.active_objects()}
        _, reward, terminated, truncated, info = env.step(space.encode(POKE, 0, int(row), int(col)))
        moved = [i for i, p in positions.items() if world.active[i] and np.linalg.norm(world.object_position(i) - p) > 0.005]
        assert info["primitive"] == POKE and info["num_motions"] == 2
        assert moved, "the poke moved nothing"
        assert info["change_detected"] and reward == RewardConfig().improved  # the poke's own rule
        assert not info["lifted"] and info["grasp_failure"] is None and not info["wrong_grasp"]

        # The same poke tried and undone, then a grasp: the episode goes on after it.
        tried = env.try_step(space.encode(POKE, 4, int(row), int(col)))
        assert tried[4]["primitive"] == POKE and env.num_motions == 2
        if not (terminated or truncated):
            _, _, _, _, info = env.step(space.encode(GRASP, 0, int(row), int(col)))
            assert info["primitive"] == GRASP and info["num_motions"] == 3
    finally:
        env.close()
