"""benchmarks/camera_channels.py: the channel swap hands a policy the ray cast's planes, and the
paired differences are A minus B per seed."""

import gymnasium as gym
import numpy as np
import pytest

import mpg_envs  # noqa: F401


class Recorder:
    name = "recorder"

    def __init__(self):
        self.seen = []

    def reset(self):
        pass

    def act(self, obs):
        self.seen.append({k: np.array(v) for k, v in obs.items()})
        return 0


def test_a_swapped_channel_is_the_clean_ray_cast_of_the_state(benchmark_script):
    script = benchmark_script("camera_channels")
    # On a ray-cast env without randomization the clean ray cast is the observation itself.
    env = gym.make("MPG-Stage2-v0")
    obs, _ = env.reset(seed=3)
    recorder = Recorder()
    swap = script.RaycastSwap(recorder, env, ("color", "depth"))
    swap.act(obs)
    np.testing.assert_array_equal(recorder.seen[0]["color"], obs["color"])
    np.testing.assert_array_equal(recorder.seen[0]["depth"], obs["depth"])
    # What the swap replaces is what the policy sees; the rest passes through untouched.
    altered = dict(obs, color=np.zeros_like(obs["color"]), depth=np.ones_like(obs["depth"]))
    script.RaycastSwap(recorder, env, ("color",)).act(altered)
    np.testing.assert_array_equal(recorder.seen[1]["color"], obs["color"])
    np.testing.assert_array_equal(recorder.seen[1]["depth"], altered["depth"])
    np.testing.assert_array_equal(recorder.seen[1]["mask"], obs["mask"])
    script.RaycastSwap(recorder, env, ()).act(altered)
    np.testing.assert_array_equal(recorder.seen[2]["color"], altered["color"])
    swap.close()
    env.close()


def test_paired_differences_and_summary_by_hand(benchmark_script):
    script = benchmark_script("camera_channels")

    def record(seed, success, motions, pushes=0, end="success"):
        return {"seed": seed, "success": success, "motions": motions, "primitives": {"push": pushes, "grasp": 1, "move": 0}, "end_reason": end}

    a = [record(1, True, 2), record(2, True, 3), record(3, False, 10, 9, "motion_cap")]
    b = [record(1, False, 10, 9, "motion_cap"), record(2, True, 5, 4), record(3, False, 10, 9, "motion_cap")]
    diff = script.paired(a, b)
    assert diff["success_difference"] == pytest.approx(1 / 3)
    assert diff["motions_difference"] == pytest.approx((-8 - 2 + 0) / 3)
    s = script.summary(b)
    assert (s["episodes"], s["pushes"], s["motion_caps"]) == (3, 22, 2)
    assert s["success"] == pytest.approx(1 / 3) and s["motions"] == pytest.approx(25 / 3)


def test_q_star_needs_a_network_policy(benchmark_script, monkeypatch, capsys):
    script = benchmark_script("camera_channels")
    argv = ["camera_channels.py", "--env", "MPG-Stage2-v0", "--policy", "oracle", "--q-star", "0.5", "--episodes", "1"]
    monkeypatch.setattr("sys.argv", argv)
    with pytest.raises(SystemExit):
        script.main()
    assert "--policy must be an MPGNet checkpoint" in capsys.readouterr().err
