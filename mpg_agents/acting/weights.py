"""MPGNet's weight file: safetensors tensors with one JSON header (architecture, Q*_g, extras).

Never unpickles anything. ``read_checkpoint_header`` reads the header alone (what the CLIs
check before building a network): its ``config`` and ``primitives`` must be there, ``extra`` a
mapping, and Q*_g a number in :func:`~mpg_agents.acting.grasp_threshold.q_star_range` or
``null``. ``check_tensor_dtypes`` reads each tensor's stored type (no tensor data): a file
re-saved with other types (float weights as int32) is refused. ``load_mpgnet_weights`` checks
both and the architecture first and names any mismatch, and refuses tensors with NaN or
infinite values; ``save_mpgnet`` refuses to write them.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save

from mpg_agents.acting.coordination import check_coordination
from mpg_agents.acting.grasp_threshold import UNCALIBRATED, as_record, check_in_range, exported_q_star
from mpg_agents.acting.spaces import finger_geometry
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet import MPGNet
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_envs import __version__
from mpg_envs.files import same_file, write_bytes_whole
from mpg_envs.grid.actions import check_primitives
from mpg_envs.simulation.mujoco_version import running_mujoco

CHECKPOINT_FORMAT = "mpgnet-safetensors-v1"


def checkpoint_metadata(
    net: MPGNet,
    q_star: float | None = UNCALIBRATED,
    extra: Mapping[str, Any] | None = None,
    config: MPGNetConfig | None = None,
) -> dict[str, str]:
    """The safetensors metadata header: one JSON document under key ``"mpgnet"``; its
    ``"q_star"`` is where a checkpoint stores Q*_g (:mod:`mpg_agents.acting.grasp_threshold`), its
    ``"package_version"`` the version of the package that wrote it and ``"mujoco_version"`` the
    MuJoCo it ran on (a net trained on one MuJoCo major version acts on scenes of another; the
    env id, with its version, a training run writes under ``extra``). ``config``: the configuration
    the checkpoint acts with, when it differs from ``net``'s in :data:`SETTINGS_WITHOUT_WEIGHTS` alone.

    Raises:
        ValueError: ``config`` differs from ``net``'s in a setting that has weights (named)."""
    if config is not None:
        theirs, mine = config.to_dict(), net.config.to_dict()
        changed = {k for k in set(theirs) | set(mine) if theirs.get(k) != mine.get(k)}
        weighty = sorted(changed - set(SETTINGS_WITHOUT_WEIGHTS))
        if weighty:
            raise ValueError(f"the checkpoint config differs from the net in {weighty}; only {SETTINGS_WITHOUT_WEIGHTS} may")
    header = {
        "format": CHECKPOINT_FORMAT,
        "package_version": __version__,
        "mujoco_version": running_mujoco(),
        "variant": net.config.variant,
        "primitives": list(net.primitives),
        "q_star": as_record(q_star),
        "config": (net.config if config is None else config).to_dict(),
    }
    if extra:
        header["extra"] = dict(extra)
    return {"mpgnet": json.dumps(header)}


