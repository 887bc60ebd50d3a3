"""How well the locator finds the target: pure numpy, unit-tested by hand.

The figures the model card and the benchmark give: intersection over union of the predicted
mask with the simulator's top-surface pixels, by how much of the target shows
(:data:`VISIBILITY_BANDS`), and how often "seen" is claimed for a target that does not show
at all (false claims) or denied for one that does.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

VISIBILITY_BANDS: tuple[tuple[float, float], ...] = ((0.0, 0.0), (0.0, 0.1), (0.1, 0.3), (0.3, 0.6), (0.6, 1.01))
"""Visible-fraction bands: hidden (exactly 0), then ``(low, high]``."""


def band_name(band: tuple[float, float]) -> str:
    """``"hidden"`` or ``"10-30%"`` style names of :data:`VISIBILITY_BANDS` entries."""
    low, high = band
    if high == 0.0:
        return "hidden"
    return f"{round(low * 100)}-{min(100, round(high * 100))}%"


def in_band(visible_fraction: float, band: tuple[float, float]) -> bool:
    """Whether ``visible_fraction`` lies in ``band`` (hidden: exactly 0; else ``(low, high]``)."""
    low, high = band
    if high == 0.0:
        return visible_fraction == 0.0
    return low < visible_fraction <= high


def iou(predicted: np.ndarray, label: np.ndarray) -> float:
    """Intersection over union of two boolean maps; 1.0 when both are empty."""
    predicted, label = np.asarray(predicted) > 0, np.asarray(label) > 0
    union = np.logical_or(predicted, label).sum()
    if union == 0:
        return 1.0
    return float(np.logical_and(predicted, label).sum() / union)


def locator_figures(
    predicted: Sequence[np.ndarray], seen: Sequence[bool], labels: Sequence[np.ndarray], visible: Sequence[float]
) -> dict[str, dict[str, float]]:
    """Per visibility band (:func:`band_name`): ``samples``, mean ``iou`` (bands where the target
    shows), and ``seen_rate`` (the share of samples where "seen" was claimed: false claims in
    the hidden band). ``"at least 30%"`` pools the two upper bands, the issue's criterion."""
    figures: dict[str, dict[str, float]] = {}
    groups: list[tuple[str, tuple[float, float] | None]] = [(band_name(b), b) for b in VISIBILITY_BANDS]
    groups.append(("at least 30%", None))
    for name, band in groups:
        picked = [i for i, v in enumerate(visible) if (float(v) >= 0.3 if band is None else in_band(float(v), band))]
        if not picked:
            continue
        entry = {"samples": float(len(picked)), "seen_rate": float(np.mean([bool(seen[i]) for i in picked]))}
        if name != "hidden":
            entry["iou"] = float(np.mean([iou(predicted[i], labels[i]) for i in picked]))
        figures[name] = entry
    return figures
