"""Objects from mesh files: one file (:func:`load_mesh_file`) or a folder (:func:`load_mesh_folder`).

Each mesh becomes an :class:`~mpg_envs.simulation.assets.ObjectAsset` made of convex parts
(:mod:`mpg_envs.simulation.decomposition`: its bodies, their union, coacd where needed). That
work runs in a worker process with a time limit (:mod:`mpg_envs.simulation.isolated_call`), so
a native crash or hang becomes a :class:`MeshLoadError` naming the file, never a dead
interpreter; a mesh made of separate convex bodies falls back to one part per body. Geometry is
cached on disk (:mod:`mpg_envs.simulation.geometry_cache`); colour, mass and friction are not
cached: they are cheap and derived from the geometry at load time.

Fitting a set to the 2F-85: ``scale`` multiplies every mesh (units, or a set's size), then
``fit="gripper"`` scales each object by the factor nearest 1 that brings its bounding box into
the blocks' range (:data:`~mpg_envs.simulation.gripper_fit.BLOCKS_EXTENTS`: every extent
2.5-10 cm, the two smallest at most 6 cm). The product is the asset's ``scale``, which a
scene file records so the object can be loaded again with ``load_mesh_file(source, scale=...)``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import warnings
from pathlib import Path
from typing import Literal

import numpy as np
import trimesh

from mpg_envs.simulation.assets import DEFAULT_FRICTION, TABLEAU_10, WOOD_DENSITY, ObjectAsset, check_seed, make_asset
from mpg_envs.simulation.decomposition import CONVEX_VOLUME_RATIO, CoacdParams, Solid, decompose
from mpg_envs.simulation.geometry_cache import CachedSolid, cached_solid, resolve_cache_dir
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange, FitError, fit_scale
from mpg_envs.simulation.isolated_call import IsolatedCallError, WorkerCallError, WorkerTimeoutError, shared_worker

__all__ = [
    "CONVEX_VOLUME_RATIO",
    "DEFAULT_TIME_LIMIT_S",
    "MESH_SUFFIXES",
    "CoacdParams",
    "MeshLoadError",
    "decompose",
    "load_mesh_file",
    "load_mesh_folder",
]

MESH_SUFFIXES = (".obj", ".stl")
"""File types :func:`load_mesh_folder` reads (case-insensitive)."""

DEFAULT_TIME_LIMIT_S = 180.0
"""Seconds one mesh's decomposition may take in the worker before it is stopped."""

SOLID_ENTRY = "mpg_envs.simulation.decomposition:solid_from_mesh_file"
"""What the worker runs for each mesh (``"module:function"``, see
:func:`~mpg_envs.simulation.decomposition.solid_from_mesh_file`)."""

MESH_PIPELINE_VERSION = 2
"""Part of the cache key: bump when the path from a file to its parts changes."""

Fit = Literal["none", "gripper"] | ExtentRange


class MeshLoadError(ValueError):
    """A mesh file cannot be made into an object; the message names the file and why."""


