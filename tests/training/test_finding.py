"""What finding the target cost (mpg_agents.evaluation.finding): motions to first sight and
look-alike grasps, by hand, through an episode record and in the evaluation's summary."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import run_episode, summarise
from mpg_agents.evaluation.finding import FindingTally, finding_line, finding_summary, first_sight


def test_first_sight_by_hand():
    assert first_sight(0.2, [0.0, 0.5]) == 0  # shows at reset
    assert first_sight(0.0, [0.0, None, 0.01, 0.0]) == 3  # first shows after the third motion
    assert first_sight(0.0, [0.0, 0.0]) is None  # never shows
    assert first_sight(None, [0.5]) is None  # the env reports no visibility


def test_a_tally_counts_look_alikes_only_where_reported():
    tally = FindingTally(0.0)
    tally.step({"visible_fraction": 0.0})
    assert tally.lookalike_grasps is None and tally.first_sight is None
    tally.step({"visible_fraction": 0.3, "wrong_grasp_lookalike": False})
    tally.step({"visible_fraction": 0.3, "wrong_grasp_lookalike": True})
    assert tally.lookalike_grasps == 1 and tally.first_sight == 2


def _record(index, visible, sight, lookalikes=None, wrong=0):
    return EpisodeRecord(
        index=index, seed=index, success=True, motions=3, end_reason="target_grasped",
        primitives={"move": 2, "push": 0, "grasp": 1}, grasp_attempts=1 + wrong, target_grasps=1,
        wrong_grasps=wrong, objects_left=10, visible_fraction=visible, first_sight=sight, lookalike_grasps=lookalikes,
    )  # fmt: skip


def test_the_summary_over_episodes_by_hand():
    records = [
        _record(0, 0.2, 0, 0, 1),
        _record(1, 0.0, 2, 1, 1),
        _record(2, 0.0, None, 2, 3),
        _record(3, None, None),
    ]
    summary = finding_summary(records)
    assert summary == {
        "episodes": 3, "shown_at_reset": 1, "sighted": 2, "motions_to_sight": 1.0,
        "lookalike_grasps_per_episode": 1.0, "other_mispicks_per_episode": (1 + 1 + 3 - 3) / 3,
    }  # fmt: skip
    assert finding_line(summary) == (
        "2/3 sighted (1 at reset), 1.00 motions to first sight; "
        "look-alike grasps 1.00, other mis-picks 0.67 per episode"
    )
    assert finding_summary([_record(0, 0.0, None)]) == {
        "episodes": 1,
        "shown_at_reset": 0,
        "sighted": 0,
        "motions_to_sight": None,
    }
    assert finding_line({"episodes": 0}) == "n/a"


def test_records_keep_look_alikes_only_where_reported_and_the_result_sums_them():
    told, untold = _record(0, 0.0, 1, 1, 1), _record(1, 0.1, 0)
    assert told.to_dict()["lookalike_grasps"] == 1 and told.to_dict()["first_sight"] == 1
    assert "lookalike_grasps" not in untold.to_dict() and untold.to_dict()["first_sight"] == 0
    result = summarise([told, untold], "p", "MPG-OccludedHardExemplar-v0", 15, 0, 0.0)
    assert result.finding["lookalike_grasps_per_episode"] == 1.0 and result.finding["sighted"] == 2
    assert "look-alike grasps 1.00" in result.table()
    json.dumps(result.to_dict())


class Scripted(gym.Env):
    """An env whose steps report the visible fractions and look-alike mis-picks it is given."""

    observation_space = gym.spaces.Box(0, 1, (1,))
    action_space = gym.spaces.Discrete(2)

    def __init__(self, visible, lookalikes):
        self.visible, self.lookalikes = visible, lookalikes

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.k = 0
        return np.zeros(1, np.float32), {"visible_fraction": self.visible[0]}

    def step(self, action):
        self.k += 1
        done = self.k == len(self.visible) - 1
        info = {"primitive": "grasp", "target_grasped": done, "wrong_grasp": self.lookalikes[self.k - 1] is not None,
                "visible_fraction": self.visible[self.k], "is_success": done, "num_motions": self.k,
                "end_reason": "target_grasped" if done else None}  # fmt: skip
        if self.lookalikes[self.k - 1] is not None:
            info["wrong_grasp_lookalike"] = self.lookalikes[self.k - 1]
        return np.zeros(1, np.float32), 0.0, done, False, info


class First:
    name = "first"

    def act(self, obs):
        return 0


@pytest.mark.parametrize(
    ("visible", "lookalikes", "sight", "counted"),
    [
        ([0.0, 0.0, 0.2, None], [None, None, None], 2, None),
        ([0.3, 0.3, None], [True, None], 0, 1),
        ([0.0, 0.0, None], [False, None], None, 0),
    ],
)
def test_an_episode_records_its_first_sight_and_look_alikes(visible, lookalikes, sight, counted):
    record = run_episode(First(), Scripted(visible, lookalikes), index=0, seed=1)
    assert record.first_sight == sight and record.lookalike_grasps == counted
