"""Scene files: read and write them, and say what is wrong with them.

This module only reads and writes files; :meth:`mpg_envs.tasks.env.MPGEnv.reset` (option
``scene``) applies a :class:`SceneFile` to a world (:mod:`mpg_envs.scenes.scene_loading`), and
:meth:`MPGEnv.current_scene` makes one from the current episode.

Our format is JSON (``.json``): the object set, each object's asset, pose and state, and
the target. The peers' plain-text files (``.txt``, poses in VPG's frame) load too: VPG's
test cases (``mesh r g b x y z rx ry rz`` per line, the first object is the target) and
Grasping the Invisible's presets (``name mesh x y z rx ry rz``, the target named by its
colour); :mod:`mpg_envs.scenes.vpg_scenes` reads them and says how their poses map onto ours.

Errors (:class:`SceneFileError`, a ``ValueError``) name the file, the object (its index and,
for text files, its line) and what is wrong: an unreadable file, an unknown mesh or asset, a
missing or out-of-range target, a malformed position, orientation or colour, an orientation
that is not a unit quaternion (:data:`QUAT_TOLERANCE`), more objects than a scene may hold
(:data:`MAX_OBJECTS`), an object outside the workspace or above it, objects interpenetrating
(:data:`PENETRATION_TOLERANCE_M`, checked once they are placed:
:mod:`mpg_envs.scenes.scene_loading`). Objects outside the workspace can be dropped instead
(``drop_outside=True``; a warning names them).

A scene file records the SHA-256 digest of each mesh file it names (``"sha256"``); reading it
again with a mesh file that changed since raises, or with ``allow_changed_meshes=True`` warns
(files written before digests were recorded load as they are).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import warnings
from pathlib import Path
from typing import cast

import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.scene_file import (  # noqa: F401  (re-exported: a scene file's types, read and written here)
    BELOW_TABLE,
    MAX_OBJECTS,
    PENETRATION_TOLERANCE_M,
    QUAT_TOLERANCE,
    SceneFile,
    SceneFileError,
    SceneObject,
    check_scene,
    scene_text,
)
from mpg_envs.scenes.vpg_scenes import read_vpg_text
from mpg_envs.simulation.families import family_asset
from mpg_envs.simulation.family_shapes import FAMILY_NAMES
from mpg_envs.simulation.objects import ObjectAsset, blocks_object_set, load_mesh_folder, load_object_set
from mpg_envs.simulation.random_urdfs import PACKED_SOURCE_PREFIX, TEST_SET_NAME

SCENE_FORMAT = "mpg-scene"
SCENE_VERSION = 1


def objects_outside(scene: SceneFile, workspace: Workspace) -> list[int]:
    """Active objects whose pose is not finite, whose centre is outside the workspace
    footprint, below the table or above the workspace's top."""
    out = []
    for i, obj in enumerate(scene.objects):
        pos = np.asarray(obj.position, float)
        if not obj.active:
            continue
        if (
            not np.all(np.isfinite(pos))
            or not workspace.contains_xy(pos[0], pos[1])
            or not BELOW_TABLE <= pos[2] <= workspace.z_max
        ):
            out.append(i)
    return out


def describe_objects(scene: SceneFile, indices: list[int] | np.ndarray, positions: np.ndarray | None = None) -> str:
    """``"object 3 ('cube', line 4) at (0.86, -0.20, 0.03), ..."`` for messages."""
    parts = []
    for k, i in enumerate(indices):
        obj = scene.objects[int(i)]
        pos = np.asarray(obj.position if positions is None else positions[k], float)
        parts.append(f"{obj.label or f'object {int(i)}'} at ({pos[0]:.3f}, {pos[1]:.3f}, {pos[2]:.3f})")
    return ", ".join(parts)


def resolve_outside(
    scene: SceneFile,
    outside: list[int],
    workspace: Workspace,
    drop_outside: bool,
    when: str,
    positions: np.ndarray | None = None,
) -> None:
    """Raise a :class:`SceneFileError` naming the ``outside`` objects (at ``positions``, else
    their file poses), or, with ``drop_outside``, warn naming them (the caller leaves them out)."""
    if not outside:
        return
    ws = workspace
    what = (
        f"{len(outside)} object(s) outside the workspace (x in [{ws.x_min}, {ws.x_max}], y in [{ws.y_min}, "
        f"{ws.y_max}], z in [{BELOW_TABLE}, {ws.z_max}]: on the table) "
        f"{when}: {describe_objects(scene, outside, positions)}"
    )
    if not drop_outside:
        raise SceneFileError(
            f"scene {scene.source!r}: {what}. Pass reset(options={{'drop_outside': True}}) to leave them out."
        )
    warnings.warn(f"scene {scene.source!r}: leaving out {what}", stacklevel=3)


