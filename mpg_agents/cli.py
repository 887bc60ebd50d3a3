"""Command lines: ``mpg-train``, ``mpg-eval``, ``mpg-calibrate``, ``mpg-export`` and ``mpg-plot``.

Bad input (an unknown env id, a missing or foreign checkpoint, an unreadable config file, a bad
setting, an output path that cannot be written, a run folder another process trains in) ends
the command before any work with exit status 2 and one clear line on stderr. An evaluation in
which some episodes (or case runs) raise keeps, prints and writes those that finished, names
the failed ones in one line on stderr and exits with status 1.
"""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from collections.abc import Sequence
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import gymnasium as gym

from mpg_agents.acting.coordination import COORDINATIONS
from mpg_agents.acting.device import DEVICES, resolve_device
from mpg_agents.cli_input import (  # noqa: E501
    UsageError,
    check_checkpoint,
    check_env_id,
    check_env_options,
    check_net_setting,
    check_output,
    check_q_star_flag,
    check_seed_flag,
    check_thread_setting,
    fail,
    read_config,
)
from mpg_agents.evaluation.env_options import parse_env_options
from mpg_agents.evaluation.failures import NothingFinished
from mpg_agents.evaluation.policy_zoo import BUILTIN, make_policy
from mpg_agents.learning.plotting import check_image_path, plot_runs
from mpg_agents.learning.run_folder import RunFolderBusy
from mpg_envs.files import WriteFailed, write_text_whole
from mpg_envs.threads import set_torch_threads

# Start-up time: each command imports torch, the simulation or the evaluation's statistics
# (scipy) inside its function, once its arguments are read, so --help and argument errors
# answer at once (those imports are marked noqa: PLC0415).


def training_settings(path: str | None) -> tuple[Any, tuple[Any, ...]]:
    """The ``TrainConfig`` and the stage table a ``--config`` file (TOML or JSON) describes:
    ``TrainConfig`` fields at the top level, ``[stages.StageN]`` tables of stage fields."""
    from mpg_agents.learning import training_stages as ts  # noqa: PLC0415
    from mpg_agents.learning.train_config import TrainConfig  # noqa: PLC0415

    settings = read_config(path)
    stages = ts.with_overrides(ts.TRAINING_STAGES, settings.pop("stages", {}))
    return TrainConfig.from_dict(settings), stages


def _add_net_setting_arguments(parser: argparse.ArgumentParser, prefix: str) -> None:
    """The options that override a checkpoint's settings without weights (read by :func:`_net_settings`)."""
    parser.add_argument(
        "--grasp-region",
        choices=("rectangle", "target", "visible"),
        help=prefix + "where a grasp may act (override the checkpoint's: the target's "
        "rectangle, its footprint, or the part of it where the target shows)",
    )
    parser.add_argument(
        "--target-margin",
        type=int,
        help=prefix
        + "grow (> 0) or shrink (< 0) the target's pixels by this many pixels for grasp regions 'target' and 'visible'",
    )
    parser.add_argument(
        "--move-region",
        choices=("rectangle", "top"),
        help=prefix + "where a move may act (override the checkpoint's: the target's "
        "rectangle or the top of its footprint, the occluder)",
    )
    parser.add_argument(
        "--grasp-fingers",
        choices=("any", "clear"),
        help=prefix
        + "which grasps may act (override the checkpoint's): any, or only those whose open fingers land least blocked",
    )
    parser.add_argument(
        "--move-fingers",
        choices=("any", "clear"),
        help=prefix
        + "which moves may act (override the checkpoint's): any, or only those whose open fingers land least blocked",
    )


def _net_settings(args: argparse.Namespace) -> dict[str, Any]:
    """``MPGNetConfig`` field -> value of the :func:`_add_net_setting_arguments` options given (checked)."""
    check_net_setting("--target-margin", "target_margin_px", args.target_margin)
    given = (
        ("grasp_region", args.grasp_region),
        ("target_margin_px", args.target_margin),
        ("move_region", args.move_region),
        ("grasp_fingers", args.grasp_fingers),
        ("move_fingers", args.move_fingers),
    )
    return {name: value for name, value in given if value is not None}


