"""What the command lines check before any work: the config file, the env id, output paths and
checkpoints; bad input is a :class:`UsageError`, reported on one line with exit status 2."""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym

import mpg_envs
from mpg_agents.acting.seeds import check_seed
from mpg_envs.files import WriteFailed, check_writable, same_file
from mpg_envs.settings_fields import read_settings_file
from mpg_envs.threads import requested_threads

# Start-up time: checks that need torch (a checkpoint's header and tensors, Q*_g, the net's
# settings) or the simulation (an env's keywords) import them inside, when they run (noqa: PLC0415).

__all__ = [
    "UsageError",
    "check_checkpoint",
    "check_env_id",
    "check_env_options",
    "check_net_setting",
    "check_output",
    "check_q_star_flag",
    "check_seed_flag",
    "check_thread_setting",
    "fail",
    "read_config",
]


class UsageError(Exception):
    """Bad command-line input: reported on one line, exit status 2."""


def fail(exc: BaseException) -> int:
    """Report ``exc`` on stderr as one line; the exit status of bad input (2)."""
    print(f"error: {exc}", file=sys.stderr)
    return 2


def read_config(path: str | None) -> dict[str, Any]:
    """The settings of a TOML or JSON config file (none without a path)."""
    if path is None:
        return {}
    try:
        settings = read_settings_file(path, "config file")
    except ValueError as exc:
        raise UsageError(str(exc)) from exc
    if not isinstance(settings, dict):
        raise UsageError(
            f"config file {path!r} holds a {type(settings).__name__}; valid: a JSON object (or TOML table) of "
            f'settings by name, e.g. {{"steps": 1000, "stages": {{"Stage2": {{...}}}}}}'
        )
    return settings


def check_env_id(env_id: str) -> None:
    """A registered env id, else a :class:`UsageError` listing the valid ones."""
    if env_id not in gym.registry:
        tracks = [k for k in gym.registry if k.startswith("MPG-") and k not in mpg_envs.ENV_IDS]  # the tracks
        raise UsageError(f"unknown env id {env_id!r}; valid: {', '.join([*mpg_envs.ENV_IDS, *tracks])}")


def check_output(path: str | None, flag: str, inputs: Mapping[str, str | None] | None = None) -> None:
    """An output file's path, checked before any work: a regular file (or a new one) in a folder
    that exists and takes a new file (one is made and removed there: a read-only folder, a full
    disk or ``/proc`` is refused here, not after the work), and no file the command reads.

    Args:
        path: the output (``None``: none asked for).
        flag: how the message names it, e.g. ``"--json"``.
        inputs: the files the command reads, by what they are (``{"the --policy checkpoint":
            "v.safetensors"}``); an output that is one of them (through a link or another
            spelling too) is refused, as it would overwrite it.
    """
    if path is None:
        return
    for what, source in (inputs or {}).items():
        if source is not None and same_file(path, source):
            raise UsageError(f"{flag} {path!r} is {what}; write it to another file")
    if Path(path).is_dir():
        raise UsageError(f"{flag} {path!r} is a folder; give a file path")
    try:
        check_writable(path)
    except WriteFailed as exc:
        raise UsageError(f"{flag} {path!r}: {exc.reason}") from None


def check_checkpoint(path: str | None) -> None:
    """An existing MPGNet safetensors checkpoint, else a :class:`UsageError`: its header readable
    and whole (:func:`~mpg_agents.acting.weights.read_checkpoint_header`: config, branches, a
    Q*_g in range) and its tensors stored in the types it was written with
    (:func:`~mpg_agents.acting.weights.check_tensor_dtypes`); no tensor data is read."""
    if path is None:
        return
    if not Path(path).is_file():
        raise UsageError(f"checkpoint {path!r} does not exist")
    from mpg_agents.acting.weights import check_tensor_dtypes, read_checkpoint_header  # noqa: PLC0415

    try:
        check_tensor_dtypes(path, read_checkpoint_header(path))
    except ValueError as exc:  # each names the file and what is wrong with it
        raise UsageError(str(exc)) from exc
    except Exception as exc:  # safetensors raises its own types for foreign files
        raise UsageError(f"{path!r} is not an MPGNet safetensors checkpoint: {exc}") from exc


def check_q_star_flag(value: float | None, flag: str = "--q-star") -> None:
    """A Q*_g given on the command line, in :func:`~mpg_agents.acting.grasp_threshold.q_star_range`,
    else a :class:`UsageError` naming ``flag`` and the valid range (``None``: not given)."""
    from mpg_agents.acting.grasp_threshold import check_in_range  # noqa: PLC0415

    try:
        check_in_range(value, flag)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def check_net_setting(flag: str, field: str, value: Any) -> None:
    """A network setting given on the command line (``field`` of ``MPGNetConfig``, e.g.
    ``target_margin_px`` from ``--target-margin``) checked as the configuration checks it, before
    any work; a :class:`UsageError` names ``flag`` and what is valid (``None``: not given)."""
    if value is None:
        return
    from mpg_agents.network.mpgnet_config import MPGNetConfig  # noqa: PLC0415

    try:
        MPGNetConfig(**{field: value})
    except ValueError as exc:
        raise UsageError(f"{flag} {value}: {exc}") from None


def check_seed_flag(value: int | None, flag: str = "--seed") -> None:
    """A seed given on the command line in ``0..2**64 - 1``
    (:func:`~mpg_agents.acting.seeds.check_seed`), else a :class:`UsageError` naming ``flag``
    and the valid range (``None``: not given)."""
    if value is None:
        return
    try:
        check_seed(value, flag)
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def check_thread_setting() -> None:
    """``MPG_NUM_THREADS``, when set, a positive integer
    (:func:`mpg_envs.threads.requested_threads`), else a :class:`UsageError` naming it."""
    try:
        requested_threads()
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def check_env_options(env_id: str, options: Mapping[str, Any]) -> None:
    """The ``--env-option`` keywords of ``env_id`` checked before any work, by making its env
    once (no world is built; then closed): a :class:`UsageError` names the option and what is
    valid (a ``config`` of the wrong type or with a bad field, an ``object_set`` or
    ``camera_config`` of the wrong kind, ``render_mode=human`` without pygame)."""
    if not options:
        return
    from mpg_envs.tasks.env import MPGEnv  # noqa: PLC0415

    options = dict(options)
    if options.get("render_mode") == "human":
        if importlib.util.find_spec("pygame") is None:
            raise UsageError(
                "--env-option render_mode=human shows each frame in a window through pygame, which is not installed "
                "(pip install pygame); valid without it: render_mode=rgb_array, or no render_mode"
            )
        options["render_mode"] = "rgb_array"  # gym.make shows such an env's frames itself (HumanRendering)
    try:
        env = MPGEnv(**{**gym.spec(env_id).kwargs, **options})
    except (ValueError, TypeError) as exc:
        raise UsageError(f"--env-option: {exc}") from None
    env.close()
