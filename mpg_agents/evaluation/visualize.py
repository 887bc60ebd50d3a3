"""Q-map pictures that explain a decision: every primitive's best Q map on one colour scale,
titled, with a colour bar in Q units and the chosen action drawn and named."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from mpg_agents.acting.agent import batch_observation
from mpg_envs.files import write_bytes_whole
from mpg_envs.grid.actions import PRIMITIVES, PixelAction, decode_action
from mpg_envs.grid.primitive_specs import GRASP, PUSH
from mpg_envs.grid.workspace import rotation_angle, rotation_direction

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


# Layout of the picture, in pixels: a title bar above the panels, a caption below, the
# colour bar on the right. Text uses OpenCV's Hershey simplex font.
HEADER_PX = 58
FOOTER_PX = 30
COLORBAR_PX = 110
FONT = cv2.FONT_HERSHEY_SIMPLEX
WHITE, GREY, BLACK = (255, 255, 255), (200, 200, 200), (0, 0, 0)


def action_label(action: PixelAction, q: float | None = None) -> str:
    """``"push at 90.0 deg, pixel (row 60, col 100), Q 0.812"``: the action in words."""
    degrees = math.degrees(rotation_angle(action.rotation))
    text = f"{action.primitive} at {degrees:.1f} deg, pixel (row {action.row}, col {action.col})"
    return text if q is None else f"{text}, Q {q:.3f}"


def _text(img: np.ndarray, text: str, origin: tuple[int, int], scale: float = 0.55, color=WHITE, bold: bool = False) -> None:
    cv2.putText(img, text, origin, FONT, scale, color, 2 if bold else 1, cv2.LINE_AA)


def _colorbar(height: int, lo: float, hi: float) -> np.ndarray:
    """A vertical JET colour bar for Q values ``lo``..``hi`` with five labelled ticks (BGR)."""
    bar = np.zeros((height, COLORBAR_PX, 3), np.uint8)
    top, bottom, x0, x1 = HEADER_PX, height - FOOTER_PX, 10, 30
    ramp = np.linspace(255, 0, bottom - top).astype(np.uint8)[:, None]
    bar[top:bottom, x0:x1] = cv2.applyColorMap(np.repeat(ramp, x1 - x0, axis=1), cv2.COLORMAP_JET)
    _text(bar, "Q value", (6, 16), 0.5, bold=True)
    _text(bar, "(max over", (6, 32), 0.4, GREY)
    _text(bar, "rotations)", (6, 46), 0.4, GREY)
    for f in np.linspace(0.0, 1.0, 5):
        y = int(round(bottom - 1 - f * (bottom - top - 1)))
        cv2.line(bar, (x1, y), (x1 + 4, y), WHITE, 1)
        _text(bar, f"{lo + f * (hi - lo):.3g}", (x1 + 7, y + 5), 0.42)
    return bar


def save_qmap_png(
    path: str | Path,
    obs: Mapping[str, Any],
    q_maps: Mapping[str, Any],
    action: Any = None,
    primitives: Sequence[str] | None = None,
    scale: int = 2,
    notes: Mapping[str, str] | None = None,
) -> Path:
    """Write a PNG that explains one decision: one panel per primitive, titled, on one colour scale.

    Each panel is the colour heightmap under that primitive's Q map (the max over rotations,
    JET colours), the target outlined in white. All panels share one colour scale, shown by
    the colour bar on the right in Q units. The chosen action is drawn on its panel (a black
    ring at the pixel and a white line along its rotation: push, an arrow of the 10 cm
    stroke; grasp/move, the fingers' closing line) and named in that panel's title and in
    the caption: primitive, angle, pixel and Q.

    Args:
        path: output file (``.png``).
        obs: a raw observation (its ``color``; the target ``mask`` is outlined).
        q_maps: ``{primitive: (R, H, W)}`` (or ``(1, R, H, W)``) Q maps, tensors or arrays.
        action: the chosen action: a flat index (decoded with ``primitives``), a
            ``PixelAction``/``Decision``, or ``None``.
        primitives: the action space's primitive order for a flat ``action`` (default: the
            keys of ``q_maps`` in canonical order).
        scale: integer upscaling of each heightmap panel.
        notes: ``{primitive: text}`` added to that panel's title (e.g. what masks its map).

    Returns:
        The written path. Panels start at row ``HEADER_PX``, side by side, each
        ``size * scale`` pixels square.
    """
    names = [p for p in PRIMITIVES if p in q_maps]
    if not names:
        raise ValueError(f"q_maps must have at least one of {PRIMITIVES}, got keys {sorted(q_maps)}")
    if int(scale) < 1:
        raise ValueError(f"scale must be a positive integer, got {scale!r}")
    color = _color_hwc(obs["color"])
    size = color.shape[0]
    side = size * scale
    chosen = _resolve_action(action, primitives if primitives is not None else names, size)
    if chosen is not None and chosen.primitive not in names:
        raise ValueError(f"the chosen action's primitive {chosen.primitive!r} has no Q map (maps: {names})")
    base = cv2.cvtColor(color, cv2.COLOR_RGB2BGR)
    mask = _as_numpy(obs["mask"]).reshape(size, size) > 0 if "mask" in obs else None
    best = {name: _best_map(q_maps[name]) for name in names}
    finite = [b[np.isfinite(b)] for b in best.values()]
    values = np.concatenate(finite) if any(v.size for v in finite) else np.zeros(1)
    lo, hi = float(values.min()), float(values.max())
    chosen_q = None
    if chosen is not None:
        chosen_q = float(_as_numpy(q_maps[chosen.primitive]).reshape(-1, size, size)[chosen.rotation, chosen.row, chosen.col])
    panels = []
    for name in names:
        q = np.nan_to_num(best[name], nan=lo, neginf=lo, posinf=hi)
        norm = np.zeros(q.shape, np.uint8) if hi - lo < 1e-12 else ((q - lo) / (hi - lo) * 255).astype(np.uint8)
        panel = cv2.addWeighted(base, 0.5, cv2.applyColorMap(norm, cv2.COLORMAP_JET), 0.5, 0.0)
        panel = cv2.resize(panel, (side, side), interpolation=cv2.INTER_NEAREST)
        if mask is not None and mask.any():
            contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(panel, [c * scale for c in contours], -1, WHITE, 1)
        header = np.zeros((HEADER_PX, side, 3), np.uint8)
        note = f" {notes[name]}" if notes and name in notes else ""
        top = best[name][np.isfinite(best[name])]
        _text(header, f"{name} Q map{note}, max {float(top.max()) if top.size else float('nan'):.3f}", (8, 22), 0.6, bold=True)
        if chosen is not None and chosen.primitive == name:
            _draw_action(panel, chosen, scale)
            _text(header, "chosen: " + action_label(chosen).split(" at ", 1)[1], (8, 46), 0.45)
        panels.append(np.concatenate([header, panel], axis=0))
    body = np.concatenate(panels, axis=1)
    footer = np.zeros((FOOTER_PX, body.shape[1], 3), np.uint8)
    caption = "chosen action: " + action_label(chosen, chosen_q) if chosen is not None else "no action chosen"
    legend = caption + "   (white outline: target)"
    fits = cv2.getTextSize(legend, FONT, 0.5, 1)[0][0] + 16 <= footer.shape[1]
    _text(footer, legend if fits else caption, (8, 20), 0.5)
    image = np.concatenate([body, footer], axis=0)
    image = np.concatenate([image, _colorbar(image.shape[0], lo, hi)], axis=1)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    encoded, data = cv2.imencode(path.suffix or ".png", image)  # the format the suffix names, as cv2.imwrite
    if not encoded:
        raise ValueError(f"could not encode the Q maps for {path} in the format of its suffix")
    write_bytes_whole(path, data.tobytes())  # whole or not at all: a full disk is a WriteFailed naming it
    return path


def save_policy_qmaps(path: str | Path, policy: Any, obs: Mapping[str, Any]) -> Path:
    """:func:`save_qmap_png` for an agent's decision on ``obs`` (an
    :class:`~mpg_agents.acting.agent.MPGAgent` or SB3's ``MPGNetPolicy``), with the Q maps of every
    primitive the network has (the decision itself may compute only some of them)."""
    decision = policy.decide(obs)
    net = policy.q_net.mpgnet
    obs_tensor, _ = batch_observation(obs, next(net.parameters()).device)
    notes = {}
    with torch.inference_mode():
        enc = net.encode(obs_tensor)
        maps = {name: q[0] for name, q in net.maps_from(enc, policy.usable_primitives).items()}
        if GRASP in maps and enc.grasp_fingers is not None:
            # Show only the grasps the finger mask keeps: the ones the policy chooses among.
            maps[GRASP] = maps[GRASP].masked_fill(~enc.grasp_fingers[0], float("-inf"))
            notes[GRASP] = "(fingers clear)"
    return save_qmap_png(path, obs, maps, decision, primitives=policy.action_primitives, notes=notes)


def _draw_action(panel: np.ndarray, action: PixelAction, scale: int) -> None:
    """Draw the action in image coordinates: x = column, y = row (rotation from +x toward +y)."""
    dx, dy = rotation_direction(action.rotation)
    cx, cy = (action.col + 0.5) * scale, (action.row + 0.5) * scale
    if action.primitive == PUSH:
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
