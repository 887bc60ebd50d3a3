"""Object geometry cache on disk.

Convex parts are cached as ``.npz`` files (default ``$MPG_CACHE_DIR/objects`` or
``~/.cache/mpg_envs/objects``), keyed by a hash of everything that shapes them (generator
parameters or mesh file bytes, the seed, the decomposition parameters and a format
version), so a second call only reads files, and one seed always gives the same arrays,
bit for bit. Files are written to a temporary name and renamed, so parallel processes
(vector envs) never see a half-written file. Meshes from outside also store the solid's volume
(:func:`cached_solid`: the union of overlapping bodies, for the mass) and a note on how the
parts were made when it is worth saying again at every load (a fallback).
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
import warnings
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mpg_envs.simulation.assets import Part, centre_parts

CACHE_FORMAT_VERSION = 2
"""Bump when the cached geometry changes for the same inputs; old files are then ignored."""


def default_cache_dir() -> Path:
    """``$MPG_CACHE_DIR/objects`` if that variable is set, else ``~/.cache/mpg_envs/objects``."""
    root = os.environ.get("MPG_CACHE_DIR")
    base = Path(root).expanduser() if root else Path.home() / ".cache" / "mpg_envs"
    return base / "objects"


def resolve_cache_dir(cache_dir: str | os.PathLike[str] | None) -> Path:
    """The folder cache files go to: ``cache_dir`` itself, else :func:`default_cache_dir`."""
    return Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir()


def _cache_path(folder: Path, label: str, key_data: dict[str, Any]) -> Path:
    blob = json.dumps({"format": CACHE_FORMAT_VERSION, **key_data}, sort_keys=True).encode()
    digest = hashlib.sha256(blob).hexdigest()[:32]
    safe_label = re.sub(r"[^A-Za-z0-9_.-]+", "_", label)[:60]
    return folder / f"{safe_label}-{digest}.npz"


def cached_parts(
    folder: Path, label: str, key_data: dict[str, Any], generate: Callable[[], list[Part]]
) -> tuple[list[Part], np.ndarray]:
    """Centred convex parts for ``key_data`` and their centre of mass in the source frame:
    from the cache if present, else generated and stored."""
    path = _cache_path(folder, label, key_data)
    cached = _read_cache(path)
    if cached is not None:
        return cached.parts, cached.com
    parts, com = centre_parts(generate())
    _write_cache(path, parts, com)
    return parts, com


@dataclass(frozen=True)
class CachedSolid:
    """Centred convex parts, their centre of mass in the source frame, the solid's volume (m^3)
    and a note on how they were made (``""`` when there is nothing to say)."""

    parts: list[Part]
    com: np.ndarray
    volume: float
    note: str = ""


def cached_solid(
    folder: Path, label: str, key_data: dict[str, Any], generate: Callable[[], tuple[list[Part], float, str]]
) -> CachedSolid:
    """Like :func:`cached_parts`, with the solid's volume and a note: ``generate`` returns
    ``(parts, volume, note)``. Entries without a volume (written by :func:`cached_parts`)
    count as missing."""
    cached = read_cached_solid(folder, label, key_data)
    if cached is not None:
        return cached
    path = _cache_path(folder, label, key_data)
    raw_parts, volume, note = generate()
    parts, com = centre_parts(raw_parts)
    _write_cache(path, parts, com, volume=float(volume), note=note)
    return CachedSolid(parts, com, float(volume), note)


def read_cached_solid(folder: Path, label: str, key_data: dict[str, Any]) -> CachedSolid | None:
    """What :func:`cached_solid` would read for ``key_data``, or ``None`` (nothing is made)."""
    cached = _read_cache(_cache_path(folder, label, key_data))
    if cached is None or cached.volume is None:
        return None
    return CachedSolid(cached.parts, cached.com, cached.volume, cached.note)


@dataclass(frozen=True)
class _Entry:
    parts: list[Part]
    com: np.ndarray
    volume: float | None
    note: str


def _read_cache(path: Path) -> _Entry | None:
    """The entry stored in ``path``, or None if it is missing or unreadable (then regenerate)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if int(data["format"]) != CACHE_FORMAT_VERSION:
                return None
            count = int(data["num_parts"])
            parts = [(data[f"v{i}"], data[f"f{i}"]) for i in range(count)]
            com = np.asarray(data["com"], dtype=np.float64)
            volume = float(data["volume"]) if "volume" in data.files else None
            note = str(data["note"]) if "note" in data.files else ""
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        return None
    ok = count > 0 and all(
        v.dtype == np.float64 and v.ndim == 2 and v.shape[1] == 3 and f.dtype == np.int32 and f.ndim == 2 for v, f in parts
    )
    return _Entry(parts, com, volume, note) if ok and com.shape == (3,) else None


def _write_cache(path: Path, parts: list[Part], com: np.ndarray, volume: float | None = None, note: str = "") -> None:
    """Write atomically (temporary file + rename) so concurrent readers never see half a file."""
    arrays: dict[str, Any] = {  # np.savez's keywords
        "format": np.array(CACHE_FORMAT_VERSION),
        "num_parts": np.array(len(parts)),
        "com": np.asarray(com, dtype=np.float64),
    }
    if volume is not None:
        arrays["volume"] = np.array(volume, dtype=np.float64)
        arrays["note"] = np.array(note)
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
