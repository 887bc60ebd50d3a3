"""Behaviour cloning by number of demonstrations: held-out success and motions, a table and a plot.

    python benchmarks/bc_table.py [--results benchmarks/results/bc] [--plot success_by_demos.png]

Reads every run folder ``RESULTS/<track>/bc<N>/`` holding ``weights.safetensors`` (an
``mpg-train --baseline bc`` checkpoint: its header names the demonstrations, the settings, the
steps and the wall time of training), ``bc_progress.csv`` (the seconds of each step) and
``heldout.json`` (``mpg-eval --json`` of that checkpoint on its own track's held-out seeds); each
further ``heldout_<name>.json`` is the same policy on another track's held-out seeds (the
unseen-object track, which no training may use) or under another MuJoCo (each evaluation
records its version; a row says which). Prints a Markdown table, one row per evaluated
track and number of demonstrations, and with ``--plot`` draws
held-out success against demonstrations (log scale, 95% intervals as bars). Nothing is run: the
runs and evaluations are the commands the Benchmark page gives.
"""

from __future__ import annotations

import argparse
import csv
import json
import statistics
import sys
from pathlib import Path
from typing import Any

from mpg_agents.acting.weights import read_checkpoint_header
from mpg_envs.simulation.mujoco_version import mujoco_major

EVAL = "heldout.json"
WEIGHTS = "weights.safetensors"
PROGRESS = "bc_progress.csv"


def read_runs(results: Path) -> list[dict[str, Any]]:
    """One row per evaluation of each run folder under ``results``, ordered by track and demos."""
    rows = []
    for weights in sorted(results.glob(f"*/bc*/{WEIGHTS}")):
        folder = weights.parent
        if not (folder / EVAL).is_file():
            raise FileNotFoundError(f"{folder} has {WEIGHTS} but no {EVAL}: evaluate it with mpg-eval --json")
        card = read_checkpoint_header(weights)["extra"]["imitation"]
        with open(folder / PROGRESS, newline="") as f:
            step_s = [float(row["step_s"]) for row in csv.DictReader(f)]
        for evaluation in sorted(folder.glob("heldout*.json")):
            rows.append(_row(card, json.loads(evaluation.read_text()), step_s))
    return sorted(rows, key=lambda r: (r["track"], r["trained_on"], r["mujoco"], r["demos"]))


def _row(card: dict[str, Any], ev: dict[str, Any], step_s: list[float]) -> dict[str, Any]:
    dataset = card["dataset"]
    objects = dict(dataset.get("env_kwargs") or {}).get("num_objects")
    return {
        "track": f"{ev['env_id']} ({ev['num_objects']} objects)",
        "trained_on": dataset["env_id"] + (f" ({objects} objects)" if objects else ""),
        "demos": int(card["demo_episodes"]),
        "samples": int(dataset["samples"]),
        "steps": int(card["steps"]),
        "wall_min": float(card["wall_time_s"]) / 60,
        "step_s": statistics.median(step_s) if step_s else float("nan"),
        "rotations": card.get("rotations_per_sample", 16),
        "turns": bool(card.get("quarter_turns", False)),
        "episodes": int(ev["episodes"]),
        "seed": int(ev["seed"]),
        "success": float(ev["task_success_rate"]),
        "interval": ev["success_interval"],
        "motions": float(ev["average_motions"]),
        "mispicks": float(ev["mispicks_per_episode"]),
        "mujoco": ev.get("versions", {}).get("mujoco", "3.x"),
    }


def markdown(rows: list[dict[str, Any]]) -> str:
    """The table the Benchmark page shows."""
    lines = [
        "| track | demonstrations of | MuJoCo | demonstrations (samples) | steps | s per step (median) | training (min) "
        "| held-out success [95%] | motions | mis-picks / episode |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in rows:
        lo, hi = r["interval"]
        run = f"{r['demos']} ({r['samples']}) | {r['steps']} | {r['step_s']:.2f} | {r['wall_min']:.0f}"
        lines.append(
            f"| {r['track']} | {r['trained_on']} | {r['mujoco']} | {run} "
            f"| {100 * r['success']:.0f}% [{100 * lo:.0f}, {100 * hi:.0f}] of {r['episodes']} "
            f"| {r['motions']:.2f} | {r['mispicks']:.2f} |"
        )
    return "\n".join(lines)


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """Held-out success against the number of demonstrations, one line per track (and MuJoCo major version)."""
    import matplotlib  # noqa: PLC0415 - only the plot needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    fig, ax = plt.subplots(figsize=(5, 3.4))
    majors = sorted({mujoco_major(r["mujoco"]) for r in rows})
    for track, trained_on, version in sorted({(r["track"], r["trained_on"], mujoco_major(r["mujoco"])) for r in rows}):
        mine = [r for r in rows if (r["track"], r["trained_on"], mujoco_major(r["mujoco"])) == (track, trained_on, version)]
        x = [r["demos"] for r in mine]
        y = [100 * r["success"] for r in mine]
        err = [
            [100 * (r["success"] - r["interval"][0]) for r in mine],
            [100 * (r["interval"][1] - r["success"]) for r in mine],
        ]
        own = track.split(" ")[0] == trained_on.split(" ")[0]
        label = track if own else f"{track}, copying {trained_on.split(' ')[0]}"
        label += f", MuJoCo {version}.x" if len(majors) > 1 else ""
        ax.errorbar(x, y, yerr=err, marker="o", capsize=3, label=label)
    ax.axhline(100, color="grey", linestyle="--", linewidth=1, label="the oracle it copies")
    ax.set_xscale("log")
    ticks = sorted({r["demos"] for r in rows})
    ax.set_xticks(ticks, [str(t) for t in ticks])
    ax.minorticks_off()
    ax.set_xlabel("demonstrations (oracle episodes)")
    ax.set_ylabel("held-out success (%)")
    ax.set_ylim(0, 105)
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2))  # below the axes: no curve hidden
    fig.savefig(path, dpi=120, bbox_inches="tight")
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, default=Path(__file__).parent / "results" / "bc")
    parser.add_argument("--plot", type=Path, default=None, help="also draw success against demonstrations here (.png)")
    args = parser.parse_args(argv)
    rows = read_runs(args.results)
    if not rows:
        print(f"no behaviour-cloning runs with {EVAL} under {args.results}", file=sys.stderr)
        return 1
    print(markdown(rows))
    settings = {(r["rotations"], r["turns"], r["seed"]) for r in rows}
    for rotations, turns, seed in sorted(settings):
        print(
            f"\nsettings: {rotations} rotations per sample, quarter turns {'on' if turns else 'off'}; "
            f"held-out seeds from {seed}"
        )
    if args.plot is not None:
        plot(rows, args.plot)
        print(f"plot: {args.plot}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
