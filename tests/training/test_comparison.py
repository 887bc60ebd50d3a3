"""Paired comparison of two policies' eval records (mpg_agents.evaluation.comparison, benchmarks/compare_evals.py)."""

from __future__ import annotations

import json

import pytest

from mpg_agents.evaluation.comparison import compare_main, compare_paired, load_eval_records


def write_eval(path, policy, episodes, env_id="MPG-Occluded-v0", num_objects=15, primitives=None):
    """An mpg-eval --json file with the fields the comparison reads: (seed, success, motions) per
    episode, and each episode's primitive counts when ``primitives`` (one dict per episode) is given."""
    records = [{"seed": s, "success": ok, "motions": m} for s, ok, m in episodes]
    for record, counts in zip(records, primitives or []):
        record["primitives"] = counts
    path.write_text(json.dumps({"policy": policy, "env_id": env_id, "num_objects": num_objects, "records": records}))
    return path


def test_paired_differences_on_shared_seeds_by_hand(tmp_path):
    a = load_eval_records([
        write_eval(tmp_path / "a1.json", "A", [(1, True, 2), (2, True, 3)]),
        write_eval(tmp_path / "a2.json", "A", [(3, False, 10), (9, True, 1)]),  # seed 9: B never played it
    ])
    b = load_eval_records([write_eval(tmp_path / "b.json", "B", [(1, True, 4), (2, False, 10), (3, True, 4)])])
    result = compare_paired(a, b)
    assert result.episodes == 3
    assert result.success_a == pytest.approx(2 / 3) and result.success_b == pytest.approx(2 / 3)
    assert result.success_difference == pytest.approx(0.0)
    # A - B motions per pair: -2, -7, +6 -> mean -1.
    assert (result.motions_a, result.motions_b, result.motions_difference) == pytest.approx((5.0, 6.0, -1.0))
    assert (result.fewer_motions_a, result.fewer_motions_b) == (2, 1)
    lo, hi = result.motions_interval
    assert -7 <= lo <= -1 <= hi <= 6
    assert result == compare_paired(a, b)  # seeded bootstrap
    text = result.describe("MPGNet", "GO")
    assert "3 paired episodes" in text and "difference -1.00" in text and "MPGNet in 2 episodes, GO in 1" in text


def test_identical_policies_differ_by_a_point_interval(tmp_path):
    eps = [(s, s % 2 == 0, 1 + s % 4) for s in range(10)]
    a = load_eval_records([write_eval(tmp_path / "a.json", "A", eps)])
    b = load_eval_records([write_eval(tmp_path / "b.json", "B", eps)])
    result = compare_paired(a, b)
    assert result.motions_interval == (0.0, 0.0) and result.success_interval == (0.0, 0.0)


def test_records_of_other_cells_or_repeated_seeds_are_refused(tmp_path):
    a = write_eval(tmp_path / "a.json", "A", [(1, True, 2), (2, True, 2)])
    with pytest.raises(ValueError, match="one policy and cell per side"):
        load_eval_records([a, write_eval(tmp_path / "c.json", "A", [(3, True, 2)], num_objects=30)])
    with pytest.raises(ValueError, match="episode seed 1 appears twice"):
        load_eval_records([a, write_eval(tmp_path / "d.json", "A", [(1, True, 2)])])
    with pytest.raises(ValueError, match="no eval JSON file"):
        load_eval_records([])
    b30 = load_eval_records([write_eval(tmp_path / "b.json", "B", [(1, True, 2), (2, True, 2)], num_objects=30)])
    with pytest.raises(ValueError, match="different cells"):
        compare_paired(load_eval_records([a]), b30)
    few = load_eval_records([write_eval(tmp_path / "e.json", "B", [(2, True, 2), (7, True, 1)])])
    with pytest.raises(ValueError, match="share 1 episode seeds"):
        compare_paired(load_eval_records([a]), few)


