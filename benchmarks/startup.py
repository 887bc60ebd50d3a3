"""Start-up time of the command lines: ``--help`` and a mistyped flag.

Each CLI imports only argparse-level modules before it parses its arguments (``mpg_agents``
loads torch and Stable-Baselines3 lazily), so help and argument errors should answer in
under 0.5 s on a quiet machine. Runs each command ``--repeats`` times in a fresh interpreter
and prints the median wall time per case; the last stdout line is JSON.

    python benchmarks/startup.py --repeats 7
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

CLIS = {
    "mpg-train": "mpg_agents.cli:train_main",
    "mpg-eval": "mpg_agents.cli:eval_main",
    "mpg-plot": "mpg_agents.cli:plot_main",
    "mpg-demo": "mpg_agents.demo:main",
}
GOAL_S = 0.5


def _command(entry: str, args: list[str]) -> list[str]:
    module, func = entry.split(":")
    # What the console script does, without depending on where pip put it.
    code = f"import sys; from {module} import {func}; sys.exit({func}(sys.argv[1:]))"
    return [sys.executable, "-c", code, *args]


def time_command(cmd: list[str], repeats: int) -> tuple[float, int]:
    """Median wall seconds of ``repeats`` runs and the exit status of the last."""
    times, status = [], 0
    for _ in range(repeats):
        start = time.perf_counter()
        status = subprocess.run(cmd, capture_output=True).returncode
        times.append(time.perf_counter() - start)
    return statistics.median(times), status


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    load = os.getloadavg()[0]
    results: dict[str, dict[str, float]] = {}
    baseline, _ = time_command([sys.executable, "-c", "pass"], args.repeats)
    for name, entry in CLIS.items():
        help_s, help_rc = time_command(_command(entry, ["--help"]), args.repeats)
        bad_s, bad_rc = time_command(_command(entry, ["--no-such-flag"]), args.repeats)
        if help_rc != 0 or bad_rc != 2:
            raise SystemExit(f"{name}: --help exited {help_rc} (want 0), a bad flag {bad_rc} (want 2)")
        results[name] = {"help_s": round(help_s, 3), "bad_flag_s": round(bad_s, 3)}
        print(f"{name:10s} --help {help_s:.3f} s   bad flag {bad_s:.3f} s")
    worst = max(max(r.values()) for r in results.values())
    print(f"python -c pass: {baseline:.3f} s; worst case {worst:.3f} s (goal < {GOAL_S} s); 1-min load {load:.2f}")
    print(json.dumps({"startup_s": results, "python_s": round(baseline, 3), "worst_s": round(worst, 3), "goal_s": GOAL_S, "load": round(load, 2)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
