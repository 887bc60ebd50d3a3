"""The distributed Table I harness: same records for any number of workers, the table, the benchmark."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

from mpg_agents.evaluate import EpisodeRecord, summarise
from mpg_agents.parallel import EvalJob, chunk_indices, evaluate_jobs, start_ray
from mpg_agents.table1 import PAPER_ROWS, format_markdown, format_text, paper_json, rows_json, table_rows

BENCHMARK = Path(__file__).resolve().parents[2] / "benchmarks" / "table1.py"


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


def test_benchmark_prints_the_table_and_ends_with_its_json(ray_two_cpus, tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("table1_benchmark", BENCHMARK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    argv = ["--policies", "grasp-only", "--episodes", "2", "--objects", "15", "--max-motions", "1", "--workers", "2", "--out", str(tmp_path), "--speedup"]
    report = module.main(argv)
    lines = capsys.readouterr().out.strip().splitlines()
    assert json.loads(lines[-1]) == json.loads((tmp_path / "table1.json").read_text()) == report
    cell = report["rows"]["grasp-only"]["15"]
    assert cell["episodes"] == 2 and 0.0 <= cell["success"] <= 1.0 and cell["motions"] == 1.0
    assert cell["success_ci"][0] <= cell["success"] <= cell["success_ci"][1]
    assert report["identical_to_serial"] is True and report["speedup"] > 0 and report["workers"] == 2
    assert any("MPGNet (paper)" in line for line in lines) and any("parallelism" in line for line in lines)
    assert "| grasp-only |" in (tmp_path / "table1.md").read_text()


def test_mpg_eval_json_is_the_same_for_one_and_two_workers_and_a_cluster(ray_two_cpus, tmp_path):
    from mpg_agents.cli import eval_main

    argv = ["--policy", "random", "--env", "MPG-Stage2-v0", "--episodes", "2", "--seed", "3", "--quiet"]
    # the running Ray stands in for a cluster: without --workers, one chunk per cluster CPU
    runs = {"w1": ["--workers", "1"], "w2": ["--workers", "2"], "cluster": ["--ray-address", "auto"]}
    for name, extra in runs.items():
        assert eval_main(argv + extra + ["--json", str(tmp_path / f"{name}.json")]) == 0
    texts = {(tmp_path / f"{name}.json").read_bytes() for name in runs}
    assert len(texts) == 1
