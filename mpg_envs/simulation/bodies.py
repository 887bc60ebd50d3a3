"""MuJoCo bodies for objects: an :class:`~mpg_envs.simulation.assets.ObjectAsset` as a free body of an ``MjSpec``."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence

import mujoco
import numpy as np

from mpg_envs.simulation.assets import ObjectAsset

TORSIONAL_FRICTION = 0.005
"""Torsional friction (used by condim 4 contacts)."""

ROLLING_FRICTION = 0.0001
"""Rolling friction (only used if a contact has condim 6)."""

OBJECT_CONDIM = 4
"""Contact dimensionality of object geoms: sliding plus torsional friction, so an object
pinched by the pads does not spin about the pinch axis; rolling friction (6) is not needed."""

OBJECT_GEOM_GROUP = 1
"""Geom group of object geoms: the heightmap ray casts see groups 0 and 1 only."""


def part_mesh_name(vertices: np.ndarray, faces: np.ndarray) -> str:
    """The spec name of the mesh of one convex part: a digest of its vertices and faces, so
    equal parts share one mesh and different parts never collide by name."""
    digest = hashlib.blake2b(np.ascontiguousarray(vertices, np.float64).tobytes(), digest_size=8)
    digest.update(np.ascontiguousarray(faces, np.int64).tobytes())
    return f"part/{digest.hexdigest()}"


_PART_MESHES: dict[int, tuple[ObjectAsset, tuple[tuple[str, bytes], ...]]] = {}
"""id of an asset -> the asset and, per part, its mesh name and ``.msh`` file (an asset is
frozen; a world compiles the same assets again and again, and a reset from a test set builds
one). Bounded: the oldest entries go first."""


def _part_meshes(asset: ObjectAsset) -> tuple[tuple[str, bytes], ...]:
    kept = _PART_MESHES.get(id(asset))
    if kept is None or kept[0] is not asset:
        kept = (asset, tuple((part_mesh_name(v, f), msh_bytes(v, f)) for v, f in asset.parts))
        if len(_PART_MESHES) >= 4096:
            _PART_MESHES.pop(next(iter(_PART_MESHES)))
        _PART_MESHES[id(asset)] = kept
    return kept[1]


def mesh_file_name(mesh_name: str) -> str:
    """The in-memory file name of the mesh ``mesh_name`` (:func:`part_mesh_name`) in a spec's assets."""
    return mesh_name.replace("/", "_") + ".msh"


def msh_bytes(vertices: np.ndarray, faces: np.ndarray) -> bytes:
    """A convex part as a MuJoCo binary ``.msh`` file: the counts of vertices, normals,
    texture coordinates and faces (int32), then the vertices as float32 and the faces as int32
    (MuJoCo keeps mesh vertices as float32, so this is the mesh it would be given otherwise)."""
    vertices = np.ascontiguousarray(vertices, np.float32).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, np.int32).reshape(-1, 3)
    return np.array([len(vertices), 0, 0, len(faces)], np.int32).tobytes() + vertices.tobytes() + faces.tobytes()


def add_object_body(
    spec: mujoco.MjSpec,
    parent: mujoco.MjsBody,
    asset: ObjectAsset,
    name: str,
    pos: Sequence[float] = (0.0, 0.0, 0.0),
    quat: Sequence[float] = (1.0, 0.0, 0.0, 0.0),
) -> mujoco.MjsBody:
    """Add ``asset`` to ``spec`` as a free body named ``name``, child of ``parent``.

    Uses one mesh asset per convex part of the asset, shared by every body of the same
    shape (named by a digest of the part's vertices and faces, so compiling a scene of 30
    objects processes each distinct part once, and given as an in-memory ``.msh`` file, so
    MuJoCo's asset cache keeps it processed for the next compile); a body ``name`` at
    ``pos``/``quat`` (relative to ``parent``) with a free joint ``f"{name}/joint"``; and one
    mesh geom ``f"{name}/geom{i}"`` per part: group :data:`OBJECT_GEOM_GROUP`,
    contype/conaffinity 1, condim :data:`OBJECT_CONDIM`, friction
    ``(asset.friction, 0.005, 0.0001)``, the asset's rgba, and mass ``asset.mass`` split across
    parts by volume. Meshes use MuJoCo's convex inertia (exact for convex parts, and robust
    for thin ones), so the body's mass is exactly ``asset.mass`` and its centre of mass is the
    body origin. Solver parameters are left at the model's defaults.

    Raises:
        ValueError: empty ``name``, or a body of that name already exists in ``spec``.
    """
    if not name:
        raise ValueError("object body name must be non-empty")
    if spec.body(name) is not None:
        raise ValueError(f"the spec already has a body named {name!r}")
    volumes = asset.part_volumes
    masses = asset.mass * volumes / volumes.sum()
    body = parent.add_body(name=name, pos=[float(x) for x in pos], quat=[float(x) for x in quat])
    body.add_freejoint(name=f"{name}/joint")
    for i, (part_mass, (mesh_name, mesh_file)) in enumerate(zip(masses, _part_meshes(asset))):
        if spec.mesh(mesh_name) is None:
            # An in-memory mesh file: MuJoCo's compiler keeps the processed mesh (hull,
            # inertia) in its asset cache by file name, so a later world with the same part
            # compiles it in microseconds; the name is a digest of the part, never reused.
            file = mesh_file_name(mesh_name)
            spec.assets[file] = mesh_file
            mesh = spec.add_mesh(name=mesh_name, file=file)
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
