"""Load every pybullet ``random_urdfs`` mesh, fitted to the gripper, in one process.

Each mesh goes through :func:`mpg_envs.simulation.meshes.load_mesh_file` (decomposition in a
worker process with a time limit), so no mesh can end this process natively; every mesh that
cannot be used must fail with an error naming its file. Prints how many loaded, the failures
by kind with each file, fallbacks (warnings), the part counts and the time, and, as the last
line, JSON. A second run reads the geometry cache.

    python benchmarks/load_random_urdfs.py [--folder PATH] [--split all|test|train] [--fit gripper|none]
        [--min-extent 0.025] [--cache-dir DIR] [--time-limit 180] [--json PATH]
"""

from __future__ import annotations

import argparse
import collections
import json
import re
import sys
import time
import warnings
from pathlib import Path

from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange
from mpg_envs.simulation.meshes import DEFAULT_TIME_LIMIT_S, MeshLoadError, load_mesh_file
from mpg_envs.simulation.random_urdfs import RANDOM_URDFS_LICENCE, SPLITS, random_urdf_entries

KINDS = (
    ("cannot be scaled into the range", "does not fit the extent range"),
    ("zero volume", "zero volume (flat or degenerate)"),
    ("no triangles", "empty or unreadable"),
    ("empty or unreadable", "empty or unreadable"),
    ("cannot load it", "empty or unreadable"),
    ("non-finite", "non-finite vertices"),
    ("time limit", "decomposition past the time limit"),
    ("crashed", "decomposition crashed"),
    ("union", "union of the bodies failed"),
)


def kind_of(message: str) -> str:
    """A short name for an error message (the file names differ, the kinds repeat)."""
    for needle, kind in KINDS:
        if needle in message:
            return kind
    return re.sub(r"\d+(\.\d+)?", "#", message.split(": ", 1)[-1])[:80]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--folder", help="a random_urdfs folder (default: the installed pybullet's)")
    parser.add_argument("--split", choices=SPLITS, default="all")
    parser.add_argument("--fit", choices=("gripper", "none"), default="gripper")
    parser.add_argument("--min-extent", type=float, default=BLOCKS_EXTENTS.min_extent,
                        help="smallest allowed extent (m) of the fit; the blocks' is 0.025")  # fmt: skip
    parser.add_argument("--cache-dir", help="geometry cache (default: the package's)")
    parser.add_argument("--time-limit", type=float, default=DEFAULT_TIME_LIMIT_S, help="seconds per mesh")
    parser.add_argument("--json", help="also write the JSON here")
    args = parser.parse_args(argv)
    fit = "none" if args.fit == "none" else ExtentRange(args.min_extent, BLOCKS_EXTENTS.max_extent, BLOCKS_EXTENTS.max_two_smallest)
    entries = random_urdf_entries(args.folder, args.split)
    # Records name each file from the folder above random_urdfs, not from this machine's root.
    root = f"{Path(entries[0].mesh).parents[2]}/" if entries else ""

    def shown(what: object) -> str:
        return str(what).replace(root, "")

    start = time.perf_counter()
    loaded, parts, failures, fallbacks = [], [], [], []
    for i, entry in enumerate(entries):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                asset = load_mesh_file(
                    entry.mesh, cache_dir=args.cache_dir, scale=entry.scale, fit=fit, name=entry.name,
                    time_limit_s=args.time_limit, licence=RANDOM_URDFS_LICENCE,
                )  # fmt: skip
                loaded.append(entry.number)
                parts.append(asset.num_parts)
            except MeshLoadError as exc:
                failures.append({"file": shown(entry.mesh), "kind": kind_of(str(exc)), "error": shown(exc)})
            except Exception as exc:  # a bug, not a bad mesh: still reported with its file
                failures.append({"file": shown(entry.mesh), "kind": f"unexpected {type(exc).__name__}", "error": shown(exc)})
        fallbacks += [f"{shown(entry.mesh)}: {w.message}" for w in caught if issubclass(w.category, RuntimeWarning)]
        if (i + 1) % 50 == 0:
            print(f"{i + 1}/{len(entries)}: {len(loaded)} loaded, {len(failures)} failed, "
                  f"{time.perf_counter() - start:.0f} s", flush=True)  # fmt: skip
    seconds = time.perf_counter() - start
    by_kind = collections.Counter(f["kind"] for f in failures)
    print(f"\n{len(loaded)} of {len(entries)} loaded ({100 * len(loaded) / len(entries):.1f}%), "
          f"{len(failures)} failed, {len(fallbacks)} fallbacks, {seconds:.0f} s")  # fmt: skip
    tests_loaded = sum(1 for n in loaded if n % 10 == 0)
    print(f"test objects (numbers ending in 0): {tests_loaded} of {sum(1 for e in entries if e.is_test)} loaded")
    for kind, count in by_kind.most_common():
        print(f"  {count:4d}  {kind}")
    for f in failures:
        print(f"  FAILED {f['file']}: {f['error']}")
    for line in fallbacks:
        print(f"  FALLBACK {line}")
    if parts:
        print(f"parts per object: median {sorted(parts)[len(parts) // 2]}, max {max(parts)}")
    summary = {
        "split": args.split,
        "fit": args.fit if args.fit == "none" else {"min_extent": args.min_extent, "max_extent": BLOCKS_EXTENTS.max_extent,
                                                      "max_two_smallest": BLOCKS_EXTENTS.max_two_smallest},
        "meshes": len(entries),
        "loaded": len(loaded),
        "test_loaded": tests_loaded,
        "failed": len(failures),
        "failures_by_kind": dict(by_kind),
        "fallbacks": len(fallbacks),
        "seconds": round(seconds, 1),
        "max_parts": max(parts, default=0),
        "failures": failures,
    }  # fmt: skip
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(summary, fh, indent=1)
    print(json.dumps({k: v for k, v in summary.items() if k != "failures"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
