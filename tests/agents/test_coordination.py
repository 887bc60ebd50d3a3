"""The paper's coordination as a pure rule (mpg_agents.acting.coordination)."""

from __future__ import annotations

import math

import pytest

from mpg_agents.acting.coordination import choose_primitive, usable_primitives

ALL = ("move", "push", "grasp")


def asked(values: dict[str, float]):
    """``best_q`` over ``values`` that records which primitives the rule asked for."""
    calls: list[str] = []

    def best_q(p: str) -> float:
        calls.append(p)
        return values[p]

    return best_q, calls


def test_workflow_occluded_moves_without_computing_anything():
    best_q, calls = asked({"move": -1.0, "push": 5.0, "grasp": 5.0})
    assert choose_primitive("workflow", ALL, True, 1.85, best_q) == "move"
    assert calls == []


@pytest.mark.parametrize("grasp_q, expected, needed", [(1.85, "grasp", ["grasp"]), (1.2, "push", ["grasp"])])
def test_workflow_grasps_at_or_above_q_star_else_pushes(grasp_q, expected, needed):
    best_q, calls = asked({"move": 9.0, "push": 0.1, "grasp": grasp_q})
    assert choose_primitive("workflow", ALL, False, 1.85, best_q) == expected
    assert calls == needed  # the push net is not needed to decide


def test_workflow_uncalibrated_takes_the_larger_of_grasp_and_push():
    assert choose_primitive("workflow", ALL, False, None, asked({"push": 0.3, "grasp": 0.2})[0]) == "push"
    assert choose_primitive("workflow", ALL, False, None, asked({"push": 0.2, "grasp": 0.2})[0]) == "grasp"


def test_max_q_takes_the_largest_even_when_occluded():
    best_q, calls = asked({"move": 0.1, "push": 0.7, "grasp": 0.4})
    assert choose_primitive("max_q", ALL, True, 1.85, best_q) == "push"
    assert calls == list(ALL)


def test_a_net_lacking_branches_uses_only_its_own():
    # Grasp-only checkpoint on MPG-Occluded-v0: the paper's Grasping-Only baseline.
    grasp_only = usable_primitives(ALL, ("grasp",))
    assert grasp_only == ("grasp",)
    assert choose_primitive("workflow", grasp_only, True, 1.85, asked({})[0]) == "grasp"
    # A push+grasp net: its own rule without move, occluded or not.
    push_grasp = usable_primitives(ALL, ("push", "grasp"))
    assert choose_primitive("workflow", push_grasp, True, 1.0, asked({"push": 0.0, "grasp": 2.0})[0]) == "grasp"
    assert choose_primitive("workflow", push_grasp, True, 1.0, asked({"push": 0.0, "grasp": 0.5})[0]) == "push"
    # A move+grasp net when the target is visible: grasp.
    assert choose_primitive("workflow", ("move", "grasp"), False, 1.0, asked({"grasp": -3.0})[0]) == "grasp"


def test_bad_rule_and_no_usable_primitive_are_named():
    with pytest.raises(ValueError, match="coordination must be one of"):
        choose_primitive("vote", ALL, False, 1.0, asked({})[0])
    with pytest.raises(ValueError, match="include none of the primitives"):
        usable_primitives(("move",), ("grasp",))


@pytest.mark.parametrize(
    "occluded, grasp_q, expected, needed",
    [
        (True, 0.8, "grasp", ["grasp"]),  # covered, but the grasp net scores it graspable: no move
        (True, 0.7, "move", ["grasp"]),  # covered and not graspable: the workflow's move
        (False, 0.8, "grasp", ["grasp"]),
        (False, 0.7, "push", ["grasp"]),
    ],
)
def test_grasp_first_asks_the_grasp_before_the_occlusion(occluded, grasp_q, expected, needed):
    best_q, calls = asked({"move": 9.0, "push": 0.1, "grasp": grasp_q})
    assert choose_primitive("grasp_first", ALL, occluded, 0.75, best_q) == expected
    assert calls == needed


def test_grasp_first_is_the_workflow_until_q_star_is_calibrated_or_without_a_grasp_branch():
    best_q, calls = asked({"move": -1.0, "push": 5.0, "grasp": 5.0})
    assert choose_primitive("grasp_first", ALL, True, None, best_q) == "move"
    assert calls == []
    assert choose_primitive("grasp_first", ("move", "push"), True, 0.75, asked({})[0]) == "move"


@pytest.mark.parametrize(
    "occluded, values, expected, needed",
    [
        (True, {"move": 0.6, "push": 0.9, "grasp": 5.0}, "push", ["move", "push"]),  # a push may uncover it too
        (True, {"move": 0.9, "push": 0.6, "grasp": 5.0}, "move", ["move", "push"]),
        (True, {"move": 0.7, "push": 0.7, "grasp": 5.0}, "move", ["move", "push"]),  # a tie keeps the move
        (False, {"move": 9.0, "push": 0.1, "grasp": 0.8}, "grasp", ["grasp"]),  # uncovered: the workflow
        (False, {"move": 9.0, "push": 0.1, "grasp": 0.7}, "push", ["grasp"]),
    ],
)
def test_uncover_max_q_weighs_move_against_push_only_while_covered(occluded, values, expected, needed):
    best_q, calls = asked(values)
    assert choose_primitive("uncover_max_q", ALL, occluded, 0.75, best_q) == expected
    assert calls == needed


def test_uncover_max_q_without_a_push_branch_moves_while_covered():
    best_q, calls = asked({"move": 0.1, "grasp": 5.0})
    assert choose_primitive("uncover_max_q", ("move", "grasp"), True, 0.75, best_q) == "move"
    assert calls == []


@pytest.mark.parametrize(
    "occluded, values, expected, needed",
    [
        (True, {"move": 0.6, "push": 0.9, "grasp": 0.8}, "grasp", ["grasp"]),  # covered but graspable
        (True, {"move": 0.6, "push": 0.9, "grasp": 0.7}, "push", ["grasp", "move", "push"]),  # then uncover by the larger
        (True, {"move": 0.9, "push": 0.6, "grasp": 0.7}, "move", ["grasp", "move", "push"]),
        (False, {"move": 9.0, "push": 0.1, "grasp": 0.7}, "push", ["grasp"]),  # uncovered: the workflow
    ],
)
def test_grasp_first_uncover_max_q_grasps_then_uncovers_by_the_larger(occluded, values, expected, needed):
    best_q, calls = asked(values)
    assert choose_primitive("grasp_first_uncover_max_q", ALL, occluded, 0.75, best_q) == expected
    assert calls == needed


def test_nan_is_no_way_to_say_no_q_star():
    from mpg_agents.acting.grasp_threshold import GraspThreshold

    with pytest.raises(ValueError, match="None"):
        choose_primitive("workflow", ALL, False, math.nan, asked({"push": 0.3, "grasp": 0.2})[0])
    held = GraspThreshold()
    assert held.get() is None and not held.calibrated
    with pytest.raises(ValueError, match="None"):
        held.set(float("nan"))
    held.set(1.85)
    assert held.get() == 1.85 and held.calibrated
