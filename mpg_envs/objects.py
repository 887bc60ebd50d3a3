"""Object sets: rigid objects made of convex parts, ready to be added to a MuJoCo scene.

An :class:`ObjectAsset` is a list of convex meshes in the object frame (origin at the centre
of mass of the parts, z up in the object's canonical pose) plus its colour, mass and
friction. Two sources exist:

* ``"blocks"`` (:func:`blocks_object_set`): eight VPG-like wooden blocks generated with
  ``trimesh`` -- cube, long box, flat box, tall box, cylinder, disc, triangular prism and an
  arch (a box minus a cylinder, the only concave one, split into convex parts by ``coacd``).
  The seed jitters every dimension by up to +-10 %.
* any folder of OBJ/STL meshes (:func:`load_mesh_folder`): concave meshes are split by
  ``coacd``, convex ones become their convex hull.

Geometry is cached on disk as ``.npz`` files (default ``$MPG_CACHE_DIR/objects`` or
``~/.cache/mpg_envs/objects``), keyed by a hash of everything that shapes it (generator
parameters or mesh file bytes, the seed, the decomposition parameters and a format
version), so a second call only reads files, and one seed always gives the same arrays,
bit for bit. Files are written to a temporary name and renamed, so parallel processes
(vector envs) never see a half-written file. Colour, mass and friction are not cached:
they are cheap and derived from the geometry at load time.

:func:`add_object_body` turns an asset into a free-floating body of a ``mujoco.MjSpec``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import re
import tempfile
import warnings
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import coacd
import mujoco
import numpy as np
import trimesh

TABLEAU_10: tuple[tuple[float, float, float, float], ...] = tuple(
    (int(h[0:2], 16) / 255.0, int(h[2:4], 16) / 255.0, int(h[4:6], 16) / 255.0, 1.0)
    for h in (
        "4e79a7",  # blue
        "f28e2b",  # orange
        "e15759",  # red
        "76b7b2",  # teal
        "59a14f",  # green
        "edc948",  # yellow
        "b07aa1",  # purple
        "ff9da7",  # pink
        "9c755f",  # brown
        "bab0ac",  # grey
    )
)
"""The Tableau-10 palette (RGBA in [0, 1]), in Tableau's order."""

WOOD_DENSITY = 600.0
"""Default density (kg/m^3): the blocks are wooden."""

MASS_RANGE = (0.02, 0.3)
"""Default masses (kg) are clamped to this range so a closed 2F-85 can lift every object."""

DEFAULT_FRICTION = 0.9
"""Sliding friction of the objects. MuJoCo uses the larger of two geoms' values, so this
governs object-table and object-object contacts; the 2F-85 pads have ``priority=1``, so
pad contacts use the pads' own 0.7 whatever the object says."""

TORSIONAL_FRICTION = 0.005
"""Torsional friction (used by condim 4 contacts)."""

ROLLING_FRICTION = 0.0001
"""Rolling friction (only used if a contact has condim 6)."""

OBJECT_CONDIM = 4
"""Contact dimensionality of object geoms: sliding plus torsional friction, so an object
pinched by the pads does not spin about the pinch axis; rolling friction (6) is not needed."""

OBJECT_GEOM_GROUP = 1
"""Geom group of object geoms: the heightmap ray casts see groups 0 and 1 only."""

CONVEX_VOLUME_RATIO = 0.97
"""A watertight mesh whose volume is at least this fraction of its convex hull's volume is
treated as convex (one part, its hull); anything else is decomposed with coacd."""

MIN_PART_VOLUME = 1e-9
"""Convex parts smaller than this (m^3, i.e. 1 mm^3) are dropped: they do not matter for
contacts and MuJoCo cannot compute a sensible inertia for them."""

MESH_SUFFIXES = (".obj", ".stl")
"""File types :func:`load_mesh_folder` reads (case-insensitive)."""

CACHE_FORMAT_VERSION = 2
"""Bump when the cached geometry changes for the same inputs; old files are then ignored."""

