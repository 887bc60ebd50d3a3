"""Recorded results reproduce: episodes of committed result cells, run again with today's code,
take the recorded actions and end as recorded (success, motions, grasps, end reason).

The cells were measured on MuJoCo 3.x. MuJoCo 4 settles a seed's scene and runs each motion
differently, so there the replays are skipped (its results are recorded with their own version,
:mod:`mpg_envs.simulation.mujoco_version`).
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import pytest

import mpg_envs
from mpg_agents.evaluation.evaluate import run_episode
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_envs.simulation.mujoco_version import mujoco_major

ROOT = Path(__file__).resolve().parents[2]
TRACKS = ROOT / "benchmarks" / "results" / "tracks"
OUTCOME = ("seed", "success", "motions", "end_reason", "primitives", "grasp_attempts", "target_grasps",
           "wrong_grasps", "objects_left", "visible_fraction", "actions")

pytestmark = pytest.mark.skipif(
    mujoco_major(mujoco.__version__) != 3,
    reason=f"the cells were recorded on MuJoCo 3.x; MuJoCo {mujoco.__version__} settles the same seeds into "
    "other scenes and runs motions differently, so its episodes are its own",
)


def replay(path: Path, policy: str, indices: list[int]) -> None:
    """Run episodes ``indices`` of the cell in ``path`` with ``policy`` and compare each with its record."""
    cell = json.loads(path.read_text())
    env = mpg_envs.make(cell["env_id"], num_objects=cell["num_objects"])
    try:
        agent = make_policy(policy, env, seed=cell["seed"])
        for index in indices:
            got = run_episode(agent, env, index, cell["seed"]).to_dict()
            want = cell["records"][index]
            assert {k: json.loads(json.dumps(got[k])) for k in OUTCOME} == {k: want[k] for k in OUTCOME}, (path.name, index)
    finally:
        env.close()


def test_the_pixel_heuristic_replays_its_table1_episodes():
    # A one-grasp episode of Table I's heuristic cell (15 objects, seed 500005).
    replay(ROOT / "benchmarks/results/table1/cells/Pixel_heuristic__grasp_at_the_target_mask_15.json", "pixel-heuristic", [5])


@pytest.mark.heavy
@pytest.mark.parametrize(
    "cell, indices",
    [
        ("hard/cells/MPGNet__shipped_15.json", [0, 1]),
        ("hard/cells/MPGNet__shipped_30.json", [10]),
        ("hard-novel/cells/MPGNet__shipped_15.json", [1]),
        ("hard-camera/cells/MPGNet__shipped_15.json", [2]),
    ],
    ids=["blocks-15", "blocks-30", "unseen-15", "camera-15"],
)
def test_the_shipped_net_replays_its_held_out_episodes(cell, indices):
    # The shipped file is the weights these cells ran (colorfree_s1.safetensors, byte for byte).
    assert (ROOT / "mpg_agents/checkpoints/mpgnet_small.safetensors").read_bytes() == (
        ROOT / "benchmarks/results/fast_pipeline/colorfree_s1.safetensors"
    ).read_bytes()
    replay(TRACKS / cell, "shipped", indices)
