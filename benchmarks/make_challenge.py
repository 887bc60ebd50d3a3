"""Build the shipped challenge set (``mpg_envs/challenge``) from its readable specs.

Each case is a list of blocks (a shape of the ``blocks`` set, a position in millimetres from
the workspace centre, a yaw in degrees, lying as built or on its side) and the target among
them. The blocks are stacked in the order listed: each one's lowest point is put just above
whatever is already under its footprint. The scene then goes through the env's own loading
path (:func:`mpg_envs.scenes.scene_loading.load_scene`: placed, settled until at rest) and is
checked: every block still within the loading tolerance of its designed pose (so nothing
toppled), the target's visible fraction in the case's band, and the saved file reproducing
the settled scene exactly. ``--oracle`` also runs the oracle on each case in strict
retrieval (a mis-pick fails) and reports it; every case must be solved. Writes one JSON scene
per case (``mpg_envs.scenes.scene_io.save_scene``) and ``index.json`` (the cases in order, each with
its note).

    python benchmarks/make_challenge.py [--out mpg_envs/challenge] [--only NAME ...] [--oracle] [--runs N]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

import mpg_envs  # noqa: F401  (registers the envs)
from mpg_envs.scenes.arranged import Arrangement, Block, arrangement_scene, settle_arrangement
from mpg_envs.scenes.cases import INDEX_FILE, challenge_dir, jitter_scene
from mpg_envs.scenes.scene_io import read_scene, save_scene
from mpg_envs.scenes.scene_loading import pose_errors

ENV_ID = "MPG-Occluded-v0"
Spec = Arrangement  # a case is an arrangement written by hand (mpg_envs.scenes.arranged)


def ring(shape: str, radius: float, count: int, start: float = 0.0) -> tuple[Block, ...]:
    """``count`` blocks on a circle of ``radius`` mm around the centre, each facing it."""
    angles = [start + 360.0 * k / count for k in range(count)]
    return tuple(Block(shape, radius * math.cos(math.radians(a)), radius * math.sin(math.radians(a)), a) for a in angles)


SPECS: tuple[Spec, ...] = (
    Spec("tower", "a two-block tower stands on the target: take it down block by block", 0, (
        Block("cube", 0, 0), Block("flat_box", 0, 0, 90), Block("cube", 0, 0, 20),
    ), (0.0, 0.2)),
    Spec("cross-cover", "fully hidden under two flat boxes laid crosswise: only the mask says where it is", 0, (
        Block("disc", 0, 0), Block("flat_box", 0, 0), Block("flat_box", 0, 0, 90),
    ), (0.0, 0.0)),
    Spec("bridge", "under a bridge of two tall pillars and a span: the span stops the gripper coming down", 0, (
        Block("disc", 0, 0), Block("tall_box", 0, 50), Block("tall_box", 0, -50), Block("long_box", 0, 0, 90),
    ), (0.1, 0.9)),
    Spec("low-arch", "lying in a low arch of two cubes and a span, 2 mm clear on each side: lift the span first", 0, (
        Block("tall_box", 0, 0, 90, side=True), Block("cube", 0, 49), Block("cube", 0, -49), Block("long_box", 0, 0, 90),
    ), (0.1, 0.9)),
    Spec("boxed-in", "boxed in by eight tall blocks, 1-2 mm away on every side and corner", 0, (
        Block("cube", 0, 0), Block("tall_box", 48, 0), Block("tall_box", -48, 0), Block("tall_box", 0, 48),
        Block("tall_box", 0, -48), Block("tall_box", 50, 50), Block("tall_box", -50, 50), Block("tall_box", 50, -50),
        Block("tall_box", -50, -50),
    ), (0.9, 1.0)),
    Spec("wall", "a long box against a wall of tall blocks: its only grasp, across it, puts a finger in the wall", 0, (
        Block("long_box", 0, 0), Block("tall_box", -48, 41), Block("tall_box", 0, 41), Block("tall_box", 48, 41),
    ), (0.9, 1.0)),
    Spec("far-edge", "at the far edge of the workspace behind five tall blocks: a push or a nudge outward loses it", 0, (
        Block("cube", 196, 0), Block("tall_box", 148, 0), Block("tall_box", 196, 49), Block("tall_box", 196, -49),
        Block("tall_box", 148, 48), Block("tall_box", 148, -48),
    ), (0.9, 1.0)),
    Spec("corner", "in a corner of the workspace behind three tall blocks", 0, (
        Block("cylinder", 196, 196), Block("tall_box", 149, 196), Block("tall_box", 196, 149), Block("tall_box", 149, 149),
    ), (0.9, 1.0)),
    Spec("ring", "standing in a closed ring of six cylinders of its own height, 1.6 mm apart", 0, (
        Block("cylinder", 0, 0),
    ) + ring("cylinder", 50, 6), (0.9, 1.0)),
    Spec("twin", "1.6 mm from an identical cube (same shape and colour), both hemmed in: only the mask tells them apart, and lifting the twin fails", 0, (
        Block("cube", 0, 0), Block("cube", 0, 53), Block("long_box", 0, -45), Block("tall_box", -48, 0),
        Block("tall_box", 48, 0), Block("tall_box", -48, 50), Block("tall_box", 48, 50),
    ), (0.9, 1.0)),
    Spec("sandwich", "the middle one of three flat boxes, the top one across it: take the top one, and not the one below", 1, (
        Block("flat_box", 0, 0), Block("flat_box", 0, 0), Block("flat_box", 0, 0, 90),
    ), (0.05, 0.6)),
    Spec("crowd", "a lying cylinder in a tight crowd of ten blocks, 1-2 mm from its neighbours on every side", 0, (
        Block("cylinder", 0, 0, 0, side=True), Block("cube", -76, 55), Block("long_box", 0, 55), Block("cube", 76, 55),
        Block("tall_box", -60, -55), Block("flat_box", 0, -58), Block("cube", 64, -55), Block("disc", -52, 0),
        Block("disc", 52, 0), Block("triangular_prism", -145, 50, 90), Block("arch", 140, -60),
    ), (0.9, 1.0)),
)
"""The challenge cases, in order."""


# ------------------------------------------------------------------------------ building
def build(spec: Arrangement, env, out: Path) -> dict:
    """Settle, check and write one case; returns what was measured."""
    settled, visible = settle_arrangement(env, spec)
    obs = env.last_observation
    moved = float(np.nanmax(pose_errors(env.world, arrangement_scene(spec, env.config.workspace))[0]))
    path = save_scene(settled, out / f"{spec.name}.json")
    obs2, _ = env.reset(options={"scene": str(path)})
    if not all(np.array_equal(obs[k], obs2[k]) for k in obs):
        raise RuntimeError(f"{spec.name}: the saved file does not reproduce the settled scene")
    return {"name": spec.name, "visible_fraction": round(visible, 3), "settled_mm": round(1000 * moved, 2)}


def oracle_runs(name: str, path: Path, env, runs: int) -> list[tuple[bool, int, str, float]]:
    """The oracle on ``runs`` jittered runs of a case: (success, motions, end reason, seconds) each."""
    from mpg_envs.policies.oracle import OraclePolicy

    scene = read_scene(path)
    oracle = OraclePolicy(env)
    results = []
    for run in range(runs):
        start = time.perf_counter()
        obs, _ = env.reset(seed=run, options={"scene": jitter_scene(scene, run, name, env.unwrapped.config.workspace)})
        oracle.reset()
        done, info = False, {}
        while not done:
            obs, _, terminated, truncated, info = env.step(oracle.act(obs))
            done = terminated or truncated
        results.append((bool(info["is_success"]), int(info["num_motions"]), str(info.get("end_reason")), time.perf_counter() - start))
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", default=str(challenge_dir()), help="folder to write the scenes and index.json to")
    parser.add_argument("--only", nargs="*", help="build only these cases (index.json still lists them all)")
    parser.add_argument("--oracle", action="store_true", help="also run the oracle on each case (strict retrieval)")
    parser.add_argument("--runs", type=int, default=1, help="oracle runs per case (run 0 as written, the others jittered)")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    env = gym.make(ENV_ID, wrong_grasp="fail")
    unknown = set(args.only or ()) - {s.name for s in SPECS}
    if unknown:
        parser.error(f"unknown cases {sorted(unknown)}; valid: {[s.name for s in SPECS]}")
    failed = 0
    for spec in SPECS:
        if args.only and spec.name not in args.only:
            continue
        made = build(spec, env.unwrapped, out)
        line = f"{spec.name:<12} visible {made['visible_fraction']:.2f}, settled {made['settled_mm']:.1f} mm"
        if args.oracle:
            runs = oracle_runs(spec.name, out / f"{spec.name}.json", env, args.runs)
            wins = sum(r[0] for r in runs)
            failed += wins < len(runs)
            line += f"; oracle {wins}/{len(runs)} in {np.mean([r[1] for r in runs]):.1f} motions ({', '.join(r[2] for r in runs)}; {sum(r[3] for r in runs):.0f} s)"
        print(line, flush=True)
    (out / INDEX_FILE).write_text(json.dumps([{"name": s.name, "note": s.note} for s in SPECS], indent=1) + "\n")
    env.close()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
