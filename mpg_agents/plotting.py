"""Learning curves of ``mpg-train`` runs (the paper's Fig. "Learning curves"), drawn to PNG."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np


def read_progress(path: Path) -> dict[str, np.ndarray]:
    """Columns of a ``progress.csv`` as arrays (empty cells become NaN)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if not rows:
        raise ValueError(f"{path} has no iterations yet")
    out: dict[str, np.ndarray] = {}
    for key in rows[0]:
        values = [r[key] for r in rows]
        try:
            out[key] = np.array([float(v) if v != "" else np.nan for v in values])
        except ValueError:
            out[key] = np.array(values)
    return out


def window_success(data: dict[str, np.ndarray], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Target grasp success rate of the grasps in each ``window`` iterations (paper metric)."""
    it = data["iteration"]
    grasp = data["primitive"] == "grasp"
    xs, ys = [], []
    for start in range(0, int(it.max()), window):
        sel = grasp & (it > start) & (it <= start + window)
        if sel.any():
            xs.append(start + window)
            ys.append(float(data["target_grasped"][sel].mean()))
    return np.array(xs), np.array(ys)


def episode_motions(data: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Motions of each finished episode, at the iteration it ended."""
    ep = data["episode"]
    ends = np.flatnonzero(np.diff(ep) > 0)
    return data["iteration"][ends], data["num_motions"][ends]


def plot_run(run: str | Path, out: str | Path | None = None, window: int = 200) -> Path:
    """Draw success rate, loss, epsilon and motions per episode for a run or a pipeline."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    run = Path(run)
    if (run / "progress.csv").is_file():
        stages = [(run.name, run / "progress.csv")]
    else:
        stages = [(p.parent.name, p) for p in sorted(run.glob("Stage*/progress.csv"))]
    if not stages:
        raise FileNotFoundError(f"no progress.csv in {run} or its Stage*/ folders")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    offset = 0
    for name, path in stages:
        d = read_progress(path)
        x, y = window_success(d, window)
        axes[0, 0].plot(x + offset, y, marker="o", label=name)
        loss = d["loss"]
        ok = np.isfinite(loss)
        if ok.sum() > 1:
            k = min(50, int(ok.sum()))
            smooth = np.convolve(loss[ok], np.ones(k) / k, mode="valid")
            axes[0, 1].plot(d["iteration"][ok][k - 1 :] + offset, smooth, label=name)
        axes[1, 0].plot(d["iteration"] + offset, d["epsilon"], label=name)
        ex, ey = episode_motions(d)
        axes[1, 1].plot(ex + offset, ey, ".", alpha=0.5, label=name)
        offset += int(d["iteration"].max())
    axes[0, 0].set(title=f"target grasp success per {window} iterations", xlabel="iteration", ylim=(0, 1))
    axes[0, 1].set(title="Huber loss (moving average)", xlabel="iteration")
    axes[1, 0].set(title="epsilon", xlabel="iteration")
    axes[1, 1].set(title="motions per episode", xlabel="iteration")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(out) if out is not None else run / "curves.png"
    fig.savefig(out, dpi=100)
    plt.close(fig)
    return out
