"""The ROC AUC and summary of mpg_agents.evaluation.grasp_outcomes on hand-checked cases."""

import math

import pytest

from mpg_agents.evaluation import grasp_outcomes as bench


def test_auc_separates_and_ties():
    assert bench.roc_auc([0.1, 0.2, 0.9, 0.8], [False, False, True, True]) == 1.0
    assert bench.roc_auc([0.9, 0.8, 0.1, 0.2], [False, False, True, True]) == 0.0
    assert bench.roc_auc([0.5, 0.5, 0.5], [True, False, False]) == 0.5
    # one positive (0.6) above one of two negatives (0.4) and below the other (0.7)
    assert bench.roc_auc([0.6, 0.4, 0.7], [True, False, False]) == 0.5
    assert math.isnan(bench.roc_auc([0.3, 0.4], [True, True]))
    with pytest.raises(ValueError, match="one length"):
        bench.roc_auc([0.1, 0.2], [True])


def test_summary_counts_and_shares():
    rec = lambda q, occ, took, fail: {"q": q, "occluded": occ, "target": took, "wrong": False, "failure": fail}  # noqa: E731
    records = [rec(0.9, False, True, None), rec(0.8, True, False, "closed_empty"),
               rec(0.7, False, True, None), rec(0.6, True, False, "closed_empty")]
    out = bench.summarise(records, q_star=0.75)
    assert (out["grasps"], out["target"], out["failures"]) == (4, 2, {"closed_empty": 2})
    assert (out["target_share_covered"], out["target_share_uncovered"]) == (0.0, 1.0)
    assert out["q_auc"] == 0.75  # 0.9 beats both misses, 0.7 beats only 0.6
    assert (out["q_at_least_q_star"], out["target_share_q_at_least_q_star"]) == (2, 0.5)
    with pytest.raises(ValueError, match="no grasps"):
        bench.summarise([], q_star=0.75)


def test_moves_and_pushes_are_tallied():
    rec = lambda p, before, after, nothing=False: {  # noqa: E731
        "primitive": p, "covered_before": before, "covered_after": after, "held_nothing": nothing}
    others = [rec("move", True, False), rec("move", True, True, True), rec("move", False, False),
              rec("push", True, True), rec("push", False, True)]
    out = bench.summarise_motions(others)
    assert out["move"] == {"count": 3, "covered_before": 2, "uncovered_it": 1, "held_nothing": 1}
    assert out["push"] == {"count": 2, "covered_before": 1, "uncovered_it": 0, "held_nothing": 0}
    assert bench.summarise_motions([])["move"]["count"] == 0


def test_angle_trials_count_the_misses_another_angle_would_take():
    rec = lambda occ, took, other: {"q": 0.5, "occluded": occ, "target": took, "wrong": False,  # noqa: E731
                                    "failure": None if took else "closed_empty", "other_angle_takes": other}
    records = [rec(False, True, False), rec(False, False, True), rec(False, False, False), rec(True, False, True)]
    out = bench.summarise(records, q_star=0.0)
    assert (out["missed_uncovered"], out["missed_uncovered_other_angle_takes"]) == (2, 1)
    assert (out["missed_covered"], out["missed_covered_other_angle_takes"]) == (1, 1)
    plain = [dict(r, other_angle_takes=None) for r in records]
    assert "missed_covered" not in bench.summarise(plain, q_star=0.0)  # no trials, no such counts


def test_finger_blocking_is_summarised():
    rec = lambda took, blocked: {"q": 0.5, "occluded": False, "target": took, "wrong": False,  # noqa: E731
                                 "failure": None if took else "closed_empty", "blocked": blocked}
    records = [rec(True, -0.01), rec(False, 0.02), rec(True, 0.01), rec(False, -0.005), rec(False, 0.03)]
    out = bench.summarise(records, q_star=0.0)
    assert out["fingers_free"] == 2
    assert (out["target_share_fingers_free"], out["target_share_fingers_blocked"]) == (0.5, 1 / 3)
    # Minus the blocking: the target grasps (0.01, -0.01) beat 3 and 2 of the 3 misses (-0.02, 0.005, -0.03).
    assert out["fingers_auc"] == pytest.approx(5 / 6)
    assert "fingers_auc" not in bench.summarise([dict(r, blocked=float("nan")) for r in records], q_star=0.0)