def load_mesh_file(
    path: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    scale: float = 1.0,
    mass: float | None = None,
    *,
    fit: Fit = "none",
    name: str | None = None,
    rgba: tuple[float, float, float, float] = TABLEAU_10[0],
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
    time_limit_s: float = DEFAULT_TIME_LIMIT_S,
    licence: str = "",
) -> ObjectAsset:
    """One OBJ/STL mesh file as an object.

    The mesh is loaded with ``trimesh`` (``force="mesh"``), multiplied by ``scale``, cleaned
    (coincident opposite faces removed) and made into convex parts
    (:func:`~mpg_envs.simulation.decomposition.solid_from_mesh_file`), in a worker process
    that may run at most ``time_limit_s`` seconds. The object frame is the mesh frame shifted
    to the parts' centre of mass. The mass is ``density`` times the solid's volume (the union
    of its bodies, so overlapping parts count once), clamped to
    :data:`~mpg_envs.simulation.assets.MASS_RANGE`, unless ``mass`` is given.

    Args:
        path: the mesh file.
        seed: non-negative integer, the coacd seed.
        cache_dir: folder for the geometry cache; ``None`` uses the default cache.
        scale: multiplies vertex coordinates (e.g. 0.001 for meshes in millimetres).
        mass: mass (kg); ``None`` means ``density * volume`` clamped to ``MASS_RANGE``.
        fit: ``"none"`` keeps the size; ``"gripper"`` then scales the object by the factor
            nearest 1 that brings its extents into the blocks' range (every extent 2.5-10 cm,
            the two smallest at most 6 cm); an :class:`ExtentRange` uses that range instead.
        name: the object's name (default: the file stem).
        rgba: its colour.
        density: kg/m^3, used when ``mass`` is ``None``.
        friction: sliding friction.
        coacd_params: decomposition settings (default :class:`CoacdParams`).
        time_limit_s: seconds the decomposition of this mesh may take.
        licence: the licence of the file, recorded in the asset.

    Returns:
        The object; its ``scale`` is ``scale`` times the fit's factor.

    Raises:
        MeshLoadError: the file cannot be read or is empty, flat or degenerate, cannot be
            fitted, or its decomposition crashed or ran past ``time_limit_s`` with no
            fallback; the message names the file and what is valid.
        ValueError: a bad argument (named).
    """
    seed = check_seed(seed)
    _check_positive("scale", scale)
    _check_positive("time_limit_s", time_limit_s)
    if mass is not None:
        _check_positive("mass", mass)
    extent_range = _extent_range(fit)
    path = Path(path).expanduser()
    params = coacd_params or CoacdParams()
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise MeshLoadError(f"mesh file {str(path)!r}: cannot read it ({exc})") from exc
    # Fit first on the vertices' box, so the parts are made at the size they will have (the
    # smallest-part threshold is absolute), then again on the parts' box (hull-exact, but
    # coacd's hulls may reach a little further).
    first = 1.0 if extent_range is None else _fit(path, scale, _vertex_extents(path, data) * scale, extent_range)
    key_data = {
        "kind": "mesh_file",
        "pipeline": MESH_PIPELINE_VERSION,
        "suffix": path.suffix.lower(),
        "sha256": hashlib.sha256(data).hexdigest(),
        "scale": float(scale * first),
        "seed": seed,
        "convex_ratio": CONVEX_VOLUME_RATIO,
        "coacd": dataclasses.asdict(params),
    }
    solid = cached_solid(
        resolve_cache_dir(cache_dir),
        f"mesh-{path.stem}",
        key_data,
        lambda: _isolated_solid(path, scale * first, seed, params, time_limit_s),
    )
    if solid.note:
        warnings.warn(f"mesh file {str(path)!r}: {solid.note}", RuntimeWarning, stacklevel=2)
    second = 1.0
    if extent_range is not None:
        second = _fit(path, scale, np.ptp(np.concatenate([v for v, _ in solid.parts]), axis=0), extent_range)
        solid = _scaled(solid, second)
    return make_asset(
        name if name is not None else path.stem,
        solid.parts,
        rgba,
        density,
        mass,
        friction,
        str(path),
        solid.com,
        volume=solid.volume,
        scale=float(scale) * first * second,
        licence=licence,
    )


def load_mesh_folder(
    folder: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    scale: float = 1.0,
    mass: float | None = None,
    *,
    fit: Fit = "none",
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
    time_limit_s: float = DEFAULT_TIME_LIMIT_S,
) -> list[ObjectAsset]:
    """Every OBJ/STL mesh of a folder (not recursive) as an object, sorted by file name.

    Each file is loaded by :func:`load_mesh_file` (same arguments). The object's name is the
    file stem; its colour is ``TABLEAU_10[i % 10]`` for the ``i``-th file in sorted order
    (colours or textures carried by the files are ignored, so every set looks alike and masks
    stay easy to tell apart).

    Raises:
        FileNotFoundError: ``folder`` does not exist.
        NotADirectoryError: ``folder`` is not a folder.
        ValueError: no mesh in the folder, or a bad argument.
        MeshLoadError: a mesh that cannot be used (see :func:`load_mesh_file`; names the file).
    """
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
    return [
        load_mesh_file(
            path, seed, cache_dir, scale, mass, fit=fit, rgba=TABLEAU_10[index % len(TABLEAU_10)],
            density=density, friction=friction, coacd_params=coacd_params, time_limit_s=time_limit_s,
        )  # fmt: skip
        for index, path in enumerate(files)
    ]


