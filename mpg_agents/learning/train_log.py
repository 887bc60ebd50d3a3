"""The learner's log: one :class:`IterationRecord` per iteration to TensorBoard and ``progress.csv``.

``progress.csv`` (columns :data:`CSV_COLUMNS`) is what ``mpg-plot`` draws; it is appended to,
so a resumed run continues the same file. TensorBoard gets the loss, epsilon, reward,
iteration time, the windowed grasp success rate and, per episode, motions and task success.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

CSV_COLUMNS = [
    "iteration", "episode", "primitive", "how", "reward", "loss", "epsilon", "grasp_success", "target_grasped",
    "is_success", "num_motions", "grasp_success_rate", "decide_s", "act_s", "iteration_s",
]


@dataclass(frozen=True)
class IterationRecord:
    """What happened in one training iteration."""

    iteration: int
    episode: int
    primitive: str
    how: str  # "greedy", "explore" or "heuristic"
    reward: float
    loss: float  # NaN when no gradient step was taken
    epsilon: float
    info: Mapping[str, Any]  # the env step's info (grasp_success, target_grasped, is_success, num_motions)
    decide_s: float
    act_s: float
    iteration_s: float
    grasp_success_rate: float | None = None  # set on the iterations that close a window

    def csv_row(self) -> list[Any]:
        info, rate = self.info, self.grasp_success_rate
        return [
            self.iteration, self.episode, self.primitive, self.how, f"{self.reward:.3f}", f"{self.loss:.5f}",
            f"{self.epsilon:.4f}", int(info["grasp_success"]), int(info["target_grasped"]), int(info["is_success"]),
            info["num_motions"], "" if rate is None else f"{rate:.4f}", f"{self.decide_s:.3f}", f"{self.act_s:.3f}",
            f"{self.iteration_s:.3f}",
        ]


class TrainingLog:
    """TensorBoard writer and CSV file of one run folder; use as a context manager."""

    def __init__(self, run_dir: str | Path) -> None:
        from torch.utils.tensorboard import SummaryWriter

        run_dir = Path(run_dir)
        self.writer = SummaryWriter(str(run_dir / "tb"))
        path = run_dir / "progress.csv"
        new = not path.exists()
        self._file = open(path, "a", newline="")
        self._csv = csv.writer(self._file)
        if new:
            self._csv.writerow(CSV_COLUMNS)

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

    def __enter__(self) -> "TrainingLog":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
