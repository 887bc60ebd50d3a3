"""The scripted oracle: the Policy protocol, its memory of tried actions, and its jaw geometry."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_envs.grid.grasp_geometry import (
    angle_gap,
    angle_to_rotation,
    extent_along,
    finger_region,
    footprint_rect,
    jaw_strip_heights,
    other_grasp_angles,
    polygon_mask,
    region_max,
)
from mpg_envs.policies.oracle import ActionMemory, OracleConfig, OraclePolicy, Policy
from mpg_envs.grid.workspace import Workspace

# ----------------------------------------------------------------- geometry (hand-checked)


def test_footprint_rect_of_a_rotated_rectangle() -> None:
    # A 6 x 2 rectangle turned by 30 degrees: the short side points along 120 degrees.
    a = math.radians(30)
    long_dir, short_dir = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
    pts = np.array([sx * 3 * long_dir + sy * 1 * short_dir for sx in (-1, 1) for sy in (-1, 1)]) + (10.0, 5.0)
    centre, sizes, theta = footprint_rect(pts)
    np.testing.assert_allclose(centre, (10.0, 5.0), atol=1e-4)
    np.testing.assert_allclose(sizes, (6.0, 2.0), atol=1e-4)
    assert angle_gap(theta, math.radians(120)) < 1e-4


def test_angle_to_rotation_and_gap() -> None:
    assert angle_to_rotation(0.0) == 0
    assert angle_to_rotation(math.radians(22.5)) == 1
    assert angle_to_rotation(math.radians(190)) == 0  # grasps are symmetric: 180 + 10 -> 0
    assert angle_to_rotation(math.radians(190), symmetric=False) == 8
    assert angle_gap(math.radians(10), math.radians(170)) == pytest.approx(math.radians(20))
    assert angle_gap(0.0, math.pi) == pytest.approx(0.0)
    # rotation 11 is 247.5 degrees, the grasp angle 3 (67.5 degrees) turned by 180
    assert other_grasp_angles(11) == [0, 1, 2, 4, 5, 6, 7] == other_grasp_angles(3)


def test_extent_along() -> None:
    pts = np.array([[0.0, 0.0], [2.0, 1.0], [1.0, -3.0]])
    assert extent_along(pts, np.array([1.0, 0.0]), np.array([1.0, 0.0])) == (-1.0, 1.0)
    assert extent_along(pts, np.zeros(2), np.array([0.0, 1.0])) == (-3.0, 1.0)


def test_finger_region_corners() -> None:
    corners = finger_region(np.array([1.0, 1.0]), 0.0, side=-1, inner=0.02, outer=0.05, half_width=0.01)
    xs, ys = corners[:, 0], corners[:, 1]
    assert xs.min() == pytest.approx(0.95) and xs.max() == pytest.approx(0.98)
    assert ys.min() == pytest.approx(0.99) and ys.max() == pytest.approx(1.01)
    with pytest.raises(ValueError, match="side"):
        finger_region(np.zeros(2), 0.0, side=0, inner=0.0, outer=1.0, half_width=1.0)


def test_polygon_mask_fills_pixel_centres_inside() -> None:
    ws = Workspace()
    # A 10 x 4 mm box whose corner is the workspace corner: 5 x 2 pixels.
    mask = polygon_mask(ws, np.array([[ws.x_min, ws.y_min], [ws.x_min + 0.01, ws.y_min], [ws.x_min + 0.01, ws.y_min + 0.004], [ws.x_min, ws.y_min + 0.004]]))
    assert mask[:2, :5].all()
    assert mask.sum() <= (3 * 6)  # the border pixels at most, never more
    assert region_max(np.arange(mask.size, dtype=float).reshape(mask.shape), mask) >= 4
    assert region_max(np.ones(mask.shape), np.zeros(mask.shape, bool), outside=-1.0) == -1.0


def test_jaw_strip_heights() -> None:
    # Object 4 cm wide; a 3 cm high neighbour at +3 cm, a 1 cm one at -5 cm.
    s = np.array([-0.05, -0.01, 0.0, 0.01, 0.03])
    h = np.array([0.01, 0.04, 0.04, 0.04, 0.03])
    kw = dict(open_inner=0.0425, finger_thickness=0.0095, margin=0.004)
    low, high = jaw_strip_heights(s, h, 0.04, 0.0, **kw)
    assert (low, high) == (0.01, 0.03)  # the object's own pixels (|s| < 2.4 cm) are never under a finger
    # Jaw slid 1.6 cm down: the upper finger sweeps from +3.6 cm (-1.6 + 4.25 + 0.95) in to +2.4 cm.
    low, high = jaw_strip_heights(s, h, 0.04, -0.016, **kw)
    assert low == 0.01 and high == 0.03
    # Slid 3 cm down: the upper finger's outer face is at +2.2 cm, inside the object's side: no strip.
    low, high = jaw_strip_heights(s, h, 0.04, -0.03, **kw)
    assert high == 0.0 and low == 0.01


# ----------------------------------------------------------------- memory of tried actions


def test_action_memory_repeats_only_on_an_unchanged_scene() -> None:
    mem = ActionMemory(OracleConfig())
    depth = np.zeros((224, 224), np.float32)
    mem.record("grasp", 3, 100, 100, depth)
    assert mem.repeats("grasp", 3, 100, 100, depth)
    assert mem.repeats("grasp", 11, 102, 98, depth)  # same jaw angle (mod 180) and nearly the same pixel
    assert not mem.repeats("grasp", 4, 100, 100, depth)  # another angle
    assert not mem.repeats("move", 3, 100, 100, depth)  # another primitive
    assert not mem.repeats("grasp", 3, 120, 100, depth)  # elsewhere
    changed = depth.copy()
    changed[110, 105] = 0.03  # something moved next to it
    assert not mem.repeats("grasp", 3, 100, 100, changed)
    far = depth.copy()
    far[10, 10] = 0.03  # a change far away does not make it new
    assert mem.repeats("grasp", 3, 100, 100, far)
    mem.record("push", 3, 50, 50, depth)
    assert not mem.repeats("push", 11, 50, 50, depth)  # push directions are not symmetric
    mem.clear()
    assert len(mem) == 0 and not mem.repeats("grasp", 3, 100, 100, depth)


# ----------------------------------------------------------------- the oracle in an env


@pytest.fixture(scope="module")
def occluded_env():
    env = gym.make("MPG-Occluded-v0").unwrapped
    yield env
    env.close()


def test_oracle_is_a_policy(occluded_env) -> None:
    oracle = OraclePolicy(occluded_env)
    assert isinstance(oracle, Policy)
    assert oracle.name == "oracle"


def test_oracle_never_repeats_an_action_on_the_scene_it_failed_on(occluded_env) -> None:
    """Acting again on an unchanged scene (the last action did nothing) gives a new action every time."""
    obs, _ = occluded_env.reset(seed=90221)
    oracle = OraclePolicy(occluded_env, OracleConfig(verify_grasps=1, verify_preparations=1))
    oracle.reset()
    seen = []
    for _ in range(6):
        action = occluded_env.action_space.decode(oracle.act(obs))
        key = (action.primitive, action.rotation % 8 if action.primitive != "push" else action.rotation, action.row, action.col)
        assert key not in seen, f"repeated {action} on an unchanged scene"
        seen.append(key)
    assert oracle.last_plan is not None and "kind" in oracle.last_plan


def test_oracle_forgets_at_reset(occluded_env) -> None:
    obs, _ = occluded_env.reset(seed=90223)
    oracle = OraclePolicy(occluded_env, OracleConfig(verify_grasps=1, verify_preparations=1))
    first = oracle.act(obs)
    assert oracle.act(obs) != first
    oracle.reset()
    assert oracle.act(obs) == first  # same state, fresh memory: the same plan


def test_oracle_moves_the_occluder_first_without_trials(occluded_env) -> None:
    """Planning by geometry alone, an occluded target's occluder is moved before any grasp."""
    obs, info = occluded_env.reset(seed=90228)
    assert info["occluded"]
    oracle = OraclePolicy(occluded_env, OracleConfig(verify_grasps=0))
    action = occluded_env.action_space.decode(oracle.act(obs))
    assert action.primitive == "move"
    assert oracle.last_plan["kind"] == "move_occluder"


