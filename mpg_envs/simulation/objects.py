"""Object sets: rigid objects made of convex parts, ready to be added to a MuJoCo scene.

:func:`load_object_set` picks a set by name (``"blocks"``, a procedural family such as
``"superquadrics"``, or ``"procedural"``) or by the path of a folder of
meshes. The pieces live in modules of their own and are re-exported here:

* :mod:`mpg_envs.simulation.assets` -- the :class:`ObjectAsset` type, colours and material defaults;
* :mod:`mpg_envs.simulation.blocks` -- the generated "blocks" set (:func:`blocks_object_set`);
* :mod:`mpg_envs.simulation.families` -- the procedural sets (:func:`family_object_set`);
* :mod:`mpg_envs.simulation.meshes` -- mesh files (:func:`load_mesh_file`) and
  :mod:`mpg_envs.simulation.mesh_folder` -- folders of them, in parallel, a mesh that fails skipped
  with a warning (:func:`load_mesh_folder`, :class:`MeshFolderObjects`), decomposed in worker
  processes (:mod:`~mpg_envs.simulation.decomposition`,
  :mod:`~mpg_envs.simulation.isolated_call`) and fitted to the gripper (:mod:`~mpg_envs.simulation.gripper_fit`);
* :mod:`mpg_envs.simulation.random_urdfs` -- pybullet's ``random_urdfs`` objects (:func:`load_random_urdfs`);
  its test split ships packed as the set ``"random_urdfs_test"`` (:mod:`~mpg_envs.simulation.object_packs`),
  held out from training (:func:`check_not_held_out`);
* :mod:`mpg_envs.simulation.geometry_cache` -- the on-disk geometry cache (:func:`default_cache_dir`);
* :mod:`mpg_envs.simulation.bodies` -- :func:`add_object_body`, an asset as a free body of an ``MjSpec``.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from mpg_envs.simulation.assets import (
    DEFAULT_FRICTION,
    MASS_RANGE,
    MIN_PART_VOLUME,
    TABLEAU_10,
    WOOD_DENSITY,
    ObjectAsset,
    Part,
)
from mpg_envs.simulation.blocks import ARCH_TUNNEL_RATIO, BLOCK_SHAPES, BLOCKS_JITTER, CYLINDER_SECTIONS, blocks_object_set
from mpg_envs.simulation.bodies import OBJECT_CONDIM, OBJECT_GEOM_GROUP, ROLLING_FRICTION, TORSIONAL_FRICTION, add_object_body
from mpg_envs.simulation.families import FAMILY_SEED_RANGES, PROCEDURAL_SETS, family_object_set
from mpg_envs.simulation.geometry_cache import CACHE_FORMAT_VERSION, default_cache_dir
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange, fit_scale
from mpg_envs.simulation.mesh_folder import MeshFolderObjects, SkippedMesh, load_mesh_folder
from mpg_envs.simulation.meshes import CONVEX_VOLUME_RATIO, MESH_SUFFIXES, CoacdParams, MeshLoadError, load_mesh_file
from mpg_envs.simulation.object_packs import load_object_pack
from mpg_envs.simulation.random_urdfs import (
    RANDOM_URDFS_LICENCE,
    TEST_SET_NAME,
    is_test_object,
    load_random_urdfs,
    random_urdf_entries,
    test_pack_path,
)  # fmt: skip

__all__ = [
    "ARCH_TUNNEL_RATIO",
    "BLOCKS_EXTENTS",
    "BLOCKS_JITTER",
    "BLOCK_SHAPES",
    "CACHE_FORMAT_VERSION",
    "CONVEX_VOLUME_RATIO",
    "CYLINDER_SECTIONS",
    "CoacdParams",
    "HELD_OUT_OBJECT_SETS",
    "HeldOutObjectsError",
    "DEFAULT_FRICTION",
    "FAMILY_SEED_RANGES",
    "ExtentRange",
    "MASS_RANGE",
    "MESH_SUFFIXES",
    "MeshFolderObjects",
    "MeshLoadError",
    "MIN_PART_VOLUME",
    "OBJECT_CONDIM",
    "OBJECT_GEOM_GROUP",
    "ObjectAsset",
    "PROCEDURAL_SETS",
    "Part",
    "RANDOM_URDFS_LICENCE",
    "SkippedMesh",
    "ROLLING_FRICTION",
    "TABLEAU_10",
    "TORSIONAL_FRICTION",
    "WOOD_DENSITY",
    "add_object_body",
    "blocks_object_set",
    "check_not_held_out",
    "default_cache_dir",
    "family_object_set",
    "fit_scale",
    "held_out_objects",
    "load_mesh_file",
    "load_mesh_folder",
    "load_object_set",
    "load_random_urdfs",
    "random_urdf_entries",
]


HELD_OUT_OBJECT_SETS: tuple[str, ...] = (TEST_SET_NAME,)
"""Object sets for testing only: the project's training refuses them (:func:`check_not_held_out`)."""

