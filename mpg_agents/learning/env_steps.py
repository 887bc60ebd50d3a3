"""The env steps a training run took, read from its folder: the budget runs are compared on.

Per stage folder (a single-stage run's folder, or each ``StageN/`` of a pipeline's):

- **iterations**: one env step of the acting policy each (the saved state's ``counters.json``);
- **demonstrations**: the oracle's env steps put into the replay, kept or dropped
  (``demonstrations.json``, :class:`~mpg_agents.learning.demonstrations.DemoStats`);
- **calibration grasps**: the greedy grasps of in-scene Q*_g calibrations (the ``grasps`` of each
  line of ``calibration.json``'s history; a ``calibrates_q_star`` stage's estimate reads its own
  training grasps and costs none).

Not counted: the trials a stage tries in the simulation and undoes (grasp, move, rival and
covered-grasp trials), which label the step taken rather than act, as in every run of this
project, and the env steps of a dataset a starting net was cloned from (give those as
``extra``: its model card names the episodes, the dataset their steps).
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from mpg_agents.learning.demonstrations import DEMONSTRATIONS_FILE
from mpg_agents.learning.run_state import COUNTERS_FILE, state_folder
from mpg_agents.learning.stage_calibration import CALIBRATION_FILE


@dataclass(frozen=True)
class StageSteps:
    """The env steps of one stage folder."""

    name: str
    iterations: int
    demonstrations: int
    calibration_grasps: int

    @property
    def total(self) -> int:
        return self.iterations + self.demonstrations + self.calibration_grasps


def stage_env_steps(folder: str | Path) -> StageSteps:
    """The env steps recorded in one stage's run folder.

    Raises:
        FileNotFoundError: ``folder`` holds no saved state (no training ran there).
    """
    folder = Path(folder)
    state = state_folder(folder)  # state.old when a kill landed between the two renames of a save
    if state is None:
        raise FileNotFoundError(f"{folder} is no stage run folder: it has no saved state")
    iterations = int(json.loads((state / COUNTERS_FILE).read_text())["iteration"])
    demos = folder / DEMONSTRATIONS_FILE
    demonstrations = int(json.loads(demos.read_text())["env_steps"]) if demos.is_file() else 0
    calibration = folder / CALIBRATION_FILE
    history = json.loads(calibration.read_text()).get("history", []) if calibration.is_file() else []
    return StageSteps(folder.name, iterations, demonstrations, sum(int(line["grasps"]) for line in history))


def run_env_steps(run: str | Path) -> list[StageSteps]:
    """Every stage of ``run``: a pipeline's folder (its stage folders, by name) or one stage's.

    Raises:
        FileNotFoundError: ``run`` is neither.
    """
    run = Path(run)
    if state_folder(run) is not None:
        return [stage_env_steps(run)]
    stages = sorted(p for p in run.iterdir() if p.is_dir() and state_folder(p) is not None) if run.is_dir() else []
    if not stages:
        raise FileNotFoundError(f"{run} holds no training run (no stage folder with a saved state)")
    return [stage_env_steps(p) for p in stages]


def format_env_steps(stages: Sequence[StageSteps], extra: int = 0) -> str:
    """A Markdown table of ``stages`` and their sum (plus ``extra`` steps taken elsewhere)."""
    rows = ["| stage | iterations | demonstrations | calibration grasps | env steps |", "| --- | ---: | ---: | ---: | ---: |"]
    rows += [f"| {s.name} | {s.iterations} | {s.demonstrations} | {s.calibration_grasps} | {s.total} |" for s in stages]
    if extra:
        rows.append(f"| elsewhere (a cloned net's dataset) | | {extra} | | {extra} |")
    total = sum(s.total for s in stages) + extra
    rows.append(
        f"| all | {sum(s.iterations for s in stages)} | {sum(s.demonstrations for s in stages) + extra} "
        f"| {sum(s.calibration_grasps for s in stages)} | {total} |"
    )
    return "\n".join(rows)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m mpg_agents.learning.env_steps RUN [--extra N]``: print the run's env steps."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", help="a pipeline's run folder or one stage's")
    parser.add_argument("--extra", type=int, default=0, help="env steps taken elsewhere (a cloned net's demonstrations)")
    args = parser.parse_args(argv)
    if args.extra < 0:
        parser.error(f"--extra must be >= 0, got {args.extra}")
    print(format_env_steps(run_env_steps(args.run), args.extra))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
