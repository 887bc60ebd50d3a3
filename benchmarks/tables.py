"""The results tables (the paper's Table I, the hard tracks), distributed on Ray.

Every (policy, object count) cell runs ``--episodes`` episodes (episode i reset with seed
``--seed + i``, so every policy meets the same scenes at a given object count) as Ray tasks:
a local Ray with ``--workers`` CPUs by default, or the cluster at ``--ray-address``, or a
local process pool (``--backend processes``). Results are identical for any ``--workers``.
Prints the table (rates with their 95% Wilson intervals, mean motions with a 95% bootstrap
interval) and the wall time, writes ``<track>.json`` and ``<track>.md`` to ``--out`` and every
cell's episodes to ``--out/cells/`` (``mpg-eval --json``'s format, for
``benchmarks/compare_evals.py``); the last stdout line is the JSON.

The parallelism printed is task seconds over wall seconds (how many tasks ran at once); it is
not a speed-up, since tasks slow down when they share cores. ``--speedup`` measures the
speed-up: it runs every cell again in one process, prints serial wall time over parallel wall
time, and checks the two runs gave the same records.

    python benchmarks/tables.py --track hard --policy-file benchmarks/tables.toml \\
        --episodes 100 --objects 15 30 --seed 500000 --workers 2 [--backend processes] [--out DIR]
    python benchmarks/tables.py --track table1 --policies oracle pixel-heuristic random shipped [CKPT ...]
    python benchmarks/tables.py --track hard --objects 30 --from-evals "Oracle=runs/hard30/oracle_*.json" ...

``--from-evals LABEL=GLOB ...`` runs nothing: it makes the table of one object count from
``mpg-eval --json`` files run in seed blocks (one row per label, its blocks pooled).

``--tracks TRACK ...`` makes the track table, one table over the hard tracks (blocks, unseen
shapes, camera images; :mod:`mpg_agents.evaluation.track_table`): each cell that ``--out``
lacks runs alone and is written to ``OUT/<track>/cells/`` as soon as it ends (run the command
again to resume), cells of earlier runs are taken from ``--reuse``'s file, and
``OUT/tracks.{json,md}`` hold the table. ``--run-policies`` runs only the cells of those
policies (``oracle``, ``shipped``, a checkpoint path as the policy file gives it), ``--no-run``
none: the table then shows the cells recorded so far, a cell not run is ``-``.
``--block-episodes K`` runs each missing cell as blocks of K seeds kept as they end
(``<cell>.blocks/``), for cells longer than a sitting.

    python benchmarks/tables.py --tracks hard hard-novel hard-camera --policy-file benchmarks/tracks.toml \
        --reuse benchmarks/results/tracks/reused.toml --episodes 100 --objects 15 30 --seed 500000 \
        --out benchmarks/results/tracks --workers 16 --backend processes
"""

from __future__ import annotations

import argparse
import glob
import json
import os
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

from mpg_agents.evaluation.env_options import parse_env_options  # noqa: E402
from mpg_agents.evaluation.policy_zoo import BUILTIN, is_builtin  # noqa: E402
from mpg_agents.evaluation.reused_cells import read_reused  # noqa: E402
from mpg_agents.evaluation.table_runs import PolicySpec, read_policy_specs, run_table, table_from_evals  # noqa: E402
from mpg_agents.evaluation.tables import TABLE_TRACKS  # noqa: E402
from mpg_agents.evaluation.track_cells import CellRequest, cell_file_name  # noqa: E402
from mpg_agents.evaluation.track_table import make_track_table  # noqa: E402

