"""The learner's log: one :class:`IterationRecord` per iteration to TensorBoard and ``progress.csv``.

``progress.csv`` (columns :data:`CSV_COLUMNS`) is what ``mpg-plot`` draws; it is appended to,
so a resumed run continues the same file. It goes with the run state: the learner makes the
rows durable (:meth:`TrainingLog.sync`) before it saves a state, and a run that starts from a
state of iteration ``n`` first rewrites the file to its header and rows 1..n, each once
(:func:`rewind_progress`, through a temporary file swapped in), so after a ``kill -9`` at any
moment and a resume the file holds every iteration exactly once. TensorBoard gets the loss,
epsilon, reward, iteration time, the windowed grasp success rate and, per episode, motions and
task success.
"""

from __future__ import annotations

import csv
import io
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mpg_envs.files import write_text_whole

CSV_COLUMNS = [
    "iteration",
    "episode",
    "primitive",
    "how",
    "reward",
    "loss",
    "epsilon",
    "grasp_success",
    "target_grasped",
    "is_success",
    "num_motions",
    "grasp_success_rate",
    "decide_s",
    "act_s",
    "iteration_s",
]


@dataclass(frozen=True)
class IterationRecord:
    """What happened in one training iteration."""

    iteration: int
    episode: int
    primitive: str
    chosen_by: str  # "greedy", "explore" or "heuristic" (the column "how")
    reward: float
    loss: float  # NaN when no gradient step was taken
    epsilon: float
    info: Mapping[str, Any]  # the env step's info (lifted, target_grasped, is_success, num_motions)
    decide_s: float
    act_s: float
    iteration_s: float
    grasp_success_rate: float | None = None  # set on the iterations that close a window

    def csv_row(self) -> list[Any]:
        info, rate = self.info, self.grasp_success_rate
        return [
            self.iteration,
            self.episode,
            self.primitive,
            self.chosen_by,
            f"{self.reward:.3f}",
            f"{self.loss:.5f}",
            f"{self.epsilon:.4f}",
            int(info["lifted"]),  # the column keeps its former name, grasp_success
            int(info["target_grasped"]),
            int(info["is_success"]),
            info["num_motions"],
            "" if rate is None else f"{rate:.4f}",
            f"{self.decide_s:.3f}",
            f"{self.act_s:.3f}",
            f"{self.iteration_s:.3f}",
        ]


def rewind_progress(path: str | Path, iteration: int) -> int:
    """Rewrite ``progress.csv`` to its header and the rows of iterations 1..``iteration``, each
    once, in order (rows after it, a half-written last row and repeats are dropped); written
    whole or not at all (:func:`mpg_envs.files.write_text_whole`), so a kill or a full disk
    meanwhile leaves the old file. Returns the rows
    kept; warns naming the iterations of 1..``iteration`` it lacks (a log written before its
    rows were made durable with the state, or edited by hand).
    """
    path = Path(path)
    rows: dict[int, list[str]] = {}
    if path.is_file():
        with open(path, newline="") as f:
            for row in csv.reader(f):
                if len(row) != len(CSV_COLUMNS) or not row[0].isdigit():
                    continue  # the header, or a row cut short by a kill
                it = int(row[0])
                if 1 <= it <= iteration and it not in rows:
                    rows[it] = row
    missing = [it for it in range(1, iteration + 1) if it not in rows]
    if missing:
        warnings.warn(
            f"{path} lacks the rows of {len(missing)} iterations ({missing[:5]}{' ...' if len(missing) > 5 else ''}) "
            f"that its saved state (iteration {iteration}) has done; they cannot be written again",
            stacklevel=2,
        )
    text = io.StringIO()
    writer = csv.writer(text)
    writer.writerow(CSV_COLUMNS)
    writer.writerows(rows[it] for it in sorted(rows))
    write_text_whole(path, text.getvalue())
    return len(rows)


class TrainingLog:
    """TensorBoard writer and CSV file of one run folder; use as a context manager.

    Args:
        run_dir: the run folder.
        iteration: the iteration the run starts from (its saved state's; 0 for a fresh run):
            ``progress.csv`` is first rewound to it (:func:`rewind_progress`).
    """

    def __init__(self, run_dir: str | Path, iteration: int = 0) -> None:
        # Start-up time: TensorBoard loads torch; the logs and plots are read without it.
        from torch.utils.tensorboard import SummaryWriter  # noqa: PLC0415

        run_dir = Path(run_dir)
        path = run_dir / "progress.csv"
        rewind_progress(path, iteration)
        self.writer = SummaryWriter(str(run_dir / "tb"))
        self._file = open(path, "a", newline="")
        self._csv = csv.writer(self._file)

    def sync(self) -> None:
        """Make every row written so far durable (before a run state that counts them is saved)."""
        self._file.flush()
        os.fsync(self._file.fileno())

    def record(self, rec: IterationRecord) -> None:
        w, it = self.writer, rec.iteration
        w.add_scalar("train/loss", rec.loss, it)
        w.add_scalar("train/epsilon", rec.epsilon, it)
        w.add_scalar("train/reward", rec.reward, it)
        w.add_scalar("time/iteration_s", rec.iteration_s, it)
        if rec.grasp_success_rate is not None:
            w.add_scalar("train/grasp_success_rate", rec.grasp_success_rate, it)
        self._csv.writerow(rec.csv_row())

    def episode_end(self, iteration: int, info: Mapping[str, Any]) -> None:
        self.writer.add_scalar("train/motions_per_episode", info["num_motions"], iteration)
        self.writer.add_scalar("train/task_success", float(info["is_success"]), iteration)

    def close(self) -> None:
        self._file.close()
        self.writer.close()

    def __enter__(self) -> TrainingLog:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
