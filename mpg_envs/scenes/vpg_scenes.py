"""The peers' plain-text scene files, all in VPG's frame: VPG's test cases and Grasping the
Invisible's presets.

Two formats, one object per line:

* VPG's test cases (``mesh r g b x y z rx ry rz``): the first object is the target.
* Grasping the Invisible's presets (``name mesh x y z rx ry rz``): ``name`` is ``block`` for a
  clutter object and a colour (:data:`GTI_COLOURS`) for the target, which takes that colour;
  blocks are GTI's grey. Lines starting with ``#`` are comments.

Both were made in CoppeliaSim. VPG's workspace is ours rotated 180 degrees about z, so a
pose ``(x, y)`` maps to ``(-x, -y)``. The Euler angles (``R = Rx(rx) Ry(ry) Rz(rz)``) are
those of the *shape frame* CoppeliaSim gives a mesh when it imports it: its frame is
re-oriented along the mesh's bounding box, which for most of VPG's block meshes is not the
OBJ file's frame (:data:`VPG_SHAPE_FRAMES`). Read in the OBJ's frame, the blocks of a
stack stand on end inside each other (an arch of ``exploration-00`` collapses and blocks fly
off the table); read in the shape frame, every object of the bottom layer of every peer file
rests on the table to 0.3 mm. Positions are those of the mesh's bounding-box centre.

The peers' simulator keeps about 1 mm of contact margin around every shape: objects rest
1 mm above the table and stacked ones about 2 mm above each other, so on loading a stack
settles by up to about 2 mm per layer. A few of the presets pose an object inside the table
(a tall box or a cube given the height of a 25 mm slab); such an object is raised onto the
table when read, with a warning naming it.

Meshes are read from ``mesh_dir``, else from a ``blocks`` folder beside the file's folder
(the peers' repository layout), else from ``vpg/blocks`` there (a folder holding both
peers), else mapped onto our ``blocks`` set (:data:`VPG_TO_BLOCKS`, an approximation).
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from pathlib import Path

import mujoco
import numpy as np

from mpg_envs.scenes.scene_file import BELOW_TABLE, SceneFile, SceneFileError, SceneObject, scene_text
from mpg_envs.simulation.assets import ObjectAsset
from mpg_envs.simulation.objects import blocks_object_set, load_mesh_folder

GTI_COLOURS: dict[str, tuple[float, float, float]] = {
    name: (r / 255.0, g / 255.0, b / 255.0)
    for name, (r, g, b) in {
        "block": (184, 179, 168),
        "red": (255, 0, 0),
        "orange": (255, 127, 0),
        "yellow": (255, 255, 0),
        "green": (0, 255, 0),
        "blue": (0, 0, 255),
        "indigo": (38, 0, 51),
        "violet": (148, 0, 211),
    }.items()
}
"""Grasping the Invisible's object names and their colours (``block``: clutter; the others name the target)."""

TABLE_PENETRATION = 0.001
"""A file pose reaching deeper than this (m) below the table top is raised onto the table."""


