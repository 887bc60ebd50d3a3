"""Q-map pictures: the colour heightmap with each primitive's best Q map and the chosen action."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import cv2
import numpy as np
import torch

from mpg_envs.actions import PRIMITIVES, PixelAction, decode_action
from mpg_envs.workspace import rotation_direction

# Drawn lengths in pixels at the 2 mm heightmap resolution: the 10 cm push stroke and the
# 2F-85's 85 mm opening across which the fingers close.
PUSH_LENGTH_PX = 50
GRIPPER_OPENING_PX = 42


def _as_numpy(x: Any) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().float().cpu().numpy()
    return np.asarray(x)


def _unbatched(arr: np.ndarray, ndim: int, what: str) -> np.ndarray:
    """``arr`` without a leading batch of one (``ndim`` + 1 dimensions); a larger batch is an error."""
    if arr.ndim == ndim + 1:
        if arr.shape[0] != 1:
            raise ValueError(f"save_qmap_png draws one observation; got {what} of shape {arr.shape}")
        arr = arr[0]
    return arr


def _color_hwc(color: Any) -> np.ndarray:
    img = _unbatched(_as_numpy(color), 3, "a colour batch")
    if img.ndim == 3 and img.shape[0] == 3 and img.shape[-1] != 3:
        img = img.transpose(1, 2, 0)
    if img.ndim != 3 or img.shape[-1] != 3:
        raise ValueError(f"colour heightmap must be (H, W, 3) or (3, H, W), got {img.shape}")
    return np.clip(img, 0, 255).astype(np.uint8)


def _best_map(q: Any) -> np.ndarray:
    arr = _unbatched(_as_numpy(q), 3, "Q maps for a batch")
    if arr.ndim != 3:
        raise ValueError(f"a primitive's Q maps must be (R, H, W), got shape {arr.shape}")
    return arr.max(axis=0)


def _resolve_action(action: Any, primitives: Sequence[str], size: int) -> PixelAction | None:
    if action is None:
        return None
    if hasattr(action, "primitive") and hasattr(action, "rotation"):
        return PixelAction(action.primitive, int(action.rotation), int(action.row), int(action.col))
    return decode_action(primitives, np.asarray(action).reshape(()).item(), size=size)


def save_qmap_png(
    path: str | Path,
    obs: Mapping[str, Any],
    q_maps: Mapping[str, Any],
    action: Any = None,
    primitives: Sequence[str] | None = None,
    scale: int = 2,
) -> Path:
    """Write a PNG with one panel per primitive: colour heightmap + max-over-rotations Q heatmap.

    Args:
        path: output file (``.png``).
        obs: a raw observation (its ``color``; the target ``mask`` outline is drawn too).
        q_maps: ``{primitive: (R, H, W)}`` (or ``(1, R, H, W)``) Q maps, tensors or arrays.
        action: the chosen action: a flat index (decoded with ``primitives``), a
            ``PixelAction``/``Decision``, or ``None``. It is drawn on its primitive's panel: a
            circle at the pixel and a line along rotation ``k`` (push: an arrow of the 10 cm
            stroke; grasp/move: the fingers' closing line).
        primitives: the action space's primitive order for a flat ``action`` (default: the
            keys of ``q_maps`` in canonical order).
        scale: integer upscaling of each panel for readability.

    Returns:
        The written path.
    """
    names = [p for p in PRIMITIVES if p in q_maps]
    if not names:
        raise ValueError(f"q_maps must have at least one of {PRIMITIVES}, got keys {sorted(q_maps)}")
    color = _color_hwc(obs["color"])
    size = color.shape[0]
    chosen = _resolve_action(action, primitives if primitives is not None else names, size)
    base = cv2.cvtColor(color, cv2.COLOR_RGB2BGR)
    mask = _as_numpy(obs["mask"]).reshape(size, size) > 0 if "mask" in obs else None
    panels = []
    for name in names:
        best = _best_map(q_maps[name])
        lo, hi = float(best.min()), float(best.max())
        norm = (
            np.zeros_like(best, dtype=np.uint8) if hi - lo < 1e-12 else ((best - lo) / (hi - lo) * 255).astype(np.uint8)
        )
        heat = cv2.applyColorMap(norm, cv2.COLORMAP_JET)
        panel = cv2.addWeighted(base, 0.5, heat, 0.5, 0.0)
        panel = cv2.resize(panel, (size * scale, size * scale), interpolation=cv2.INTER_NEAREST)
        if mask is not None and mask.any():
            contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(panel, [c * scale for c in contours], -1, (255, 255, 255), 1)
        label = f"{name}  Q max {hi:.3f}"
        if chosen is not None and chosen.primitive == name:
            _draw_action(panel, chosen, scale)
            chosen_q = _as_numpy(q_maps[name]).reshape(-1, size, size)[chosen.rotation, chosen.row, chosen.col]
            label += f"  chosen {float(chosen_q):.3f}"
        cv2.putText(panel, label, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        panels.append(panel)
    image = np.concatenate(panels, axis=1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), image):
        raise OSError(f"could not write {path}")
    return path


def _draw_action(panel: np.ndarray, action: PixelAction, scale: int) -> None:
    """Draw the action in image coordinates: x = column, y = row (rotation from +x toward +y)."""
    dx, dy = rotation_direction(action.rotation)
    cx, cy = (action.col + 0.5) * scale, (action.row + 0.5) * scale
    if action.primitive == "push":
        end = (int(round(cx + dx * PUSH_LENGTH_PX * scale)), int(round(cy + dy * PUSH_LENGTH_PX * scale)))
        cv2.arrowedLine(panel, (int(round(cx)), int(round(cy))), end, (255, 255, 255), 2, cv2.LINE_AA, tipLength=0.2)
    else:
        half = GRIPPER_OPENING_PX * scale / 2.0
        a = (int(round(cx - dx * half)), int(round(cy - dy * half)))
        b = (int(round(cx + dx * half)), int(round(cy + dy * half)))
        cv2.line(panel, a, b, (255, 255, 255), 2, cv2.LINE_AA)
        for end in (a, b):  # the two fingers
            cv2.circle(panel, end, max(2, scale * 2), (255, 255, 255), -1, cv2.LINE_AA)
    cv2.circle(panel, (int(round(cx)), int(round(cy))), max(3, int(math.ceil(scale * 2))), (0, 0, 0), 2, cv2.LINE_AA)
