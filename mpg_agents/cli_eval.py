"""The ``mpg-eval`` command line: a policy on seeded episodes or on a case set, with the paper's metrics.

Bad input ends the command before any episode with exit status 2 and one clear line on stderr.
An evaluation in which some episodes (or case runs) raise keeps, prints and writes those that
finished, names the failed ones in one line on stderr and exits with status 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from mpg_agents.acting.coordination import COORDINATIONS
from mpg_agents.acting.device import DEVICES, resolve_device
from mpg_agents.cli_input import (
    UsageError,
    check_checkpoint,
    check_env_id,
    check_env_options,
    check_output,
    check_q_star_flag,
    check_seed_flag,
    check_thread_setting,
    fail,
)
from mpg_agents.cli_net_settings import add_net_setting_arguments, net_settings
from mpg_agents.evaluation.env_options import parse_env_options
from mpg_agents.evaluation.failures import NothingFinished
from mpg_agents.evaluation.policy_zoo import BUILTIN, is_builtin
from mpg_envs.files import WriteFailed, write_text_whole

# Start-up time: the evaluation (torch, the simulation, scipy) is imported inside the functions,
# once the arguments are read, so --help and argument errors answer at once (noqa: PLC0415).


def eval_main(argv: Sequence[str] | None = None) -> int:
    """``mpg-eval``: a policy on seeded episodes (or a case set, ``--cases``), its metrics printed
    and, with ``--json``, written; the exit status (0, 1: some episodes failed, 2: bad input)."""
    parser = argparse.ArgumentParser(
        prog="mpg-eval", description="Evaluate a policy with the paper's metrics (task success within 10 motions, motions)."
    )
    parser.add_argument("--policy", required=True, help=f"a checkpoint (.safetensors), or {' | '.join(BUILTIN)}")
    parser.add_argument("--env", default="MPG-Occluded-v0")
    parser.add_argument("--num-objects", type=int)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    parser.add_argument("--json", help="also write the metrics and every episode's record to this JSON file")
    parser.add_argument("--coordination", choices=COORDINATIONS, help="network policies: override the coordination")
    add_net_setting_arguments(parser, "network policies: ")
    parser.add_argument(
        "--q-star", type=float, help="network policies: grasp threshold Q*_g (override the checkpoint's calibrated one)"
    )
    parser.add_argument(
        "--avoid-repeats",
        action="store_true",
        help="network policies: never repeat an action on an unchanged scene (take the best other one)",
    )
    parser.add_argument(
        "--grasp-retries",
        type=int,
        metavar="K",
        help="network policies: after K grasps in a row that did not take the target, "
        "push once (a move without a push net); 0: never (default: the checkpoint's)",
    )
    parser.add_argument("--device", choices=DEVICES, help="network policies: auto (default: CUDA when available), cpu or cuda")
    parser.add_argument(
        "--locator",
        metavar="PATH",
        help="network policies on an env that names its target by an exemplar: the target locator's "
        "weights (mpg-train-locator's locator.safetensors; needed while no locator ships with the package)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        help="worker processes on Ray; default 1 (in this process, no Ray), or "
        "the cluster's CPUs with --ray-address; same results for any number",
    )
    parser.add_argument("--ray-address", help="join this Ray cluster (e.g. auto or HOST:6379) instead of starting a local Ray")
    parser.add_argument(
        "--backend",
        choices=("ray", "processes"),
        default="ray",
        help="with --workers > 1: Ray (default) or a local process pool (no Ray start-up)",
    )
    parser.add_argument("--quiet", action="store_true", help="no line per episode")
    parser.add_argument(
        "--env-option",
        action="append",
        metavar="KEY=VALUE",
        help="an env keyword, e.g. wrong_grasp=fail, obs_mode=camera, "
        "'visible_range=(0, 0.3)' (repeatable; recorded in the JSON)",
    )
    parser.add_argument(
        "--cases",
        help="run a case set instead of seeded episodes: challenge | epg | gti, or a scene file or folder "
        "(strict retrieval, a mis-pick ends a run as a failure, unless --env-option wrong_grasp=remove)",
    )
    parser.add_argument(
        "--runs", type=int, default=1, help="with --cases: runs per case (run 0 as written, the others jittered)"
    )
    parser.add_argument("--peers", help="with --cases epg or gti: the folder holding the peers' files (vpg/, gti/)")
    args = parser.parse_args(argv)
    try:
        from mpg_agents.evaluation.eval_runner import EvalJob, evaluate_parallel  # noqa: PLC0415

        check_env_id(args.env)
        check_thread_setting()
        check_seed_flag(args.seed)
        check_output(
            args.json,
            "--json",
            {"the --policy checkpoint": None if is_builtin(args.policy) else args.policy, "the --cases file": args.cases},
        )
        if args.device is not None:
            resolve_device(args.device)  # CUDA asked for where there is none: say so before any episode
        if not is_builtin(args.policy):
            check_checkpoint(args.policy)
        if args.episodes < 1:
            raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
        if args.workers is not None and args.workers < 1:
            raise UsageError(f"--workers must be >= 1, got {args.workers}")
        workers = 1 if args.workers is None and args.ray_address is None else args.workers
        extra: tuple[tuple[str, Any], ...] = (("coordination", args.coordination),) if args.coordination else ()
        extra += tuple(net_settings(args).items())
        if args.avoid_repeats:
            extra += (("avoid_repeats", True),)
        if args.grasp_retries is not None:
            if args.grasp_retries < 0:
                raise UsageError(f"--grasp-retries must be >= 0, got {args.grasp_retries}")
            extra += (("grasp_retries", args.grasp_retries),)
        if args.q_star is not None:
            check_q_star_flag(args.q_star)
            extra += (("q_star", args.q_star),)
        if args.device is not None:
            extra += (("device", args.device),)
        if args.locator is not None:
            if is_builtin(args.policy) and args.policy != "shipped":
                raise UsageError(f"--locator goes with a network policy (shipped or a checkpoint), not {args.policy!r}")
            if not Path(args.locator).is_file():
                raise UsageError(f"--locator: no file at {args.locator!r}")
            extra += (("locator", str(args.locator)),)
        env_options = parse_env_options(args.env_option)
        check_env_options(args.env, env_options)
        if args.cases is not None:
            return _eval_cases(args, dict(extra), env_options)
        job = EvalJob(args.policy, args.env, args.episodes, args.seed, args.num_objects, extra, tuple(env_options.items()))
        on_record = None if args.quiet else (lambda record: print("  " + record.describe(), flush=True))
        result = evaluate_parallel(job, workers, args.ray_address, on_record=on_record, backend=args.backend, keep_going=True)
    except (UsageError, FileNotFoundError, ValueError) as exc:  # also a stale or changed test set (TestSetError)
        return fail(exc)
    except NothingFinished as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    return _report_run(result, args.json)


def _report_run(result: Any, json_path: str | None) -> int:
    """:func:`_report` of a run's result (what finished), then one line on stderr naming what
    failed, if anything did: exit status 1."""
    code = _report(result, json_path)
    if result.failures:
        print(f"error: {result.failures_line()}", file=sys.stderr)
        return 1
    return code


def _report(result: Any, json_path: str | None) -> int:
    """Print a result's table and, with ``--json``, write its ``to_dict()`` (whole or not at all)."""
    print(result.table())
    if json_path:
        path = Path(json_path)
        try:
            write_text_whole(path, json.dumps(result.to_dict(), indent=1, sort_keys=True))
        except WriteFailed as exc:
            return fail(exc)
        print(f"metrics written to {path.resolve()}")
    return 0


def _eval_cases(args: argparse.Namespace, policy_kwargs: dict[str, Any], env_options: dict[str, Any]) -> int:
    """``mpg-eval --cases``: every case of a set, ``--runs`` runs each, one row per case
    (strict retrieval unless ``--env-option wrong_grasp=...`` says otherwise)."""
    from mpg_agents.evaluation.case_runs import run_case_set, without_output  # noqa: PLC0415
    from mpg_envs.scenes.cases import load_cases  # noqa: PLC0415

    if args.workers not in (None, 1) or args.ray_address is not None:
        raise UsageError("--cases runs in this process: leave out --workers and --ray-address")
    if args.runs < 1:
        raise UsageError(f"--runs must be >= 1, got {args.runs}")
    if args.peers is not None and not Path(args.peers).is_dir():
        raise UsageError(f"--peers {args.peers!r} is not a folder")
    case_set = without_output(load_cases(args.cases, args.peers), args.json)  # a result written among the cases is none
    on_record = None if args.quiet else (lambda case, record: print(f"  {case.name}: {record.describe()}", flush=True))
    result = run_case_set(args.policy, case_set, args.runs, args.seed, args.env, env_options, policy_kwargs, on_record)
    return _report_run(result, args.json)
