"""``mpg-train --baseline bc``: behaviour cloning from a dataset of ``mpg-demos``.

``mpg-train --baseline bc --demos DIR [--demo-episodes N] --out RUN [--steps K] [--seed S]
[--variant small|large] [--device D] [--config FILE] [--resume-anyway]``: the env is the
dataset's, so neither ``--env`` nor ``--pipeline`` is given; ``--config`` holds
:class:`~mpg_agents.imitation.bc_config.BCConfig` fields (the flags win over it). Bad input ends
the command before any work with exit status 2 and one line naming what is wrong and what is
valid.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from typing import Any

from mpg_agents.cli_input import UsageError, check_thread_setting, fail, read_config
from mpg_agents.imitation.bc_config import BC_FIELDS, BCConfig
from mpg_agents.imitation.bc_training import StepRecord, train_bc
from mpg_agents.learning.run_folder import RunFolderBusy
from mpg_agents.learning.stop_signal import StopRequested
from mpg_envs.files import WriteFailed
from mpg_envs.threads import set_torch_threads

FLAGS_OF_BC = {"steps": "--steps", "seed": "--seed", "variant": "--variant", "device": "--device"}
"""The ``mpg-train`` flags that set a behaviour-cloning setting of the same name."""

NOT_FOR_BC = {
    "env": "--env",
    "pipeline": "--pipeline",
    "init": "--init",
    "num_objects": "--num-objects",
    "q_star": "--q-star",
    "discriminator": "--discriminator",
    "replay_ratio": "--replay-ratio",
    "actors": "--actors",
    "actor_backend": "--actor-backend",
    "ray_address": "--ray-address",
    "weights_refresh": "--weights-refresh",
    "stages": "--stages",
    "no_multistage": "--no-multistage",
    "no_alternating": "--no-alternating",
}
"""The ``mpg-train`` options of reinforcement learning, which behaviour cloning refuses."""


def check_bc_arguments(args: argparse.Namespace) -> None:
    """``UsageError`` when ``--demos`` is missing or an option of reinforcement learning is given."""
    given = [flag for name, flag in NOT_FOR_BC.items() if getattr(args, name, None) not in (None, False)]
    if given:
        raise UsageError(
            f"--baseline bc learns from --demos and takes no {', '.join(given)}; "
            f"its options: --demos, --demo-episodes, --out, {', '.join(FLAGS_OF_BC.values())}, --config, --resume-anyway"
        )
    if not args.demos:
        raise UsageError("--baseline bc needs --demos DIR: a dataset folder recorded by mpg-demos")


def bc_settings(args: argparse.Namespace) -> BCConfig:
    """The settings of ``--config`` (BCConfig fields) with the flags over them.

    Raises:
        UsageError: a key the settings do not have, or a value out of range (named, with the valid ones).
    """
    settings: dict[str, Any] = read_config(args.config)
    for name in FLAGS_OF_BC:
        if getattr(args, name, None) is not None:
            settings[name] = getattr(args, name)
    if args.demo_episodes is not None:
        settings["demo_episodes"] = args.demo_episodes
    try:
        return BCConfig.from_dict(settings)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"{exc} (behaviour-cloning settings: {', '.join(BC_FIELDS)})") from None


def print_step(every: int, steps: int) -> Callable[[StepRecord], None]:
    """A progress printer: a line every ``every`` steps and at the last."""

    def show(record: StepRecord) -> None:
        if record.step % every == 0 or record.step == steps:
            print(
                f"step {record.step}/{steps}: loss {record.loss:.4f}, top-1 {record.accuracy:.2f}, {record.step_s:.2f} s/step",
                flush=True,
            )

    return show


def bc_main(args: argparse.Namespace) -> int:
    """Run ``mpg-train --baseline bc`` with ``mpg-train``'s parsed ``args``; the exit status."""
    try:
        check_bc_arguments(args)
        check_thread_setting()
        config = bc_settings(args)
        set_torch_threads()  # the cores free now (MPG_NUM_THREADS overrides), as mpg-train's other runs
        summary = train_bc(
            config,
            args.demos,
            args.out,
            resume_anyway=args.resume_anyway,
            on_step=print_step(max(1, config.steps // 20), config.steps),
        )
    except ImportError as exc:  # Minari, the demos extra
        return fail(UsageError(str(exc)))
    except (UsageError, FileNotFoundError, ValueError, RunFolderBusy, WriteFailed) as exc:
        return fail(exc)
    except KeyboardInterrupt:
        print("interrupted: the last saved state stays; run the same command to resume", file=sys.stderr)
        return 130
    except StopRequested:
        print("stopped: state saved at the last step, run the same command to resume", file=sys.stderr)
        return 143
    print(json.dumps(summary))
    return 0
