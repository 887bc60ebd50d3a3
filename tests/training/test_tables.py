"""The distributed table harness: same records for any number of workers, the tables (Table I and
the hard track), the policy file, the metrics that count mis-picks and visibility."""

from __future__ import annotations

import json

import pytest

from mpg_agents.evaluation.eval_result import EpisodeRecord
from mpg_agents.evaluation.evaluate import summarise
from mpg_agents.evaluation.eval_runner import EvalJob, chunk_indices, evaluate_jobs, start_ray
from mpg_agents.evaluation.table_runs import PolicySpec, read_policy_specs, run_table
from mpg_agents.evaluation.tables import PAPER_ROWS, format_markdown, format_text, paper_json, rows_json, table_rows


@pytest.fixture(scope="module")
def ray_two_cpus():
    """One local Ray for the module (starting it costs seconds); evaluate_jobs reuses it."""
    ray = start_ray(workers=2)
    yield ray
    ray.shutdown()


def test_chunks_deal_every_index_once_round_robin():
    assert chunk_indices(5, 2) == [[0, 2, 4], [1, 3]]
    assert chunk_indices(2, 4) == [[0], [1]]
    assert sorted(i for c in chunk_indices(50, 3) for i in c) == list(range(50))
    with pytest.raises(ValueError, match="chunks"):
        chunk_indices(3, 0)


def test_jobs_and_workers_are_checked():
    with pytest.raises(ValueError, match="episodes"):
        EvalJob("random", episodes=0)
    with pytest.raises(ValueError, match="workers"):
        evaluate_jobs([EvalJob("random", episodes=1)], workers=0)


def test_two_workers_give_the_records_of_one(ray_two_cpus):
    # cheap episodes: Stage 2 has 5 objects and only grasps; random acts at most 3 times
    job = EvalJob("random", "MPG-Stage2-v0", episodes=3, seed=11, env_kwargs=(("max_motions", 3),))
    (one,), serial_timing = evaluate_jobs([job], workers=1)
    (two,), timing = evaluate_jobs([job], workers=2)
    assert serial_timing.workers == 1 and timing.workers == 2 and timing.tasks == 2
    assert one.records == two.records and one.to_dict() == two.to_dict()
    assert [r.seed for r in two.records] == [11, 12, 13] and sum(two.end_reasons.values()) == 3
    # seeded by episode: episode 2 is its chunk's 2nd on two workers, the 3rd on one, same actions
    assert len({r.actions for r in one.records}) == 3 and all(len(r.actions) == r.motions for r in one.records)
    assert one.primitive_counts["grasp"] == sum(r.motions for r in one.records)


def test_a_local_process_pool_gives_the_records_of_one():
    job = EvalJob("random", "MPG-Stage2-v0", episodes=3, seed=11, env_kwargs=(("max_motions", 2),))
    (one,), _ = evaluate_jobs([job], workers=1)
    (pool,), timing = evaluate_jobs([job], workers=2, backend="processes")
    assert timing.workers == 2 and timing.tasks == 2
    assert one.records == pool.records
    with pytest.raises(ValueError, match="backend"):
        evaluate_jobs([job], workers=2, backend="threads")
    with pytest.raises(ValueError, match="address"):
        evaluate_jobs([job], workers=2, ray_address="auto", backend="processes")


def _result(policy: str, successes: int, motions: list[int]) -> object:
    records = [
        EpisodeRecord(i, i, i < successes, m, "target_grasped" if i < successes else "motion_cap", {"move": 0, "push": 0, "grasp": m}, m, int(i < successes), 0, 10)
        for i, m in enumerate(motions)
    ]
    return summarise(records, policy, "MPG-Occluded-v0", 15, 0, 1.0)


def test_table_has_the_papers_rows_then_the_measured_cells_with_intervals():
    cells = {("oracle", 15): _result("oracle", 4, [1, 2, 2, 3, 10]), ("oracle", 30): _result("oracle", 5, [2, 2, 3, 3, 4])}
    header, body, paper_rows = table_rows(["oracle"], [15, 30], cells)
    assert header == ["Method", "success, 15 obj.", "success, 30 obj.", "motions, 15 obj.", "motions, 30 obj."]
    assert paper_rows == len(PAPER_ROWS) and body[paper_rows - 1] == ["MPGNet (paper)", "92%", "84%", "2.85", "3.74"]
    measured = body[paper_rows]
    lo, hi = cells[("oracle", 15)].success_interval
    assert measured[0] == "oracle" and measured[1] == f"80% [{100 * lo:.0f}, {100 * hi:.0f}]"
    assert measured[3].startswith("3.60 [") and measured[2].startswith("100% [")
    text, markdown = format_text(header, body, paper_rows), format_markdown(header, body)
    assert "Grasping-Only (paper)" in text and len(markdown.splitlines()) == 2 + len(body)
    rows = rows_json(cells)
    assert rows["oracle"]["15"]["success"] == 0.8 and rows["oracle"]["30"]["motions"] == pytest.approx(2.8)
    assert rows["oracle"]["15"]["end_reasons"] == {"motion_cap": 1, "target_grasped": 4}
    assert paper_json([15])["Grasping-Only"] == {"15": {"success": 0.26, "motions": 6.46}}


