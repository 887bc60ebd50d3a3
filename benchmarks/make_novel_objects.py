"""Pack pybullet's ``random_urdfs`` test split for the unseen-object track (``object_set="random_urdfs_test"``).

Reads the test objects (folders whose number ends in 0) from an installed ``pybullet`` (or
``--folder``), loads each with the gripper fit (``fit="gripper"``: every extent 2.5-10 cm, the
two smallest at most 6 cm; CoACD in a worker process), and writes their convex parts, scale and
mass properties to ``mpg_envs/test_scenes/random_urdfs_test_objects.npz`` with the licence
beside it (``random_urdfs_test_LICENSE.txt``). The rule for leaving an object out is decided
on the objects alone, never on test results: an object that no uniform scale fits to the
gripper's range (too slender or too flat), that cannot be loaded, or whose decomposition has
more than :data:`MAX_PARTS` convex parts (a mesh of many separate bodies; the 4 such test
objects have 44-104 parts against a median of 7, each adding as many geoms to simulate and
ray-cast to every scene it is in as several typical objects) is left out, and
the pack's metadata lists it with the reason. After re-packing, regenerate the track's test
scenes (``benchmarks/make_test_sets.py --envs MPG-OccludedHardNovel-v0``).

    python benchmarks/make_novel_objects.py [--folder PATH] [--out mpg_envs/test_scenes]
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import mpg_envs  # noqa: E402
from mpg_envs.simulation.assets import TABLEAU_10  # noqa: E402
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS  # noqa: E402
from mpg_envs.simulation.meshes import MeshLoadError, load_mesh_file  # noqa: E402
from mpg_envs.simulation.object_packs import save_object_pack  # noqa: E402
from mpg_envs.simulation.random_urdfs import (  # noqa: E402
    PACKED_SOURCE_PREFIX, RANDOM_URDFS_LICENCE, RANDOM_URDFS_SOURCE, TEST_PACK_FILE, random_urdf_entries,
)  # fmt: skip

LICENCE_FILE = "random_urdfs_test_LICENSE.txt"

MAX_PARTS = 12
"""Objects with more convex parts than this are left out (see the module docstring)."""

LICENCE_TEXT = """\
The objects of random_urdfs_test_objects.npz are convex decompositions, scaled to fit a
Robotiq 2F-85 gripper, of meshes from pybullet_data/random_urdfs (object numbers ending in 0),
part of the Bullet Physics SDK (https://github.com/bulletphysics/bullet3), pybullet {version}
(authors: Erwin Coumans, Yunfei Bai, Jasmine Hsu, per the package metadata). They are altered
from the original meshes (decomposed into convex parts and rescaled). Licence: zlib, as below
(the LICENSE.txt of the pybullet package).

{licence}"""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--folder", help="a random_urdfs folder (default: the installed pybullet's)")
    parser.add_argument("--out", default=str(Path(mpg_envs.__file__).parent / "test_scenes"))
    args = parser.parse_args(argv)
    out = Path(args.out)
    entries = random_urdf_entries(args.folder, "test")
    assets, left_out = [], {}
    for entry in entries:
        try:
            asset = load_mesh_file(
                entry.mesh, 0, None, entry.scale, fit="gripper", name=entry.name,
                rgba=TABLEAU_10[len(assets) % len(TABLEAU_10)], licence=RANDOM_URDFS_LICENCE,
            )  # fmt: skip
        except MeshLoadError as exc:
            left_out[entry.number] = str(exc).split(": ", 1)[-1]
            continue
        if asset.num_parts > MAX_PARTS:
            left_out[entry.number] = f"{asset.num_parts} convex parts, more than {MAX_PARTS}"
            continue
        # The source recorded is the set's, not this machine's path.
        assets.append(_with_source(asset, f"{PACKED_SOURCE_PREFIX}{entry.number:03d}/{entry.number:03d}.obj"))
    version = _pybullet_version()
    meta = {
        "source": RANDOM_URDFS_SOURCE,
        "pybullet_version": version,
        "licence": RANDOM_URDFS_LICENCE,
        "licence_file": LICENCE_FILE,
        "split": "test (object numbers ending in 0)",
        "numbers": json.dumps([e.number for e in entries if e.number not in left_out]),
        "left_out": json.dumps({f"{n:03d}": why for n, why in left_out.items()}),
        "rule": f"fit='gripper' (BLOCKS_EXTENTS); objects that no uniform scale fits, that cannot be loaded, or with more than {MAX_PARTS} convex parts are left out",
        "fit": json.dumps([BLOCKS_EXTENTS.min_extent, BLOCKS_EXTENTS.max_extent, BLOCKS_EXTENTS.max_two_smallest]),
        "package_version": mpg_envs.__version__,
        "coacd_version": _version("coacd"),
    }
    path = save_object_pack(out / TEST_PACK_FILE, assets, meta)
    licence = _pybullet_licence()
    (out / LICENCE_FILE).write_text(LICENCE_TEXT.format(version=version, licence=licence))
    parts = [a.num_parts for a in assets]
    print(
        f"{path}: {len(assets)} of {len(entries)} test objects ({len(left_out)} left out: "
        f"{', '.join(f'{n:03d}' for n in left_out)}); parts per object median {sorted(parts)[len(parts) // 2]}, "
        f"max {max(parts)}; {path.stat().st_size / 1024:.0f} kB"
    )
    return 0


def _with_source(asset, source: str):
    import dataclasses

    return dataclasses.replace(asset, source=source)


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


def _pybullet_version() -> str:
    return _version("pybullet")


def _pybullet_licence() -> str:
    try:
        files = importlib.metadata.files("pybullet") or []
    except importlib.metadata.PackageNotFoundError:
        files = []
    for f in files:
        if f.name == "LICENSE.txt":
            return Path(f.locate()).read_text().strip() + "\n"
    raise SystemExit("pybullet's LICENSE.txt was not found: install pybullet (pip install 'mpg-grasp[novel]')")


if __name__ == "__main__":
    raise SystemExit(main())
