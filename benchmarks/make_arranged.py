"""Write a set of arranged scenes (:mod:`mpg_envs.scenes.arrangement_draw`) drawn from consecutive
seeds: each drawn, settled and checked (every block where it was designed, the target's
visible fraction in its kind's band); a seed whose arrangement does not stand is skipped and
listed with the reason. Writes one scene file per kept seed, ``index.json`` (the scenes in
order, each with its note, as ``benchmarks/cases.py --sets FOLDER`` reads it) and
``arranged.json`` (the seeds tried, kept and skipped, and the kinds).

Arranged tuning scenes stand in for the peers' arranged cases while choosing (seeds
700000-; the peers' cases and the challenge set stay the tests):

    python benchmarks/make_arranged.py --seed 700000 --count 40 --out runs/arranged/tuning
    python benchmarks/cases.py --sets runs/arranged/tuning --policies oracle shipped --runs 1
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path

import gymnasium as gym

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_envs.scenes.arranged import ARRANGEMENT_KINDS, ArrangementError, settle_arrangement
from mpg_envs.scenes.arrangement_draw import draw_arrangement
from mpg_envs.scenes.cases import INDEX_FILE
from mpg_envs.scenes.scene_io import save_scene

ENV_ID = "MPG-Occluded-v0"


def make_set(seed: int, count: int, out: Path, kinds: tuple[str, ...] | None = None, max_tries: int | None = None) -> dict:
    """Keep ``count`` arranged scenes from seeds ``seed, seed + 1, ...`` in ``out`` (at most
    ``max_tries`` seeds, default ``4 * count``); returns what ``arranged.json`` records."""
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(ENV_ID, wrong_grasp="fail").unwrapped
    kept, skipped = [], []
    tries = max_tries if max_tries is not None else 4 * count
    s = seed
    try:
        while len(kept) < count and s < seed + tries:
            kind = None if not kinds else kinds[(s - seed) % len(kinds)]
            arrangement = draw_arrangement(s, env.config.workspace, kind=kind)
            try:
                scene, visible = settle_arrangement(env, arrangement)
            except ArrangementError as exc:
                skipped.append({"seed": s, "reason": str(exc)})
            else:
                save_scene(scene, out / f"{arrangement.name}.json")
                kept.append({"name": arrangement.name, "seed": s, "note": arrangement.note, "blocks": len(arrangement.blocks), "visible_fraction": round(visible, 3)})
            s += 1
    finally:
        env.close()
    (out / INDEX_FILE).write_text(json.dumps([{"name": k["name"], "note": k["note"]} for k in kept], indent=1) + "\n")
    record = {
        "first_seed": seed, "seeds_tried": s - seed, "kept": kept, "skipped": skipped,
        "kinds": dict(collections.Counter(k["name"].rsplit("-", 1)[0] for k in kept)),
    }  # fmt: skip
    (out / "arranged.json").write_text(json.dumps(record, indent=1) + "\n")
    return record


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=700000, help="first seed (700000-: tuning)")
    parser.add_argument("--count", type=int, default=40, help="scenes to keep")
    parser.add_argument("--out", required=True, help="folder for the scenes, index.json and arranged.json")
    parser.add_argument("--kinds", nargs="+", choices=ARRANGEMENT_KINDS, help="only these kinds, in turn (default: drawn per seed)")
    args = parser.parse_args(argv)
    if args.count < 1 or args.seed < 0:
        parser.error("--count must be at least 1 and --seed non-negative")
    start = time.perf_counter()
    record = make_set(args.seed, args.count, Path(args.out), tuple(args.kinds) if args.kinds else None)
    for reason in record["skipped"]:
        print(f"skipped seed {reason['seed']}: {reason['reason']}")
    print(f"kept {len(record['kept'])} of {record['seeds_tried']} seeds in {time.perf_counter() - start:.0f} s; kinds {record['kinds']}")
    return 0 if len(record["kept"]) == args.count else 1


if __name__ == "__main__":
    sys.exit(main())
