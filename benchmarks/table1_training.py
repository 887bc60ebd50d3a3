"""Train every learned row of Table I at one budget: MPGNet, its three ablations, three baselines.

Each run is one ``mpg-train --pipeline`` command on the same config (default
``mpg_agents/checkpoints/mpgnet_train.toml``) and seed, in its own folder under ``--out``:

| run | what | command flags |
|---|---|---|
| ``mpgnet`` | MPGNet, Stages I -> II -> Q*_g -> III -> IV -> V | |
| ``no-multistage`` | ablation: Stage V only, from scratch | ``--no-multistage`` |
| ``no-alternating`` | ablation: Stage V by max Q, all nets at once | ``--no-alternating`` |
| ``no-both`` | ablation: both | ``--no-multistage --no-alternating`` |
| ``grasp-only`` | baseline: the grasp net alone, at MPGNet's total iterations | ``--baseline grasp-only`` |
| ``to-vpg`` | baseline: push + grasp, action by the larger Q | ``--baseline to-vpg`` |
| ``push-grasp`` | baseline: push + grasp, grasp when Q >= Q*_g, trained in turn | ``--baseline push-grasp`` |

Runs go one after another (``--parallel N`` runs N at once: on a machine with more cores;
each run then gets ``MPG_NUM_THREADS = cores // N``). A finished run (its ``pipeline.json``
exists) is skipped and an interrupted one resumes, so the command can simply be run again.
Each run's output goes to ``<out>/<run>/train.log``. Then the table and the curves:

    python benchmarks/tables.py --track table1 --policies runs/table1/mpgnet/Stage5/weights.safetensors ... --objects 15 30
    mpg-plot runs/table1/mpgnet runs/table1/no-multistage runs/table1/no-alternating runs/table1/no-both \\
        --stage Stage5 --labels "MPGNet,w/o multi-stage,w/o alternating,w/o both" --out ablations.png

    python benchmarks/table1_training.py [--out runs/table1] [--only mpgnet,to-vpg] [--parallel 1] [--dry-run]

The last output line is one JSON object: each run's status and wall seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

RUNS: dict[str, tuple[str, ...]] = {
    "mpgnet": (),
    "no-multistage": ("--no-multistage",),
    "no-alternating": ("--no-alternating",),
    "no-both": ("--no-multistage", "--no-alternating"),
    "grasp-only": ("--baseline", "grasp-only"),
    "to-vpg": ("--baseline", "to-vpg"),
    "push-grasp": ("--baseline", "push-grasp"),
}
DEFAULT_CONFIG = str(Path(__file__).resolve().parent.parent / "mpg_agents" / "checkpoints" / "mpgnet_train.toml")


def command(run: str, config: str, out: Path, seed: int) -> list[str]:
    """The ``mpg-train`` command line of ``run``."""
    return [sys.executable, "-m", "mpg_agents.cli", "--pipeline", "--config", config, "--out", str(out / run),
            "--seed", str(seed), *RUNS[run]]


def train(run: str, config: str, out: Path, seed: int, threads: int | None) -> dict:
    folder = out / run
    if (folder / "pipeline.json").is_file():
        return {"run": run, "status": "finished before", "seconds": 0.0}
    folder.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    if threads is not None:
        env["MPG_NUM_THREADS"] = str(threads)
    start = time.perf_counter()
    with open(folder / "train.log", "a") as log:
        code = subprocess.call(command(run, config, out, seed), stdout=log, stderr=subprocess.STDOUT, env=env)
    seconds = round(time.perf_counter() - start, 1)
    status = "finished" if code == 0 and (folder / "pipeline.json").is_file() else f"exit {code}"
    print(f"{run}: {status} in {seconds} s (log: {folder / 'train.log'})", flush=True)
    return {"run": run, "status": status, "seconds": seconds}


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default=DEFAULT_CONFIG, help="the training config all runs share")
    parser.add_argument("--out", default="runs/table1", help="one folder per run under this")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", help=f"comma-separated runs, of {', '.join(RUNS)}")
    parser.add_argument("--parallel", type=int, default=1, help="runs at once (default 1)")
    parser.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = parser.parse_args(argv)
    chosen = [r for r in args.only.split(",") if r] if args.only else list(RUNS)
    unknown = [r for r in chosen if r not in RUNS]
    if unknown or args.parallel < 1:
        parser.error(f"runs must be among {list(RUNS)} (got {unknown}); --parallel must be >= 1")
    if not Path(args.config).is_file():
        parser.error(f"config {args.config!r} does not exist")
    out = Path(args.out)
    if args.dry_run:
        for run in chosen:
            print(" ".join(command(run, args.config, out, args.seed)))
        return {"runs": chosen}
    threads = max(1, (os.cpu_count() or 1) // args.parallel) if args.parallel > 1 else None
    with ThreadPoolExecutor(args.parallel) as pool:
        results = list(pool.map(lambda r: train(r, args.config, out, args.seed, threads), chosen))
    summary = {"config": args.config, "out": str(out), "seed": args.seed, "runs": results}
    print(json.dumps(summary))
    return summary


if __name__ == "__main__":
    main()