BLOCKS_JITTER = 0.1
"""Relative jitter of every block dimension (uniform in [1 - j, 1 + j])."""

CYLINDER_SECTIONS = 32
"""Facets around generated cylinders (discs, cylinders, the arch's tunnel)."""

BLOCK_SHAPES: tuple[tuple[str, str, tuple[tuple[str, float], ...]], ...] = (
    # (name, kind, nominal parameters in metres). Nominal sizes are chosen so that any jitter
    # keeps every extent in [2.5, 10] cm and the two smallest extents <= 6 cm (some horizontal
    # width fits the 85 mm opening with margin in any resting pose).
    ("cube", "box_cube", (("size", 0.05),)),
    ("long_box", "box", (("x", 0.09), ("y", 0.035), ("z", 0.035))),
    ("flat_box", "box", (("x", 0.08), ("y", 0.05), ("z", 0.028))),
    ("tall_box", "box", (("x", 0.04), ("y", 0.04), ("z", 0.09))),
    ("cylinder", "cylinder", (("diameter", 0.045), ("height", 0.06))),
    ("disc", "cylinder", (("diameter", 0.054), ("height", 0.028))),
    ("triangular_prism", "prism", (("length", 0.08), ("base", 0.05), ("height", 0.045))),
    ("arch", "arch", (("length", 0.08), ("depth", 0.045), ("height", 0.045))),
)
"""The "blocks" set, in colour order (object ``i`` gets ``TABLEAU_10[i]``)."""

ARCH_TUNNEL_RATIO = 0.3
"""Arch tunnel radius as a fraction of the arch length: leaves legs of 0.2 x length."""

Part = tuple[np.ndarray, np.ndarray]
"""One convex part: vertices (V, 3) float64 metres, faces (F, 3) int32."""


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


@dataclass(frozen=True, eq=False)
class ObjectAsset:
    """A rigid object made of convex parts.

    ``parts`` are in the object frame, whose origin is the centre of mass of the parts
    (uniform density), so a body built from them has its centre of mass at the body origin.
    Arrays are stored read-only. Equality is identity (arrays make ``==`` ambiguous).
    """

    name: str
    parts: tuple[Part, ...]
    rgba: tuple[float, float, float, float]
    mass: float
    friction: float
    source: str
    mesh_offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Where the object frame's origin (the centre of mass) lies in the source mesh's frame,
    so a pose given for the mesh frame (a VPG scene file) converts to the body's pose."""

    def __post_init__(self) -> None:
        if not self.parts:
            raise ValueError(f"object {self.name!r}: needs at least one convex part")
        parts = []
        for i, (vertices, faces) in enumerate(self.parts):
            v = np.array(vertices, dtype=np.float64)
            f = np.array(faces, dtype=np.int32)
            if v.ndim != 2 or v.shape[1] != 3 or len(v) < 4 or not np.all(np.isfinite(v)):
                raise ValueError(f"object {self.name!r} part {i}: vertices must be finite (V>=4, 3)")
            if f.ndim != 2 or f.shape[1] != 3 or len(f) < 4 or f.min() < 0 or f.max() >= len(v):
                raise ValueError(f"object {self.name!r} part {i}: faces must be (F>=4, 3) vertex indices")
            v.setflags(write=False)
            f.setflags(write=False)
            parts.append((v, f))
        # Frozen dataclass: normalise through object.__setattr__ (only here, at construction).
        object.__setattr__(self, "parts", tuple(parts))
        rgba = tuple(float(c) for c in self.rgba)
        if len(rgba) != 4 or not all(0.0 <= c <= 1.0 for c in rgba):
            raise ValueError(f"object {self.name!r}: rgba must be 4 values in [0, 1], got {self.rgba}")
        object.__setattr__(self, "rgba", rgba)
        if not (math.isfinite(self.mass) and self.mass > 0):
            raise ValueError(f"object {self.name!r}: mass must be positive, got {self.mass}")
        if not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"object {self.name!r}: friction must be positive, got {self.friction}")

    @property
    def num_parts(self) -> int:
        """Number of convex parts."""
        return len(self.parts)

    @property
    def vertices(self) -> np.ndarray:
        """All part vertices stacked, (sum V, 3)."""
        return np.concatenate([v for v, _ in self.parts])

    @property
    def bounds(self) -> np.ndarray:
        """Axis-aligned bounding box in the object frame, [[xmin, ymin, zmin], [xmax, ymax, zmax]]."""
        v = self.vertices
        return np.stack([v.min(axis=0), v.max(axis=0)])

    @property
    def extents(self) -> np.ndarray:
        """Bounding-box size (x, y, z) in metres, in the object frame."""
        b = self.bounds
        return b[1] - b[0]

    @property
    def part_volumes(self) -> np.ndarray:
        """Volume (m^3) of each convex part."""
        return np.array([_closed_mesh_volume(v, f) for v, f in self.parts])

    @property
    def volume(self) -> float:
        """Total volume (m^3): the sum of the part volumes."""
        return float(self.part_volumes.sum())


