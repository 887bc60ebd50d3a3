"""Independent training runs (seeds, learned baselines, ablations) as Ray tasks from one command.

A run is one ``mpg-train --pipeline`` of a shared config, named by what it trains (:data:`RUNS`)
and its training seed, in its own folder ``<out>/<run>-s<seed>/`` with its log in
``train.log`` there. Each run is a Ray task that starts the pipeline as a subprocess (one torch
and OpenMP thread, its own signal handling), so a run keeps what ``mpg-train`` gives it: a
killed run resumes where it stopped when the command is run again, and a finished one (its
``pipeline.json`` exists) is skipped. Ray is local by default (``workers`` CPUs: runs at once);
with ``ray_address`` the tasks go to a cluster, whose nodes need this package installed and
``out`` on a filesystem they share.

Command line: ``mpg-train-runs --runs mpgnet,grasp-only --seeds 0,1 --out runs/strict``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

from mpg_envs.threads import WORKER_THREAD_ENV as THREAD_ENV

RUNS: dict[str, tuple[str, ...]] = {
    "mpgnet": (),
    "no-multistage": ("--no-multistage",),
    "no-alternating": ("--no-alternating",),
    "no-both": ("--no-multistage", "--no-alternating"),
    "grasp-only": ("--baseline", "grasp-only"),
    "to-vpg": ("--baseline", "to-vpg"),
    "push-grasp": ("--baseline", "push-grasp"),
}
"""Run name -> the ``mpg-train --pipeline`` flags that make it: MPGNet, its three ablations
(paper, Fig. 5), and the learned baselines of the results tables at MPGNet's total iterations."""

DEFAULT_CONFIG = Path(__file__).resolve().parents[1] / "checkpoints" / "mpgnet_train.toml"  # mpg_agents/checkpoints/
"""The shipped MPGNet's training config."""


@dataclass(frozen=True)
class RunSpec:
    """One training run: what it trains, its seed, the shared config and where it writes."""

    run: str
    seed: int
    config: str
    out: str

    def __post_init__(self) -> None:
        if self.run not in RUNS:
            raise ValueError(f"unknown run {self.run!r}; valid: {', '.join(RUNS)}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"a run's seed must be an integer >= 0, got {self.seed!r}")

    @property
    def folder(self) -> Path:
        return Path(self.out) / f"{self.run}-s{self.seed}"

    def command(self) -> list[str]:
        """The ``mpg-train`` command line of this run."""
        return [
            sys.executable,
            "-m",
            "mpg_agents.cli",
            "--pipeline",
            "--config",
            self.config,
            "--out",
            str(self.folder),
            "--seed",
            str(self.seed),
            *RUNS[self.run],
        ]

    @property
    def finished(self) -> bool:
        return (self.folder / "pipeline.json").is_file()


@dataclass(frozen=True)
class RunResult:
    """How one run ended: ``finished``, ``finished before`` (skipped) or ``exit N``."""

    run: str
    seed: int
    folder: str
    status: str
    seconds: float


def train_run(spec: RunSpec) -> RunResult:
    """Run (or resume) one pipeline in a subprocess with one thread; its output goes to
    ``train.log`` in its folder (appended, so a resumed run keeps its history)."""
    if spec.finished:
        return RunResult(spec.run, spec.seed, str(spec.folder), "finished before", 0.0)
    spec.folder.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, **THREAD_ENV}
    start = time.perf_counter()
    with open(spec.folder / "train.log", "a") as log:
        code = subprocess.call(spec.command(), stdout=log, stderr=subprocess.STDOUT, env=env)
    status = "finished" if code == 0 and spec.finished else f"exit {code}"
    return RunResult(spec.run, spec.seed, str(spec.folder), status, round(time.perf_counter() - start, 1))


def plan_runs(
    runs: Sequence[str], seeds: Sequence[int], config: str | Path = DEFAULT_CONFIG, out: str | Path = "runs"
) -> list[RunSpec]:
    """Every (run, seed) pair as a :class:`RunSpec`, seeds innermost.

    Raises:
        ValueError: an unknown run name (names the valid ones), a bad seed, no runs or seeds,
            or a config file that does not exist.
    """
    if not runs or not seeds:
        raise ValueError(f"need at least one run and one seed, got runs={list(runs)} seeds={list(seeds)}")
    if not Path(config).is_file():
        raise ValueError(f"training config {str(config)!r} does not exist")
    return [RunSpec(run, seed, str(config), str(out)) for run in runs for seed in seeds]


def train_runs(specs: Sequence[RunSpec], workers: int | None = 1, ray_address: str | None = None) -> list[RunResult]:
    """Run ``specs`` as Ray tasks, ``workers`` at once on a local Ray (one CPU each), or on the
    cluster at ``ray_address``; results in the order of ``specs``."""
    # Start-up time: the evaluation runner loads its statistics (scipy); --help does not need it.
    from mpg_agents.evaluation.eval_runner import ray_session  # noqa: PLC0415

    with ray_session(workers, ray_address) as ray:
        remote = ray.remote(num_cpus=1, max_retries=0)(train_run)
        return list(ray.get([remote.remote(spec) for spec in specs]))


def _int_list(text: str) -> list[int]:
    try:
        return [int(part) for part in text.split(",") if part.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None


def main(argv: Sequence[str] | None = None) -> int:
    """``mpg-train-runs``: train several runs as Ray tasks; prints one JSON object at the end."""
    parser = argparse.ArgumentParser(
        description="Train MPGNet, its ablations and the learned baselines, each for several seeds, as Ray tasks (resumable)."
    )
    parser.add_argument(
        "--runs", default="mpgnet,grasp-only", help=f"comma-separated, of {', '.join(RUNS)} (default mpgnet,grasp-only)"
    )
    parser.add_argument("--seeds", type=_int_list, default=[0, 1], help="comma-separated training seeds (default 0,1)")
    parser.add_argument("--config", default=str(DEFAULT_CONFIG), help="the training config every run shares")
    parser.add_argument("--out", default="runs", help="one folder <run>-s<seed> per run under this")
    parser.add_argument("--workers", type=int, default=None, help="runs at once on a local Ray (default: the number of runs)")
    parser.add_argument("--ray-address", default=None, help="join this Ray cluster instead of starting a local Ray")
    parser.add_argument("--dry-run", action="store_true", help="print the commands only")
    args = parser.parse_args(argv)
    if Path(args.out).exists() and not Path(args.out).is_dir():
        parser.error(f"--out {args.out!r} is a file; give a folder (made if missing)")
    try:
        specs = plan_runs([r for r in args.runs.split(",") if r], args.seeds, args.config, args.out)
    except ValueError as exc:
        parser.error(str(exc))
    if args.dry_run:
        for spec in specs:
            print(" ".join(spec.command()))
        return 0
    workers = None if args.ray_address else (args.workers or len(specs))
    results = train_runs(specs, workers, args.ray_address)
    print(json.dumps({"config": args.config, "out": args.out, "runs": [asdict(r) for r in results]}))
    return 0 if all(r.status.startswith("finished") for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