def kept_target(scene: SceneFile, dropped: set[int]) -> int | None:
    """The target once ``dropped`` objects are left out; raises if the scene then has none."""
    target = scene.target
    if target is None:
        return None
    if target not in dropped:
        return target
    if scene.target_is_first_kept:
        kept = [i for i, obj in enumerate(scene.objects) if obj.active and i not in dropped]
        if kept:
            warnings.warn(
                f"scene {scene.source!r}: the target {scene.objects[target].label} was left out; the first object "
                f"listed that stays, {scene.objects[kept[0]].label}, is the target",
                stacklevel=3,
            )
            return kept[0]
    raise SceneFileError(f"scene {scene.source!r}: the target {scene.objects[target].label} is not in the scene (left out)")


# ------------------------------------------------------------------------------ writing
def save_scene(scene: SceneFile | object, path: str | Path) -> Path:
    """Write a scene as JSON: a :class:`SceneFile`, or an env's current scene
    (``env.unwrapped.current_scene()``)."""
    if not isinstance(scene, SceneFile):
        scene = scene.unwrapped.current_scene()  # type: ignore[attr-defined]
    scene = cast(SceneFile, scene)
    digests: dict[str, str] = {}
    objects = []
    for obj in scene.objects:
        entry = {
            "name": obj.asset.name,
            "source": obj.asset.source,
            "rgba": list(obj.asset.rgba),
            "position": np.asarray(obj.position, float).tolist(),
            "quat": np.asarray(obj.quat, float).tolist(),
            "active": bool(obj.active),
        }
        if obj.asset.source != "blocks" and Path(obj.asset.source).is_file():  # a mesh file (the blocks are made in code)
            entry["sha256"] = _digest(obj.asset.source, digests)
        objects.append(entry)
    doc = {
        "format": SCENE_FORMAT,
        "version": SCENE_VERSION,
        "stage": scene.stage,
        "object_set_seed": scene.object_set_seed,
        "target": scene.target,
        "objects": objects,
    }
    path = Path(path)
    path.write_text(json.dumps(doc, indent=1))
    return path


# ------------------------------------------------------------------------------ reading
def read_scene(
    path: str | Path,
    mesh_dir: str | Path | None = None,
    object_set_seed: int = 0,
    allow_changed_meshes: bool = False,
) -> SceneFile:
    """Read a scene file: ours (``.json``), or a VPG test case or Grasping the Invisible
    preset (``.txt``, see :mod:`mpg_envs.scenes.vpg_scenes`); ``object_set_seed`` is used for the
    text files (ours carry their own). A mesh file whose digest differs from the one our file
    recorded raises, or with ``allow_changed_meshes`` warns."""
    if not isinstance(path, (str, os.PathLike)):
        raise SceneFileError(f"scene file {path!r} is not a path; valid: a .json or .txt scene file's path (str or Path)")
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
    if path.suffix.lower() == ".txt":
        return read_vpg_text(path, mesh_dir, object_set_seed)
    if path.suffix.lower() == ".json":
        return _read_json_scene(path, mesh_dir, allow_changed_meshes)
    raise SceneFileError(
        f"scene file {str(path)!r}: expected a .json scene, or a VPG test case or Grasping the Invisible preset (.txt)"
    )