NAMED_SETS = ("blocks", *HELD_OUT_OBJECT_SETS)
"""Object sets :func:`load_object_set` takes by name."""


class HeldOutObjectsError(ValueError):
    """Training was asked to use objects held out for testing."""


def held_out_objects(assets: Sequence[ObjectAsset]) -> list[str]:
    """Names of the objects in ``assets`` that are held out for testing (pybullet's
    ``random_urdfs`` test split, by name or source; see :func:`~mpg_envs.simulation.random_urdfs.is_test_object`)."""
    return [a.name for a in assets if is_test_object(a.name, a.source)]


def check_not_held_out(object_set: object, assets: Sequence[ObjectAsset] = (), what: str = "training") -> None:
    """Raise :class:`HeldOutObjectsError` when ``object_set`` (a name, path or asset list) is
    a held-out set or ``assets`` hold a held-out object; ``what`` names the caller in the message."""
    if isinstance(object_set, (str, os.PathLike)) and str(object_set) in HELD_OUT_OBJECT_SETS:
        raise HeldOutObjectsError(
            f"{what} may not use object_set={str(object_set)!r}: it is held out for testing (the unseen-object "
            f"track); train on 'blocks' or another set (held out: {list(HELD_OUT_OBJECT_SETS)})"
        )
    names = held_out_objects(assets)
    if names:
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        raise HeldOutObjectsError(
            f"{what} may not use objects held out for testing (pybullet random_urdfs test split, numbers "
            f"ending in 0): {shown}; use the training split (load_random_urdfs(split='train')) or another set"
        )


def load_object_set(
    name_or_path: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
) -> list[ObjectAsset]:
    """An object set by name (``"blocks"``, a procedural family, ``"random_urdfs_test"``) or by
    the path of a folder of OBJ/STL meshes.

    ``"random_urdfs_test"`` is pybullet's ``random_urdfs`` test split as shipped: fitted to the
    gripper and packed beside the test scenes (no pybullet needed; ``seed`` and ``cache_dir``
    do not apply). It is held out from training.

    Names: ``"blocks"``, and the procedural sets of :data:`PROCEDURAL_SETS` (each family,
    e.g. ``"superquadrics"``, and ``"procedural"``, a mix of all; ``seed`` picks the set, see
    :data:`FAMILY_SEED_RANGES`). A name wins over a folder that happens to be called so in the
    working directory; pass ``"./blocks"`` to load such a folder.

    Raises:
        ValueError: neither a known set name nor an existing folder (lists the choices).
    """
    if isinstance(name_or_path, str) and name_or_path == "blocks":
        return blocks_object_set(seed=seed, cache_dir=cache_dir)
    if isinstance(name_or_path, str) and name_or_path == TEST_SET_NAME:
        return load_object_pack(test_pack_path())
    if isinstance(name_or_path, str) and name_or_path in PROCEDURAL_SETS:
        return family_object_set(name_or_path, seed=seed, cache_dir=cache_dir)
    # str(...) guards against "" silently meaning the working directory.
    path = Path(name_or_path).expanduser()
    if str(name_or_path).strip() and path.is_dir():
        return load_mesh_folder(path, seed=seed, cache_dir=cache_dir)
    raise ValueError(
        f"unknown object set {str(name_or_path)!r}: valid choices are "
        f"{', '.join(map(repr, NAMED_SETS))}, one of {list(PROCEDURAL_SETS)} or the path of an "
        f"existing folder of {'/'.join(MESH_SUFFIXES)} meshes"
    )
