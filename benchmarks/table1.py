"""The paper's Table I on MPG-Occluded-v0, distributed on Ray.

Every (policy, object count) cell runs ``--episodes`` episodes (episode i reset with seed
``--seed + i``, so every policy meets the same scenes at a given object count) as Ray tasks:
a local Ray with ``--workers`` CPUs by default, or the cluster at ``--ray-address``. Results
are identical for any ``--workers``. Prints the table (success rate with its 95% Wilson
interval, mean motions with a 95% bootstrap interval) below the paper's rows and the wall
time, writes ``table1.json`` and ``table1.md`` to ``--out``; the last stdout line is the JSON.

The parallelism printed is task seconds over wall seconds (how many tasks ran at once); it is
not a speed-up, since tasks slow down when they share cores. ``--speedup`` measures the
speed-up: it runs every cell again in one process (``--workers 1``), prints serial wall time
over parallel wall time, and checks the two runs gave the same records.

    python benchmarks/table1.py --policies oracle grasp-only random shipped [CKPT ...] \\
        --episodes 50 --objects 15 30 --seed 0 --workers 2 [--ray-address ADDR] [--out DIR] [--speedup]
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from mpg_agents.baselines import BUILTIN  # noqa: E402
from mpg_agents.parallel import EvalJob, evaluate_jobs  # noqa: E402
from mpg_agents.table1 import ENV_ID, format_markdown, format_text, paper_json, rows_json, table_rows  # noqa: E402


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="+", default=["oracle", "grasp-only", "random", "shipped"], help=f"{' | '.join(BUILTIN)} or checkpoint paths")
    parser.add_argument("--episodes", type=int, default=50, help="per cell (paper: 50)")
    parser.add_argument("--objects", type=int, nargs="+", default=[15, 30])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, help="CPUs of a local Ray and chunks per cell (1: in this process, no Ray); default 2, or the cluster's CPUs with --ray-address")
    parser.add_argument("--ray-address", help="join this Ray cluster instead of starting a local one")
    parser.add_argument("--backend", choices=("ray", "processes"), default="ray", help="ray (default; local or --ray-address) or processes (a local process pool, no Ray start-up)")
    parser.add_argument("--max-motions", type=int, help="override the env's motion cap (paper: 10); for quick checks")
    parser.add_argument("--out", default="runs/table1", help="folder for table1.json and table1.md")
    parser.add_argument("--quiet", action="store_true", help="no line per finished episode")
    parser.add_argument("--speedup", action="store_true", help="run the cells again with --workers 1: speed-up and equality")
    args = parser.parse_args(argv)
    if args.workers is None and args.ray_address is None:
        args.workers = 2
    if args.episodes < 1 or (args.workers is not None and args.workers < 1):
        parser.error(f"--episodes and --workers must be >= 1, got {args.episodes} and {args.workers}")
    for policy in args.policies:
        if policy not in BUILTIN and not Path(policy).is_file():
            parser.error(f"--policies: {policy!r} is neither one of {BUILTIN} nor a checkpoint file")
    return args


def measure_speedup(jobs: list[EvalJob], results: list, wall_seconds: float) -> dict:
    """Run ``jobs`` again in this process: serial wall time, speed-up, same records or not."""
    print("--speedup: the same cells with --workers 1 ...", flush=True)
    serial, timing = evaluate_jobs(jobs, 1)
    identical = [a.to_dict() for a in serial] == [b.to_dict() for b in results]
    speedup = timing.wall_seconds / wall_seconds
    print(f"workers 1: wall time {timing.wall_seconds:.1f} s; speed-up {speedup:.2f}x; records identical: {identical}")
    return {"serial_wall_seconds": round(timing.wall_seconds, 2), "speedup": round(speedup, 3), "identical_to_serial": identical}


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    env_kwargs = () if args.max_motions is None else (("max_motions", args.max_motions),)
    cells = [(policy, n) for policy in args.policies for n in args.objects]
    jobs = [EvalJob(policy, ENV_ID, args.episodes, args.seed, n, env_kwargs=env_kwargs) for policy, n in cells]

    def on_record(job: EvalJob, record) -> None:
        print(f"  [{job.policy}, {job.num_objects} obj.] {record.describe()}", flush=True)

    print(f"Table I: {len(cells)} cells x {args.episodes} episodes on {ENV_ID}, seeds {args.seed}..{args.seed + args.episodes - 1}, workers: {args.workers or 'the cluster CPUs'}", flush=True)
    results, timing = evaluate_jobs(jobs, args.workers, args.ray_address, on_record=None if args.quiet else on_record, backend=args.backend)
    by_cell = dict(zip(cells, results))
    header, body, paper_rows = table_rows(args.policies, args.objects, by_cell)
    print()
    print(format_text(header, body, paper_rows))
    print("intervals: 95% (Wilson for success, percentile bootstrap of the mean for motions)")
    print(
        f"wall time {timing.wall_seconds:.1f} s (+ {timing.startup_seconds:.1f} s starting Ray), "
        f"task time {timing.task_seconds:.1f} s over {timing.tasks} tasks on {timing.workers} worker(s): "
        f"parallelism {timing.parallelism:.2f} (task seconds / wall seconds)"
    )
    report = {
        "env": ENV_ID,
        "episodes": args.episodes,
        "objects": args.objects,
        "seed": args.seed,
        "max_motions": args.max_motions,
        "rows": rows_json(by_cell),
        "paper": paper_json(args.objects),
        "workers": timing.workers,
        "wall_seconds": round(timing.wall_seconds, 2),
        "startup_seconds": round(timing.startup_seconds, 2),
        "task_seconds": round(timing.task_seconds, 2),
        "parallelism": round(timing.parallelism, 3),
    }
    if args.speedup:
        report.update(measure_speedup(jobs, results, timing.wall_seconds))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "table1.json").write_text(json.dumps(report, indent=1))
    (out / "table1.md").write_text(format_markdown(header, body) + "\n")
    print(f"written: {(out / 'table1.json').resolve()} and {(out / 'table1.md').resolve()}")
    print(json.dumps(report))
    return report


if __name__ == "__main__":
    main()
