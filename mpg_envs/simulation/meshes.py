"""Objects from mesh files: one file (:func:`load_mesh_file`, in steps: :class:`MeshJob`).

Each mesh becomes an :class:`~mpg_envs.simulation.assets.ObjectAsset` made of convex parts
(:mod:`mpg_envs.simulation.decomposition`: its bodies, their union, coacd where needed). That
work runs in a worker process with a time limit (:mod:`mpg_envs.simulation.isolated_call`), so
a native crash or hang becomes a :class:`MeshLoadError` naming the file, never a dead
interpreter; when coacd crashes, fails or runs out of time, a mesh made of separate convex
bodies falls back to one part per body and a closed mesh close to its convex hull
(:data:`HULL_FALLBACK_RATIO`) to that hull, with a warning. Folders of meshes are
:mod:`mpg_envs.simulation.mesh_folder`'s. Geometry is
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
from typing import Any, Literal

import numpy as np
import trimesh

from mpg_envs.simulation.assets import (
    DEFAULT_FRICTION,
    TABLEAU_10,
    WOOD_DENSITY,
    ObjectAsset,
    check_seed,
    make_asset,
    mesh_volume,
)
from mpg_envs.simulation.decomposition import CONVEX_VOLUME_RATIO, HULL_FALLBACK_RATIO, CoacdParams, Solid, decompose
from mpg_envs.simulation.geometry_cache import CachedSolid, cached_solid, read_cached_solid, resolve_cache_dir
from mpg_envs.simulation.gripper_fit import BLOCKS_EXTENTS, ExtentRange, FitError, fit_scale
from mpg_envs.simulation.isolated_call import (
    IsolatedCallError,
    IsolatedWorker,
    WorkerCallError,
    WorkerPool,
    WorkerTimeoutError,
    shared_worker,
)  # fmt: skip

__all__ = [
    "CONVEX_VOLUME_RATIO",
    "DEFAULT_TIME_LIMIT_S",
    "HULL_FALLBACK_RATIO",
    "MESH_SUFFIXES",
    "CoacdParams",
    "MeshJob",
    "MeshLoadError",
    "decompose",
    "load_mesh_file",
]

MESH_SUFFIXES = (".obj", ".stl")
"""File types a mesh folder's loader reads (case-insensitive)."""

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
    that may run at most ``time_limit_s`` seconds. If that decomposition crashes, fails or
    runs out of time, the mesh is made without it: separate convex bodies as one part each, a
    closed mesh close to its convex hull
    (:data:`~mpg_envs.simulation.decomposition.HULL_FALLBACK_RATIO`) as its hull, with a
    warning naming the file and why. The object frame is the mesh frame shifted
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
            fitted, or its decomposition crashed, failed or ran past ``time_limit_s`` with no
            fallback; the message names the file and what is valid.
        ValueError: a bad argument (named).
    """
    job = MeshJob.prepare(
        path, seed, cache_dir, scale, mass, fit=fit, density=density, friction=friction,
        coacd_params=coacd_params, time_limit_s=time_limit_s, licence=licence,
    )  # fmt: skip
    return job.asset(job.solid(shared_worker()), name=name, rgba=rgba)


@dataclasses.dataclass(frozen=True)
class MeshJob:
    """One mesh file read and checked, in steps: :meth:`solid` (its convex parts from the cache
    or a worker process: the slow step, safe to run in threads) and :meth:`asset` (the object;
    any warning is given here). :func:`load_mesh_file` runs both; a folder's meshes run their
    :meth:`solid` steps in parallel (:mod:`mpg_envs.simulation.mesh_folder`)."""

    path: Path
    scale: float
    """The caller's scale (before any fit)."""
    first_fit: float
    """The fit's factor from the vertices' box (1 without a fit)."""
    extent_range: ExtentRange | None
    seed: int
    cache_dir: Path
    params: CoacdParams
    time_limit_s: float
    key_data: dict
    mass: float | None
    density: float
    friction: float
    licence: str

    @classmethod
    def prepare(
        cls,
        path: str | os.PathLike[str],
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
        licence: str = "",
    ) -> MeshJob:
        """Check the arguments (those of :func:`load_mesh_file`), read the file and fit its vertices' box.

        Raises:
            MeshLoadError: the file cannot be read, or its vertices cannot be fitted.
            ValueError: a bad argument (named).
        """
        seed = check_seed(seed)
        _check_positive("scale", scale)
        _check_positive("time_limit_s", time_limit_s)
        _check_positive("density", density)
        _check_positive("friction", friction)
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
        return cls(
            path, float(scale), first, extent_range, seed, resolve_cache_dir(cache_dir), params, float(time_limit_s),
            key_data, mass, float(density), float(friction), licence,
        )  # fmt: skip

    def solid(self, worker: IsolatedWorker | WorkerPool) -> CachedSolid:
        """The mesh's convex parts, from the cache or made by ``worker`` (no warning here).

        A fallback made because the decomposition ran out of time is cached for that time limit
        only (how far coacd gets depends on the machine's load): a larger ``time_limit_s`` tries
        the decomposition again.

        Raises:
            MeshLoadError: the mesh cannot be made into convex parts, even by the fallback.
        """
        label = f"mesh-{self.path.stem}"
        timed_out_key = {**self.key_data, "fallback_after_time_limit_s": self.time_limit_s}
        for key in (self.key_data, timed_out_key):
            cached = read_cached_solid(self.cache_dir, label, key)
            if cached is not None:
                return cached
        parts, volume, note, timed_out = _isolated_solid(
            self.path, self.scale * self.first_fit, self.seed, self.params, self.time_limit_s, worker
        )
        return cached_solid(
            self.cache_dir, label, timed_out_key if timed_out else self.key_data, lambda: (parts, volume, note)
        )

    def asset(
        self, solid: CachedSolid, *, name: str | None = None, rgba: tuple[float, float, float, float] = TABLEAU_10[0]
    ) -> ObjectAsset:
        """The object made of ``solid`` (from :meth:`solid`), fitted again on its parts' box; a
        fallback's note is warned about (``RuntimeWarning`` naming the file).

        Raises:
            MeshLoadError: the parts cannot be fitted.
        """
        path = self.path
        if solid.note:
            warnings.warn(f"mesh file {str(path)!r}: {solid.note}", RuntimeWarning, stacklevel=3)
        second = 1.0
        if self.extent_range is not None:
            second = _fit(path, self.scale, np.ptp(np.concatenate([v for v, _ in solid.parts]), axis=0), self.extent_range)
            solid = _scaled(solid, second)
        return make_asset(
            name if name is not None else path.stem,
            solid.parts,
            rgba,
            self.density,
            self.mass,
            self.friction,
            str(path),
            solid.com,
            volume=solid.volume,
            scale=self.scale * self.first_fit * second,
            licence=self.licence,
        )