def _isolated_solid(path: Path, scale: float, seed: int, params: CoacdParams, time_limit_s: float) -> tuple[list, float, str]:
    """The mesh's solid from the worker: (parts, volume, note); a fallback is noted."""
    worker = shared_worker()
    fields = dataclasses.asdict(params)  # plain data: a crashing stand-in need not import anything
    try:
        solid: Solid = worker.call(SOLID_ENTRY, (str(path), float(scale), seed, fields, True), time_limit_s)
        return solid.parts, solid.volume, ""
    except WorkerCallError as exc:
        raise _as_load_error(path, exc) from exc
    except IsolatedCallError as exc:
        failure = _failure_text(exc, time_limit_s)
    # Retry without coacd: a mesh of separate convex bodies still loads, one part per body.
    try:
        solid = worker.call(SOLID_ENTRY, (str(path), float(scale), seed, fields, False), time_limit_s)
    except IsolatedCallError as exc:
        reason = _as_load_error(path, exc) if isinstance(exc, WorkerCallError) else _failure_text(exc, time_limit_s)
        raise MeshLoadError(
            f"mesh file {str(path)!r}: convex decomposition {failure}, and the fallback without it failed "
            f"({reason}); a mesh of separate convex bodies, or one that coacd can decompose, is needed"
        ) from exc
    note = f"convex decomposition {failure}; using the hulls of its {len(solid.parts)} convex bodies instead"
    warnings.warn(f"mesh file {str(path)!r}: {note}", RuntimeWarning, stacklevel=4)
    return solid.parts, solid.volume, note


def _failure_text(exc: IsolatedCallError, time_limit_s: float) -> str:
    if isinstance(exc, WorkerTimeoutError):
        return f"did not finish within the time limit of {time_limit_s:g} s (time_limit_s)"
    return f"crashed ({exc})"


def _as_load_error(path: Path, exc: WorkerCallError) -> MeshLoadError:
    """The worker's exception as a MeshLoadError; a ValueError already names the file."""
    if exc.exc_type == "ValueError":
        return MeshLoadError(exc.exc_message)
    return MeshLoadError(f"mesh file {str(path)!r}: could not be made into convex parts ({exc.exc_type}: {exc.exc_message})")


def _vertex_extents(path: Path, data: bytes) -> np.ndarray:
    """Bounding-box size of the file's finite vertices (trimesh's parser: Python, no native code)."""
    try:
        mesh = trimesh.load(trimesh.util.wrap_as_stream(data), file_type=path.suffix.lower()[1:], force="mesh", process=False)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
    except Exception as exc:  # trimesh raises many types for bad files; report them uniformly
        raise MeshLoadError(f"mesh file {str(path)!r}: cannot load it ({type(exc).__name__}: {exc})") from exc
    finite = vertices[np.all(np.isfinite(vertices), axis=1)] if vertices.ndim == 2 else vertices[:0]
    if len(finite) < 4:
        raise MeshLoadError(
            f"mesh file {str(path)!r}: empty or unreadable mesh ({len(vertices)} vertices, {len(finite)} of them "
            "finite); a solid needs at least 4 finite vertices"
        )
    vertices = finite
    return np.ptp(vertices, axis=0)


def _fit(path: Path, scale: float, extents: np.ndarray, extent_range: ExtentRange) -> float:
    try:
        return fit_scale(extents, extent_range)
    except (FitError, ValueError) as exc:  # ValueError: a zero extent (flat)
        raise MeshLoadError(f"mesh file {str(path)!r} (scale {scale:g}): {exc}") from exc


def _scaled(solid: CachedSolid, factor: float) -> CachedSolid:
    if factor == 1.0:
        return solid
    parts = [(v * factor, f) for v, f in solid.parts]
    return CachedSolid(parts, solid.com * factor, solid.volume * factor**3, solid.note)


def _extent_range(fit: Fit) -> ExtentRange | None:
    if isinstance(fit, ExtentRange):
        return fit
    if fit == "gripper":
        return BLOCKS_EXTENTS
    if fit == "none":
        return None
    raise ValueError(f"fit must be 'none', 'gripper' or an ExtentRange, got {fit!r}")


def _check_positive(what: str, value: object) -> None:
    if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{what} must be a positive number, got {value!r}")