# --------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------


def blocks_object_set(
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    *,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    coacd_params: CoacdParams | None = None,
) -> list[ObjectAsset]:
    """The "blocks" object set: eight VPG-like wooden blocks.

    Names, in order (object ``i`` has colour ``TABLEAU_10[i]``): ``cube``, ``long_box``,
    ``flat_box``, ``tall_box``, ``cylinder``, ``disc``, ``triangular_prism``, ``arch``.
    ``seed`` jitters every dimension independently by up to +-10 % (the cube stays a cube)
    and seeds coacd for the arch. Every extent is within 2.5-10 cm and the two smallest
    extents are <= 6 cm, so a 2F-85 can grasp each block from the top whichever face it
    rests on. Mass is ``density * volume`` clamped to :data:`MASS_RANGE`.

    Args:
        seed: non-negative integer.
        cache_dir: folder for the geometry cache; ``None`` uses :func:`default_cache_dir`.
        density: kg/m^3.
        friction: sliding friction of every block.
        coacd_params: decomposition settings for the arch (default :class:`CoacdParams`).
    """
    seed = _check_seed(seed)
    params = coacd_params or CoacdParams()
    folder = _resolve_cache_dir(cache_dir)
    assets = []
    for index, (name, kind, nominal) in enumerate(BLOCK_SHAPES):
        dims = _jitter_dims(nominal, seed, index)
        key_data = {"kind": kind, "dims": dims, "seed": seed, "coacd": dataclasses.asdict(params)}
        parts, com = _cached_parts(
            folder, f"blocks-{name}", key_data, lambda kind=kind, dims=dims: _make_block(kind, dims, seed, params)
        )
        assets.append(_make_asset(name, parts, TABLEAU_10[index % len(TABLEAU_10)], density, None, friction, "blocks", com))
    return assets


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
    seed = _check_seed(seed)
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
    cache = _resolve_cache_dir(cache_dir)
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
        parts, com = _cached_parts(
            cache, f"mesh-{path.stem}", key_data, lambda path=path: _parts_from_mesh_file(path, scale, seed, params)
        )
        rgba = TABLEAU_10[index % len(TABLEAU_10)]
        assets.append(_make_asset(path.stem, parts, rgba, density, mass, friction, str(path), com))
    return assets


def load_object_set(
    name_or_path: str | os.PathLike[str],
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
) -> list[ObjectAsset]:
    """An object set by name (``"blocks"``) or by the path of a folder of OBJ/STL meshes.

    The name ``"blocks"`` wins over a folder that happens to be called ``blocks`` in the
    working directory; pass ``"./blocks"`` to load such a folder.

    Raises:
        ValueError: neither a known set name nor an existing folder (lists the choices).
    """
    if isinstance(name_or_path, str) and name_or_path == "blocks":
        return blocks_object_set(seed=seed, cache_dir=cache_dir)
    # str(...) guards against "" silently meaning the working directory.
    path = Path(name_or_path).expanduser()
    if str(name_or_path).strip() and path.is_dir():
        return load_mesh_folder(path, seed=seed, cache_dir=cache_dir)
    raise ValueError(
        f"unknown object set {str(name_or_path)!r}: valid choices are 'blocks' or the path of an "
        f"existing folder of {'/'.join(MESH_SUFFIXES)} meshes"
    )