def _rot_x(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rot_z(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


_SWAP_XZ = np.array(
    [[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]
)  # also Efficient Push-Grasping's fix for these meshes

VPG_SHAPE_FRAMES: dict[str, np.ndarray] = {
    "0": _SWAP_XZ,  # triangular prism
    "1": _SWAP_XZ,  # arch
    # A 50 x 50 x 25 mm slab whose square sides lie 15.39 degrees off the OBJ's axes.
    "2": _rot_x(math.radians(-15.39)),
    "3": _SWAP_XZ,  # long box
    "4": _SWAP_XZ,  # cube
    "6": np.eye(3),  # tall box
    "7": np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]),  # short cylinder
    "8": _SWAP_XZ,  # cylinder
}
"""VPG block mesh stem -> rotation from the OBJ file's frame to CoppeliaSim's shape frame
(``v_shape = M @ v_obj``), fitted to the peers' files. Other meshes are taken as given."""

VPG_TO_BLOCKS: dict[str, tuple[str, np.ndarray]] = {
    "0": ("triangular_prism", _SWAP_XZ @ _rot_z(math.pi / 2)),  # ours is extruded along x, VPG's along y
    "1": ("arch", _SWAP_XZ),
    "2": ("flat_box", _rot_y(math.pi / 2)),  # VPG's slab is thin along x, ours along z
    "3": ("long_box", _SWAP_XZ),
    "4": ("cube", _SWAP_XZ),
    "6": ("tall_box", np.eye(3)),
    "7": ("disc", VPG_SHAPE_FRAMES["7"]),
    "8": ("cylinder", _SWAP_XZ),
}
"""VPG block mesh stem -> the blocks-set shape that resembles it (by size and shape) and the
rotation from that block's frame to the VPG mesh's shape frame."""


def read_vpg_text(path: Path, mesh_dir: str | Path | None, seed: int) -> SceneFile:
    """A VPG test case or a Grasping the Invisible preset (told apart by the first line:
    VPG's starts with a mesh file name, GTI's with an object name); see the module docstring."""
    lines = [(n, line.split()) for n, line in enumerate(scene_text(path).splitlines(), start=1)]
    lines = [(n, fields) for n, fields in lines if fields and not fields[0].startswith("#")]
    if not lines:
        raise SceneFileError(f"scene file {str(path)!r} lists no objects")
    gti = not Path(lines[0][1][0]).suffix
    shapes = _shapes(path, mesh_dir, seed)
    objects: list[SceneObject] = []
    targets: list[int] = []
    for lineno, fields in lines:
        where = f"{path}:{lineno}"
        if gti:
            if len(fields) != 8:
                raise SceneFileError(
                    f"{where}: expected Grasping the Invisible's 'name mesh x y z rx ry rz', got {len(fields)} fields"
                )
            name, mesh, numbers = fields[0], fields[1], fields[2:]
            if name not in GTI_COLOURS:
                raise SceneFileError(f"{where}: unknown name {name!r}; valid: {', '.join(GTI_COLOURS)}")
            if name != "block":
                targets.append(len(objects))
            rgb = GTI_COLOURS[name]
        else:
            if len(fields) != 10:
                raise SceneFileError(f"{where}: expected 'mesh r g b x y z rx ry rz', got {len(fields)} fields")
            mesh, numbers = fields[0], fields[4:]
            r, g, b = _numbers(where, fields[1:4])
            rgb = (r, g, b)
        label = (
            f"object {len(objects)} ({mesh}, line {lineno})"
            if not gti
            else f"object {len(objects)} ({name} {mesh}, line {lineno})"
        )
        objects.append(_vpg_object(shapes, mesh, rgb, _numbers(where, numbers), where, label))
    if gti and len(targets) != 1:
        colours = ", ".join(c for c in GTI_COLOURS if c != "block")
        found = (
            "no line names" if not targets else f"{len(targets)} lines ({', '.join(objects[t].label for t in targets)}) name"
        )
        raise SceneFileError(f"preset {str(path)!r}: {found} a target colour ({colours}); exactly one must")
    objects = _onto_table(objects, path)
    if gti:
        return SceneFile(tuple(objects), targets[0], str(path), None, seed, settle=True)
    return SceneFile(tuple(objects), 0, str(path), None, seed, settle=True, target_is_first_kept=True)


# ------------------------------------------------------------------------------ helpers
_Shapes = tuple[dict[str, ObjectAsset], dict[str, np.ndarray], str]  # assets by stem, shape frames, where from


def _shapes(path: Path, mesh_dir: str | Path | None, seed: int) -> _Shapes:
    """The assets a file's mesh names refer to, each one's shape frame, and where they come from."""
    if mesh_dir is not None and not Path(mesh_dir).is_dir():
        raise FileNotFoundError(f"mesh_dir {str(mesh_dir)!r} does not exist")
    candidates = (
        [Path(mesh_dir)] if mesh_dir is not None else [path.parent.parent / "blocks", path.parent.parent / "vpg" / "blocks"]
    )
    folder = next((c for c in candidates if c.is_dir()), None)
    if folder is not None:
        assets = {a.name: a for a in load_mesh_folder(folder, seed=seed)}
        return assets, {stem: VPG_SHAPE_FRAMES.get(stem, np.eye(3)) for stem in assets}, str(folder)
    blocks = {a.name: a for a in blocks_object_set(seed=seed)}
    assets = {stem: blocks[name] for stem, (name, _) in VPG_TO_BLOCKS.items()}
    frames = {stem: frame for stem, (_, frame) in VPG_TO_BLOCKS.items()}
    return assets, frames, f"the blocks set (VPG meshes known: {sorted(VPG_TO_BLOCKS)})"


def _numbers(where: str, fields: list[str]) -> list[float]:
    try:
        values = [float(v) for v in fields]
    except ValueError as exc:
        raise SceneFileError(f"{where}: {exc}") from exc
    if not all(math.isfinite(v) for v in values):
        raise SceneFileError(f"{where}: non-finite number in {fields}")
    return values


def _vpg_object(
    shapes: _Shapes, mesh: str, rgb: tuple[float, float, float], numbers: list[float], where: str, label: str
) -> SceneObject:
    """One object at its VPG pose: the shape frame's Euler angles, the bounding-box centre."""
    assets, frames, source = shapes
    stem = Path(mesh).stem
    if stem not in assets:
        raise SceneFileError(f"{where}: unknown mesh {mesh!r}, not in {source}")
    asset = dataclasses.replace(assets[stem], rgba=(*rgb, 1.0))
    x, y, z, rx, ry, rz = numbers
    shape = _rot_z(math.pi) @ _rot_x(rx) @ _rot_y(ry) @ _rot_z(rz)  # the shape frame in our world
    rot = shape @ frames[stem]  # the asset frame in our world
    local = asset.vertices @ frames[stem].T  # vertices in the shape frame
    centre = (local.min(axis=0) + local.max(axis=0)) / 2
    # The asset's origin is its centre of mass; the file gives the bounding-box centre.
    position = np.array([-x, -y, z]) - shape @ centre
    quat = np.empty(4)
    mujoco.mju_mat2Quat(quat, rot.ravel())
    return SceneObject(asset, position, quat, True, label)


def _onto_table(objects: list[SceneObject], path: Path) -> list[SceneObject]:
    """Raise objects posed inside the table onto it (warning naming them)."""
    out, raised = [], []
    for obj in objects:
        rot = np.empty(9)
        mujoco.mju_quat2Mat(rot, obj.quat)
        bottom = obj.position[2] + float((obj.asset.vertices @ rot.reshape(3, 3).T)[:, 2].min())
        # Objects that fell off the peers' table (z down to -1000 m) stay where they are: outside.
        if obj.position[2] >= BELOW_TABLE and bottom < -TABLE_PENETRATION:
            obj = dataclasses.replace(obj, position=obj.position + np.array([0.0, 0.0, -bottom]))
            raised.append(f"{obj.label} by {-1000 * bottom:.1f} mm")
        out.append(obj)
    if raised:
        warnings.warn(f"scene {str(path)!r}: raised onto the table, posed inside it: {', '.join(raised)}", stacklevel=4)
    return out