STRICT_TRACKS = tuple(name for name, track in TABLE_TRACKS.items() if track.strict_columns)


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--track", choices=tuple(TABLE_TRACKS), default="table1", help="; ".join(f"{name}: {t.env_id}" for name, t in TABLE_TRACKS.items()))
    parser.add_argument("--tracks", nargs="+", choices=STRICT_TRACKS, help="the track table over these tracks, cell by cell in OUT/<track>/cells/ (resumes)")
    parser.add_argument("--reuse", help="with --tracks: a TOML file of [[cell]] entries recorded by earlier runs")
    parser.add_argument("--run-policies", nargs="+", metavar="POLICY", help="with --tracks: run only these policies' missing cells")
    parser.add_argument(
        "--block-episodes", type=int, metavar="K",
        help="with --tracks: run each missing cell as blocks of K seeds, each kept as it ends (a stopped cell resumes at its first missing block)",
    )
    parser.add_argument("--no-run", action="store_true", help="with --tracks: run nothing, make the table of the cells recorded")
    parser.add_argument("--policies", nargs="+", help=f"{' | '.join(BUILTIN)} or checkpoint paths (default: oracle pixel-heuristic random shipped)")
    parser.add_argument("--policy-file", help="a TOML file of [[policy]] entries (label, policy, settings) instead of --policies")
    parser.add_argument("--episodes", type=int, default=100, help="per cell")
    parser.add_argument("--objects", type=int, nargs="+", default=[15, 30])
    parser.add_argument("--seed", type=int, default=500000, help="first episode seed (500000 on: the held-out test scenes)")
    parser.add_argument("--env-option", action="append", metavar="KEY=VALUE", help="an env keyword for every cell (repeatable)")
    parser.add_argument("--workers", type=int, help="CPUs of a local Ray and chunks per cell (1: in this process); default 2, or the cluster's CPUs with --ray-address")
    parser.add_argument("--ray-address", help="join this Ray cluster instead of starting a local one")
    parser.add_argument("--backend", choices=("ray", "processes"), default="ray", help="ray (default; local or --ray-address) or processes (a local process pool, no Ray start-up)")
    parser.add_argument("--out", default="runs/tables", help="folder for <track>.json and <track>.md")
    parser.add_argument("--quiet", action="store_true", help="no line per finished episode")
    parser.add_argument("--speedup", action="store_true", help="run the cells again with --workers 1: speed-up and equality")
    parser.add_argument("--from-evals", nargs="+", metavar="LABEL=GLOB", help="run nothing: the table of one --objects count from mpg-eval --json files")
    args = parser.parse_args(argv)
    if args.from_evals:
        if len(args.objects) != 1:
            parser.error("--from-evals makes the table of one object count: give one --objects")
        args.cells = {}
        for item in args.from_evals:
            label, sep, pattern = item.partition("=")
            files = sorted(glob.glob(pattern))
            if not sep or not files:
                parser.error(f"--from-evals {item!r}: expected LABEL=GLOB matching mpg-eval JSON files")
            args.cells[label] = files
        return args
    if args.workers is None and args.ray_address is None:
        args.workers = 2
    if args.episodes < 1 or (args.workers is not None and args.workers < 1):
        parser.error(f"--episodes and --workers must be >= 1, got {args.episodes} and {args.workers}")
    if args.policies and args.policy_file:
        parser.error("give --policies or --policy-file, not both")
    if not args.tracks and (args.reuse or args.run_policies or args.no_run or args.block_episodes):
        parser.error("--reuse, --run-policies, --no-run and --block-episodes go with --tracks")
    if args.block_episodes is not None and args.block_episodes < 1:
        parser.error(f"--block-episodes must be >= 1, got {args.block_episodes}")
    if args.tracks and args.speedup:
        parser.error("--speedup measures a --track run, not --tracks")
    try:
        args.specs = read_policy_specs(args.policy_file) if args.policy_file else [
            PolicySpec(p, p) for p in (args.policies or ["oracle", "pixel-heuristic", "random", "shipped"])
        ]
        args.env_options = parse_env_options(args.env_option)
    except ValueError as exc:
        parser.error(str(exc))
    for spec in args.specs:
        if not is_builtin(spec.policy) and not Path(spec.policy).is_file():
            parser.error(f"policy {spec.label!r}: {spec.policy!r} is neither one of {BUILTIN} nor a checkpoint file")
    if args.run_policies:
        unknown = set(args.run_policies) - {spec.policy for spec in args.specs}
        if unknown:
            parser.error(f"--run-policies {sorted(unknown)}: not a policy of the table; its policies: {[s.policy for s in args.specs]}")
    try:
        args.reused = read_reused(args.reuse) if args.reuse else {}
    except ValueError as exc:
        parser.error(str(exc))
    return args


