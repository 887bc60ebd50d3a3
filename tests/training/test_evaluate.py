"""Evaluation: confidence intervals, per-episode records and their summary, and mpg-eval's output."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest

from mpg_agents.cli import eval_main
from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import PRIMITIVES, summarise
from mpg_agents.evaluation.stats import bootstrap_mean_interval, wilson_interval
from mpg_envs.tasks.env import END_REASONS


# ----------------------------------------------------------------------------- stats
@pytest.mark.parametrize(
    "k, n, expected",
    [
        # Wilson bounds, z = 1.959964: 0/10 -> (0, z^2 / (n + z^2)); 5/10 symmetric about 1/2.
        (0, 10, (0.0, 0.277533)),
        (5, 10, (0.236593, 0.763407)),
        (10, 10, (0.722467, 1.0)),
        (46, 50, (0.8116, 0.9684)),  # the MPGNet cell: 92% of 50
    ],
)
def test_wilson_interval_matches_hand_computed_bounds(k, n, expected):
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(expected[0], abs=5e-4) and hi == pytest.approx(expected[1], abs=5e-4)


def test_wilson_interval_is_the_score_formula():
    z, k, n = 1.959963985, 7, 20
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    assert wilson_interval(k, n) == pytest.approx((centre - half, centre + half), abs=1e-6)


@pytest.mark.parametrize(
    "args, message",
    [((11, 10), "successes"), ((-1, 10), "successes"), ((0, 0), "trials"), ((2.5, 10), "successes")],
)
def test_wilson_interval_rejects_bad_counts(args, message):
    with pytest.raises(ValueError, match=message):
        wilson_interval(*args)
    with pytest.raises(ValueError, match="confidence"):
        wilson_interval(1, 2, confidence=1.5)


def test_bootstrap_interval_is_seeded_and_brackets_the_mean():
    values = [1, 2, 2, 3, 10, 4, 2, 1, 6, 3]
    lo, hi = bootstrap_mean_interval(values, seed=3)
    assert (lo, hi) == bootstrap_mean_interval(values, seed=3)
    assert min(values) <= lo < np.mean(values) < hi <= max(values)
    # four times the data: about half the width
    lo4, hi4 = bootstrap_mean_interval(values * 4, seed=3)
    assert 0.35 < (hi4 - lo4) / (hi - lo) < 0.65


def test_bootstrap_interval_of_constant_values_is_a_point_and_needs_two_values():
    assert bootstrap_mean_interval([10, 10, 10]) == (10.0, 10.0)
    with pytest.raises(ValueError, match="at least two"):
        bootstrap_mean_interval([3])
    with pytest.raises(ValueError, match="finite"):
        bootstrap_mean_interval([1, float("nan")])


# ------------------------------------------------------------------------- summarise
def _record(index: int, success: bool, motions: int, end_reason: str, grasps: int, pushes: int = 0) -> EpisodeRecord:
    return EpisodeRecord(
        index=index,
        seed=100 + index,
        success=success,
        motions=motions,
        end_reason=end_reason,
        primitives={"move": motions - grasps - pushes, "push": pushes, "grasp": grasps},
        grasp_attempts=grasps,
        target_grasps=int(success),
        wrong_grasps=0,
        objects_left=5,
        seconds=0.1 * motions,
    )


def test_summarise_counts_end_reasons_primitives_and_rates():
    records = [
        _record(2, False, 10, "motion_cap", grasps=4, pushes=3),
        _record(0, True, 2, "target_grasped", grasps=1),
        _record(1, True, 3, "target_grasped", grasps=2, pushes=1),
    ]
    result = summarise(records, "p", "MPG-Occluded-v0", 15, seed=100, wall_seconds=1.0)
    assert [r.index for r in result.records] == [0, 1, 2]
    assert result.end_reasons == {"motion_cap": 1, "target_grasped": 2}
    assert result.primitive_counts == {"move": 3 + 1 + 0, "push": 4, "grasp": 7}
    assert list(result.primitive_counts) == list(PRIMITIVES)
    assert result.task_success_rate == pytest.approx(2 / 3)
    assert result.average_motions == pytest.approx(5.0) and result.average_motions_success == pytest.approx(2.5)
    assert result.grasp_success_rate == pytest.approx(2 / 7) and result.grasp_attempts == 7
    assert result.success_interval == wilson_interval(2, 3)
    assert result.motions_interval == bootstrap_mean_interval([2, 3, 10], seed=100)
    data = result.to_dict()
    assert "seconds" not in data["records"][0] and "wall_seconds" not in data and "workers" not in data
    json.dumps(data)  # JSON-ready


def test_summarise_needs_episodes_zero_to_n_once_each():
    with pytest.raises(ValueError, match="episodes 0..1"):
        summarise([_record(0, True, 1, "target_grasped", 1), _record(2, True, 1, "target_grasped", 1)], "p", "e", 5, 0, 0.0)
    with pytest.raises(ValueError, match="no episode"):
        summarise([], "p", "e", 5, 0, 0.0)


# --------------------------------------------------------------------------- mpg-eval
def test_mpg_eval_writes_json_only_when_asked_and_reports_end_reasons(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    argv = ["--policy", "pixel-heuristic", "--env", "MPG-Stage2-v0", "--episodes", "2", "--seed", "7"]
    assert eval_main(argv) == 0
    assert list(tmp_path.iterdir()) == []  # nothing written unasked
    out = capsys.readouterr().out
    assert "episode 0 (seed 7)" in out and "episode 1 (seed 8)" in out and "end:" in out
    assert "episodes ended by" in out and "primitives used" in out

    path = tmp_path / "sub" / "m.json"
    path.parent.mkdir()
    assert eval_main(argv + ["--json", str(path), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "episode 0" not in out and f"metrics written to {path}" in out
    data = json.loads(path.read_text())
    assert sum(data["end_reasons"].values()) == 2
    assert set(data["primitive_counts"]) == {"move", "push", "grasp"}
    assert data["primitive_counts"]["move"] == data["primitive_counts"]["push"] == 0  # Stage 2 only grasps
    assert sum(data["primitive_counts"].values()) == sum(r["motions"] for r in data["records"])
    assert [r["seed"] for r in data["records"]] == [7, 8]
    assert dict(Counter(r["end_reason"] for r in data["records"])) == data["end_reasons"]
    assert set(data["end_reasons"]) <= set(END_REASONS)
    for record in data["records"]:
        assert (record["end_reason"] == "target_grasped") == record["success"]
        # one motion record per motion, agreeing with the episode's counts
        assert len(record["steps"]) == record["motions"]
        assert Counter(m["primitive"] for m in record["steps"]) == Counter({p: n for p, n in record["primitives"].items() if n})
        assert sum(m["target_grasped"] for m in record["steps"]) == record["target_grasps"]
    assert data["success_interval"][0] <= data["task_success_rate"] <= data["success_interval"][1]


@pytest.mark.parametrize("extra, message", [(["--workers", "0"], "--workers"), (["--episodes", "0"], "--episodes")])
def test_mpg_eval_rejects_bad_counts(extra, message, capsys):
    assert eval_main(["--policy", "random", "--env", "MPG-Stage2-v0"] + extra) == 2
    assert message in capsys.readouterr().err


def test_an_episode_of_a_continuous_action_wrapper_is_recorded():
    import gymnasium as gym

    from mpg_agents.evaluation.evaluate import run_episode
    from mpg_envs.integrations.wrappers import ContinuousAction

    env = ContinuousAction(gym.make("MPG-Stage2-v0", num_objects=2, max_motions=2))

    class Corner:  # always the workspace's corner: an empty grasp
        def act(self, obs):
            return np.array([-1.0, -1.0, 0.0, 1.0], np.float32)

    record = run_episode(Corner(), env, index=0, seed=3)
    assert record.motions == 2 and not record.success
    assert record.actions == ((-1.0, -1.0, 0.0, 1.0),) * 2
    json.dumps(record.to_dict())  # the JSON record holds them
    env.close()


def test_an_episode_records_its_visual_randomization():
    """With ``visual_randomization`` on, a record carries the values drawn for its episode
    (the reset info's); without it, the JSON record has no such key."""
    import gymnasium as gym

    from mpg_agents.evaluation.evaluate import env_options_of, run_episode

    class Corner:  # the workspace's corner: an empty grasp
        def act(self, obs):
            return 0

    records = {}
    for option in (None, True):
        env = gym.make("MPG-Stage2-v0", num_objects=2, max_motions=1, visual_randomization=option)
        records[option] = run_episode(Corner(), env, index=0, seed=3)
        if option:
            assert env_options_of(env)["visual_randomization"] is True
            _, info = env.reset(seed=3)
            assert records[option].visuals == info["visual_randomization"]
        env.close()
    assert "visuals" not in records[None].to_dict()
    # mpg-eval records a track's own keywords (it makes the env by its id).
    from mpg_agents.evaluation.evaluate import registered_options

    assert registered_options("MPG-OccludedHardCamera-v0") == {"obs_mode": "camera", "visual_randomization": True}
    assert registered_options("MPG-OccludedHard-v0") == {}
    data = json.loads(json.dumps(records[True].to_dict()))
    assert data["visuals"]["seed"] == 3 and len(data["visuals"]["object_gains"]) == 2
