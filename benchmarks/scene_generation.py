"""Where generating a track's test scenes spends its time: draws per seed, time per draw
(compiling the world, the drop's physics, the start-condition check), and the check that the
saved poses reproduce the scene (what ``make_test_sets.py`` does per seed).

    python benchmarks/scene_generation.py --env MPG-OccludedHardNovel-v0 --objects 15 --seeds 5 [--seed 500000] \\
        [--config '{"generator": {"drop_settle_steps": 150}}']

One line per seed (draws, why each failed draw failed, seconds), then the totals. Timings are
wall time on one thread; a busy machine inflates them.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401
from mpg_envs.tasks import scene_source  # noqa: E402


class DrawLog:
    """Times each draw of ``drop_scene`` by wrapping the functions it calls (module attributes)."""

    def __init__(self, sim):
        self.sim = sim
        self.draws: list[dict] = []
        build, keep, accept = sim.build, scene_source.keep_inside, scene_source.acceptable_target

        def timed_build(assets):
            start = time.perf_counter()
            world = build(assets)
            self.draws.append({"build": time.perf_counter() - start, "start": time.perf_counter(), "result": "?"})
            return world

        def timed_keep(world, rng, layout, cfg):
            draw = self.draws[-1]
            draw["drop"] = time.perf_counter() - draw["start"]
            start = time.perf_counter()
            out = keep(world, rng, layout, cfg)
            draw["keep"] = time.perf_counter() - start
            draw["steps"], draw["physics"] = world.counter.steps, world.counter.seconds
            draw["result"] = "astray" if out is None else "dropped"
            return out

        def timed_accept(sim_, stage, band, candidates):
            start = time.perf_counter()
            out = accept(sim_, stage, band, candidates)
            draw = self.draws[-1]
            draw["check"] = time.perf_counter() - start
            draw["result"] = "valid" if out is not None else "no target"
            if out is None and candidates:  # how far the first candidate was from the band
                maps = sim_.heightmaps()
                mask, occluded = sim_.target_view(maps.depth, candidates[0])
                draw["visible"] = sim_.visible_fraction(maps, mask, candidates[0])
            return out

        sim.build = timed_build
        scene_source.keep_inside = timed_keep
        scene_source.acceptable_target = timed_accept


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="MPG-OccludedHardNovel-v0")
    parser.add_argument("--objects", type=int, default=15)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--seed", type=int, default=500000)
    parser.add_argument("--config", type=json.loads, help="EnvConfig fields as JSON (replaces the track's config), to try other settings")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    kwargs = {} if args.config is None else {"config": args.config}
    env = gym.make(args.env, num_objects=args.objects, use_test_set=False, **kwargs).unwrapped
    check = gym.make(args.env, num_objects=args.objects, use_test_set=False, **kwargs).unwrapped
    env.reset(seed=0 if args.seed else 1)  # loads the object set and compiles once: not a seed's cost
    print(f"{args.env} {args.objects} objects; first reset (loading) {time.perf_counter() - start:.1f} s")
    log = DrawLog(env.sim)
    rows = []
    for seed in range(args.seed, args.seed + args.seeds):
        log.draws.clear()
        t0 = time.perf_counter()
        obs, info = env.reset(seed=seed)
        t1 = time.perf_counter()
        obs2, _ = check.reset(seed=seed, options={"scene": env.current_scene()})
        t2 = time.perf_counter()
        same = all(np.array_equal(obs[k], obs2[k]) for k in obs)
        d = log.draws
        failed = {r: sum(x["result"] == r for x in d) for r in ("astray", "no target")}
        vis = [round(x["visible"], 2) for x in d if x.get("visible") is not None]
        rows.append((len(d), t1 - t0, t2 - t1, sum(x["build"] for x in d), sum(x.get("physics", 0) for x in d),
                     sum(x.get("steps", 0) for x in d), sum(x.get("check", 0) for x in d)))
        print(
            f"seed {seed}: {len(d)} draws ({failed['astray']} astray, {failed['no target']} no target; first candidate "
            f"visible {vis}), drop {t1 - t0:.1f} s (compile {rows[-1][3]:.1f}, physics {rows[-1][4]:.1f} s in "
            f"{rows[-1][5]} steps, check {rows[-1][6]:.2f}), reproduce {t2 - t1:.2f} s {'ok' if same else 'DIFFERENT'}; "
            f"visible {info['visible_fraction']:.2f}",
            flush=True,
        )
    a = np.array(rows)
    print(
        f"per seed: draws median {np.median(a[:, 0]):.0f} (max {a[:, 0].max():.0f}); seconds mean {a[:, 1].mean():.1f} "
        f"(+{a[:, 2].mean():.2f} reproduce); per draw {a[:, 1].sum() / a[:, 0].sum():.2f} s of which compile "
        f"{a[:, 3].sum() / a[:, 0].sum():.2f}, physics {a[:, 4].sum() / a[:, 0].sum():.2f} "
        f"({1000 * a[:, 4].sum() / max(a[:, 5].sum(), 1):.2f} ms/step, {a[:, 5].sum() / a[:, 0].sum():.0f} steps), "
        f"check {a[:, 6].sum() / a[:, 0].sum():.2f}; load average {os.getloadavg()[0]:.2f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
