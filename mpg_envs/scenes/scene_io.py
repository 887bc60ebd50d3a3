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
missing or out-of-range target, an object outside the workspace. Objects outside the
workspace can be dropped instead (``drop_outside=True``; a warning names them).
"""

from __future__ import annotations

import dataclasses
import json
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpg_envs.simulation.families import family_asset
from mpg_envs.simulation.family_shapes import FAMILY_NAMES
from mpg_envs.simulation.objects import ObjectAsset, blocks_object_set, load_mesh_folder
from mpg_envs.grid.workspace import Workspace

SCENE_FORMAT = "mpg-scene"
SCENE_VERSION = 1
BELOW_TABLE = -0.02
"""An object whose centre is this far below the table top (m) has fallen off it."""


class SceneFileError(ValueError):
    """A scene file that cannot be loaded as it is; the message says what and where."""


@dataclass(frozen=True)
class SceneObject:
    """One object of a scene file.

    Attributes:
        asset: the object's asset (shape, colour, mass).
        position: ``(3,)`` world position of the body frame (metres).
        quat: ``(4,)`` orientation, unit quaternion, w first.
        active: False for an object already taken out of the scene (grasped).
        label: where the object comes from, for messages (``"object 3 ('cube')"``).
    """

    asset: ObjectAsset
    position: np.ndarray
    quat: np.ndarray
    active: bool = True
    label: str = ""


@dataclass(frozen=True)
class SceneFile:
    """The content of a scene file, independent of any env.

    Attributes:
        objects: every object, in world order.
        target: index into ``objects`` of the target (``None``: no target, Stage I).
        source: the file it was read from (for messages), or ``""``.
        stage: the stage name it was saved from (ours only).
        object_set_seed: the seed of the object set its assets come from.
        settle: let the physics settle after placing (VPG's hand-made poses may start
            slightly interpenetrating; our own files were saved at rest).
        target_is_first_kept: the target is "the first object listed" (VPG's convention),
            so when outside objects are dropped it is the first object that stays.
    """

    objects: tuple[SceneObject, ...]
    target: int | None
    source: str = ""
    stage: str | None = None
    object_set_seed: int = 0
    settle: bool = False
    target_is_first_kept: bool = False


# ------------------------------------------------------------------------------ checks
def objects_outside(scene: SceneFile, workspace: Workspace) -> list[int]:
    """Active objects whose pose is not finite, whose centre is outside the workspace
    footprint, or which lie below the table."""
    out = []
    for i, obj in enumerate(scene.objects):
        pos = np.asarray(obj.position, float)
        if not obj.active:
            continue
        if not np.all(np.isfinite(pos)) or not workspace.contains_xy(pos[0], pos[1]) or pos[2] < BELOW_TABLE:
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
        f"{ws.y_max}], on the table) {when}: {describe_objects(scene, outside, positions)}"
    )
    if not drop_outside:
        raise SceneFileError(f"scene {scene.source!r}: {what}. Pass reset(options={{'drop_outside': True}}) to leave them out.")
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
    objects = [
        {
            "name": obj.asset.name,
            "source": obj.asset.source,
            "rgba": list(obj.asset.rgba),
            "position": np.asarray(obj.position, float).tolist(),
            "quat": np.asarray(obj.quat, float).tolist(),
            "active": bool(obj.active),
        }
        for obj in scene.objects
    ]
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
def read_scene(path: str | Path, mesh_dir: str | Path | None = None, object_set_seed: int = 0) -> SceneFile:
    """Read a scene file: ours (``.json``), or a VPG test case or Grasping the Invisible
    preset (``.txt``, see :mod:`mpg_envs.scenes.vpg_scenes`); ``object_set_seed`` is used for the
    text files (ours carry their own)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
    if path.suffix.lower() == ".txt":
        from mpg_envs.scenes.vpg_scenes import read_vpg_text  # it builds on this module's types

        return read_vpg_text(path, mesh_dir, object_set_seed)
    if path.suffix.lower() == ".json":
        return _read_json_scene(path, mesh_dir)
    raise SceneFileError(f"scene file {str(path)!r}: expected a .json scene, or a VPG test case or Grasping the Invisible preset (.txt)")


def _read_json_scene(path: Path, mesh_dir: str | Path | None) -> SceneFile:
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise SceneFileError(f"scene file {str(path)!r} is not readable JSON: {exc}") from exc
    if not isinstance(doc, dict) or doc.get("format") != SCENE_FORMAT or doc.get("version") != SCENE_VERSION:
        raise SceneFileError(f"scene file {str(path)!r}: not an {SCENE_FORMAT} v{SCENE_VERSION} file")
    seed = int(doc.get("object_set_seed", 0))
    blocks = None
    folders: dict[str, dict[str, ObjectAsset]] = {}
    objects = []
    for k, obj in enumerate(doc.get("objects") or []):
        try:
            name, source = obj["name"], obj["source"]
            position, quat = np.asarray(obj["position"], float), np.asarray(obj["quat"], float)
            rgba, active = tuple(obj["rgba"]), bool(obj.get("active", True))
        except (KeyError, TypeError, ValueError) as exc:
            raise SceneFileError(f"scene file {str(path)!r}: object {k} is malformed ({exc!r})") from exc
        if source == "blocks":
            blocks = blocks or {a.name: a for a in blocks_object_set(seed=seed)}
            asset = blocks.get(name)
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
        objects.append(SceneObject(dataclasses.replace(asset, rgba=rgba), position, quat, active, label))
    if not objects:
        raise SceneFileError(f"scene file {str(path)!r} lists no objects")
    target = doc.get("target")
    if target is not None:
        if not isinstance(target, int) or not 0 <= target < len(objects):
            raise SceneFileError(f"scene file {str(path)!r}: target {target!r} is not an object index 0..{len(objects) - 1}")
        if not objects[target].active:
            raise SceneFileError(f"scene file {str(path)!r}: the target {objects[target].label} is not in the scene (inactive)")
    return SceneFile(tuple(objects), target, str(path), doc.get("stage"), seed)