def _isolated_solid(
    path: Path, scale: float, seed: int, params: CoacdParams, time_limit_s: float, worker: IsolatedWorker | WorkerPool
) -> tuple[list, float, str, bool]:
    """The mesh's solid from the worker: (parts, volume, note, whether coacd ran out of time);
    a fallback is noted."""
    fields = dataclasses.asdict(params)  # plain data: a crashing stand-in need not import anything
    timed_out = False
    try:
        solid: Solid = worker.call(SOLID_ENTRY, (str(path), float(scale), seed, fields, True), time_limit_s)
        return solid.parts, solid.volume, "", False
    except WorkerCallError as exc:
        if exc.exc_type == "ValueError":  # the file itself is unusable: no fallback helps
            raise _as_load_error(path, exc) from exc
        failure = f"failed ({exc.exc_type}: {exc.exc_message})"
    except IsolatedCallError as exc:
        failure = _failure_text(exc, time_limit_s)
        timed_out = isinstance(exc, WorkerTimeoutError)
    # Retry without coacd: separate convex bodies, or a near-convex mesh as its hull.
    try:
        solid = worker.call(SOLID_ENTRY, (str(path), float(scale), seed, fields, False), time_limit_s)
    except IsolatedCallError as exc:
        if isinstance(exc, WorkerCallError) and exc.exc_type == "ValueError":
            tail = f"no fallback applies: {exc.exc_message.removeprefix(f'mesh file {str(path)!r}: ')}"
        elif isinstance(exc, WorkerCallError):
            tail = f"the fallback without it failed ({exc.exc_type}: {exc.exc_message})"
        else:
            tail = f"the fallback without it {_failure_text(exc, time_limit_s)}"
        hint = "; a larger time_limit_s may let it finish" if timed_out else ""
        raise MeshLoadError(f"mesh file {str(path)!r}: convex decomposition {failure}, and {tail}{hint}") from exc
    if solid.method == "hull-fallback":
        hull_volume = sum(mesh_volume(v, f) for v, f in solid.parts)
        note = (
            f"convex decomposition {failure}; using its convex hull "
            f"instead ({hull_volume / solid.volume:.3f} x its volume, "
            f"within the {HULL_FALLBACK_RATIO:g} allowed)"
        )
    else:
        note = f"convex decomposition {failure}; using the hulls of its {len(solid.parts)} convex bodies instead"
    if timed_out:
        note += "; a larger time_limit_s tries the decomposition again"
    return solid.parts, solid.volume, note, timed_out


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
        mesh: Any = trimesh.load(
            trimesh.util.wrap_as_stream(data), file_type=path.suffix.lower()[1:], force="mesh", process=False
        )
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
