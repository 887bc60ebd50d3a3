"""Two policies on the same episodes: paired differences of success and motions.

    python benchmarks/compare_evals.py --a A_seeds500000.json A_seeds500050.json \
        --b B_seeds500000.json B_seeds500050.json [--names MPGNet,Grasping-Only]

Each side is one policy in one cell (env, object count): one or more ``mpg-eval --json`` files,
e.g. seed blocks run apart. Episodes are paired by their reset seed; only the seeds both sides
played count. Prints A minus B with 95% paired-bootstrap intervals (``mpg_agents.comparison``).
"""

from __future__ import annotations

import argparse
import sys

from mpg_agents.comparison import compare_paired, load_eval_records


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--a", nargs="+", required=True, help="mpg-eval --json files of policy A")
    parser.add_argument("--b", nargs="+", required=True, help="mpg-eval --json files of policy B")
    parser.add_argument("--names", help="two labels, comma-separated (default: the policies' names)")
    args = parser.parse_args(argv)
    try:
        a, b = load_eval_records(args.a), load_eval_records(args.b)
        names = args.names.split(",") if args.names else [a.policy, b.policy]
        if len(names) != 2:
            raise ValueError(f"--names takes two labels, got {args.names!r}")
        result = compare_paired(a, b)
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"{a.env_id}, {a.num_objects} objects; A = {names[0]}, B = {names[1]}")
    print(result.describe(names[0], names[1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
