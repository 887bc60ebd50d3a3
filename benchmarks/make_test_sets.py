"""Generate the shipped test sets (``mpg_envs/test_scenes/*.npz``) of the test envs.

Every seed's scene is dropped as a fresh reset does (``use_test_set=False``), then rebuilt
from the saved poses in a second env and checked to give the identical observation (colour,
depth, mask, occlusion flag) and visible fraction, so the file reproduces the generated
start state exactly. Seeds run on a local process pool, one scene per task.

    python benchmarks/make_test_sets.py --envs MPG-Occluded-v0 MPG-OccludedHard-v0 \\
        --objects 15 30 --count 500 --workers 16 [--out mpg_envs/test_scenes]

Each set records the digest of the code and parameters that dropped it
(:func:`mpg_envs.tasks.scene_source.generator_digest`); a reset refuses a set whose digest is
not the running code's. ``--stamp K`` records the running code's digest in existing sets
without regenerating them, after checking that it drops their first ``K`` scenes identically
(same assets, bit-identical poses, same target); the scenes themselves are not rewritten.

A track on another object set (``MPG-OccludedHardNovel-v0``: ``object_set="random_urdfs_test"``)
gets its own files (``occluded_hard_novel_<objects>.npz``), recording the digest of the object
pack its scenes were made with.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401
from mpg_envs.scenes.test_sets import GENERATOR_VERSION, TEST_SEED_START, TestSet, load_test_set, test_set_name  # noqa: E402
from mpg_envs.simulation.random_urdfs import TEST_SET_NAME, test_pack_path  # noqa: E402
from mpg_envs.tasks.scene_source import generator_digest  # noqa: E402

_ENVS: dict[tuple[str, int, bool], gym.Env] = {}


def _env(env_id: str, num_objects: int, fixed: bool):
    key = (env_id, num_objects, fixed)
    if key not in _ENVS:
        _ENVS[key] = gym.make(env_id, num_objects=num_objects, use_test_set=False).unwrapped
    return _ENVS[key]


def make_scene(task: tuple[str, int, int]) -> dict:
    """Drop the scene of one seed and check that its saved poses reproduce it."""
    env_id, num_objects, seed = task
    start = time.perf_counter()
    env = _env(env_id, num_objects, False)
    obs, info = env.reset(seed=seed)
    scene = env.current_scene()
    check = _env(env_id, num_objects, True)
    obs2, info2 = check.reset(seed=seed, options={"scene": scene})
    same = all(np.array_equal(obs[k], obs2[k]) for k in obs) and info["visible_fraction"] == info2["visible_fraction"]
    if not same:
        raise RuntimeError(f"{env_id} {num_objects} objects seed {seed}: the saved poses do not reproduce the scene")
    return {
        "seed": seed,
        "assets": [o.asset.name for o in scene.objects],
        "positions": np.array([o.position for o in scene.objects], np.float64),
        "quats": np.array([o.quat for o in scene.objects], np.float64),
        "target": scene.target,
        "visible_fraction": info["visible_fraction"],
        "seconds": time.perf_counter() - start,
    }


def _object_pack_meta(object_set: str) -> dict[str, str]:
    """The digest of the packed objects a set's scenes were made with (tests check it against the shipped pack)."""
    if object_set != TEST_SET_NAME:
        return {}
    return {"object_pack": test_pack_path().name, "object_pack_sha256": hashlib.sha256(test_pack_path().read_bytes()).hexdigest()}


def set_name(env_id: str) -> str:
    """The name of the test sets of ``env_id`` (a stage's, on its object set)."""
    kwargs = gym.spec(env_id).kwargs
    return test_set_name(mpg_envs.STAGES[kwargs["stage"]].test_set, kwargs.get("object_set", "blocks"))


