"""The MuJoCo version of results: recorded beside the package version, read as 3.x where a file
predates it, and never compared, pooled or tabled across major versions unless asked."""

from __future__ import annotations

import json
from types import SimpleNamespace

import mujoco
import pytest

from mpg_agents.acting.weights import checkpoint_metadata
from mpg_agents.evaluation.comparison import compare_main, compare_paired, load_eval_records
from mpg_agents.evaluation.evaluate import versions
from mpg_agents.evaluation.table_runs import merged_result
from mpg_agents.evaluation.tables import check_table_mujoco, tracks_rows, tracks_success_rows
from mpg_envs.simulation.mujoco_version import (
    MuJoCoVersionError,
    check_one_mujoco,
    mujoco_major,
    recorded_mujoco,
    running_mujoco,
)


def test_versions_are_read_by_hand():
    assert mujoco_major("3.17.0") == 3 and mujoco_major("4.0.0") == 4 and mujoco_major("3.x") == 3
    with pytest.raises(ValueError, match="starts with its major number"):
        mujoco_major("unknown")
    assert recorded_mujoco({"package": "0.2.0", "mujoco": "4.0.0"}) == "4.0.0"
    assert recorded_mujoco({"package": "0.2.0"}) == "3.x" and recorded_mujoco(None) == "3.x"  # files before the field
    assert check_one_mujoco({"a": "3.17.0", "b": "3.x"}, "x") == 3
    with pytest.raises(MuJoCoVersionError, match=r"pooling mixes MuJoCo major versions \(a on MuJoCo 3.x, b on MuJoCo 4.0.0\)"):
        check_one_mujoco({"a": "3.x", "b": "4.0.0"}, "pooling")


def test_an_evaluation_records_the_mujoco_it_ran_on():
    assert versions("MPG-OccludedHard-v0") == {"package": versions("x-v0")["package"], "env": "v0", "mujoco": mujoco.__version__}
    assert running_mujoco() == mujoco.__version__


def write_eval(path, policy, seeds, mujoco_version=None, env_id="MPG-OccludedHard-v0"):
    """An mpg-eval --json file of one-motion successes on ``seeds``, its ``versions`` naming
    ``mujoco_version`` (none: a file written before MuJoCo versions were recorded)."""
    records = [
        {"index": i, "seed": s, "success": True, "motions": 1 + s % 2, "end_reason": "target_grasped",
         "primitives": {"grasp": 1 + s % 2}, "grasp_attempts": 1 + s % 2, "target_grasps": 1, "wrong_grasps": 0,
         "objects_left": 14, "visible_fraction": 0.2}
        for i, s in enumerate(seeds)
    ]
    found = {"package": "0.2.0", "env": "v0"} | ({} if mujoco_version is None else {"mujoco": mujoco_version})
    path.write_text(json.dumps({"policy": policy, "env_id": env_id, "num_objects": 15, "seed": seeds[0],
                                "env_options": {}, "records": records, "versions": found}))
    return path


def test_pairs_across_major_versions_are_refused_unless_asked(tmp_path, capsys):
    old = write_eval(tmp_path / "old.json", "shipped", [1, 2, 3])  # no version: 3.x
    new = write_eval(tmp_path / "new.json", "shipped", [1, 2, 3], "4.0.0")
    a, b = load_eval_records([new]), load_eval_records([old])
    assert (a.mujoco, b.mujoco) == ("4.0.0", "3.x")
    with pytest.raises(MuJoCoVersionError, match="A on MuJoCo 4.0.0, B on MuJoCo 3.x.*--across-mujoco"):
        compare_paired(a, b)
    result = compare_paired(a, b, across_mujoco=True)
    assert result.across_mujoco and result.motions_difference == 0.0
    assert "MuJoCo: A on 4.0.0, B on 3.x: different major versions" in result.describe()
    assert "MuJoCo" not in compare_paired(b, b).describe()  # one version: nothing to say
    assert compare_main(["--a", str(new), "--b", str(old)]) == 2
    assert "mixes MuJoCo major versions" in capsys.readouterr().err
    assert compare_main(["--a", str(new), "--b", str(old), "--across-mujoco"]) == 0
    assert "B = shipped; MuJoCo 4.0.0 (A) and 3.x (B)" in capsys.readouterr().out


def test_seed_blocks_of_two_major_versions_are_not_pooled(tmp_path):
    first = write_eval(tmp_path / "a.json", "shipped", [1, 2], "3.17.0")
    with pytest.raises(MuJoCoVersionError, match="pooling these files mixes"):
        load_eval_records([first, write_eval(tmp_path / "b.json", "shipped", [3, 4], "4.0.0")])
    pooled = load_eval_records([first, write_eval(tmp_path / "c.json", "shipped", [3, 4])])  # 3.17.0 and unrecorded
    assert pooled.mujoco == "3.x"


def test_a_pooled_cell_keeps_its_files_mujoco_not_this_process(tmp_path):
    cell = merged_result([write_eval(tmp_path / "a.json", "shipped", [5, 6], "4.0.0")])
    assert cell.versions == {"package": "0.2.0", "env": "v0", "mujoco": "4.0.0"}
    assert merged_result([write_eval(tmp_path / "b.json", "shipped", [5, 6])]).versions["mujoco"] == "3.x"


def test_a_table_of_two_major_versions_is_refused(tmp_path):
    three = {"success": 1.0, "success_ci": [0.9, 1.0], "motions": 2.0, "motions_ci": [1.5, 2.5],
             "mispicks_per_episode": 0.0, "grasp_success_rate": 1.0, "grasp_attempts": 2, "versions": {"package": "0.2.0"}}
    four = three | {"versions": {"package": "0.2.0", "mujoco": "4.0.0"}}
    cells = {("hard", "MPGNet", 15): three, ("hard", "MPGNet", 30): four}
    for lay_out in (tracks_rows, tracks_success_rows):
        with pytest.raises(MuJoCoVersionError, match="hard MPGNet 15 on MuJoCo 3.x, hard MPGNet 30 on MuJoCo 4.0.0"):
            lay_out(["hard"], ["MPGNet"], [15, 30], cells)
    assert check_table_mujoco({("hard", "MPGNet", 15): three}) == 3
    _, body = tracks_rows(["hard"], ["MPGNet"], [15, 30], {("hard", "MPGNet", 30): four})
    assert body[0][2] == "-" and body[0][3].startswith("100%")


def test_a_checkpoint_header_records_the_mujoco_beside_the_package():
    net = SimpleNamespace(primitives=("grasp",), config=SimpleNamespace(variant="small", to_dict=lambda: {}))
    header = json.loads(checkpoint_metadata(net)["mpgnet"])
    assert header["mujoco_version"] == mujoco.__version__ and header["package_version"]
