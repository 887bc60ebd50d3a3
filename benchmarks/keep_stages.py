"""Keep a training run's finished stages in the repository: the small files, not the replay.

A pipeline run folder holds, per stage, its weights, its curves data (``progress.csv``), its
Q*_g calibrations and ``done.json`` (the mark a resumed pipeline skips the stage by), beside a
replay state of tens of megabytes. This copies the small files of every finished stage, the
pipeline record and the log without its progress-bar lines, so a commit keeps what a later
session (maybe on another machine) needs to go on from the last finished stage:

    python benchmarks/keep_stages.py runs/generalize-s0 benchmarks/results/generalize/mpgnet-s0
    # later, elsewhere: copy the kept stages back and resume
    mkdir -p runs/generalize-s0 && cp -r benchmarks/results/generalize/mpgnet-s0/Stage* runs/generalize-s0/
    mpg-train --pipeline --config benchmarks/results/generalize/train.toml --out runs/generalize-s0 --seed 0

A stage in progress is left alone (its replay state cannot be kept this way): the resumed
run starts it again from the last finished stage's weights.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

STAGE_FILES = ("done.json", "weights.safetensors", "progress.csv", "calibration.json")
"""A finished stage's files that are kept (the ones that exist)."""

RUN_FILES = ("pipeline.json",)


def log_without_progress_bars(text: str) -> str:
    """``text`` without tqdm's carriage-return progress updates: each line's last segment, and
    no line that is only a progress bar."""
    kept = []
    for line in text.splitlines():
        last = line.split("\r")[-1]
        if "%|" in last and ("it/s" in last or "s/it" in last):
            continue
        if last.strip():
            kept.append(last)
    return "\n".join(kept) + ("\n" if kept else "")


def keep_stages(run: Path, dest: Path) -> list[str]:
    """Copy ``run``'s finished stages' small files, its pipeline record and its filtered log
    into ``dest``; returns the stage names kept."""
    if not run.is_dir():
        raise FileNotFoundError(f"no run folder {run}")
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
    log = run / "train.log"
    if log.is_file():
        dest.mkdir(parents=True, exist_ok=True)
        (dest / "train.log").write_text(log_without_progress_bars(log.read_text(errors="replace")))
    return kept


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="the pipeline's run folder (mpg-train --out)")
    parser.add_argument("dest", type=Path, help="where to keep its finished stages")
    args = parser.parse_args(argv)
    kept = keep_stages(args.run, args.dest)
    print(f"kept {', '.join(kept) or 'no finished stage'} of {args.run} in {args.dest}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
