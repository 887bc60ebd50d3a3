"""Object packs: a fitted object set stored as its convex parts in one ``.npz``, loadable without its source.

An object set from outside (meshes read from an installed package, decomposed and fitted to
the gripper) depends on that package, the decomposition library and the cache. A pack freezes
the result: per object its name, colour, mass, friction, the scale applied to the source mesh,
the centre of mass in the source frame, the solid's volume, its source and licence, and its
convex parts (vertices float32, faces int32). :func:`load_object_pack` rebuilds the same
:class:`~mpg_envs.simulation.assets.ObjectAsset` list from the file alone (numpy only), so a
shipped test set on such objects runs where the source package is not installed.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from mpg_envs.simulation.assets import ObjectAsset

__all__ = ["PACK_FORMAT", "PACK_VERSION", "load_object_pack", "read_pack_meta", "save_object_pack"]

PACK_FORMAT = "mpg-object-pack"
"""The ``format`` entry of a pack's metadata."""

PACK_VERSION = 1
"""Bump when the file layout changes."""


def save_object_pack(
    path: str | os.PathLike[str], assets: Sequence[ObjectAsset], meta: Mapping[str, str] | None = None
) -> Path:
    """Write ``assets`` (and string metadata, e.g. source and licence of the set) to ``path`` (compressed ``.npz``).

    Vertices are stored as float32 (sub-micrometre rounding); a loaded pack is the
    reference geometry of anything made from it (scenes are generated from the loaded pack).

    Raises:
        ValueError: no assets, duplicate names, or a metadata key that the file reserves.
    """
    if not assets:
        raise ValueError("an object pack needs at least one object")
    names = [a.name for a in assets]
    if len(set(names)) != len(names):
        raise ValueError(f"object names in a pack must be unique, got duplicates in {names}")
    meta = dict(meta or {})
    reserved = {"format", "version"} & set(meta)
    if reserved:
        raise ValueError(f"metadata keys {sorted(reserved)} are written by the pack itself")
    meta = {"format": PACK_FORMAT, "version": str(PACK_VERSION), **{str(k): str(v) for k, v in meta.items()}}
    parts = [p for a in assets for p in a.parts]
    path = Path(path)
    np.savez_compressed(
        path,
        names=np.array(names, dtype=str),
        rgba=np.array([a.rgba for a in assets], np.float64),
        mass=np.array([a.mass for a in assets], np.float64),
        friction=np.array([a.friction for a in assets], np.float64),
        scale=np.array([a.scale for a in assets], np.float64),
        mesh_offset=np.array([a.mesh_offset for a in assets], np.float64),
        volume=np.array([a.volume for a in assets], np.float64),
        sources=np.array([a.source for a in assets], dtype=str),
        licences=np.array([a.licence for a in assets], dtype=str),
        part_counts=np.array([a.num_parts for a in assets], np.int32),
        vertex_counts=np.array([len(v) for v, _ in parts], np.int32),
        face_counts=np.array([len(f) for _, f in parts], np.int32),
        vertices=np.concatenate([v for v, _ in parts]).astype(np.float32),
        faces=np.concatenate([f for _, f in parts]).astype(np.int32),
        meta_keys=np.array(list(meta), dtype=str),
        meta_values=np.array(list(meta.values()), dtype=str),
    )
    return path


def read_pack_meta(path: str | os.PathLike[str]) -> dict[str, str]:
    """The metadata of a pack (its ``format``, ``version`` and what the writer recorded)."""
    with np.load(Path(path), allow_pickle=False) as data:
        return _meta(path, data)


def load_object_pack(path: str | os.PathLike[str]) -> list[ObjectAsset]:
    """The objects of a pack, in stored order, as :func:`save_object_pack` was given them
    (vertices rounded to float32, then float64).

    Raises:
        ValueError: the file is not an object pack, or its arrays do not add up (names the file).
    """
    with np.load(Path(path), allow_pickle=False) as data:
        _meta(path, data)
        part_counts, vertex_counts, face_counts = data["part_counts"], data["vertex_counts"], data["face_counts"]
        vertices, faces = data["vertices"].astype(np.float64), data["faces"]
        if part_counts.sum() != len(vertex_counts) or vertex_counts.sum() != len(vertices) or face_counts.sum() != len(faces):
            raise ValueError(f"{path}: object pack arrays do not add up (parts, vertices or faces)")
        v_ends, f_ends = np.cumsum(vertex_counts), np.cumsum(face_counts)
        assets, k = [], 0
        for i, name in enumerate(data["names"].tolist()):
            parts = []
            for j in range(k, k + int(part_counts[i])):
                v0, f0 = v_ends[j] - vertex_counts[j], f_ends[j] - face_counts[j]
                parts.append((vertices[v0 : v_ends[j]], faces[f0 : f_ends[j]]))
            k += int(part_counts[i])
            ox, oy, oz = (float(c) for c in data["mesh_offset"][i])
            r, g, b, a = (float(c) for c in data["rgba"][i])
            assets.append(
                ObjectAsset(
                    name=name,
                    parts=tuple(parts),
                    rgba=(r, g, b, a),
                    mass=float(data["mass"][i]),
                    friction=float(data["friction"][i]),
                    source=str(data["sources"][i]),
                    mesh_offset=(ox, oy, oz),
                    scale=float(data["scale"][i]),
                    licence=str(data["licences"][i]),
                )  # fmt: skip
            )
    return assets


def _meta(path: str | os.PathLike[str], data: Mapping[str, np.ndarray]) -> dict[str, str]:
    try:
        meta = dict(zip(data["meta_keys"].tolist(), data["meta_values"].tolist()))
    except KeyError:
        meta = {}
    if meta.get("format") != PACK_FORMAT:
        raise ValueError(f"{path}: not an {PACK_FORMAT} file")
    if meta.get("version") != str(PACK_VERSION):
        raise ValueError(f"{path}: object pack version {meta.get('version')!r}, this reader reads {PACK_VERSION}")
    return meta