def stamp(env_ids: list[str], counts: list[int], out: Path, check: int, workers: int) -> int:
    """Record this code's generator digest in the sets of ``env_ids`` x ``counts`` under ``out``
    once their first ``check`` scenes drop identically; exit 1 (nothing written) if one does not."""
    cells = [(e, n, out / f"{set_name(e)}_{n}.npz") for e in env_ids for n in counts]
    sets = {path: load_test_set(path) for _, _, path in cells}
    tasks = [(e, n, int(seed)) for e, n, path in cells for seed in sets[path].seeds[:check]]
    with ProcessPoolExecutor(workers) as pool:
        made = list(pool.map(make_scene, tasks, chunksize=1))
    bad = []
    for (e, n, seed), scene in zip(tasks, made):
        ts = next(sets[path] for e2, n2, path in cells if (e2, n2) == (e, n))
        k = int(np.flatnonzero(ts.seeds == seed)[0])
        same = (
            list(ts.assets[k]) == scene["assets"] and np.array_equal(ts.positions[k], scene["positions"])
            and np.array_equal(ts.quats[k], scene["quats"]) and int(ts.targets[k]) == scene["target"]
        )
        print(f"{e} {n} objects seed {seed}: {'identical' if same else 'DIFFERENT'}", flush=True)
        bad += [] if same else [(e, n, seed)]
    if bad:
        print(f"not stamped: this code drops other scenes for {bad}; regenerate the sets instead")
        return 1
    for e, n, path in cells:
        ts = sets[path]
        meta = {**ts.meta, "generator_version": str(GENERATOR_VERSION), "generator_digest": generator_digest(_env(e, n, False).scene_request)}
        meta.pop("format", None)
        meta.pop("name", None)
        TestSet(ts.name, ts.num_objects, ts.seeds, ts.assets, ts.positions, ts.quats, ts.targets, ts.visible_fraction, meta).save(path)
        again = load_test_set(path)
        assert all(np.array_equal(getattr(again, f), getattr(ts, f)) for f in ("seeds", "assets", "positions", "quats", "targets", "visible_fraction"))
        print(f"{path}: stamped {meta['generator_digest']} (scenes unchanged)")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["MPG-Occluded-v0", "MPG-OccludedHard-v0"])
    parser.add_argument("--objects", type=int, nargs="+", default=[15, 30])
    parser.add_argument("--count", type=int, default=500, help="scenes per env and object count")
    parser.add_argument("--seed", type=int, default=TEST_SEED_START, help="first seed")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", default=str(Path(mpg_envs.__file__).parent / "test_scenes"))
    parser.add_argument("--stamp", type=int, metavar="K", help="record the digest in the existing sets after checking their first K scenes")
    args = parser.parse_args(argv)
    if args.stamp is not None:
        return stamp(args.envs, args.objects, Path(args.out), args.stamp, args.workers)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    tasks = [(e, n, args.seed + i) for e in args.envs for n in args.objects for i in range(args.count)]
    start = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        scenes = []
        for scene in pool.map(make_scene, tasks, chunksize=1):
            scenes.append(scene)
            if len(scenes) % 50 == 0:  # progress of long runs, in task order
                print(f"{len(scenes)}/{len(tasks)} scenes, {time.perf_counter() - start:.0f} s", flush=True)
    for env_id in args.envs:
        object_set = gym.spec(env_id).kwargs.get("object_set", "blocks")
        name = set_name(env_id)
        for n in args.objects:
            rows = [s for (e, m, _), s in zip(tasks, scenes) if e == env_id and m == n]
            test_set = TestSet(
                name=name,
                num_objects=n,
                seeds=np.array([r["seed"] for r in rows]),
                assets=np.array([r["assets"] for r in rows]),
                positions=np.stack([r["positions"] for r in rows]),
                quats=np.stack([r["quats"] for r in rows]),
                targets=np.array([r["target"] for r in rows]),
                visible_fraction=np.array([r["visible_fraction"] for r in rows], np.float32),
                meta={
                    "env_id": env_id,
                    "object_set": object_set,
                    **_object_pack_meta(object_set),
                    "generator_version": str(GENERATOR_VERSION),
                    "generator_digest": generator_digest(_env(env_id, n, False).scene_request),
                    "package_version": getattr(mpg_envs, "__version__", "unknown"),
                    "mujoco_version": mujoco.__version__,
                },
            )
            path = test_set.save(out / f"{name}_{n}.npz")
            secs = np.array([r["seconds"] for r in rows])
            vis = test_set.visible_fraction
            print(
                f"{path}: {len(rows)} scenes, generation median {np.median(secs):.2f} s/scene; visible fraction "
                f"median {np.median(vis):.2f}, quartiles {np.quantile(vis, 0.25):.2f}-{np.quantile(vis, 0.75):.2f}, "
                f"max {vis.max():.2f}; {path.stat().st_size / 1024:.0f} kB",
                flush=True,
            )
    print(f"{len(tasks)} scenes in {time.perf_counter() - start:.0f} s with {args.workers} workers")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
