"""The case tables: several policies on the challenge, Efficient Push-Grasping and Grasping
the Invisible case sets (:mod:`mpg_envs.scenes.cases`), in strict retrieval, printed as Markdown.

One table per case set: a row per case and an overall row, the target's mean visible
fraction at reset, a column per policy; each cell is ``successes/runs · mean motions ·
mis-picks per run``. Runs follow
:mod:`mpg_agents.evaluation.case_runs` (run 0 as written, the others jittered; seeded per case), so a
cell is reproducible on its own. ``--json`` also writes every result (rows and records).

    python benchmarks/cases.py --peers PATH/TO/PEERS [--sets challenge epg gti] \\
        [--policies oracle pixel-heuristic random shipped] [--runs 3] [--json cases.json]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

from mpg_agents.evaluation.case_runs import CaseRow, CaseRunResult, run_case_set  # noqa: E402
from mpg_envs.scenes.cases import CASE_SETS, load_cases  # noqa: E402

POLICIES = ("oracle", "pixel-heuristic", "random", "shipped")


def cell(row: CaseRow) -> str:
    """``successes/runs · mean motions · mis-picks per run``."""
    return f"{row.successes}/{row.runs} · {row.mean_motions:.1f} · {row.mis_picks:.2f}"


def markdown(set_name: str, results: list[CaseRunResult]) -> str:
    """One case set's table: a row per case, the overall row, a column per policy."""
    header = ["case", "visible", *(r.policy for r in results)]
    lines = [f"**{set_name}** (successes/runs · mean motions · mis-picks per run)", "",
             "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for k, row in enumerate(results[0].rows):
        lines.append("| " + " | ".join([row.case, row.cells()[1], *(cell(r.rows[k]) for r in results)]) + " |")
    lines.append("| " + " | ".join(["**overall**", results[0].overall.cells()[1], *(f"**{cell(r.overall)}**" for r in results)]) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", nargs="+", default=list(CASE_SETS), help=f"case sets or scene paths (default: {' '.join(CASE_SETS)})")
    parser.add_argument("--policies", nargs="+", default=list(POLICIES), help="policies (mpg-eval --policy names or checkpoints)")
    parser.add_argument("--runs", type=int, default=3, help="runs per case")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--peers", help="the folder holding the peers' files (vpg/, gti/), for epg and gti")
    parser.add_argument("--env", default="MPG-Occluded-v0")
    parser.add_argument("--json", help="also write every result to this JSON file")
    args = parser.parse_args(argv)
    try:
        sets = [load_cases(name, args.peers) for name in args.sets]
    except ValueError as exc:
        parser.error(str(exc))
    everything = {}
    for case_set in sets:
        results = []
        for policy in args.policies:
            start = time.perf_counter()
            result = run_case_set(policy, case_set, args.runs, args.seed, args.env)
            print(f"{case_set.name} / {result.policy}: {cell(result.overall)} ({time.perf_counter() - start:.0f} s)", file=sys.stderr, flush=True)
            results.append(result)
        everything[case_set.name] = [r.to_dict() for r in results]
        print(markdown(case_set.name, results) + "\n", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(everything, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