def test_the_shipped_policy_by_name_or_by_file_is_one_policy(tmp_path):
    # mpg-eval --policy shipped names it "shipped:<file>"; --policy <path to it> names it "<file>".
    by_name = write_eval(tmp_path / "a.json", "shipped:mpgnet_small.safetensors", [(1, True, 2)])
    by_file = write_eval(tmp_path / "b.json", "mpgnet_small.safetensors", [(2, False, 10)])
    records = load_eval_records([by_name, by_file])
    assert records.policy == "mpgnet_small.safetensors" and sorted(records.by_seed) == [1, 2]


def test_the_command_line_prints_a_minus_b(tmp_path, capsys):
    a = write_eval(tmp_path / "a.json", "A", [(1, True, 2), (2, True, 3)])
    b = write_eval(tmp_path / "b.json", "B", [(1, True, 3), (2, True, 5)])
    assert compare_main(["--a", str(a), "--b", str(b), "--names", "X,Y"]) == 0
    out = capsys.readouterr().out
    assert "A = X, B = Y" in out and "difference -1.50 [-2.00, -1.00]" in out


def test_a_case_set_evaluation_is_refused_by_name(tmp_path):
    """A ``mpg-eval --cases`` file keys its runs by case: a clear error, not a TypeError."""
    path = tmp_path / "cases.json"
    path.write_text(json.dumps({"policy": "A", "env_id": "MPG-Occluded-v0", "records": {"ring-1": [{"seed": 4000, "success": True, "motions": 2}]}}))
    with pytest.raises(ValueError, match=r"cases.json is not an episode evaluation.*per case"):
        load_eval_records([path])
    assert compare_main(["--a", str(path), "--b", str(path)]) == 2


def test_the_motions_difference_splits_by_primitive(tmp_path):
    def write(name, policy, prims):
        episodes = [(seed, True, sum(p.values())) for seed, p in enumerate(prims)]
        return load_eval_records([write_eval(tmp_path / name, policy, episodes, primitives=prims)])

    # Episode 0: A pushes twice where B moves once; episode 1: A grasps twice where B grasps once.
    a = write("a.json", "A", [{"push": 2, "grasp": 1}, {"grasp": 2, "move": 0, "push": 0}])
    b = write("b.json", "B", [{"move": 1, "grasp": 1}, {"grasp": 1}])
    result = compare_paired(a, b)
    assert result.primitive_differences == pytest.approx({"move": -0.5, "push": 1.0, "grasp": 0.5})
    assert sum(result.primitive_differences.values()) == pytest.approx(result.motions_difference)
    assert "motions by primitive, difference per episode: move -0.50, push +1.00, grasp +0.50" in result.describe()
    # Records without primitive counts (older files) leave the split out.
    assert compare_paired(a, load_eval_records([write_eval(tmp_path / "c.json", "C", [(0, True, 3), (1, True, 2)])])).primitive_differences == {}


def test_envs_that_differ_only_in_naming_the_target_pair_and_others_do_not():
    from mpg_agents.evaluation.comparison import same_scenes

    assert same_scenes("MPG-OccludedHard-v0", "MPG-OccludedHardVisible-v0")
    assert same_scenes("MPG-OccludedHardExemplar-v0", "MPG-OccludedHard-v0")
    assert same_scenes("MPG-OccludedHardCameraExemplar-v0", "MPG-OccludedHardCamera-v0")
    assert same_scenes("MPG-OccludedHardNovelExemplar-v0", "MPG-OccludedHardNovel-v0")
    assert not same_scenes("MPG-OccludedHard-v0", "MPG-OccludedHardNovel-v0")  # other objects
    assert not same_scenes("MPG-OccludedHardCameraExemplar-v0", "MPG-OccludedHard-v0")  # camera images
    assert not same_scenes("MPG-OccludedHard-v0", "MPG-Nowhere-v0") and same_scenes("MPG-Nowhere-v0", "MPG-Nowhere-v0")