def test_a_trial_leaves_the_world_as_it_was(occluded_env) -> None:
    obs, _ = occluded_env.reset(seed=90000)
    world = occluded_env.world
    qpos, active, steps = world.data.qpos.copy(), world.active.copy(), world.counter.steps
    target = occluded_env.target
    row, col = np.argwhere(obs["mask"] > 0).mean(axis=0).astype(int)
    result = occluded_env.sim.try_primitive("grasp", 0, int(row), int(col), obs["depth"], target)
    assert result.physics_steps > 0
    np.testing.assert_array_equal(world.data.qpos, qpos)
    np.testing.assert_array_equal(world.active, active)
    assert world.counter.steps == steps


def test_a_verified_grasp_holds_the_target_when_taken(occluded_env) -> None:
    """A grasp that held the target in the trial holds it in the env too (MuJoCo is deterministic)."""
    for seed in (90000, 90003, 90006):
        obs, _ = occluded_env.reset(seed=seed)
        oracle = OraclePolicy(occluded_env)
        action = oracle.act(obs)
        if oracle.last_plan["kind"] != "grasp_verified":
            continue
        _, _, terminated, _, info = occluded_env.step(action)
        assert info["target_grasped"] and terminated
        return
    pytest.fail("no seed gave a verified grasp at the first step")


