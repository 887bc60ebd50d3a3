"""A triangle mesh as convex parts and a solid volume: the bodies it is made of, their union, coacd.

:func:`decompose` is the raw coacd call. :func:`solid_from_mesh_file` is the whole path from a
mesh file to convex parts, meant to run in a worker process
(:mod:`mpg_envs.simulation.isolated_call`), since coacd can crash or hang on some inputs:

* a mesh whose connected bodies are all closed is split into them (inside-out ones are flipped, those under
  :data:`~mpg_envs.simulation.assets.MIN_PART_VOLUME` dropped); their union (``manifold3d``
  through trimesh) gives the solid's volume, so parts that overlap are not counted twice;
* bodies that are each convex and do not overlap (beyond :data:`OVERLAP_TOLERANCE`) are
  already a convex decomposition (as pybullet's ``random_urdfs``): each becomes one part,
  exactly, with no coacd call;
* otherwise each connected piece of the union becomes its hull if convex, else coacd's parts
  (preprocess off: the union is a clean manifold);
* an open or non-manifold surface goes to coacd with its manifold preprocess on; its volume is
  that of the parts.

Without coacd (``use_coacd=False``, the fallback when it crashed, failed or ran out of time) a
closed mesh whose convex hull is close to it (:func:`hull_close_enough`) becomes its hull; an
open surface or a clearly concave body is refused.

coacd is never given several disconnected bodies at once (that is what segfaults it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import coacd
import numpy as np
import trimesh

from mpg_envs.simulation.assets import MIN_PART_VOLUME, Part, convex_part, mesh_volume

CONVEX_VOLUME_RATIO = 0.97
"""A closed body whose volume is at least this fraction of its convex hull's volume is
treated as convex (one part, its hull); anything else is decomposed with coacd."""

HULL_FALLBACK_RATIO = 1.1
"""When convex decomposition failed or ran out of time, a closed mesh whose convex hull's volume
is at most this multiple of the mesh's own volume is used as its hull (one part, at most 10%
more volume to collide with: a near-convex shape keeps its grasps); above it the mesh is refused.
An open surface has no volume to compare, so it is always refused."""


def hull_close_enough(volume: float, hull_volume: float) -> bool:
    """Whether a solid of ``volume`` may stand in as its convex hull of ``hull_volume``:
    ``hull_volume <= HULL_FALLBACK_RATIO * volume`` (both positive).

    >>> hull_close_enough(1.0, 1.1), hull_close_enough(1.0, 1.11), hull_close_enough(0.0, 1.0)
    (True, False, False)
    """
    return volume > 0 and hull_volume <= HULL_FALLBACK_RATIO * volume


OVERLAP_TOLERANCE = 0.02
"""Convex bodies that overlap by at most this fraction of their union's volume are kept as the
parts (exact geometry; the mass still comes from the union, only the part-volume split of
mass, hence centre of mass and inertia, counts the overlap twice); more overlap (two closed
parts written over each other) has the union decomposed instead."""


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


def decompose(mesh: trimesh.Trimesh, seed: int, params: CoacdParams, preprocess: bool) -> list[Part]:
    """Convex parts of ``mesh`` from coacd (deterministic for fixed seed and parameters).

    Runs in the calling process: give it one connected body (the blocks' arch), or call it
    in a worker (:func:`solid_from_mesh_file`) for meshes from outside.
    """
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
    return _hull_parts(vertices for vertices, _faces in raw)


def _hull_parts(point_sets: Any) -> list[Part]:
    parts = []
    for points in point_sets:
        try:
            parts.append(convex_part(points))
        except ValueError:
            continue  # a flat sliver: no volume, nothing to collide with
    return parts


@dataclass(frozen=True)
class Solid:
    """What :func:`solid_from_mesh_file` returns (picklable across the worker pipe)."""

    parts: list[Part]
    volume: float
    """The solid's volume (m^3): of the union of the mesh's bodies, or of the parts if open."""
    method: str
    """How the parts were made: ``"hull"``, ``"bodies"``, ``"coacd"``, ``"coacd-preprocess"`` or
    ``"hull-fallback"`` (a near-convex mesh as its hull, without coacd)."""


def load_mesh(path: str, scale: float) -> trimesh.Trimesh:
    """A mesh file as one scaled, cleaned triangle mesh; ValueError naming the file if unusable."""
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files; report them uniformly
        raise ValueError(f"mesh file {path!r}: cannot load it ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"mesh file {path!r}: empty or unreadable mesh (no triangles)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise ValueError(f"mesh file {path!r}: non-finite vertex coordinates (NaN or inf); every vertex must be finite")
    mesh.process()  # merge duplicate vertices, drop degenerate faces (as trimesh.load does by default)
    mesh.apply_scale(scale)
    return drop_coincident_faces(mesh)


def solid_from_mesh_file(
    path: str, scale: float, seed: int, params: CoacdParams | dict[str, Any], use_coacd: bool = True
) -> Solid:
    """Convex parts and volume of the mesh file at ``path`` scaled by ``scale`` (see the module text).

    ``params`` may be given as the fields of :class:`CoacdParams` (a dict), so a caller in
    another process can send it without this module being imported to read the request.

    With ``use_coacd=False`` only meshes that need no decomposition are accepted (a convex
    mesh, separate convex bodies, or a closed mesh close to its hull: :func:`hull_close_enough`):
    the fallback when coacd crashed, failed or hung.

    Raises:
        ValueError: the file cannot be read, is empty or flat (zero volume), or needs coacd
            while ``use_coacd`` is off; the message names the file.
    """
    if isinstance(params, dict):
        params = CoacdParams(**params)
    # Flat or zero-volume bodies make trimesh divide by 0; they are caught by the checks below.
    with np.errstate(divide="ignore", invalid="ignore"):
        return _solid(path, scale, seed, params, use_coacd)


def _solid(path: str, scale: float, seed: int, params: CoacdParams, use_coacd: bool) -> Solid:
    mesh = load_mesh(path, scale)
    try:
        hull_volume = float(mesh.convex_hull.volume)
    except Exception as exc:  # qhull fails on flat or degenerate point sets
        raise ValueError(f"mesh file {path!r}: zero volume (flat or degenerate mesh); a solid object is needed") from exc
    if not hull_volume > MIN_PART_VOLUME:
        raise ValueError(
            f"mesh file {path!r}: zero volume (flat or degenerate mesh, hull {hull_volume:.3g} m^3 at scale "
            f"{scale:g}); a solid of at least {MIN_PART_VOLUME:g} m^3 is needed"
        )
    pieces = mesh.split(only_watertight=False)
    if not all(piece.is_watertight for piece in pieces):
        if not use_coacd:
            raise ValueError(
                f"mesh file {path!r}: an open surface needs convex decomposition (it has no volume to compare with "
                "its convex hull)"
            )
        # Not a closed surface: let coacd remesh it into a manifold before decomposing.
        parts = decompose(mesh, seed, params, preprocess=True)
        return _checked(path, Solid(parts, sum(mesh_volume(v, f) for v, f in parts), "coacd-preprocess"))
    # Closed bodies (touching bodies can make the whole mesh look open: an edge of four faces).
    bodies = _closed_bodies(pieces)
    if not bodies:
        raise ValueError(
            f"mesh file {path!r}: zero volume at scale {scale:g} (every closed body is under {MIN_PART_VOLUME:g} m^3); "
            "a solid with a body of at least that volume is needed (a larger scale, or fit='gripper')"
        )
    volumes = [float(b.volume) for b in bodies]
    convex = [v >= CONVEX_VOLUME_RATIO * float(b.convex_hull.volume) for b, v in zip(bodies, volumes)]
    union = bodies[0] if len(bodies) == 1 else _union(path, bodies)
    volume = float(union.volume)
    overlap = sum(volumes) > volume * (1.0 + OVERLAP_TOLERANCE)
    if len(bodies) > 1 and all(convex) and (not overlap or not use_coacd):
        return _checked(path, Solid(_hull_parts(b.vertices for b in bodies), volume, "bodies"))
    if volume >= CONVEX_VOLUME_RATIO * hull_volume:
        return _checked(path, Solid([convex_part(mesh.vertices)], volume, "hull"))
    if not use_coacd:
        if hull_close_enough(volume, hull_volume):
            return _checked(path, Solid([convex_part(mesh.vertices)], volume, "hull-fallback"))
        raise ValueError(
            f"mesh file {path!r}: a concave solid needs convex decomposition (its convex hull is "
            f"{hull_volume / volume:.2f} x its volume, over the {HULL_FALLBACK_RATIO:g} a hull may stand in for)"
        )
    parts = []
    for piece in union.split(only_watertight=False) if len(bodies) > 1 else [union]:
        if float(piece.volume) >= CONVEX_VOLUME_RATIO * float(piece.convex_hull.volume):
            parts.extend(_hull_parts([piece.vertices]))
        else:
            parts.extend(decompose(piece, seed, params, preprocess=False))
    return _checked(path, Solid(parts, volume, "coacd"))


def _checked(path: str, solid: Solid) -> Solid:
    if not solid.parts or not solid.volume > MIN_PART_VOLUME:
        raise ValueError(f"mesh file {path!r}: zero volume after convex decomposition; a solid object is needed")
    return solid


def _closed_bodies(pieces: list[trimesh.Trimesh]) -> list[trimesh.Trimesh]:
    """Closed connected bodies, each made outward-facing, the tiny ones dropped."""
    bodies = []
    for body in pieces:
        if body.volume < 0:  # consistently inside-out: flip rather than treat as concave
            body.invert()
        if body.volume >= MIN_PART_VOLUME:
            bodies.append(body)
    return bodies


def _union(path: str, bodies: list[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Boolean union of closed bodies (manifold3d); ValueError naming the file if it fails."""
    try:
        union = trimesh.boolean.union(bodies, engine="manifold", check_volume=False)
    except Exception as exc:  # manifold rejects bodies that are not clean 2-manifolds
        raise ValueError(f"mesh file {path!r}: the union of its {len(bodies)} bodies failed ({exc})") from exc
    if len(union.faces) == 0 or not union.volume > MIN_PART_VOLUME:
        raise ValueError(
            f"mesh file {path!r}: the union of its {len(bodies)} closed bodies is empty (bodies that are not clean "
            "2-manifolds); each body must be a closed, consistently oriented surface"
        )
    return union


def drop_coincident_faces(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
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