def add_object_body(
    spec: mujoco.MjSpec,
    parent: mujoco.MjsBody,
    asset: ObjectAsset,
    name: str,
    pos: Sequence[float] = (0.0, 0.0, 0.0),
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
) -> mujoco.MjsBody:
    """Add ``asset`` to ``spec`` as a free body named ``name``, child of ``parent``.

    Creates one mesh asset per convex part, named ``f"{name}/part{i}"``; a body ``name`` at
    ``pos``/``quat`` (relative to ``parent``) with a free joint ``f"{name}/joint"``; and one
    mesh geom ``f"{name}/geom{i}"`` per part: group :data:`OBJECT_GEOM_GROUP`,
    contype/conaffinity 1, condim :data:`OBJECT_CONDIM`, friction
    ``(asset.friction, 0.005, 0.0001)``, the asset's rgba, and mass ``asset.mass`` split across
    parts by volume. Meshes use MuJoCo's convex inertia (exact for convex parts, and robust
    for thin ones), so the body's mass is exactly ``asset.mass`` and its centre of mass is the
    body origin. Solver parameters are left at the model's defaults.

    Raises:
        ValueError: empty ``name``, or a mesh/body of that name already exists in ``spec``.
    """
    if not name:
        raise ValueError("object body name must be non-empty")
    if spec.body(name) is not None:
        raise ValueError(f"the spec already has a body named {name!r}")
    volumes = asset.part_volumes
    masses = asset.mass * volumes / volumes.sum()
    body = parent.add_body(name=name, pos=[float(x) for x in pos], quat=[float(x) for x in quat])
    body.add_freejoint(name=f"{name}/joint")
    for i, ((vertices, faces), part_mass) in enumerate(zip(asset.parts, masses)):
        mesh_name = f"{name}/part{i}"
        if spec.mesh(mesh_name) is not None:
            raise ValueError(f"the spec already has a mesh named {mesh_name!r}")
        mesh = spec.add_mesh(
            name=mesh_name,
            uservert=vertices.ravel().tolist(),
            userface=faces.ravel().tolist(),
        )
        mesh.inertia = mujoco.mjtMeshInertia.mjMESH_INERTIA_CONVEX
        body.add_geom(
            name=f"{name}/geom{i}",
            type=mujoco.mjtGeom.mjGEOM_MESH,
            meshname=mesh_name,
            group=OBJECT_GEOM_GROUP,
            contype=1,
            conaffinity=1,
            condim=OBJECT_CONDIM,
            friction=[asset.friction, TORSIONAL_FRICTION, ROLLING_FRICTION],
            rgba=list(asset.rgba),
            mass=float(part_mass),
        )
    return body


def default_cache_dir() -> Path:
    """``$MPG_CACHE_DIR/objects`` if that variable is set, else ``~/.cache/mpg_envs/objects``."""
    root = os.environ.get("MPG_CACHE_DIR")
    base = Path(root).expanduser() if root else Path.home() / ".cache" / "mpg_envs"
    return base / "objects"


# --------------------------------------------------------------------------------------
# Geometry
# --------------------------------------------------------------------------------------


