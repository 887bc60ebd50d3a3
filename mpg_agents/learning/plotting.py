"""Learning curves of ``mpg-train`` runs (the paper's Fig. "Learning curves"), drawn to PNG."""

from __future__ import annotations

import csv
import io
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mpg_agents.learning.train_log import CSV_COLUMNS
from mpg_envs.files import written_whole
from mpg_envs.grid.primitive_specs import GRASP

# Matplotlib is imported where a picture is drawn, not at the top: importing
# this module (the command lines, reading progress.csv) then neither loads it (start-up time)
# nor sets its backend (Agg is chosen only when drawing, so a notebook keeps its own).


PLOTTED_COLUMNS = ("iteration", "episode", "primitive", "loss", "epsilon", "target_grasped", "num_motions")
"""The ``progress.csv`` columns the curves are drawn from (``is_success`` too, where a log has it)."""

TEXT_COLUMNS = ("primitive", "how")
"""The columns of words; every other column of :data:`~mpg_agents.learning.train_log.CSV_COLUMNS` holds numbers."""


def read_progress(path: str | Path) -> dict[str, np.ndarray]:
    """Columns of a ``progress.csv`` as arrays (numbers as floats, empty cells NaN; words as text).

    A last row cut short at the end of the file (the row a running training is writing) is left
    out with a warning naming it; any other damage is an error.

    Raises:
        ValueError: one line naming the file and what is wrong: not text, no iterations yet,
            a column the curves need missing, a row with too few or too many fields, or a
            number column (``iteration``, ``loss``, ...) holding something else.
    """
    path = Path(path)
    raw = path.read_bytes()
    nul = raw.find(b"\0")
    if nul >= 0:
        raise ValueError(f"{path} is not a text CSV file (binary data at byte {nul}); mpg-train writes progress.csv as text")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ValueError(
            f"{path} is not a text CSV file (byte {exc.start} is not UTF-8); mpg-train writes progress.csv as text"
        ) from None
    try:
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise ValueError(f"{path} is not a readable CSV file: {exc}") from None
    if not rows:
        raise ValueError(f"{path} is empty; mpg-train writes a header row first")
    header = rows[0]
    missing = [c for c in PLOTTED_COLUMNS if c not in header]
    if missing:
        raise ValueError(
            f"{path} lacks the columns {', '.join(missing)} that the curves are drawn from "
            f"(its header: {','.join(header)[:80]!r}); mpg-train's progress.csv has them"
        )
    body = rows[1:]
    if body and len(body[-1]) < len(header) and not text.endswith(("\n", "\r")):
        warnings.warn(
            f"{path} line {len(rows)}: the last row is cut short (a training still writing it?); left out", stacklevel=2
        )
        body = body[:-1]
    if not body:
        raise ValueError(f"{path} has no iterations yet")
    for n, row in enumerate(body, start=2):
        if len(row) != len(header):
            raise ValueError(
                f"{path} line {n}: {len(row)} fields where the header has {len(header)} (a truncated or damaged row)"
            )
    out: dict[str, np.ndarray] = {}
    for k, key in enumerate(header):
        values = [r[k] for r in body]
        if key in TEXT_COLUMNS:
            out[key] = np.array(values)
            continue
        try:
            out[key] = np.array([float(v) if v.strip() != "" else np.nan for v in values])
        except ValueError:
            if key in CSV_COLUMNS:
                n, text = next((i, v) for i, v in enumerate(values, start=2) if v.strip() != "" and not _is_number(v))
                raise ValueError(f"{path} line {n}: {key} is {text!r}, not a number") from None
            out[key] = np.array(values)  # a column of someone else's: kept as text
    iterations = out["iteration"]
    bad = np.flatnonzero(~np.isfinite(iterations) | (iterations != np.round(iterations)) | (iterations < 0))
    if bad.size:
        raise ValueError(
            f"{path} line {int(bad[0]) + 2}: iteration is {body[int(bad[0])][header.index('iteration')]!r}, "
            "not a whole number >= 0"
        )
    return out


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


PICTURE_FORMATS = ("png", "pdf", "svg", "jpg", "jpeg", "webp", "tif", "tiff", "gif", "eps", "ps")
"""The picture formats ``mpg-plot`` writes, by suffix (those matplotlib has here)."""


