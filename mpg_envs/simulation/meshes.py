"""Objects from a folder of meshes, and the convex decomposition (coacd) they may need.

:func:`load_mesh_folder` turns every OBJ/STL mesh of a folder into an
:class:`~mpg_envs.simulation.assets.ObjectAsset`: concave meshes are split by ``coacd``
(:func:`decompose`), convex ones become their convex hull. Geometry is cached on disk
(:mod:`mpg_envs.simulation.geometry_cache`); colour, mass and friction are not cached: they are cheap
and derived from the geometry at load time.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
from dataclasses import dataclass
from pathlib import Path

import coacd
import numpy as np
import trimesh

from mpg_envs.simulation.assets import (
    DEFAULT_FRICTION,
    MIN_PART_VOLUME,
    TABLEAU_10,
    WOOD_DENSITY,
    ObjectAsset,
    Part,
    check_seed,
    convex_part,
    make_asset,
)
from mpg_envs.simulation.geometry_cache import cached_parts, resolve_cache_dir

CONVEX_VOLUME_RATIO = 0.97
"""A watertight mesh whose volume is at least this fraction of its convex hull's volume is
treated as convex (one part, its hull); anything else is decomposed with coacd."""

MESH_SUFFIXES = (".obj", ".stl")
"""File types :func:`load_mesh_folder` reads (case-insensitive)."""


@dataclass(frozen=True)
class CoacdParams:
    """Fixed coacd settings (part of the cache key). Defaults suit 2.5-15 cm objects."""

    threshold: float = 0.05
    max_convex_hull: int = 8
    resolution: int = 2000
    mcts_nodes: int = 20
    mcts_iterations: int = 150
    mcts_max_depth: int = 3
    preprocess_resolution: int = 50


def load_mesh_folder(
    folder: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    scale: float = 1.0,
    mass: float | None = None,
    *,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
) -> list[ObjectAsset]:
    """Every OBJ/STL mesh of a folder (not recursive) as an object, sorted by file name.

    Each mesh is loaded with ``trimesh`` (``force="mesh"``), multiplied by ``scale``, cleaned
    (coincident opposite faces removed), and then: if it is watertight and at least
    :data:`CONVEX_VOLUME_RATIO` of its convex hull, it becomes one part (its hull); otherwise
    coacd splits it (seeded with ``seed``). The object frame is the mesh frame shifted to the
    parts' centre of mass. The object's name is the file stem; its colour is
    ``TABLEAU_10[i % 10]`` for the ``i``-th file in sorted order (colours or textures carried
    by the files are ignored, so every set looks alike and masks stay easy to tell apart).

    Args:
        folder: folder holding the meshes; other files are ignored.
        seed: non-negative integer, the coacd seed.
        cache_dir: folder for the geometry cache; ``None`` uses :func:`default_cache_dir`.
        scale: multiplies vertex coordinates (e.g. 0.001 for meshes in millimetres).
        mass: mass (kg) of every object; ``None`` means ``density * volume`` clamped to
            :data:`MASS_RANGE`.
        density: kg/m^3, used when ``mass`` is ``None``.
        friction: sliding friction of every object.
        coacd_params: decomposition settings (default :class:`CoacdParams`).

    Raises:
        FileNotFoundError: ``folder`` does not exist.
        NotADirectoryError: ``folder`` is not a folder.
        ValueError: no mesh in the folder, or a mesh that cannot be read, is empty, or has
            no volume (the message names the file).
    """
    seed = check_seed(seed)
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale must be a positive number, got {scale!r}")
    if mass is not None and not (math.isfinite(mass) and mass > 0):
        raise ValueError(f"mass must be positive or None, got {mass!r}")
    root = Path(folder).expanduser()
    if not root.exists():
        raise FileNotFoundError(f"mesh folder {str(root)!r} does not exist")
    if not root.is_dir():
        raise NotADirectoryError(f"mesh folder {str(root)!r} is not a folder")
    files = sorted(
        (p for p in root.iterdir() if p.suffix.lower() in MESH_SUFFIXES and not p.name.startswith(".")),
        key=lambda p: p.name,
    )
    if not files:
        raise ValueError(f"mesh folder {str(root)!r} holds no {'/'.join(MESH_SUFFIXES)} files")
    params = coacd_params or CoacdParams()
    cache = resolve_cache_dir(cache_dir)
    assets = []
    for index, path in enumerate(files):
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise ValueError(f"mesh file {str(path)!r}: cannot read it ({exc})") from exc
        key_data = {
            "kind": "mesh_file",
            "suffix": path.suffix.lower(),
            "sha256": hashlib.sha256(data).hexdigest(),
            "scale": float(scale),
            "seed": seed,
            "convex_ratio": CONVEX_VOLUME_RATIO,
            "coacd": dataclasses.asdict(params),
        }
        parts, com = cached_parts(
            cache, f"mesh-{path.stem}", key_data, lambda path=path: _parts_from_mesh_file(path, scale, seed, params)
        )
        rgba = TABLEAU_10[index % len(TABLEAU_10)]
        assets.append(make_asset(path.stem, parts, rgba, density, mass, friction, str(path), com))
    return assets



def _parts_from_mesh_file(path: Path, scale: float, seed: int, params: CoacdParams) -> list[Part]:
    """Convex parts of one mesh file (not yet centred); ValueError naming the file if invalid."""
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # trimesh raises many types for bad files; report them uniformly
        raise ValueError(f"mesh file {str(path)!r}: cannot load it ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"mesh file {str(path)!r}: empty or unreadable mesh (no triangles)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValueError(f"mesh file {str(path)!r}: non-finite vertex coordinates")
    mesh.apply_scale(scale)
    mesh = _drop_coincident_faces(mesh)
    try:
        with np.errstate(divide="ignore", invalid="ignore"):  # flat input: trimesh divides by 0
            hull = mesh.convex_hull
            hull_volume = float(hull.volume)
    except Exception as exc:  # qhull fails on flat or degenerate point sets
        raise ValueError(f"mesh file {str(path)!r}: zero volume (flat or degenerate mesh)") from exc
    if not hull_volume > MIN_PART_VOLUME:
        raise ValueError(f"mesh file {str(path)!r}: zero volume (flat or degenerate mesh)")
    if mesh.is_watertight:
        if mesh.volume < 0:  # consistently inside-out: flip rather than treat as concave
            mesh.invert()
        if mesh.volume >= CONVEX_VOLUME_RATIO * hull_volume:
            return [convex_part(hull.vertices)]
        parts = decompose(mesh, seed, params, preprocess=False)
    else:
        # Not a closed surface: let coacd remesh it into a manifold before decomposing.
        parts = decompose(mesh, seed, params, preprocess=True)
    if not parts:
        raise ValueError(f"mesh file {str(path)!r}: zero volume after convex decomposition")
    return parts


def _drop_coincident_faces(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Remove faces that appear more than once (same vertices, any order).

    Exporters often leave a face and its reverse twin (a zero-thickness sliver): that makes
    the surface non-manifold and hides an otherwise closed mesh. Kept only if it helps.
    """
    key = np.sort(mesh.faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    single = counts[inverse.ravel()] == 1
    if single.all() or not single.any():
        return mesh
    cleaned = mesh.copy()
    cleaned.update_faces(single)
    cleaned.remove_unreferenced_vertices()
    return cleaned if cleaned.is_watertight or not mesh.is_watertight else mesh


def decompose(mesh: trimesh.Trimesh, seed: int, params: CoacdParams, preprocess: bool) -> list[Part]:
    """Convex parts of ``mesh`` from coacd (deterministic for fixed seed and parameters)."""
    coacd.set_log_level("error")  # coacd logs every step to stdout otherwise
    raw = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32)),
        threshold=params.threshold,
        max_convex_hull=params.max_convex_hull,
        preprocess_mode="on" if preprocess else "off",
        preprocess_resolution=params.preprocess_resolution,
        resolution=params.resolution,
        mcts_nodes=params.mcts_nodes,
        mcts_iterations=params.mcts_iterations,
        mcts_max_depth=params.mcts_max_depth,
        seed=seed % 2**31,  # a C int
    )
    parts = []
    for vertices, _faces in raw:
        try:
            part = convex_part(vertices)
        except ValueError:
            continue  # a flat sliver: no volume, nothing to collide with
        parts.append(part)
    return parts


