"""Where a policy grasps and where it uncovers: its motions counted by primitive, the target's
cover and its visible fraction before each motion, from ``mpg-eval --json`` files.

    mpg-eval --policy shipped --env MPG-OccludedHardNovel-v0 --episodes 100 --seed 500000 --json net.json
    mpg-eval --policy oracle  --env MPG-OccludedHardNovel-v0 --episodes 100 --seed 500000 --json oracle.json
    python benchmarks/visibility_steps.py net.json oracle.json

One table per file (a row per primitive and cover, a column per visibility band, grasps with
how many took the target), and how often a move or push on a covered target uncovered it.
Files written before the evaluation recorded each motion are refused, naming them.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from mpg_agents.evaluation.motion_log import MotionRecord, motions_by_visibility, uncovering_outcomes, visibility_table


def file_table(path: Path) -> str:
    """The table of one ``mpg-eval --json`` file, under a line naming its policy and cell."""
    data = json.loads(path.read_text())
    records = data.get("records")
    if not isinstance(records, list) or not records:
        raise ValueError(f"{path} holds no episode records (an `mpg-eval --env ... --json` file is needed)")
    if any("steps" not in r for r in records):
        raise ValueError(f"{path} has no per-motion records (written by an older mpg-eval); evaluate again")
    episodes = [[MotionRecord.from_dict(m) for m in r["steps"]] for r in records]
    counts = motions_by_visibility(step for steps in episodes for step in steps)
    freed, counted = uncovering_outcomes(episodes)
    title = f"{data['policy']} on {data['env_id']} ({data.get('num_objects')} objects), {len(records)} episodes"
    share = f" ({100 * freed / counted:.0f}%)" if counted else ""
    uncovering = f"moves and pushes on a covered target that left it uncovered: {freed} of {counted}{share}"
    return f"{title}\n\n{visibility_table(counts, len(records))}\n\n{uncovering}\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("evals", nargs="+", type=Path, help="mpg-eval --json files")
    args = parser.parse_args(argv)
    try:
        tables = [file_table(p) for p in args.evals]
    except (OSError, ValueError, KeyError) as exc:
        print(f"visibility_steps: {exc}", file=sys.stderr)
        return 2
    print("\n".join(tables))
    return 0


if __name__ == "__main__":
    sys.exit(main())
