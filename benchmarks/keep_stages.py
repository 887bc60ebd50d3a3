"""Keep a training run's finished stages in the repository: the small files, not the replay.

A pipeline run folder holds, per stage, its weights, its curves data (``progress.csv``), its
Q*_g calibrations and ``done.json`` (the mark a resumed pipeline skips the stage by), beside a
replay state of tens of megabytes. This copies the small files of every finished stage, the
pipeline record and the log without its progress-bar lines, so a commit keeps what a later
session (maybe on another machine) needs to go on from the last finished stage:

    mpg-train --pipeline --config ... --out runs/generalize-s0 --seed 0 > runs/generalize-s0.out 2>&1
    python benchmarks/keep_stages.py runs/generalize-s0 benchmarks/results/generalize/mpgnet-s0 \
        --log runs/generalize-s0.out
    # later, elsewhere: copy the kept stages back and resume
    mkdir -p runs/generalize-s0 && cp -r benchmarks/results/generalize/mpgnet-s0/Stage* runs/generalize-s0/
    mpg-train --pipeline --config benchmarks/results/generalize/train.toml --out runs/generalize-s0 --seed 0

A stage in progress is left alone (its replay state cannot be kept this way): the resumed
run starts it again from the last finished stage's weights.
"""

from __future__ import annotations

import argparse
import re
import shutil
import sys
from pathlib import Path

STAGE_FILES = ("done.json", "weights.safetensors", "progress.csv", "calibration.json")
"""A finished stage's files that are kept (the ones that exist)."""

RUN_FILES = ("pipeline.json",)


PROGRESS_BAR = re.compile(r"\S+:\s+\d+%\|[^|\n\r]*\|\s*\d+/\d+\s*\[[^\]\n\r]*(?:it/s|s/it)[^\]\n\r]*\]")
"""One tqdm progress update, e.g. ``Stage5:  13%|#3   | 197/1500 [04:23<33:46,  1.55s/it]``."""


def log_without_progress_bars(text: str) -> str:
    """``text`` without tqdm's progress updates: every bar is cut out wherever it stands (a
    message printed right after a bar, on the same line, is kept), carriage returns end
    lines, and lines left empty go."""
    kept = []
    for line in PROGRESS_BAR.sub("\n", text).replace("\r", "\n").splitlines():
        if line.strip():
            kept.append(line.rstrip())
    return "\n".join(kept) + ("\n" if kept else "")


def keep_stages(run: Path, dest: Path, log: Path | None = None) -> list[str]:
    """Copy ``run``'s finished stages' small files, its pipeline record and its log without
    progress bars (``log``, default ``run/train.log`` where it exists) into ``dest`` as
    ``dest/train.log``; returns the stage names kept.

    Raises:
        FileNotFoundError: no folder ``run``, or a ``log`` named that does not exist.
    """
    if not run.is_dir():
        raise FileNotFoundError(f"no run folder {run}")
    if log is not None and not log.is_file():
        raise FileNotFoundError(f"no log file {log} (the file mpg-train's output was written to)")
    kept = []
    for stage in sorted(p for p in run.iterdir() if p.is_dir() and (p / "done.json").is_file()):
        target = dest / stage.name
        target.mkdir(parents=True, exist_ok=True)
        for name in STAGE_FILES:
            if (stage / name).is_file():
                shutil.copy2(stage / name, target / name)
        kept.append(stage.name)
    for name in RUN_FILES:
        if (run / name).is_file():
            dest.mkdir(parents=True, exist_ok=True)
            shutil.copy2(run / name, dest / name)
    log = run / "train.log" if log is None else log
    if log.is_file():
        dest.mkdir(parents=True, exist_ok=True)
        (dest / "train.log").write_text(log_without_progress_bars(log.read_text(errors="replace")))
    return kept


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the pipeline's run folder (mpg-train --out)")
    parser.add_argument("dest", type=Path, help="where to keep its finished stages")
    parser.add_argument("--log", type=Path, default=None, help="the file the run's console output went to (default: RUN/train.log where it exists)")
    args = parser.parse_args(argv)
    kept = keep_stages(args.run, args.dest, args.log)
    print(f"kept {', '.join(kept) or 'no finished stage'} of {args.run} in {args.dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
