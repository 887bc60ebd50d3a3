"""Generate the shipped test sets (``mpg_envs/test_scenes/*.npz``) of the test envs.

Every seed's scene is dropped as a fresh reset does (``use_test_set=False``), then rebuilt
from the saved poses in a second env and checked to give the identical observation (colour,
depth, mask, occlusion flag) and visible fraction, so the file reproduces the generated
start state exactly. Blocks of ``--block`` seeds run on a local process pool; each finished
block is written to a shard file in ``--work`` (default ``build/test_set_work``), so a killed
run started again with the same arguments makes only the blocks not yet done; a line per
block gives the rate and the time left. The sets are written from the shards once all are
made (``--partial``: now, from the finished blocks from the first seed on, making nothing); the
scenes of an existing set in ``--out`` made by the same generator count as made, so a partial
set that was shipped is resumed too.

    python benchmarks/make_test_sets.py --envs MPG-Occluded-v0 MPG-OccludedHard-v0 \\
        --objects 15 30 --count 500 --workers 16 [--out mpg_envs/test_scenes] [--work DIR] [--partial]

Each set records the digest of the code and parameters that dropped it
(:func:`mpg_envs.tasks.scene_source.generator_digest`) and the generator settings
(:func:`mpg_envs.scenes.test_sets.generator_meta`); a reset refuses a set whose digest is not
the running code's, and a shard made by other code is refused too (delete it). ``--stamp K``
records the running code's digest in existing sets without regenerating them, after checking
that it drops their first ``K`` scenes identically (same assets, bit-identical poses, same
target); the scenes themselves are not rewritten.

A track on another object set (``MPG-OccludedHardNovel-v0``: ``object_set="random_urdfs_test"``)
gets its own files (``occluded_hard_novel_<objects>.npz``), recording the digest of the object
pack its scenes were made with.
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import os
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPG_NUM_THREADS", "1")

import gymnasium as gym  # noqa: E402
import mujoco  # noqa: E402
import numpy as np  # noqa: E402

import mpg_envs  # noqa: E402,F401
from mpg_envs.scenes.test_sets import GENERATOR_VERSION, TEST_SEED_START, TestSet, generator_meta, load_test_set, test_set_name  # noqa: E402
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


def _shard_path(work: Path, name: str, n: int, seeds: list[int]) -> Path:
    return work / f"{name}_{n}_{seeds[0]}-{seeds[-1]}.npz"


def make_block(task: tuple[str, int, list[int], str, str]) -> tuple[str, int, list[int], float]:
    """Make the scenes of a block of seeds and write them to a shard (atomically: a killed run
    leaves whole shards only); returns the cell, the seeds and the seconds taken."""
    env_id, n, seeds, path, digest = task
    start = time.perf_counter()
    rows = [make_scene((env_id, n, seed)) for seed in seeds]
    tmp = Path(path).with_suffix(".tmp.npz")
    np.savez_compressed(
        tmp, digest=np.array(digest), seeds=np.array(seeds, np.int64), assets=np.array([r["assets"] for r in rows]),
        positions=np.stack([r["positions"] for r in rows]), quats=np.stack([r["quats"] for r in rows]),
        targets=np.array([r["target"] for r in rows], np.int16), visible_fraction=np.array([r["visible_fraction"] for r in rows], np.float64),
        seconds=np.array([r["seconds"] for r in rows]),
    )  # fmt: skip
    os.replace(tmp, path)
    return env_id, n, seeds, time.perf_counter() - start


def read_shard(path: Path, digest: str, seeds: list[int]) -> dict[str, np.ndarray] | None:
    """A finished shard's arrays; ``None`` when it does not exist. Raises naming the file when
    it holds other seeds or was made by another generator (its scenes would not be this code's)."""
    if not path.is_file():
        return None
    with np.load(path, allow_pickle=False) as data:
        rows = {k: data[k] for k in data.files}
    if str(rows["digest"]) != digest or rows["seeds"].tolist() != seeds:
        raise SystemExit(
            f"{path}: made by another generator (digest {rows['digest']}, this code's {digest}) or for other seeds; "
            f"delete it (or the whole work folder) to make its scenes again"
        )
    return rows


def shards_from_set(path: Path, blocks: list[tuple[list[int], Path, str]]) -> None:
    """Count the scenes of an existing set at ``path`` made by the same generator (a partial
    set written with ``--partial``) as made: each block it holds whole, and has no shard of,
    gets one from it, so a run resumes from a shipped partial set too."""
    if not path.is_file():
        return
    made = load_test_set(path)
    for seeds, shard, digest in blocks:
        same = made.meta.get("generator_digest") == digest and made.meta.get("generator_version") == str(GENERATOR_VERSION)
        if not same or shard.exists() or not all(made.has_seed(s) for s in seeds):
            continue
        k = [int(np.flatnonzero(made.seeds == s)[0]) for s in seeds]
        np.savez_compressed(
            shard, digest=np.array(digest), seeds=np.array(seeds, np.int64), assets=made.assets[k], positions=made.positions[k],
            quats=made.quats[k], targets=made.targets[k], visible_fraction=made.visible_fraction[k].astype(np.float64),
            seconds=np.full(len(seeds), np.nan),  # not recorded in a set
        )  # fmt: skip


def write_set(env_id: str, n: int, shards: list[dict[str, np.ndarray]], out: Path) -> Path:
    """Merge a cell's shards (in seed order) into its test-set file and print its summary."""
    object_set = gym.spec(env_id).kwargs.get("object_set", "blocks")
    name = set_name(env_id)
    env = _env(env_id, n, False)
    test_set = TestSet(
        name=name,
        num_objects=n,
        seeds=np.concatenate([r["seeds"] for r in shards]),
        assets=np.concatenate([r["assets"] for r in shards]),
        positions=np.concatenate([r["positions"] for r in shards]),
        quats=np.concatenate([r["quats"] for r in shards]),
        targets=np.concatenate([r["targets"] for r in shards]),
        visible_fraction=np.concatenate([r["visible_fraction"] for r in shards]).astype(np.float32),
        meta={
            "env_id": env_id,
            "object_set": object_set,
            **_object_pack_meta(object_set),
            "generator_version": str(GENERATOR_VERSION),
            "generator_digest": generator_digest(env.scene_request),
            **generator_meta(env.config.generator),
            "package_version": getattr(mpg_envs, "__version__", "unknown"),
            "mujoco_version": mujoco.__version__,
        },
    )
    path = test_set.save(out / f"{name}_{n}.npz")
    secs = np.concatenate([r["seconds"] for r in shards])
    secs = secs[np.isfinite(secs)]  # scenes taken from an earlier set have no time
    timing = f"generation median {np.median(secs):.2f} s/scene (mean {secs.mean():.2f})" if secs.size else "no generation times"
    vis = test_set.visible_fraction
    print(
        f"{path}: {len(test_set)} scenes, {timing}; visible "
        f"fraction median {np.median(vis):.2f}, quartiles {np.quantile(vis, 0.25):.2f}-{np.quantile(vis, 0.75):.2f}, "
        f"max {vis.max():.2f}; {path.stat().st_size / 1024:.0f} kB",
        flush=True,
    )
    return path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["MPG-Occluded-v0", "MPG-OccludedHard-v0"])
    parser.add_argument("--objects", type=int, nargs="+", default=[15, 30])
    parser.add_argument("--count", type=int, default=500, help="scenes per env and object count")
    parser.add_argument("--seed", type=int, default=TEST_SEED_START, help="first seed")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", default=str(Path(mpg_envs.__file__).parent / "test_scenes"))
    parser.add_argument("--work", default="build/test_set_work", help="folder of the finished blocks of seeds (a run resumes from them)")
    parser.add_argument("--block", type=int, default=10, help="seeds per block (one shard file each)")
    parser.add_argument("--partial", action="store_true", help="make nothing: write each set from its finished blocks (the seeds from the first on, up to the first missing block)")
    parser.add_argument("--stamp", type=int, metavar="K", help="record the digest in the existing sets after checking their first K scenes")
    args = parser.parse_args(argv)
    if args.stamp is not None:
        return stamp(args.envs, args.objects, Path(args.out), args.stamp, args.workers)
    if args.count < 1 or args.block < 1 or args.workers < 1:
        parser.error("--count, --block and --workers must be at least 1")
    out, work = Path(args.out), Path(args.work)
    out.mkdir(parents=True, exist_ok=True)
    work.mkdir(parents=True, exist_ok=True)
    cells = [(e, n) for e in args.envs for n in args.objects]
    blocks: dict[tuple[str, int], list[tuple[list[int], Path, str]]] = {}
    for e, n in cells:
        digest = generator_digest(_env(e, n, False).scene_request)
        seeds = list(range(args.seed, args.seed + args.count))
        chunks = [seeds[k : k + args.block] for k in range(0, len(seeds), args.block)]
        blocks[(e, n)] = [(c, _shard_path(work, set_name(e), n, c), digest) for c in chunks]
        shards_from_set(out / f"{set_name(e)}_{n}.npz", blocks[(e, n)])
    if args.partial:
        for (e, n), bs in blocks.items():
            shards = list(itertools.takewhile(lambda r: r is not None, (read_shard(p, d, c) for c, p, d in bs)))
            if shards:
                write_set(e, n, shards, out)
            print(f"{e} {n} objects: {sum(len(r['seeds']) for r in shards)} of {args.count} scenes made", flush=True)
        return 0
    todo = [(e, n, c, str(p), d) for (e, n), bs in blocks.items() for c, p, d in bs if read_shard(p, d, c) is None]
    total = len(cells) * args.count
    remaining = sum(len(t[2]) for t in todo)
    print(f"{total - remaining}/{total} scenes already made (in {work}); making {remaining} with {args.workers} workers", flush=True)
    start, made = time.perf_counter(), 0
    with ProcessPoolExecutor(args.workers) as pool:
        for env_id, n, seeds, seconds in (f.result() for f in as_completed([pool.submit(make_block, t) for t in todo])):
            made += len(seeds)
            elapsed = time.perf_counter() - start
            rate = made / elapsed
            print(
                f"{env_id} {n} objects seeds {seeds[0]}-{seeds[-1]}: {seconds / len(seeds):.1f} s/scene; {total - remaining + made}/{total} "
                f"scenes, {rate * 60:.1f} scenes/min this run, ETA {(remaining - made) / rate / 60:.0f} min",
                flush=True,
            )
    for (e, n), bs in blocks.items():
        write_set(e, n, [read_shard(p, d, c) for c, p, d in bs], out)
    print(f"{remaining} scenes made in {time.perf_counter() - start:.0f} s with {args.workers} workers")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