def _read_json_scene(path: Path, mesh_dir: str | Path | None, allow_changed_meshes: bool = False) -> SceneFile:
    doc = json_document(path)
    if not isinstance(doc, dict) or doc.get("format") != SCENE_FORMAT or doc.get("version") != SCENE_VERSION:
        raise SceneFileError(f"scene file {str(path)!r}: not an {SCENE_FORMAT} v{SCENE_VERSION} file")
    seed = doc.get("object_set_seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SceneFileError(f"scene file {str(path)!r}: object_set_seed is {json.dumps(seed)}; valid: a non-negative integer")
    if not isinstance(doc.get("stage"), (str, type(None))):
        raise SceneFileError(
            f"scene file {str(path)!r}: stage is {json.dumps(doc['stage'])}; valid: a stage name (a string) or null"
        )
    blocks = packed = None
    folders: dict[str, dict[str, ObjectAsset]] = {}
    objects = []
    listed = doc.get("objects") or []
    if not isinstance(listed, list) or len(listed) > MAX_OBJECTS:
        what = f"{len(listed)} objects" if isinstance(listed, list) else f"objects {listed!r}"
        raise SceneFileError(f"scene file {str(path)!r} lists {what}; valid: a list of at most {MAX_OBJECTS} objects")
    digests: dict[str, str] = {}
    for k, obj in enumerate(listed):
        try:
            name, source = obj["name"], obj["source"]
            for key, value in (("name", name), ("source", source)):
                if not isinstance(value, str):
                    raise ValueError(f"{key} is {value!r}; valid: a string")
            position = _numbers(obj["position"], 3, "position", "three numbers [x, y, z] (m)")
            quat = _numbers(obj["quat"], 4, "quat", "four numbers [w, x, y, z], a unit quaternion")
            rgba = tuple(_numbers(obj["rgba"], 4, "rgba", "four numbers in [0, 1] [red, green, blue, alpha]", (0.0, 1.0)))
            active = obj.get("active", True)
            if not isinstance(active, bool):
                raise ValueError(f"active is {active!r}; valid: true or false")
        except (KeyError, TypeError, ValueError) as exc:
            raise SceneFileError(
                f"scene file {str(path)!r}: object {k} ({obj.get('name') if isinstance(obj, dict) else obj!r}) "
                f"is malformed: {exc if isinstance(exc, ValueError) else repr(exc)}"
            ) from exc
        if source == "blocks":
            blocks = blocks or {a.name: a for a in blocks_object_set(seed=seed)}
            asset = blocks.get(name)
        elif source.startswith(PACKED_SOURCE_PREFIX):  # the shipped random_urdfs test objects
            packed = packed or {a.name: a for a in load_object_set(TEST_SET_NAME)}
            asset = packed.get(name)
        elif source in FAMILY_NAMES:
            try:
                asset = family_asset(source, name, seed)
            except ValueError:
                asset = None
        else:
            folder = str(Path(mesh_dir) if mesh_dir is not None else Path(source).parent)
            if folder not in folders:
                folders[folder] = {a.name: a for a in load_mesh_folder(folder, seed=seed)} if Path(folder).is_dir() else {}
            asset = folders[folder].get(name)
        if asset is None:
            raise SceneFileError(f"scene file {str(path)!r}: object {k} has an unknown asset {name!r} (from {source!r})")
        label = f"object {k} ({name!r})"
        if "sha256" in obj and Path(asset.source).is_file() and _digest(asset.source, digests) != obj["sha256"]:
            changed = (
                f"scene file {str(path)!r}: {label}'s mesh {asset.source!r} changed since the scene was saved "
                f"(sha256 {digests[asset.source][:12]}..., recorded {str(obj['sha256'])[:12]}...)"
            )
            if not allow_changed_meshes:
                raise SceneFileError(
                    f"{changed}; restore the mesh, or read_scene(..., allow_changed_meshes=True) to load it as it is now"
                )
            warnings.warn(f"{changed}; loading the mesh as it is now", stacklevel=3)
        objects.append(SceneObject(dataclasses.replace(asset, rgba=rgba), position, quat, active, label))
    if not objects:
        raise SceneFileError(f"scene file {str(path)!r} lists no objects")
    target = doc.get("target")
    if target is not None:
        if isinstance(target, bool) or not isinstance(target, int) or not 0 <= target < len(objects):
            raise SceneFileError(
                f"scene file {str(path)!r}: target is {json.dumps(target)}; valid: an object index "
                f"0..{len(objects) - 1} (an integer), or null for no target"
            )
        if not objects[target].active:
            raise SceneFileError(
                f"scene file {str(path)!r}: the target {objects[target].label} is not in the scene (inactive)"
            )
    return SceneFile(tuple(objects), target, str(path), doc.get("stage"), seed)


def json_document(path: Path) -> object:
    """The JSON document of a scene file, else a :class:`SceneFileError` naming the file (see
    :func:`scene_text`; or not JSON)."""
    try:
        return json.loads(scene_text(path, f"an {SCENE_FORMAT} JSON file"))
    except json.JSONDecodeError as exc:
        raise SceneFileError(f"scene file {str(path)!r} is not readable JSON: {exc}") from exc


def _numbers(value: object, count: int, key: str, valid: str, bounds: tuple[float, float] | None = None) -> np.ndarray:
    """``value`` as ``count`` finite floats (within ``bounds``), else a ``ValueError`` naming ``key``."""
    ok = (
        isinstance(value, list)
        and len(value) == count
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    )
    array = np.asarray(value, float) if ok else np.zeros(0)
    if (
        not ok
        or not np.all(np.isfinite(array))
        or (bounds is not None and not np.all((array >= bounds[0]) & (array <= bounds[1])))
    ):
        raise ValueError(f"{key} is {value!r}; valid: {valid}")
    return array


def _digest(source: str, cache: dict[str, str]) -> str:
    """The SHA-256 hex digest of the file ``source`` (once per file and call)."""
    if source not in cache:
        cache[source] = hashlib.sha256(Path(source).read_bytes()).hexdigest()
    return cache[source]