def save_mpgnet(
    net: MPGNet,
    path: str | Path,
    q_star: float | None = UNCALIBRATED,
    extra: Mapping[str, Any] | None = None,
    config: MPGNetConfig | None = None,
) -> None:
    """Write ``net``'s weights (and BN statistics) to a safetensors file with a JSON header,
    whole or not at all (:func:`mpg_envs.files.write_bytes_whole`): a process killed meanwhile,
    or a full disk, leaves the old file whole. ``config``: see :func:`checkpoint_metadata`.

    Raises:
        ValueError: ``config`` changes a setting with weights.
        mpg_envs.files.WriteFailed: the file cannot be written (one line naming it and why).
    """
    state = {k: v.detach().cpu().contiguous() for k, v in net.state_dict().items()}
    check_finite(state, f"the MPGNet to be written to {path}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_whole(path, save(state, metadata=checkpoint_metadata(net, q_star, extra, config)))


def read_checkpoint_header(path: str | Path) -> dict[str, Any]:
    """The JSON header of an MPGNet safetensors file (no tensors are read)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"MPGNet checkpoint not found: {path}")
    try:
        with safe_open(str(path), framework="pt") as f:
            meta = f.metadata() or {}
    except Exception as exc:  # noqa: BLE001 - re-raised naming the file
        raise ValueError(f"{path} is not a safetensors file ({exc}); MPGNet weights are saved with save_weights()") from exc
    if "mpgnet" not in meta:
        raise ValueError(f"{path} has no 'mpgnet' metadata header; it was not written by save_mpgnet/save_weights")
    try:
        header = json.loads(meta["mpgnet"])
    except ValueError as exc:
        raise ValueError(f"{path}: its 'mpgnet' header is not JSON ({exc})") from exc
    if not isinstance(header, dict) or header.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(
            f"{path}: unsupported checkpoint format {header.get('format') if isinstance(header, dict) else header!r}, "
            f"expected {CHECKPOINT_FORMAT!r}"
        )
    for field in ("config", "primitives"):
        if field not in header:
            raise ValueError(
                f"{path}: its header has no {field!r} ({HEADER_FIELDS[field]}); it was not written by save_mpgnet/save_weights"
            )
    if not isinstance(header["config"], dict):
        raise ValueError(
            f"{path}: its header's 'config' is a {type(header['config']).__name__}; valid: {HEADER_FIELDS['config']}"
        )
    primitives = header["primitives"]
    if not isinstance(primitives, list) or not all(isinstance(p, str) for p in primitives):
        raise ValueError(f"{path}: its header's 'primitives' is {primitives!r}; valid: {HEADER_FIELDS['primitives']}")
    try:
        check_primitives(primitives)
    except ValueError as exc:
        raise ValueError(f"{path}: its header's 'primitives': {exc}") from None
    if not isinstance(header.get("extra", {}), dict):
        raise ValueError(
            f"{path}: its header's 'extra' is a {type(header['extra']).__name__}; valid: {HEADER_FIELDS['extra']}"
        )
    q_star = header.get("q_star")
    if q_star is not None:
        try:
            check_in_range(q_star, "its header's Q*_g (q_star)")
        except ValueError as exc:
            raise ValueError(f"{path}: {exc}, or null (never calibrated)") from None
    return header


HEADER_FIELDS: dict[str, str] = {
    "config": "a JSON object of MPGNetConfig fields, the network's settings",
    "primitives": 'a JSON list of the branches it holds, e.g. ["push", "grasp"]',
    "extra": "a JSON object (what training and export recorded), or none",
}
"""The header fields :func:`read_checkpoint_header` checks beyond the format and Q*_g, and
what each must be."""

_STORED_TYPES = {
    "F16": "float16",
    "BF16": "bfloat16",
    "F32": "float32",
    "F64": "float64",
    "I64": "int64",
    "I32": "int32",
    "I16": "int16",
    "I8": "int8",
    "U8": "uint8",
    "BOOL": "bool",
}


def stored_float_type(header: Mapping[str, Any]) -> str:
    """The floating type a checkpoint's weights are stored in: ``"float16"`` for an exported
    copy (its header's ``extra`` says ``float16``), else ``"float32"``, as training writes."""
    return "float16" if header.get("extra", {}).get("float16") else "float32"


def check_tensor_dtypes(path: str | Path, header: Mapping[str, Any] | None = None) -> None:
    """``ValueError`` naming the first tensor of the checkpoint at ``path`` stored in another
    type than written: weights in :func:`stored_float_type`, BatchNorm's batch counters
    (``*.num_batches_tracked``) in int64. Reads the types alone, no tensor data: a file whose
    float weights were re-saved as int32 would load as truncated weights."""
    header = read_checkpoint_header(path) if header is None else header
    floating = stored_float_type(header)
    with safe_open(str(path), framework="pt") as f:
        for key in f.keys():
            stored = f.get_slice(key).get_dtype()
            stored = _STORED_TYPES.get(stored, stored)
            expected = "int64" if key.endswith("num_batches_tracked") else floating
            if stored != expected:
                why = "its header says float16: an exported copy" if floating == "float16" else "as training writes weights"
                raise ValueError(
                    f"checkpoint {path}: tensor {key!r} is stored as "
                    f"{stored}, expected {expected} ({why}); the file was "
                    f"re-saved with other types: use the checkpoint as training or mpg-export wrote it"
                )


def check_finite(tensors: Mapping[str, Any], what: str) -> None:
    """``ValueError`` naming ``what`` and its floating tensors that hold NaN or infinite values."""
    bad = [k for k, t in tensors.items() if torch.is_floating_point(t) and not bool(torch.isfinite(t).all())]
    if bad:
        raise ValueError(
            f"{what} has NaN or infinite values in {len(bad)} tensor(s): {', '.join(bad[:5])}"
            f"{' ...' if len(bad) > 5 else ''}; weights must be finite (a diverged training?)"
        )


def load_mpgnet_weights(net: MPGNet, path: str | Path, strict_branches: bool = True) -> dict[str, Any]:
    """Load a :func:`save_mpgnet` file into ``net`` after checking the architectures match.

    Branches in the file that ``net`` does not have are ignored. With ``strict_branches=False``
    branches of ``net`` missing from the file keep their current weights (e.g. a Stage II
    grasp-only checkpoint starting Stage V); otherwise that is an error.

    Returns:
        The checkpoint header (variant, primitives, q_star, config).

    Raises:
        ValueError: naming the mismatch (variant, trunk depth, head width, a tensor's shape, a
            missing branch) when the file holds another architecture.
    """
    header = read_checkpoint_header(path)
    check_tensor_dtypes(path, header)
    file_cfg = header["config"]
    mine = net.config.to_dict()
    for key in ("variant", "trunk_depth", "head_channels", "num_rotations", "heightmap_size"):
        if file_cfg.get(key) != mine[key]:
            raise ValueError(
                f"checkpoint {path} has {key}={file_cfg.get(key)!r} but this network has {key}={mine[key]!r}; "
                "build the network with the checkpoint's configuration (MPGNetConfig.from_dict(header['config']))"
            )
    missing_branches = [p for p in net.primitives if p not in header["primitives"]]
    if missing_branches and strict_branches:
        raise ValueError(
            f"checkpoint {path} has branches {header.get('primitives')} but this network needs {list(net.primitives)} "
            f"(missing {missing_branches}); pass strict_branches=False to keep those branches' current weights"
        )
    state = load_file(str(path))
    check_finite(state, f"checkpoint {path}")
    own = net.state_dict()
    wanted = {}
    for key, target in own.items():
        if key.startswith("branches.") and key.split(".")[1] in missing_branches:
            continue
        if key not in state:
            raise ValueError(f"checkpoint {path} lacks tensor {key!r} that this {net.config.variant} MPGNet needs")
        if tuple(state[key].shape) != tuple(target.shape):
            raise ValueError(
                f"checkpoint {path}: tensor {key!r} has shape {tuple(state[key].shape)}, this network needs "
                f"{tuple(target.shape)}"
            )
        wanted[key] = state[key]
    net.load_state_dict(wanted, strict=False)
    return header


def load_mpgnet(
    path: str | Path, primitives: Sequence[str] | None = None, geometry: FingerGeometry | None = None
) -> tuple[MPGNet, dict[str, Any]]:
    """Build an MPGNet from a checkpoint's own configuration and load it.

    Args:
        path: a :func:`save_mpgnet` safetensors file.
        primitives: branches to keep (default: all the file has).
        geometry: the grasp geometry of the env it acts on, for finger masks (default: the
            default env's, :func:`~mpg_agents.acting.spaces.finger_geometry`).
    """
    header = read_checkpoint_header(path)
    cfg = MPGNetConfig.from_checkpoint(header["config"])
    if primitives is not None:
        cfg.primitives = check_primitives(primitives)
    if geometry is None and cfg.uses_finger_masks:
        geometry = finger_geometry()
    net = MPGNet(cfg, geometry)
    load_mpgnet_weights(net, path)
    return net, header


SETTINGS_WITHOUT_WEIGHTS: tuple[str, ...] = (
    "rough_mask",
    "grasp_region",
    "target_margin_px",
    "move_region",
    "move_band_m",
    "grasp_fingers",
    "move_fingers",
    "finger_tolerance_m",
)
"""Network settings that change where Q counts, not any weight: an exported checkpoint may
change them (:func:`export_weights`). The execution fields (``channels_last``,
``trunk_batch``) are not among them: loading takes those from the machine's variant defaults."""


def export_weights(
    src: str | Path,
    dst: str | Path,
    primitives: tuple[str, ...] | None = None,
    half: bool = True,
    settings: Mapping[str, Any] | None = None,
    coordination: str | None = None,
    q_star: float | None = None,
    grasp_retries: int | None = None,
) -> Path:
    """A lean copy of an MPGNet checkpoint for shipping: only ``primitives``' branches (and
    the shared mask trunk), floating tensors stored as float16 (loading casts them back).

    ``settings`` change :data:`SETTINGS_WITHOUT_WEIGHTS` in the copy's configuration (e.g. a
    move region measured better after training); the header's ``extra`` records them as
    ``settings_after_training``, so the copy never passes for what training used.
    ``coordination`` records the rule the copy acts with (:mod:`mpg_agents.acting.coordination`;
    default: the checkpoint's), for checkpoints written before the learner recorded it.
    ``q_star`` replaces Q*_g (e.g. one measured under the new settings); the header's ``extra``
    keeps training's as ``q_star_from_training`` (:func:`~mpg_agents.acting.grasp_threshold.exported_q_star`).
    ``grasp_retries`` records the copy's loop breaker for evaluation (a network policy pushes
    once after that many grasps in a row that did not take the target; 0: never), the default of
    :class:`~mpg_agents.evaluation.policy_zoo.NetworkPolicy`.
    """
    if grasp_retries is not None and (
        isinstance(grasp_retries, bool) or not isinstance(grasp_retries, int) or grasp_retries < 0
    ):
        raise ValueError(f"grasp_retries must be a non-negative integer (0: never push instead), got {grasp_retries!r}")
    if same_file(dst, src):
        raise ValueError(f"the copy {str(dst)!r} is the source checkpoint {str(src)!r}; write it to another file")
    settings = dict(settings or {})
    weighty = sorted(set(settings) - set(SETTINGS_WITHOUT_WEIGHTS))
    if weighty:
        raise ValueError(
            f"settings {weighty} change the architecture or its weights; only {SETTINGS_WITHOUT_WEIGHTS} may change"
        )
    net, header = load_mpgnet(src, primitives=primitives)
    if settings:
        net.config = MPGNetConfig.from_checkpoint(net.config.to_dict(), **settings)
    if half:
        net = net.half()
    q_star, extra = exported_q_star(header, q_star, {**header.get("extra", {}), "exported_from": str(src), "float16": half})
    if coordination is not None:
        extra["coordination"] = check_coordination(coordination)
    if grasp_retries is not None:
        extra["grasp_retries"] = grasp_retries
    if settings:
        extra["settings_after_training"] = {**extra.get("settings_after_training", {}), **settings}
    save_mpgnet(net, dst, q_star=q_star, extra=extra)
    return Path(dst)
