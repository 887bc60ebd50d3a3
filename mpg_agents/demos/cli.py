"""``mpg-demos``: record a policy's episodes on an env or track as a Minari dataset.

Bad input (an unknown env id or policy, a missing checkpoint, an output folder that is not new,
a malformed dataset id, Minari not installed) ends the command before any episode with exit
status 2 and one line on stderr. An episode that raises ends the recording with exit status 1;
the episodes before it stay in the folder as a complete dataset of that many episodes. The same
command with ``--resume`` continues a recording that stopped (killed, interrupted or failed)
after its last whole episode (:mod:`mpg_agents.demos.resume`), to the same data.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence

from mpg_agents.cli_input import UsageError, check_checkpoint, check_env_id, fail
from mpg_agents.demos.dataset import (
    DemoWriter,
    check_dataset_id,
    check_new_folder,
    default_dataset_id,
)
from mpg_agents.demos.recording import DemoJob, record_episodes
from mpg_agents.demos.resume import resume_writer
from mpg_agents.evaluation.env_options import parse_env_options
from mpg_agents.evaluation.policy_zoo import BUILTIN, is_builtin


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mpg-demos",
        description="Record a policy's episodes on an env or track as a Minari dataset: lossless observations, "
        "actions, rewards, each episode's reset seed and options, the env's spec (dataset.recover_environment()) and "
        "per step the info the metrics read. Episode i is reset with seed S + i, as mpg-eval does; the same "
        "command gives the same data for any number of workers.",
    )
    parser.add_argument(
        "--policy",
        required=True,
        help=f"{', '.join(BUILTIN)}, or an MPGNet checkpoint (.safetensors), as mpg-eval takes them",
    )
    parser.add_argument("--env", required=True, help="an env or track id, e.g. MPG-OccludedHard-v0")
    parser.add_argument("--episodes", type=int, required=True)
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help="episode i is reset with seed + i (held-out test seeds: 500000 on; tuning: 700000 on)",
    )
    parser.add_argument("--out", required=True, help="a new or empty folder for the dataset (Minari's data/ inside)")
    parser.add_argument(
        "--resume",
        action="store_true",
        help="continue the dataset in --out that this same command started and did not finish (whole episodes kept)",
    )
    parser.add_argument("--num-objects", type=int, help="objects per scene (default: the env's)")
    parser.add_argument(
        "--env-option",
        action="append",
        metavar="KEY=VALUE",
        help="an env keyword, e.g. obs_mode=camera or wrong_grasp=fail (repeatable; recorded in the env spec)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        help="worker processes, one thread each (default 1: in this process)",
    )
    parser.add_argument(
        "--format",
        choices=("parquet", "hdf5", "arrow"),
        default="parquet",
        help="Minari's storage: parquet (compressed, lossless; default), hdf5 (needs h5py) or arrow (neither compressed)",
    )
    parser.add_argument(
        "--dataset-id",
        help="the Minari id, (namespace/)name-vN (default: the --out folder's name, -v0 added)",
    )
    parser.add_argument("--device", choices=("auto", "cpu", "cuda"), help="network policies: where the network runs")
    parser.add_argument("--quiet", action="store_true", help="no line per episode")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``mpg-demos`` command; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        check_env_id(args.env)
        if args.episodes < 1:
            raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
        if args.seed < 0:
            raise UsageError(f"--seed must be >= 0, got {args.seed}")
        if args.workers < 1:
            raise UsageError(f"--workers must be >= 1, got {args.workers}")
        if args.num_objects is not None and args.num_objects < 1:
            raise UsageError(f"--num-objects must be >= 1, got {args.num_objects}")
        if not is_builtin(args.policy):
            check_checkpoint(args.policy)
        if not args.resume:
            check_new_folder(args.out)
        check_dataset_id(args.dataset_id if args.dataset_id is not None else default_dataset_id(args.out))
        env_kwargs = parse_env_options(args.env_option)
        if args.num_objects is not None:
            env_kwargs["num_objects"] = args.num_objects
        policy_kwargs = (("device", args.device),) if args.device else ()
        job = DemoJob(
            args.policy,
            args.env,
            args.episodes,
            args.seed,
            tuple(sorted(env_kwargs.items())),
            policy_kwargs,
        )
        env = job.make_env()
        job.make_policy(env)  # a policy that cannot act on this env fails here, before any episode
        if args.resume:
            writer = resume_writer(args.out, env, job, args.dataset_id, args.format)
        else:
            writer = DemoWriter(args.out, env, job, args.dataset_id, args.format)
    except (ImportError, UsageError, FileNotFoundError, ValueError) as exc:
        return fail(exc)
    first = writer.episodes
    if first:
        print(f"resuming {args.out}: episodes 0-{first - 1} are recorded, {args.episodes - first} to go", flush=True)
    start = time.perf_counter()
    steps = successes = 0
    episode_seconds = 0.0
    if args.workers > 1:
        env.close()  # the workers make their own
    try:
        for episode in record_episodes(job, args.workers, env if args.workers == 1 else None, start=first):
            writer.add(episode)
            steps += episode.steps
            successes += int(episode.success)
            episode_seconds += episode.seconds
            if not args.quiet:
                print("  " + episode.describe(), flush=True)
    except KeyboardInterrupt:
        print(
            f"interrupted: {writer.episodes} of {args.episodes} episodes are in {args.out} "
            "(the same command with --resume continues)",
            file=sys.stderr,
        )
        return 130
    except Exception as exc:  # an episode that raised: say which, keep what was written
        print(
            f"error: episode {writer.episodes} (seed {args.seed + writer.episodes}) raised "
            f"{type(exc).__name__}: {exc}; "
            f"{args.out} holds the {writer.episodes} episodes before it (--resume continues from it)",
            file=sys.stderr,
        )
        return 1
    finally:
        if args.workers == 1:
            env.close()
    wall = time.perf_counter() - start
    size, fixed = writer.size_bytes(), writer.metadata_bytes()
    recorded = writer.episodes - first
    now = f"{recorded} episodes" + (f" (episodes {first}-{writer.episodes - 1}; {first} recorded before)" if first else "")
    print(
        f"{writer.dataset_id}: {now} ({successes} successful, {steps} steps) "
        f"of {job.policy} on {args.env} in {wall:.1f} s on {args.workers} "
        f"worker{'s' if args.workers > 1 else ''} ({wall / max(recorded, 1):.2f} s per episode; "
        f"{episode_seconds / max(recorded, 1):.2f} s of episode time each); {size / 1e6:.1f} MB in {args.out} "
        f"({(size - fixed) / 1e6 / writer.episodes:.3f} MB per episode and {fixed / 1e6:.1f} MB of metadata)"
    )
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
