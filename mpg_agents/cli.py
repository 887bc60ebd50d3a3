"""Command lines: ``mpg-train``, ``mpg-eval``, ``mpg-calibrate``, ``mpg-export`` and ``mpg-plot``.

Bad input (an unknown env id, a missing or foreign checkpoint, an unreadable config file, a bad
setting, an output path that cannot be written, a run folder another process trains in) ends
the command before any work with exit status 2 and one clear line on stderr. An evaluation in
which some episodes (or case runs) raise keeps, prints and writes those that finished, names
the failed ones in one line on stderr and exits with status 1.

``mpg-eval`` lives in :mod:`mpg_agents.cli_eval` and is importable from here (``eval_main``), as
every command's entry point is.
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

from mpg_agents.acting.calibration_quantile import CALIBRATION_QUANTILE, check_quantile
from mpg_agents.acting.coordination import COORDINATIONS
from mpg_agents.acting.device import DEVICES
from mpg_agents.cli_eval import eval_main
from mpg_agents.cli_input import (  # noqa: E501
    UsageError,
    check_checkpoint,
    check_env_id,
    check_output,
    check_q_star_flag,
    check_seed_flag,
    check_thread_setting,
    fail,
    read_config,
)
from mpg_agents.cli_net_settings import add_net_setting_arguments, net_settings
from mpg_agents.evaluation.policy_zoo import make_policy
from mpg_agents.learning.plotting import check_image_path, plot_runs
from mpg_agents.learning.run_folder import RunFolderBusy
from mpg_envs.files import WriteFailed, write_text_whole
from mpg_envs.threads import set_torch_threads

__all__ = ["calibrate_main", "eval_main", "export_main", "plot_main", "train_main", "training_settings"]
"""The commands' entry points (``[project.scripts]`` in pyproject.toml) and the config reader."""

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


# ---------------------------------------------------------------------------- train
def train_main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="mpg-train",
        description="Train MPGNet: one stage (--env) or the five-stage pipeline (--pipeline); "
        "or clone the actions of a dataset recorded by mpg-demos (--baseline bc --demos DIR).",
    )
    what = parser.add_mutually_exclusive_group()  # one of them is required, except for --baseline bc (checked below)
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
        choices=("grasp-only", "to-vpg", "push-grasp", "bc"),
        help="pipeline: train a learned baseline of Table I at the same total iterations instead of MPGNet; "
        "bc: behaviour cloning of the actions recorded in --demos (no --env or --pipeline: the dataset's env)",
    )
    parser.add_argument("--demos", help="--baseline bc: a dataset folder recorded by mpg-demos")
    parser.add_argument(
        "--demo-episodes", type=int, help="--baseline bc: imitate the dataset's first N episodes (default: all)"
    )
    parser.add_argument(
        "--resume-anyway",
        action="store_true",
        help="resume a saved run even though settings differ from its own (they are listed; the record keeps the new ones)",
    )
    args = parser.parse_args(argv)
    if args.baseline == "bc":
        from mpg_agents.imitation.bc_command import bc_main  # noqa: PLC0415  (start-up time: torch, Minari)

        return bc_main(args)
    if args.demos is not None or args.demo_episodes is not None:
        parser.error("--demos and --demo-episodes go with --baseline bc")
    if args.env is None and not args.pipeline:
        parser.error("one of the arguments --env --pipeline is required (or --baseline bc with --demos)")
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
            from mpg_agents.learning import stage_variants  # noqa: PLC0415
            from mpg_agents.learning.pipeline import PipelineConfig, run_pipeline  # noqa: PLC0415

            if args.stages:
                stages = ts.select_stages(stages, args.stages.split(","))
            if args.no_multistage:
                stages = stage_variants.without_multistage(stages)
            if args.no_alternating:
                stages = stage_variants.without_alternation(stages)
            if args.baseline:
                stages = stage_variants.BASELINES[args.baseline](stages)
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
        from mpg_agents.learning.stop_signal import StopRequested  # noqa: PLC0415

        if isinstance(exc, StopRequested):
            print("stopped: state saved, run the same command to resume", file=sys.stderr)
            return 143
        raise


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
        default=CALIBRATION_QUANTILE,
        help=f"{CALIBRATION_QUANTILE:g}: the median, the paper's reading (default); the shipped config calibrates at 0.25",
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
        try:
            quantile = check_quantile(args.quantile, "--quantile")
        except ValueError as exc:
            raise UsageError(str(exc)) from None
        env = gym.make(args.env, **({"num_objects": args.num_objects} if args.num_objects is not None else {}))
        options = {"grasp_fingers": args.grasp_fingers} if args.grasp_fingers else {}
        net = make_policy(args.policy, env, **options, **({"device": args.device} if args.device else {})).policy
        print(f"Q*_g in the checkpoint: {format_q_star(net.q_star)}")

        def progress(k: int, grasps: int, taken: int) -> None:
            print(f"  episode {k + 1}/{args.episodes}: {taken} of {grasps} grasps took the target", flush=True)

        measured = calibrate_q_star(net, env, args.episodes, args.seed, quantile, on_episode=progress)
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
    add_net_setting_arguments(parser, "")
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
        settings = net_settings(args)
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