def check_image_path(out: str | Path | None) -> None:
    """A picture's path whose suffix names a format the figures can be written in (``.png``,
    ``.pdf``, ``.svg``, ...): the file is written at exactly that path (``None``: the default,
    ``curves.png``).

    Raises:
        ValueError: no suffix, or one no format has (the valid ones listed).
    """
    if out is None:
        return
    valid, suffix = image_suffixes(), Path(out).suffix
    if suffix.lower() not in valid:
        said = (
            f"its suffix {suffix!r} names no format the curves are written in"
            if suffix
            else "it has no suffix to name the picture's format"
        )
        raise ValueError(
            f"{str(out)!r}: {said}; end it with one of {', '.join(valid)} (e.g. {Path(out).stem or 'curves'}.png)"
        )


def image_suffixes() -> tuple[str, ...]:
    """The suffixes of the :data:`PICTURE_FORMATS` matplotlib writes here (``.png`` first)."""
    import matplotlib  # noqa: PLC0415 - see the note on matplotlib at the top

    matplotlib.use("Agg")
    from matplotlib.figure import Figure  # noqa: PLC0415

    kinds = Figure().canvas.get_supported_filetypes()
    return tuple("." + k for k in PICTURE_FORMATS if k in kinds)


def _save(fig, out: Path) -> None:
    """Write ``fig`` to exactly ``out``, whole or not at all, in the format its suffix names."""
    check_image_path(out)
    with written_whole(out) as tmp:
        fig.savefig(tmp, dpi=100, format=out.suffix[1:].lower())