def _write(out: Path, name: str, report: dict, markdown: str) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(report, indent=1))
    (out / f"{name}.md").write_text(markdown + "\n")
    print(f"written: {(out / f'{name}.json').resolve()} and {(out / f'{name}.md').resolve()}")


def track_table_main(args: argparse.Namespace) -> dict:
    """``--tracks``: the track table, cell by cell."""

    def run(request: CellRequest) -> bool:
        if args.no_run or (args.run_policies and request.spec.policy not in args.run_policies):
            return False
        print(f"running {request.track}, {request.spec.label}, {request.objects} obj.: {request.episodes} episodes from seed {request.seed} ...", flush=True)
        return True

    def on_cell(request: CellRequest, how: str, seconds: float) -> None:
        took = f" in {seconds:.0f} s wall on {args.workers} worker(s)" if how == "ran" else ""
        print(f"  {request.track}, {request.spec.label}, {request.objects} obj.: {how}{took}", flush=True)

    def on_record(job, record) -> None:
        print(f"    {record.describe()}", flush=True)

    report, markdown = make_track_table(
        args.tracks, args.specs, args.objects, args.episodes, args.seed, args.out, args.reused, args.env_options,
        run, args.workers, args.ray_address, args.backend, on_cell, None if args.quiet else on_record, args.block_episodes,
    )
    print()
    print(markdown)
    if report["missing"]:
        print(f"{len(report['missing'])} cell(s) not run (listed in tracks.json's 'missing')")
    _write(Path(args.out), "tracks", report, markdown)
    return report


def main(argv: list[str] | None = None) -> dict:
    args = parse_args(argv)
    if args.tracks:
        return track_table_main(args)
    if args.from_evals:
        report, text, markdown = table_from_evals(args.track, args.cells, args.objects[0])
        print(text)
        _write(Path(args.out), f"{args.track}_{args.objects[0]}", report, markdown)
        return report

    def on_record(job, record) -> None:
        print(f"  [{Path(job.policy).name}, {job.num_objects} obj.] {record.describe()}", flush=True)

    env_id = TABLE_TRACKS[args.track].env_id
    print(f"{args.track}: {len(args.specs) * len(args.objects)} cells x {args.episodes} episodes on {env_id}, seeds {args.seed}..{args.seed + args.episodes - 1}", flush=True)
    report, text, markdown = run_table(
        args.track, args.specs, args.objects, args.episodes, args.seed, args.workers, args.ray_address,
        args.backend, args.env_options, on_record=None if args.quiet else on_record,
    )
    print()
    print(text)
    print("intervals: 95% (Wilson for rates, percentile bootstrap of the mean for motions)")
    print(f"wall time {report['wall_seconds']:.1f} s (+ {report['startup_seconds']:.1f} s start-up), task time {report['task_seconds']:.1f} s "
          f"on {report['workers']} worker(s): parallelism {report['parallelism']:.2f} (task seconds / wall seconds)")
    if args.speedup:
        print("--speedup: the same cells with --workers 1 ...", flush=True)
        serial, _, _ = run_table(args.track, args.specs, args.objects, args.episodes, args.seed, 1, env_options=args.env_options)
        report["identical_to_serial"] = serial["rows"] == report["rows"]
        report["serial_wall_seconds"] = serial["wall_seconds"]
        report["speedup"] = round(serial["wall_seconds"] / report["wall_seconds"], 3)
        print(f"workers 1: wall time {serial['wall_seconds']:.1f} s; speed-up {report['speedup']:.2f}x; records identical: {report['identical_to_serial']}")
    cells = report.pop("cells")
    _write(Path(args.out), args.track, report, markdown)
    for key, cell in cells.items():  # every episode, as mpg-eval --json writes it (for compare_evals.py)
        label, n = key.rsplit("|", 1)
        path = Path(args.out) / "cells" / cell_file_name(label, int(n))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(cell))
    print(json.dumps(report))
    return report


if __name__ == "__main__":
    main()