def _check_seed(seed: int) -> int:
    """The seed as a plain int; ValueError unless a non-negative integer (numpy's RNG rule)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    return int(seed)


def _jitter_dims(nominal: tuple[tuple[str, float], ...], seed: int, index: int) -> dict[str, float]:
    """Jittered dimensions; each object has its own random stream so objects are independent."""
    rng = np.random.default_rng([seed, index])
    factors = rng.uniform(1.0 - BLOCKS_JITTER, 1.0 + BLOCKS_JITTER, size=len(nominal))
    # Rounded to 0.1 mm: readable sizes and an exact, stable cache key.
    return {k: round(v * float(f), 4) for (k, v), f in zip(nominal, factors)}


def _make_block(kind: str, dims: dict[str, float], seed: int, params: CoacdParams) -> list[Part]:
    """Convex parts of one block, in its canonical frame (z up), not yet centred."""
    if kind == "box_cube":
        s = dims["size"]
        return [_hull(trimesh.creation.box(extents=(s, s, s)).vertices)]
    if kind == "box":
        return [_hull(trimesh.creation.box(extents=(dims["x"], dims["y"], dims["z"])).vertices)]
    if kind == "cylinder":
        cyl = trimesh.creation.cylinder(radius=dims["diameter"] / 2, height=dims["height"], sections=CYLINDER_SECTIONS)
        return [_hull(cyl.vertices)]
    if kind == "prism":
        # Isosceles triangle in the y-z plane (base on z = 0), extruded along x.
        half_l, half_b, h = dims["length"] / 2, dims["base"] / 2, dims["height"]
        section = [(-half_b, 0.0), (half_b, 0.0), (0.0, h)]
        return [_hull(np.array([(x, y, z) for x in (-half_l, half_l) for y, z in section]))]
    if kind == "arch":
        length, depth, height = dims["length"], dims["depth"], dims["height"]
        box = trimesh.creation.box(extents=(length, depth, height))
        radius = ARCH_TUNNEL_RATIO * length
        # The tunnel: a cylinder along y, longer than the box so the boolean cuts clean through.
        tunnel = trimesh.creation.cylinder(radius=radius, height=1.5 * depth, sections=CYLINDER_SECTIONS)
        tunnel.apply_transform(trimesh.transformations.rotation_matrix(math.pi / 2, (1.0, 0.0, 0.0)))
        tunnel.apply_translation((0.0, 0.0, -height / 2))
        arch = box.difference(tunnel, engine="manifold")
        return _decompose(arch, seed, params, preprocess=False)
    raise ValueError(f"unknown block kind {kind!r}")


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
            return [_hull(hull.vertices)]
        parts = _decompose(mesh, seed, params, preprocess=False)
    else:
        # Not a closed surface: let coacd remesh it into a manifold before decomposing.
        parts = _decompose(mesh, seed, params, preprocess=True)
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


def _decompose(mesh: trimesh.Trimesh, seed: int, params: CoacdParams, preprocess: bool) -> list[Part]:
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
            part = _hull(vertices)
        except ValueError:
            continue  # a flat sliver: no volume, nothing to collide with
        parts.append(part)
    return parts


def _hull(points: np.ndarray) -> Part:
    """Convex hull of ``points`` as (vertices float64, faces int32); ValueError if too small."""
    points = np.asarray(points, dtype=np.float64)
    try:
        hull = trimesh.convex.convex_hull(points)
    except Exception as exc:  # qhull raises on coplanar/degenerate input
        raise ValueError("degenerate convex part") from exc
    vertices = np.asarray(hull.vertices, dtype=np.float64)
    faces = np.asarray(hull.faces, dtype=np.int32)
    if len(faces) < 4 or _closed_mesh_volume(vertices, faces) < MIN_PART_VOLUME:
        raise ValueError("degenerate convex part")
    return vertices, faces


def _closed_mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume enclosed by a closed, outward-oriented triangle mesh (divergence theorem)."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0)


def _closed_mesh_centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Centroid of the solid enclosed by a closed, outward-oriented triangle mesh."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]
    signed = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0  # tetrahedra with the origin
    return (signed[:, None] * (a + b + c) / 4.0).sum(axis=0) / signed.sum()


def _centre_parts(parts: list[Part]) -> tuple[list[Part], np.ndarray]:
    """Shift parts so their joint centre of mass (uniform density) is the origin.

    Computed from the parts rather than the source mesh so that it is exactly where MuJoCo
    puts the body's centre of mass when the mass is split across the parts by volume.
    Returns the shifted parts and the centre of mass in the source frame.
    """
    volumes = np.array([_closed_mesh_volume(v, f) for v, f in parts])
    centroids = np.array([_closed_mesh_centroid(v, f) for v, f in parts])
    com = (volumes[:, None] * centroids).sum(axis=0) / volumes.sum()
    return [(v - com, f) for v, f in parts], com


def _make_asset(
    name: str,
    parts: list[Part],
    rgba: tuple[float, float, float, float],
    density: float,
    mass: float | None,
    friction: float,
    source: str,
    com: np.ndarray,
) -> ObjectAsset:
    """An asset from centred parts; ``mass=None`` means ``density * volume`` within MASS_RANGE."""
    if mass is None:
        if not (math.isfinite(density) and density > 0):
            raise ValueError(f"density must be positive, got {density!r}")
        volume = sum(_closed_mesh_volume(v, f) for v, f in parts)
        mass = float(np.clip(density * volume, *MASS_RANGE))
    offset = tuple(float(c) for c in com)
    return ObjectAsset(name=name, parts=tuple(parts), rgba=rgba, mass=mass, friction=friction, source=source, mesh_offset=offset)


# --------------------------------------------------------------------------------------
# Disk cache
# --------------------------------------------------------------------------------------


def _resolve_cache_dir(cache_dir: str | os.PathLike[str] | None) -> Path:
    """The folder cache files go to: ``cache_dir`` itself, else :func:`default_cache_dir`."""
    return Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()


def _cached_parts(
    folder: Path, label: str, key_data: dict[str, Any], generate: Callable[[], list[Part]]
) -> tuple[list[Part], np.ndarray]:
    """Centred convex parts for ``key_data`` and their centre of mass in the source frame:
    from the cache if present, else generated and stored."""
    blob = json.dumps({"format": CACHE_FORMAT_VERSION, **key_data}, sort_keys=True).encode()
    digest = hashlib.sha256(blob).hexdigest()[:32]
    safe_label = re.sub(r"[^A-Za-z0-9_.-]+", "_", label)[:60]
    path = folder / f"{safe_label}-{digest}.npz"
    cached = _read_cache(path)
    if cached is not None:
        return cached
    parts, com = _centre_parts(generate())
    _write_cache(path, parts, com)
    return parts, com


def _read_cache(path: Path) -> tuple[list[Part], np.ndarray] | None:
    """Parts stored in ``path``, or None if it is missing or unreadable (then regenerate)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["format"]) != CACHE_FORMAT_VERSION:
                return None
            count = int(data["num_parts"])
            parts = [(data[f"v{i}"], data[f"f{i}"]) for i in range(count)]
            com = np.asarray(data["com"], dtype=np.float64)
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    ok = count > 0 and all(
        v.dtype == np.float64 and v.ndim == 2 and v.shape[1] == 3 and f.dtype == np.int32 and f.ndim == 2
        for v, f in parts
    )
    return (parts, com) if ok and com.shape == (3,) else None


def _write_cache(path: Path, parts: list[Part], com: np.ndarray) -> None:
    """Write atomically (temporary file + rename) so concurrent readers never see half a file."""
    arrays: dict[str, np.ndarray] = {
        "format": np.array(CACHE_FORMAT_VERSION),
        "num_parts": np.array(len(parts)),
        "com": np.asarray(com, dtype=np.float64),
    }
    for i, (v, f) in enumerate(parts):
        arrays[f"v{i}"] = v
        arrays[f"f{i}"] = f
    tmp_name = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.stem}-", suffix=".tmp", delete=False) as fh:
            tmp_name = fh.name
            np.savez(fh, **arrays)
        os.replace(tmp_name, path)
    except OSError as exc:
        # A read-only or full disk only costs speed: the parts are still returned.
        warnings.warn(f"could not write object cache {str(path)!r}: {exc}", RuntimeWarning, stacklevel=3)
        if tmp_name is not None:
            Path(tmp_name).unlink(missing_ok=True)