def _window_means(at: np.ndarray, values: np.ndarray, last: int, window: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the ``values`` whose iteration ``at`` lies in each ``window`` iterations up to
    ``last``; each point at its window's last iteration (a partial last window ends at ``last``),
    no point for a window without values."""
    if window < 1:
        raise ValueError(f"window must be >= 1, got {window}")
    xs, ys = [], []
    for start in range(0, last, window):
        sel = (at > start) & (at <= start + window)
        if sel.any():
            xs.append(min(start + window, last))
            ys.append(float(values[sel].mean()))
    return np.array(xs), np.array(ys)


def _episode_ends(data: dict[str, np.ndarray]) -> np.ndarray:
    """Row indices where an episode ends: its last row (the episodes of parallel actors
    interleave). The episode of the run's last row, maybe unfinished, has none; with N actors
    the N - 1 others that may still run at the end count at their last rows."""
    episodes = np.asarray(data["episode"])
    if episodes.size == 0:
        return np.zeros(0, dtype=np.int64)
    _, from_end = np.unique(episodes[::-1], return_index=True)
    last = episodes.size - 1 - from_end
    return np.sort(last[episodes[last] != episodes[-1]])


def window_success(data: dict[str, np.ndarray], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Target grasp success rate of the grasps in each ``window`` iterations (paper metric).

    Each point sits at the last iteration of its window; a last, partial window counts the
    grasps it has (a run shorter than ``window`` gives one point, at its end).
    """
    grasp = data["primitive"] == GRASP
    last = int(np.nanmax(data["iteration"]))
    return _window_means(data["iteration"][grasp], data["target_grasped"][grasp], last, window)


def window_episode_success(data: dict[str, np.ndarray], window: int) -> tuple[np.ndarray, np.ndarray]:
    """Share of the training episodes ending in each ``window`` iterations that took the target.

    Each finished episode counts once, at its last row (the run's last episode, maybe
    unfinished, is left out); points sit where :func:`window_success` puts them, and a window
    in which no episode ended gives none. This counts what the grasp rate cannot: a run that
    grasps rarely but well has a high grasp rate and few successful episodes.
    """
    if "is_success" not in data:
        raise ValueError(f"episode success needs an is_success column; the progress has {sorted(data)}")
    ends = _episode_ends(data)
    last = int(np.nanmax(data["iteration"]))
    return _window_means(data["iteration"][ends], data["is_success"][ends], last, window)


def episode_motions(data: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Motions of each finished episode, at the iteration it ended."""
    ends = _episode_ends(data)
    return data["iteration"][ends], data["num_motions"][ends]


def plot_run(run: str | Path, out: str | Path | None = None, window: int = 200) -> Path:
    """Draw success rate, loss, epsilon and motions per episode for a run or a pipeline."""
    import matplotlib  # noqa: PLC0415 - see the note on matplotlib at the top

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    run = Path(run)
    if (run / "progress.csv").is_file():
        stages = [(run.name, run / "progress.csv")]
    else:
        stages = [(p.parent.name, p) for p in sorted(run.glob("Stage*/progress.csv"))]
    if not stages:
        raise FileNotFoundError(f"no progress.csv in {run} or its Stage*/ folders")
    fig, axes = plt.subplots(2, 2, figsize=(11, 7))
    offset = 0
    longest = 0
    no_loss = []
    for name, path in stages:
        d = read_progress(path)
        x, y = window_success(d, min(window, max(1, int(d["iteration"].max()))))
        axes[0, 0].plot(x + offset, y, marker="o", label=name)
        loss = d["loss"]
        ok = np.isfinite(loss)
        if ok.any():
            k = max(1, min(50, int(ok.sum()) // 5))  # a short run still gets a curve
            smooth = np.convolve(loss[ok], np.ones(k) / k, mode="valid")
            axes[0, 1].plot(d["iteration"][ok][k - 1 :] + offset, smooth, marker="." if len(smooth) < 20 else None, label=name)
        else:
            no_loss.append(name)
        axes[1, 0].plot(d["iteration"] + offset, d["epsilon"], label=name)
        ex, ey = episode_motions(d)
        axes[1, 1].plot(ex + offset, ey, ".", alpha=0.5, label=name)
        longest = max(longest, int(d["iteration"].max()))
        offset += int(d["iteration"].max())
    shown = min(window, longest)  # a run shorter than the window: one window of what there is
    note = "" if shown == window else f"\n(the run is shorter than the {window}-iteration window)"
    axes[0, 0].set(
        title=f"target grasp success per {shown} iterations{note}",
        xlabel="iteration",
        ylabel="success rate",
        ylim=(-0.02, 1.02),
    )
    axes[0, 1].set(title="Huber loss (moving average)", xlabel="iteration", ylabel="loss")
    if no_loss:
        axes[0, 1].text(
            0.5, 0.5, "no training steps yet in " + ", ".join(no_loss), ha="center", transform=axes[0, 1].transAxes
        )
    axes[1, 0].set(title="exploration epsilon", xlabel="iteration", ylabel="epsilon")
    axes[1, 1].set(title="motions per finished episode", xlabel="iteration (episode end)", ylabel="motions")
    for ax in axes.flat:
        ax.set_xlim(0, max(offset, 1))
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(out) if out is not None else run / "curves.png"
    try:
        _save(fig, out)
    finally:
        plt.close(fig)
    return out


def plot_compare(runs: Sequence[tuple[str, str | Path]], stage: str, out: str | Path, window: int = 200) -> Path:
    """One stage of several runs side by side: target grasp success per ``window`` iterations
    (left; the paper's ablation figure: MPGNet's Stage V beside its ablations at equal
    iterations) and the share of training episodes that took the target (right; runs whose
    progress has no ``is_success`` column are left out of it).

    ``runs`` are ``(label, pipeline or run directory)``; a pipeline contributes ``stage``'s
    folder, a single run its own ``progress.csv``.
    """
    import matplotlib  # noqa: PLC0415 - see the note on matplotlib at the top

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    if not runs:
        raise ValueError("plot_compare needs at least one run")
    fig, (grasps, episodes) = plt.subplots(1, 2, figsize=(12, 4.5))
    for label, run in runs:
        run = Path(run)
        path = run / stage / "progress.csv" if (run / stage / "progress.csv").is_file() else run / "progress.csv"
        if not path.is_file():
            raise FileNotFoundError(f"no {stage}/progress.csv or progress.csv in {run}")
        data = read_progress(path)
        grasps.plot(*window_success(data, window), marker="o", label=label)
        if "is_success" in data:
            episodes.plot(*window_episode_success(data, window), marker="o", label=label)
    grasps.set(
        title=f"{stage}: target grasp success per {window} iterations",
        xlabel="iteration",
        ylabel="target grasps / grasps",
        ylim=(-0.02, 1.02),
    )
    episodes.set(
        title=f"{stage}: training episodes that took the target, per {window} it.",
        xlabel="iteration",
        ylabel="successful episodes / episodes",
        ylim=(-0.02, 1.02),
    )
    for ax in (grasps, episodes):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(out)
    try:
        _save(fig, out)
    finally:
        plt.close(fig)
    return out


def plot_runs(
    runs: Sequence[str | Path],
    out: str | Path | None = None,
    window: int = 200,
    stage: str | None = None,
    labels: Sequence[str] | None = None,
) -> Path:
    """``mpg-plot``: one run or pipeline (:func:`plot_run`), or ``stage`` of several runs on one
    axis (:func:`plot_compare`, labelled by ``labels`` or the folder names); returns the picture's path."""
    if not stage and len(runs) == 1:
        return plot_run(runs[0], out, window)
    if not stage or not out:
        raise ValueError("comparing runs needs --stage and --out")
    labels = list(labels) if labels else [Path(r).name for r in runs]
    if len(labels) != len(runs):
        raise ValueError(f"--labels names {len(labels)} runs, {len(runs)} given")
    return plot_compare(list(zip(labels, runs)), stage, out, window)