# ---------------------------------------------------------------------------- train
def train_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-train", description="Train MPGNet: one stage (--env) or the five-stage pipeline (--pipeline)."
    )
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--env", help="one stage, by its env id, e.g. MPG-Stage4-v0")
    what.add_argument("--pipeline", action="store_true", help="run Stages I-V in order (with Q*_g calibration after II)")
    parser.add_argument("--init", help="start from this MPGNet checkpoint (safetensors)")
    parser.add_argument("--out", default="runs/mpg", help="run directory (resumes if it holds a saved state)")
    parser.add_argument(
        "--config",
        help="JSON or TOML file of training settings: TrainConfig fields, and 'stages': {name: {TrainingStage field: value}}",
    )
    # Flags named after TrainConfig fields override the config file (dest = the field's name).
    parser.add_argument("--steps", type=int, help="iterations (one stage), or iterations of every stage (pipeline)")
    parser.add_argument("--seed", type=int, help="default 0")
    parser.add_argument("--variant", choices=("small", "large"), help="MobileNetV3 trunks (default small)")
    parser.add_argument("--num-objects", type=int, help="a fixed object count (default: the stage's)")
    parser.add_argument("--q-star", type=float, help="the grasp threshold Q*_g (default: from --init or calibrated)")
    parser.add_argument(
        "--device", choices=DEVICES, help="networks and batches: auto (default: CUDA when available), cpu or cuda"
    )
    parser.add_argument(
        "--discriminator", help="the discriminator: a fixed grasp-net checkpoint scoring states (Stages III-V)"
    )
    parser.add_argument(
        "--replay-ratio", type=float, help="gradient steps per env step (default 1.0: one per iteration, the paper's)"
    )
    parser.add_argument("--actors", type=int, help="env-stepping actor processes (default 1: in this process, no Ray)")
    parser.add_argument(
        "--actor-backend",
        choices=("auto", "ray", "processes"),
        help="with --actors > 1: Ray actors (auto, the default, when Ray is installed) or local processes",
    )
    parser.add_argument("--ray-address", help="with --actors > 1: run the actors on this Ray cluster (e.g. auto or HOST:6379)")
    parser.add_argument(
        "--weights-refresh",
        type=int,
        help="with --actors > 1: actors get the learner's weights every this many gradient steps (default 10)",
    )
    parser.add_argument("--stages", help="pipeline: which stages, by name or position, e.g. 1,2")
    parser.add_argument("--no-multistage", action="store_true", help="pipeline ablation: only Stage V, from scratch")
    parser.add_argument("--no-alternating", action="store_true", help="pipeline ablation: Stage V by max Q, all nets at once")
    parser.add_argument(
        "--baseline",
        choices=("grasp-only", "to-vpg", "push-grasp"),
        help="pipeline: train a learned baseline of Table I at the same total iterations instead of MPGNet",
    )
    parser.add_argument(
        "--resume-anyway",
        action="store_true",
        help="resume a saved run even though settings differ from its own (they are listed; the record keeps the new ones)",
    )
    args = parser.parse_args(argv)
    try:
        from mpg_agents.acting.grasp_threshold import as_record  # noqa: PLC0415
        from mpg_agents.learning import training_stages as ts  # noqa: PLC0415
        from mpg_agents.learning.learner import Learner  # noqa: PLC0415
        from mpg_agents.learning.train_config import TrainConfig, json_safe  # noqa: PLC0415

        check_thread_setting()
        set_torch_threads()  # the cores free now, so a busy machine is not oversubscribed (MPG_NUM_THREADS overrides)
        check_seed_flag(args.seed)
        check_q_star_flag(args.q_star)
        base, stages = training_settings(args.config)
        flags = {f.name: getattr(args, f.name) for f in fields(TrainConfig) if getattr(args, f.name, None) is not None}
        base = replace(base, **flags)
        check_checkpoint(args.init)
        check_checkpoint(args.discriminator)
        if args.pipeline:
            from mpg_agents.learning.pipeline import PipelineConfig, run_pipeline  # noqa: PLC0415

            if args.stages:
                stages = ts.select_stages(stages, args.stages.split(","))
            if args.no_multistage:
                stages = ts.without_multistage(stages)
            if args.no_alternating:
                stages = ts.without_alternation(stages)
            if args.baseline:
                stages = ts.BASELINES[args.baseline](stages)
            summary = run_pipeline(
                PipelineConfig(base=base, stages=stages), args.out, init=args.init, resume_anyway=args.resume_anyway
            )
            print(json.dumps(summary, indent=1))
            return 0
        check_env_id(args.env)
        learner = Learner(base, ts.stage_for_env(args.env, stages), args.out, init=args.init, resume_anyway=args.resume_anyway)
        summary = learner.run()
        print(json.dumps({**json_safe(summary), "q_star": as_record(learner.policy.q_star)}))  # the Q*_g its weights carry
        return 0
    except (
        UsageError,
        FileNotFoundError,
        ValueError,
        RunFolderBusy,
        WriteFailed,
    ) as exc:  # also another architecture, a run folder in use, a full disk
        return fail(exc)
    except KeyboardInterrupt:
        print("interrupted: state saved, run the same command to resume", file=sys.stderr)
        return 130
    except Exception as exc:
        from mpg_agents.learning.learner import StopRequested  # noqa: PLC0415

        if isinstance(exc, StopRequested):
            print("stopped: state saved, run the same command to resume", file=sys.stderr)
            return 143
        raise