def test_a_table_run_gives_every_cell_with_its_label_settings_and_the_mis_pick_columns(ray_two_cpus, tmp_path):
    specs = [PolicySpec("Heuristic", "pixel-heuristic"), PolicySpec("Random, 1 motion", "random")]
    report, text, markdown = run_table("hard", specs, [15], 2, 500000, workers=2, env_options={"max_motions": 1})
    assert set(report["rows"]) == {"Heuristic", "Random, 1 motion"} and report["env"] == "MPG-OccludedHard-v0"
    cell = report["rows"]["Heuristic"]["15"]
    assert cell["episodes"] == 2 and cell["motions"] == 1.0 and cell["env_options"] == {"max_motions": 1}
    assert cell["clean_success"] == cell["success"]  # strict retrieval: every success is clean
    assert sum(c["episodes"] for c in cell["success_by_visibility"].values()) == 2
    assert set(cell["success_by_visibility"]) <= {"0-0.1", "0.1-0.3"}  # the hard track's targets
    assert cell["versions"]["env"] == "v0" and cell["versions"]["package"]
    assert "mis-picks/ep., 15 obj." in text and "(paper)" not in text and "| Heuristic |" in markdown
    with pytest.raises(ValueError, match="unknown track"):
        run_table("easy", specs, [15], 1, 0, workers=1)
    with pytest.raises(ValueError, match="labels must differ"):
        run_table("hard", [specs[0], specs[0]], [15], 1, 0, workers=1)


def test_a_policy_file_gives_labels_and_settings(tmp_path):
    path = tmp_path / "policies.toml"
    path.write_text('[[policy]]\nlabel = "GO"\npolicy = "x.safetensors"\ngrasp_fingers = "clear"\n[[policy]]\nlabel = "Oracle"\npolicy = "oracle"\n')
    assert read_policy_specs(path) == [PolicySpec("GO", "x.safetensors", (("grasp_fingers", "clear"),)), PolicySpec("Oracle", "oracle")]
    path.write_text('[[policy]]\nlabel = "no policy"\n')
    with pytest.raises(ValueError, match="entry 0 needs"):
        read_policy_specs(path)
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    specs = read_policy_specs(root / "benchmarks" / "tables.toml")
    assert len(specs) == 20 and len({s.label for s in specs}) == 20  # the shipped net and the same config on clean heightmaps (seeds 1, 0) among them
    from mpg_agents.evaluation.policy_zoo import is_builtin

    # Every row is a built-in policy or a checkpoint that is in the repository.
    assert all(is_builtin(s.policy) or (root / s.policy).is_file() for s in specs)


def test_mis_picks_and_visibility_bands_are_counted_per_episode():
    records = [
        EpisodeRecord(0, 0, True, 2, "target_grasped", {"move": 0, "push": 0, "grasp": 2}, 2, 1, 1, 10, visible_fraction=0.05),
        EpisodeRecord(1, 1, True, 1, "target_grasped", {"move": 0, "push": 0, "grasp": 1}, 1, 1, 0, 10, visible_fraction=0.2),
        EpisodeRecord(2, 2, False, 1, "wrong_object", {"move": 0, "push": 0, "grasp": 1}, 1, 0, 1, 10, visible_fraction=0.25),
        EpisodeRecord(3, 3, True, 3, "target_grasped", {"move": 1, "push": 1, "grasp": 1}, 1, 1, 0, 10, visible_fraction=0.9),
    ]
    result = summarise(records, "p", "MPG-Occluded-v0", 15, 0, 1.0)
    assert result.task_success_rate == 0.75 and result.clean_success_rate == 0.5 and result.mispicks_per_episode == 0.5
    assert result.grasp_success_rate == 3 / 5
    by_band = result.success_by_visibility
    assert {band: (c["successes"], c["episodes"]) for band, c in by_band.items()} == {"0-0.1": (1, 1), "0.1-0.3": (1, 2), "0.6-1": (1, 1)}
    assert by_band["0.1-0.3"]["interval"][0] < 0.5 < by_band["0.1-0.3"]["interval"][1]
    assert "without a mis-pick" in result.table() and "0.1-0.3: 1/2" in result.table()


def test_mpg_eval_json_is_the_same_for_one_and_two_workers_and_a_cluster(ray_two_cpus, tmp_path):
    from mpg_agents.cli import eval_main

    argv = ["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "2", "--seed", "3", "--quiet"]
    # the running Ray stands in for a cluster: without --workers, one chunk per cluster CPU
    runs = {"w1": ["--workers", "1"], "w2": ["--workers", "2"], "cluster": ["--ray-address", "auto"]}
    for name, extra in runs.items():
        assert eval_main(argv + extra + ["--json", str(tmp_path / f"{name}.json")]) == 0
    texts = {(tmp_path / f"{name}.json").read_bytes() for name in runs}
    assert len(texts) == 1


def test_a_table_from_seed_blocks_pools_their_episodes(tmp_path):
    from mpg_agents.evaluation.table_runs import table_from_evals

    def block(start: int, successes: list[bool]) -> str:
        records = [
            EpisodeRecord(i, start + i, ok, 1, "target_grasped" if ok else "wrong_object", {"move": 0, "push": 0, "grasp": 1}, 1, int(ok), int(not ok), 29, visible_fraction=0.05)
            for i, ok in enumerate(successes)
        ]
        path = tmp_path / f"b{start}.json"
        path.write_text(json.dumps(summarise(records, "oracle", "MPG-OccludedHard-v0", 30, start, 1.0).to_dict()))
        return str(path)

    report, text, _ = table_from_evals("hard", {"Oracle": [block(500000, [True, True]), block(500010, [True, False])]}, 30)
    cell = report["rows"]["Oracle"]["30"]
    assert cell["episodes"] == 4 and cell["success"] == 0.75 and cell["mispicks_per_episode"] == 0.25
    assert report["episodes"] == {"Oracle": 4} and "Oracle" in text
    with pytest.raises(ValueError, match="not MPG-OccludedHard-v0 with 15"):
        table_from_evals("hard", {"Oracle": [block(500020, [True])]}, 15)
