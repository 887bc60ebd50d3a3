"""Scene files: save the current scene, load it again, and load VPG's test cases.

Our format is JSON (``.json``): the object set, each object's asset, pose and state, and
the target. VPG's plain-text test cases (``.txt``, one ``mesh r g b x y z rx ry rz`` line per
object, poses in VPG's frame) load too: VPG's workspace is ours rotated 180 degrees about z,
so a VPG pose ``(x, y)`` maps to ``(-x, -y)``; its Euler angles are CoppeliaSim's
(``R = Rx(rx) Ry(ry) Rz(rz)``) of the mesh frame. The first object of a VPG case is the
target. Mesh files are read from ``mesh_dir``, else from a ``blocks`` folder beside the
test-case folder (VPG's layout), else mapped onto our blocks set (:data:`VPG_TO_BLOCKS`).
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from mpg_envs.objects import ObjectAsset, blocks_object_set, load_mesh_folder

if TYPE_CHECKING:
    from mpg_envs.env import MPGEnv

SCENE_FORMAT = "mpg-scene"
SCENE_VERSION = 1

VPG_TO_BLOCKS: dict[str, str] = {
    "0": "triangular_prism",
    "1": "arch",
    "2": "disc",
    "3": "long_box",
    "4": "cube",
    "6": "tall_box",
    "7": "flat_box",
    "8": "cylinder",
}
"""VPG block mesh stem -> the blocks-set shape it resembles (by size and shape)."""


def save_scene(env: "MPGEnv", path: str | Path) -> Path:
    """Write the env's current scene (every object's asset and pose, the target) as JSON."""
    env = env.unwrapped
    world = env.world
    if world is None:
        raise RuntimeError("call reset() before save_scene()")
    objects = []
    for i, asset in enumerate(world.assets):
        pos, quat = world.object_pose(i)
        objects.append(
            {
                "name": asset.name,
                "source": asset.source,
                "rgba": list(asset.rgba),
                "position": pos.tolist(),
                "quat": quat.tolist(),
                "active": bool(world.active[i]),
            }
        )
    doc = {
        "format": SCENE_FORMAT,
        "version": SCENE_VERSION,
        "stage": env.stage.name,
        "object_set_seed": env.config.object_set_seed,
        "target": env.target,
        "objects": objects,
    }
    path = Path(path)
    path.write_text(json.dumps(doc, indent=1))
    return path


def load_scene(env: "MPGEnv", path: str | Path, mesh_dir: str | Path | None = None) -> None:
    """Rebuild ``env``'s world from a scene file (ours ``.json`` or VPG's ``.txt``)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file {str(path)!r} does not exist")
    if path.suffix.lower() == ".txt":
        assets, poses, active, target = _read_vpg_case(path, mesh_dir, env.config.object_set_seed)
    elif path.suffix.lower() == ".json":
        assets, poses, active, target = _read_json_scene(path, mesh_dir)
    else:
        raise ValueError(f"scene file {str(path)!r}: expected a .json scene or a VPG .txt test case")
    world = env._build_world(assets)
    for i, (pos, quat) in enumerate(poses):
        if active[i]:
            world.set_object_pose(i, pos, quat)
    world.forward()
    # Poses below the table or outside the room (VPG files hold a few) leave the object out.
    for i in world.objects_out_of_room().tolist() + world.objects_off_table().tolist():
        world.remove_object(i)
    world.forward()
    if path.suffix.lower() == ".txt":
        # VPG poses are hand-made and may start slightly interpenetrating; our own files were
        # saved at rest and are restored exactly.
        world.settle(4 * world.physics.settle_max_steps)
    env.target = target


def _read_json_scene(path: Path, mesh_dir: str | Path | None):
    try:
        doc = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"scene file {str(path)!r} is not readable JSON: {exc}") from exc
    if doc.get("format") != SCENE_FORMAT or doc.get("version") != SCENE_VERSION:
        raise ValueError(f"scene file {str(path)!r}: not an {SCENE_FORMAT} v{SCENE_VERSION} file")
    seed = int(doc.get("object_set_seed", 0))
    blocks = None
    folders: dict[str, dict[str, ObjectAsset]] = {}
    assets, poses, active = [], [], []
    for k, obj in enumerate(doc["objects"]):
        if obj["source"] == "blocks":
            blocks = blocks or {a.name: a for a in blocks_object_set(seed=seed)}
            asset = blocks.get(obj["name"])
        else:
            folder = str(Path(mesh_dir) if mesh_dir is not None else Path(obj["source"]).parent)
            if folder not in folders:
                folders[folder] = {a.name: a for a in load_mesh_folder(folder, seed=seed)}
            asset = folders[folder].get(obj["name"])
        if asset is None:
            raise ValueError(f"scene file {str(path)!r}: object {k} ({obj['name']!r} from {obj['source']!r}) not found")
        assets.append(dataclasses.replace(asset, rgba=tuple(obj["rgba"])))
        poses.append((np.asarray(obj["position"], float), np.asarray(obj["quat"], float)))
        active.append(bool(obj["active"]))
    target = doc.get("target")
    if target is not None and not 0 <= int(target) < len(assets):
        raise ValueError(f"scene file {str(path)!r}: target {target} is not an object index 0..{len(assets) - 1}")
    return assets, poses, active, None if target is None else int(target)


def _read_vpg_case(path: Path, mesh_dir: str | Path | None, seed: int):
    folder = Path(mesh_dir) if mesh_dir is not None else path.parent.parent / "blocks"
    by_name: dict[str, ObjectAsset]
    if folder.is_dir():
        by_name = {a.name: a for a in load_mesh_folder(folder, seed=seed)}
        mapping = None
    else:
        if mesh_dir is not None:
            raise FileNotFoundError(f"mesh_dir {str(mesh_dir)!r} does not exist")
        by_name = {a.name: a for a in blocks_object_set(seed=seed)}
        mapping = VPG_TO_BLOCKS
    assets, poses, active = [], [], []
    for lineno, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        fields = line.split()
        if len(fields) != 10:
            raise ValueError(f"{path}:{lineno}: expected 'mesh r g b x y z rx ry rz', got {len(fields)} fields")
        stem = Path(fields[0]).stem
        name = mapping.get(stem, stem) if mapping else stem
        if name not in by_name:
            raise ValueError(f"{path}:{lineno}: mesh {fields[0]!r} not found in {str(folder) if mapping is None else 'the blocks set'}")
        try:
            r, g, b, x, y, z, rx, ry, rz = (float(v) for v in fields[1:])
        except ValueError as exc:
            raise ValueError(f"{path}:{lineno}: {exc}") from exc
        asset = dataclasses.replace(by_name[name], rgba=(r, g, b, 1.0))
        rot = _rot_z(math.pi) @ _rot_x(rx) @ _rot_y(ry) @ _rot_z(rz)
        # The VPG pose is the mesh frame's; our body frame sits at the parts' centre of mass.
        position = np.array([-x, -y, z]) + rot @ np.asarray(asset.mesh_offset)
        quat = np.empty(4)
        mujoco.mju_mat2Quat(quat, rot.ravel())
        assets.append(asset)
        poses.append((position, quat))
        active.append(bool(np.all(np.isfinite(position))))
    if not assets:
        raise ValueError(f"VPG test case {str(path)!r} lists no objects")
    return assets, poses, active, 0


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