# ----------------------------------------------------------------------------- eval
def eval_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-eval", description="Evaluate a policy with the paper's metrics (task success within 10 motions, motions)."
    )
    parser.add_argument(
        "--policy", required=True, help="a checkpoint (.safetensors), or oracle | random | grasp-only | shipped"
    )
    parser.add_argument("--env", default="MPG-Occluded-v0")
    parser.add_argument("--num-objects", type=int)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--seed", type=int, default=0, help="episode i is reset with seed + i")
    parser.add_argument("--json", help="also write the metrics and every episode's record to this JSON file")
    parser.add_argument("--coordination", choices=COORDINATIONS, help="network policies: override the coordination")
    _add_net_setting_arguments(parser, "network policies: ")
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
            {"the --policy checkpoint": None if args.policy in BUILTIN else args.policy, "the --cases file": args.cases},
        )
        if args.device is not None:
            resolve_device(args.device)  # CUDA asked for where there is none: say so before any episode
        if args.policy not in BUILTIN:
            check_checkpoint(args.policy)
        if args.episodes < 1:
            raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
        if args.workers is not None and args.workers < 1:
            raise UsageError(f"--workers must be >= 1, got {args.workers}")
        workers = 1 if args.workers is None and args.ray_address is None else args.workers
        extra: tuple[tuple[str, Any], ...] = (("coordination", args.coordination),) if args.coordination else ()
        extra += tuple(_net_settings(args).items())
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


# ----------------------------------------------------------------------- calibrate
def calibrate_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-calibrate",
        description="Measure Q*_g of a checkpoint in an env's scenes, as a training stage does: greedy grasp-only "
        "episodes on the run seed's calibration scenes, no learning; Q*_g is a quantile of the Q of the "
        "grasps that took the target. Use the result with mpg-eval --q-star.",
    )
    parser.add_argument("--policy", required=True, help="a checkpoint (.safetensors) with a grasp branch, or shipped")
    parser.add_argument("--env", default="MPG-Occluded-v0")
    parser.add_argument("--num-objects", type=int)
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument(
        "--quantile",
        type=float,
        default=0.5,
        help="0.5: the median, the paper's reading (default); the shipped config calibrates at 0.25",
    )
    parser.add_argument(
        "--seed", type=int, default=0, help="the run seed whose calibration scenes are used (a run's own: --seed of mpg-train)"
    )
    parser.add_argument(
        "--grasp-fingers",
        choices=("any", "clear"),
        help="which grasps may act (override the checkpoint's; calibrate with the setting you evaluate with)",
    )
    parser.add_argument("--json", help="also write the measurement (every successful grasp's Q) to this JSON file")
    parser.add_argument("--device", choices=DEVICES, help="the network: auto (default: CUDA when available), cpu or cuda")
    args = parser.parse_args(argv)
    try:
        from mpg_agents.acting.grasp_threshold import calibrate_q_star, calibration_dict, format_q_star  # noqa: PLC0415

        check_env_id(args.env)
        check_thread_setting()
        check_seed_flag(args.seed)
        check_output(args.json, "--json", {"the --policy checkpoint": None if args.policy == "shipped" else args.policy})
        if args.policy != "shipped":
            check_checkpoint(args.policy)
        if args.episodes < 1:
            raise UsageError(f"--episodes must be >= 1, got {args.episodes}")
        if not 0.0 <= args.quantile <= 1.0:
            raise UsageError(f"--quantile must be in [0, 1], got {args.quantile}")
        env = gym.make(args.env, **({"num_objects": args.num_objects} if args.num_objects is not None else {}))
        options = {"grasp_fingers": args.grasp_fingers} if args.grasp_fingers else {}
        net = make_policy(args.policy, env, **options, **({"device": args.device} if args.device else {})).policy
        print(f"Q*_g in the checkpoint: {format_q_star(net.q_star)}")

        def progress(k: int, grasps: int, taken: int) -> None:
            print(f"  episode {k + 1}/{args.episodes}: {taken} of {grasps} grasps took the target", flush=True)

        measured = calibrate_q_star(net, env, args.episodes, args.seed, args.quantile, on_episode=progress)
        env.close()
    except (UsageError, FileNotFoundError, ValueError, RuntimeError) as exc:
        return fail(exc)
    print(
        f"Q*_g {measured.q_star:.4f}: quantile {measured.quantile:g} of the Q of {len(measured.target_grasp_q)} "
        f"of {measured.grasps} greedy grasps that took the target in {measured.episodes} episodes"
    )
    if args.json:
        path = Path(args.json)
        record = {
            "policy": args.policy,
            "env_id": args.env,
            "num_objects": args.num_objects,
            "seed": args.seed,
            "grasp_fingers": net.net_config.grasp_fingers,
            **calibration_dict(measured),
        }
        try:
            write_text_whole(path, json.dumps(record, indent=1))
        except WriteFailed as exc:
            return fail(exc)
        print(f"written to {path.resolve()}")
    return 0


