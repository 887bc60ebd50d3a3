"""The primitive records and the registries keyed by them (record, motion, reward rule)."""

from __future__ import annotations

import pytest

from mpg_envs.grid.actions import PRIMITIVES, check_primitives
from mpg_envs.grid.primitive_specs import (
    GRASP,
    MOVE,
    PUSH,
    PrimitiveSpec,
    half_turn_symmetric,
    primitive_spec,
    register_primitive,
    registered_primitives,
    unregister_primitive,
)
from mpg_envs.integrations.wrappers import SYMMETRIC_PRIMITIVES, grid_rotation
from mpg_envs.simulation.motions import motion_of, register_motion, unregister_motion
from mpg_envs.simulation.primitives import PrimitiveExecutor, Primitives
from mpg_envs.tasks.rewards import (
    RewardConfig,
    StepOutcome,
    register_reward_rule,
    reward_per_primitive,
    reward_rule,
    unregister_reward_rule,
)


def test_the_papers_three_in_codec_order_with_their_properties():
    assert PRIMITIVES == registered_primitives() == (MOVE, PUSH, GRASP) == ("move", "push", "grasp")
    move, push, grasp = (primitive_spec(p) for p in PRIMITIVES)
    assert (move.half_turn_symmetric, push.half_turn_symmetric, grasp.half_turn_symmetric) == (True, False, True)
    assert (move.lifts, push.lifts, grasp.lifts) == (True, False, True)
    assert (move.retrieves, push.retrieves, grasp.retrieves) == (False, False, True)
    assert (move.rough_masked, push.rough_masked, grasp.rough_masked) == (True, False, True)
    assert SYMMETRIC_PRIMITIVES == (MOVE, GRASP) and half_turn_symmetric(GRASP) and not half_turn_symmetric(PUSH)


def test_symmetry_spreads_the_wrappers_rotations_as_before():
    # 4 grid rotations: move and grasp over 180 degrees (k = 0, 2, 4, 6), push over 360 (k = 0, 4, 8, 12).
    assert [grid_rotation(GRASP, r, 4) for r in range(4)] == [0, 2, 4, 6]
    assert [grid_rotation(MOVE, r, 4) for r in range(4)] == [0, 2, 4, 6]
    assert [grid_rotation(PUSH, r, 4) for r in range(4)] == [0, 4, 8, 12]


def test_each_paper_primitive_is_paid_by_its_rule():
    c = RewardConfig()
    uncovered = dict(change_detected=True, move_success=True)
    assert reward_per_primitive(StepOutcome(MOVE, **uncovered), c) == 1.0  # R_m: success
    assert reward_per_primitive(StepOutcome(PUSH, **uncovered), c) == 0.0  # R_p: changed, no Q gain
    assert reward_per_primitive(StepOutcome(PUSH), c) == -0.5  # R_p: no change
    assert reward_per_primitive(StepOutcome(GRASP, lifted=True, target_grasped=True), c) == 1.0  # R_g2
    assert reward_per_primitive(StepOutcome(GRASP, lifted=True), c) == 0.0  # R_g2: another object
    assert [reward_rule(primitive_spec(p).reward_rule).__name__ for p in PRIMITIVES] == [
        "reward_move",
        "reward_push",
        "reward_grasp_target",
    ]


def test_bad_records_and_names_are_one_line_errors():
    with pytest.raises(ValueError, match="identifier"):
        PrimitiveSpec("po ke", reward_rule="x")
    with pytest.raises(ValueError, match="reward_rule"):
        PrimitiveSpec("poke")
    with pytest.raises(ValueError, match="retrieves=True needs lifts=True"):
        PrimitiveSpec("poke", retrieves=True, reward_rule="x")
    with pytest.raises(TypeError, match="PrimitiveSpec"):
        register_primitive("poke")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="already registered"):
        register_primitive(PrimitiveSpec(GRASP, reward_rule="x"))
    with pytest.raises(ValueError, match="not registered"):
        unregister_primitive("poke")
    with pytest.raises(ValueError, match="unknown primitive 'poke'"):
        primitive_spec("poke")
    with pytest.raises(ValueError, match="unknown primitive 'poke'"):
        motion_of("poke")
    with pytest.raises(ValueError, match="unknown primitive 'poke'"):
        register_motion("poke", lambda *a: None)  # not a registered primitive
    with pytest.raises(ValueError, match="has a motion already"):
        register_motion(PUSH, lambda *a: None)
    with pytest.raises(ValueError, match="cannot be unregistered"):
        unregister_motion(MOVE)
    with pytest.raises(ValueError, match="unknown reward rule 'nope'"):
        reward_rule("nope")
    with pytest.raises(ValueError, match="already registered"):
        register_reward_rule("uncover", lambda o, c: 0.0)
    with pytest.raises(ValueError, match="cannot be unregistered"):
        unregister_reward_rule("grasp_target")
    with pytest.raises(ValueError, match="non-empty subset"):
        check_primitives(("poke",))


def test_the_executor_keeps_its_former_name_and_runs_the_registered_motions():
    assert Primitives is PrimitiveExecutor
    assert motion_of(GRASP) is PrimitiveExecutor.grasp and motion_of(PUSH) is PrimitiveExecutor.push
    assert motion_of(MOVE) is PrimitiveExecutor.move