def test_oracle_prepares_with_a_tried_move_when_no_grasp_holds(occluded_env) -> None:
    """Seed 90001 (15 objects): no grasp of the buried target holds, so the oracle moves an
    object; the move it takes was tried, and it is the first of its candidates after which a
    grasp holds or the best it found."""
    obs, _ = occluded_env.reset(seed=90001)
    oracle = OraclePolicy(occluded_env, OracleConfig(verify_grasps=2, verify_preparations=2))
    action = occluded_env.action_space.decode(oracle.act(obs))
    assert action.primitive in ("move", "push")
    assert oracle.last_plan["kind"] in ("move_occluder", "move_blocker", "push")
    # The tried grasps and the preparation were all remembered: the same state gives a new action.
    assert occluded_env.action_space.decode(oracle.act(obs)) != action


def test_action_memory_forbids_a_tried_action_until_its_surroundings_change():
    from dataclasses import dataclass

    from mpg_envs.policies.action_memory import ActionMemory

    @dataclass
    class Rule:
        repeat_pixels: int = 1
        repeat_window: int = 3
        repeat_height_change: float = 0.005

    memory = ActionMemory(Rule())
    depth = np.zeros((10, 10), np.float32)
    memory.record("grasp", 3, 5, 5, depth)
    barred = memory.forbidden("grasp", depth, 16)
    # rotations 3 and 11 (a grasp is symmetric), pixels within 1 of (5, 5): 2 x 9 actions
    assert barred.sum() == 18 and barred[[3, 11], 4:7, 4:7].all()
    assert not memory.forbidden("push", depth, 16).any()
    moved = depth.copy()
    moved[7, 8] = 0.02  # inside the 3-pixel window: the scene there changed
    assert not memory.forbidden("grasp", moved, 16).any()
    far = depth.copy()
    far[0, 0] = 0.02  # outside the window: still the same scene there
    assert memory.forbidden("grasp", far, 16).sum() == 18
