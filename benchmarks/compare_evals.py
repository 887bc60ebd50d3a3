"""Two policies on the same episodes: paired differences of success and motions.

    python benchmarks/compare_evals.py --a A_seeds500000.json A_seeds500050.json \
        --b B_seeds500000.json B_seeds500050.json [--names MPGNet,Grasping-Only]

Each side is one policy in one cell (env, object count): one or more ``mpg-eval --json`` files,
e.g. seed blocks run apart. Episodes are paired by their reset seed; only the seeds both sides
played count. Prints A minus B with 95% paired-bootstrap intervals (``mpg_agents.evaluation.comparison``),
and the motions' difference split by primitive (moves, pushes, grasps per episode).

Each side's files must be of one MuJoCo major version (their ``versions``; a file that records
none was measured on MuJoCo 3.x), and so must the two sides: ``--across-mujoco`` pairs a MuJoCo 4
cell with a 3.x one on the same seeds anyway, to measure what the MuJoCo version changes.
"""

from __future__ import annotations

import sys

from mpg_agents.evaluation.comparison import compare_main

if __name__ == "__main__":
    sys.exit(compare_main())