# ------------------------------------------------------------------------- export
def export_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-export",
        description="A lean copy of a trained checkpoint for shipping: float16, optionally only some branches, "
        "with settings that change where Q counts (not any weight) and a Q*_g measured after training; "
        "the header records what changed.",
    )
    parser.add_argument("src", help="the trained checkpoint (.safetensors), e.g. RUN/Stage5/weights.safetensors")
    parser.add_argument("dst", help="the copy to write")
    parser.add_argument("--primitives", help="comma-separated branches to keep (default: all)")
    parser.add_argument("--float32", action="store_true", help="keep float32 (default: float16)")
    _add_net_setting_arguments(parser, "")
    parser.add_argument("--q-star", type=float, help="Q*_g of the copy (training's stays on record in the header)")
    parser.add_argument("--coordination", choices=COORDINATIONS, help="the rule the copy acts with")
    parser.add_argument(
        "--grasp-retries",
        type=int,
        metavar="K",
        help="the copy's default loop breaker: push once after K grasps in a row that did not take the target (0: never)",
    )
    args = parser.parse_args(argv)
    try:
        from mpg_agents.acting.weights import export_weights, read_checkpoint_header  # noqa: PLC0415

        check_checkpoint(args.src)
        check_q_star_flag(args.q_star)
        check_output(args.dst, "dst", {"the source checkpoint": args.src})
        settings = _net_settings(args)
        primitives = tuple(p.strip() for p in args.primitives.split(",")) if args.primitives else None
        dst = export_weights(
            args.src,
            args.dst,
            primitives=primitives,
            half=not args.float32,
            settings=settings,
            coordination=args.coordination,
            q_star=args.q_star,
            grasp_retries=args.grasp_retries,
        )
        header = read_checkpoint_header(dst)
    except (UsageError, FileNotFoundError, ValueError, WriteFailed) as exc:
        return fail(exc)
    q_star = "none (never calibrated)" if header["q_star"] is None else f"{header['q_star']:.4f}"
    print(
        f"{dst}: {dst.stat().st_size / 1000:.0f} kB, branches {header['primitives']}, Q*_g {q_star}, "
        f"coordination {header['extra'].get('coordination', 'workflow')}, settings after training "
        f"{header['extra'].get('settings_after_training', {})}"
    )
    return 0


# ----------------------------------------------------------------------------- plot
def plot_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-plot", description="Learning curves of a run (or pipeline) directory to a picture (PNG by default)."
    )
    parser.add_argument(
        "run",
        nargs="+",
        help="a run directory (holding progress.csv) or a pipeline directory (Stage*/progress.csv); "
        "several with --stage: that stage of each on one axis",
    )
    parser.add_argument(
        "--out",
        help="picture path, its suffix the format: .png, .pdf, .svg, "
        "... (default: RUN/curves.png; required with several runs)",
    )
    parser.add_argument("--window", type=int, default=200, help="iterations per grasp-success point (paper: 200)")
    parser.add_argument("--stage", help="compare this stage (e.g. Stage5) of the runs given")
    parser.add_argument("--labels", help="comma-separated legend labels, one per run (default: the folder names)")
    args = parser.parse_args(argv)
    try:
        try:
            check_image_path(args.out)
        except ValueError as exc:
            raise UsageError(f"--out {exc}") from None
        check_output(args.out, "--out", {f"the progress.csv of {r}": str(Path(r) / "progress.csv") for r in args.run})
        with warnings.catch_warnings(record=True) as notes:  # e.g. a cut last row: said below, one line each
            warnings.simplefilter("always")
            out = plot_runs(args.run, args.out, args.window, args.stage, args.labels.split(",") if args.labels else None)
        for note in notes:
            print(f"warning: {note.message}", file=sys.stderr)
    except (UsageError, FileNotFoundError, ValueError, WriteFailed) as exc:
        return fail(exc)
    print(f"learning curves written to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(train_main())
