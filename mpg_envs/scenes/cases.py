"""Case sets: fixed scenes to run a policy on, with the target each case names.

A :class:`Case` is a scene (a scene file or a :class:`~mpg_envs.scenes.scene_io.SceneFile`) and
optionally the target it asks for; a :class:`CaseSet` is a named list of them.
:func:`load_cases` gives the named sets or any scene file or folder of them:

* ``challenge``: the project's own hand-designed scenes, shipped with the package
  (``mpg_envs/challenge``; ``benchmarks/make_challenge.py`` builds them, each with one line
  saying what makes it hard).
* ``epg``: Efficient Push-Grasping's ten test cases (Xu et al., 2021): VPG's
  ``test-10-obj-*`` files with the goal object that paper published for each case. Its case
  ``k`` is VPG's ``test-10-obj-k`` up to 5 and ``test-10-obj-(k+1)`` after (it left out
  VPG's case 06), its case 0 has object 1 two centimetres closer to VPG's y = 0 than VPG's
  file, and its loader shifts every object 10 cm along VPG's +y axis; all three as in its
  repository (:data:`EPG_CASES`, :data:`EPG_SHIFT`). Read from the folder the user names.
* ``gti``: Grasping the Invisible's twelve presets (Yang et al., 2020), from the folder the
  user names.

Objects outside the workspace in a file are left out of the case (VPG's cases keep three
to seven of their ten objects in it; the rest lay on the peers' larger table, out of view).

Each run of a case gets a small pose jitter (:func:`jitter_scene`, :data:`JITTER_M`,
:data:`JITTER_DEG`): the whole scene moved rigidly, so that N runs of a case are not N copies
of one episode; run 0 is the case as written.
"""

from __future__ import annotations

import dataclasses
import json
import math
import zlib
from collections.abc import Iterator
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import mujoco
import numpy as np

from mpg_envs.grid.workspace import Workspace
from mpg_envs.scenes.scene_file import SceneFile, SceneFileError
from mpg_envs.scenes.scene_io import kept_target, objects_outside, read_scene

CASE_SETS = ("challenge", "epg", "gti")
"""The named case sets."""

EPG_CASES: tuple[tuple[str, int], ...] = (
    ("test-10-obj-00", 4),
    ("test-10-obj-01", 7),
    ("test-10-obj-02", 8),
    ("test-10-obj-03", 7),
    ("test-10-obj-04", 7),
    ("test-10-obj-05", 3),
    ("test-10-obj-07", 1),
    ("test-10-obj-08", 7),
    ("test-10-obj-09", 5),
    ("test-10-obj-10", 9),
)
"""Efficient Push-Grasping's cases 0..9: (VPG's file, the goal object: its 0-based line)."""

EPG_SHIFT = 0.1
"""Efficient Push-Grasping's loader adds this (m) to VPG's y of every object (our -y)."""

EPG_CASE0_MOVE = (1, -0.02)
"""Efficient Push-Grasping's case 0: (object, change of VPG's y in m) against VPG's file."""

GTI_PRESETS = tuple(f"exploration-{i:02d}" for i in range(4)) + tuple(f"coordination-{i:02d}" for i in range(8))
"""Grasping the Invisible's presets: the target hidden (exploration) or packed in (coordination)."""

JITTER_M = 0.005
"""Run jitter: the scene moves by up to this (m) along x and along y."""

JITTER_DEG = 3.0
"""Run jitter: the scene turns by up to this (degrees) about the vertical through its centre."""


@dataclass(frozen=True)
class Case:
    """One scene to run a policy on.

    Attributes:
        name: the case's name (unique within its set).
        scene: a scene file (ours or a peer's, see :func:`mpg_envs.scenes.scene_io.read_scene`) or a
            :class:`~mpg_envs.scenes.scene_io.SceneFile`.
        target: the target's object index (file order), overriding the file's; ``None``
            keeps the file's.
        mesh_dir: meshes of a peer file (``None``: found beside it, see
            :mod:`mpg_envs.scenes.vpg_scenes`).
        note: one line saying what makes the case hard.
    """

    name: str
    scene: str | Path | SceneFile
    target: int | None = None
    mesh_dir: str | Path | None = None
    note: str = ""

    def scene_file(self, workspace: Workspace = Workspace(), object_set_seed: int = 0) -> SceneFile:
        """The case's scene: its target set, objects outside ``workspace`` left out.

        Raises:
            SceneFileError: the target is not an object of the scene, or lies outside.
        """
        scene = self.scene if isinstance(self.scene, SceneFile) else read_scene(self.scene, self.mesh_dir, object_set_seed)
        if self.target is not None:
            if not 0 <= self.target < len(scene.objects):
                raise SceneFileError(
                    f"case {self.name!r}: target {self.target} is not an object index 0..{len(scene.objects) - 1}"
                )
            scene = dataclasses.replace(scene, target=self.target, target_is_first_kept=False)
        outside = objects_outside(scene, workspace)
        target = kept_target(scene, set(outside)) if outside else scene.target
        objects = tuple(dataclasses.replace(obj, active=False) if i in outside else obj for i, obj in enumerate(scene.objects))
        return dataclasses.replace(scene, objects=objects, target=target, target_is_first_kept=False)


@dataclass(frozen=True)
class CaseSet:
    """A named list of cases (iterable, with ``len``)."""

    name: str
    cases: tuple[Case, ...]

    def __iter__(self) -> Iterator[Case]:
        return iter(self.cases)

    def __len__(self) -> int:
        return len(self.cases)

    def describe(self) -> str:
        """One line per case: its name and what makes it hard."""
        width = max(len(c.name) for c in self.cases)
        return "\n".join(f"{c.name:<{width}}  {c.note}".rstrip() for c in self.cases)


def load_cases(name_or_path: str | Path, peers_dir: str | Path | None = None) -> CaseSet:
    """A case set: ``challenge``, ``epg`` or ``gti`` (the last two read from ``peers_dir``,
    the folder holding the peers' files: ``vpg/test-cases`` and ``vpg/blocks``, ``gti``; or
    the set's own folder), or the path of a scene file or a folder of them (``.json``,
    ``.txt``; one case per file, sorted by name).

    Raises:
        ValueError: an unknown name or a path that is not there (the message lists what is
            valid), or a set's files not found in ``peers_dir``.
    """
    name = str(name_or_path)
    if name == "challenge":
        return challenge_set()
    if name in ("epg", "gti"):
        if peers_dir is None:
            raise ValueError(
                f"case set {name!r} is read from the peers' files: name the folder holding them (peers_dir, mpg-eval --peers)"
            )
        return epg_set(Path(peers_dir)) if name == "epg" else gti_set(Path(peers_dir))
    path = Path(name_or_path).expanduser()
    if name.strip() and path.is_file():
        return CaseSet(path.stem, (Case(path.stem, path),))
    if name.strip() and path.is_dir():
        return folder_set(path)
    raise ValueError(
        f"unknown case set {name!r}: valid are {', '.join(CASE_SETS)}, or the path of a scene file or a folder of them"
    )


# ------------------------------------------------------------------------------ named sets
INDEX_FILE = "index.json"
"""The challenge folder's list of its cases, in order, with each one's note."""


def challenge_dir() -> Path:
    """The shipped challenge scenes' folder."""
    return Path(str(resources.files("mpg_envs").joinpath("challenge")))


def challenge_set() -> CaseSet:
    """The project's hand-designed challenge cases (shipped)."""
    return dataclasses.replace(folder_set(challenge_dir()), name="challenge")


def folder_set(folder: Path) -> CaseSet:
    """Every scene file of ``folder`` (``.json``, ``.txt``) as a case: in the order of its
    ``index.json`` with each one's note where it has one (``[{"name": ..., "note": ...}]``),
    else sorted by name."""
    index = folder / INDEX_FILE
    if index.is_file():
        entries = _index_entries(index)
        return CaseSet(
            folder.name, tuple(Case(e["name"], _scene_path(folder, e["name"]), note=e.get("note", "")) for e in entries)
        )
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".json", ".txt"))
    if not files:
        raise ValueError(f"case folder {str(folder)!r} holds no .json or .txt scene files")
    return CaseSet(folder.name, tuple(Case(p.stem, p) for p in files))


def _index_entries(index: Path) -> list[dict[str, Any]]:
    """The entries of a case folder's ``index.json``; a ``ValueError`` naming the file and what
    is valid when it is not a JSON list of ``{"name": ..., "note": ...}`` objects."""
    valid = 'valid: a JSON list of {"name": <a scene file\'s name>, "note": <text, optional>} objects'
    try:
        entries = json.loads(index.read_text())
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError is a ValueError
        raise ValueError(f"{index}: not valid JSON ({exc}); {valid}") from None
    if not isinstance(entries, list):
        raise ValueError(
            f"{index} holds a JSON {type(entries).__name__ if not isinstance(entries, dict) else 'object'}; {valid}"
        )
    for k, entry in enumerate(entries):
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) or not isinstance(entry.get("note", ""), str):
            raise ValueError(f"{index}: entry {k} is {entry!r}; {valid}")
    return entries


def _scene_path(folder: Path, name: str) -> Path:
    for suffix in (".json", ".txt"):
        if (folder / f"{name}{suffix}").is_file():
            return folder / f"{name}{suffix}"
    raise ValueError(f"case folder {str(folder)!r}: {INDEX_FILE} lists {name!r}, but there is no {name}.json or {name}.txt")


def epg_set(peers_dir: Path) -> CaseSet:
    """Efficient Push-Grasping's ten cases from VPG's files in ``peers_dir`` (see the module docstring)."""
    folder = _find(peers_dir, ("vpg/test-cases", "test-cases", "."), "test-10-obj-00.txt", "epg", "VPG's test-10-obj-*.txt")
    cases = []
    for k, (stem, goal) in enumerate(EPG_CASES):
        scene = read_scene(folder / f"{stem}.txt")
        moves = {i: np.array([0.0, -EPG_SHIFT, 0.0]) for i in range(len(scene.objects))}  # VPG's +y is our -y
        if k == 0:
            moves[EPG_CASE0_MOVE[0]] = moves[EPG_CASE0_MOVE[0]] - np.array([0.0, EPG_CASE0_MOVE[1], 0.0])
        objects = tuple(dataclasses.replace(obj, position=obj.position + moves[i]) for i, obj in enumerate(scene.objects))
        scene = dataclasses.replace(scene, objects=objects, source=f"{scene.source} (Efficient Push-Grasping's case {k})")
        cases.append(Case(f"epg-{k:02d}", scene, target=goal, note=f"VPG's {stem}, goal object {goal}"))
    return CaseSet("epg", tuple(cases))


def gti_set(peers_dir: Path) -> CaseSet:
    """Grasping the Invisible's twelve presets in ``peers_dir``."""
    folder = _find(peers_dir, ("gti", "."), "exploration-00.txt", "gti", "Grasping the Invisible's presets")
    notes = {"exploration": "the target starts hidden", "coordination": "the target is packed in among blocks"}
    return CaseSet("gti", tuple(Case(name, folder / f"{name}.txt", note=notes[name.split("-")[0]]) for name in GTI_PRESETS))


def _find(root: Path, subfolders: tuple[str, ...], marker: str, set_name: str, what: str) -> Path:
    for sub in subfolders:
        if (root / sub / marker).is_file():
            return root / sub
    tried = ", ".join(str(root / sub) for sub in subfolders)
    raise ValueError(f"case set {set_name!r}: {what} not found (looked for {marker} in {tried})")


# ------------------------------------------------------------------------------ jitter
def jitter_scene(scene: SceneFile, run: int, key: str = "", workspace: Workspace = Workspace()) -> SceneFile:
    """``scene`` moved rigidly for run ``run``: turned by up to :data:`JITTER_DEG` about the
    vertical through the centre of its objects and moved by up to :data:`JITTER_M` along x
    and y, drawn from a generator seeded by ``run`` and ``key`` (a case's name). Run 0 is
    ``scene`` itself. Every object's centre stays inside ``workspace``: the turn is dropped
    when it alone would take one out, and the move is drawn within what keeps them in.
    Objects left out of the scene (inactive) stay where they are.
    """
    if isinstance(run, bool) or not isinstance(run, (int, np.integer)) or run < 0:
        raise ValueError(f"run must be a non-negative integer, got {run!r}")
    active = [i for i, obj in enumerate(scene.objects) if obj.active]
    if run == 0 or not active:
        return scene
    rng = np.random.default_rng([int(run), zlib.crc32(key.encode())])
    angle = math.radians(rng.uniform(-JITTER_DEG, JITTER_DEG))
    u, v = rng.uniform(0.0, 1.0, size=2)
    xy = np.array([np.asarray(scene.objects[i].position, float)[:2] for i in active])
    centre = (xy.min(axis=0) + xy.max(axis=0)) / 2
    turned = _turn(xy, centre, angle)
    lo, hi = np.array([workspace.x_min, workspace.y_min]), np.array([workspace.x_max, workspace.y_max])
    if np.any(turned < lo) or np.any(turned > hi):
        angle, turned = 0.0, xy
    low = np.maximum(-JITTER_M, lo - turned.min(axis=0))
    high = np.minimum(JITTER_M, hi - turned.max(axis=0))
    shift = low + np.array([u, v]) * np.maximum(high - low, 0.0)
    spin = np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])
    objects = list(scene.objects)
    for k, i in enumerate(active):
        obj = objects[i]
        position = np.asarray(obj.position, float).copy()
        position[:2] = turned[k] + shift
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, spin, np.asarray(obj.quat, float) / np.linalg.norm(obj.quat))
        objects[i] = dataclasses.replace(obj, position=position, quat=quat)
    return dataclasses.replace(scene, objects=tuple(objects))


def _turn(xy: np.ndarray, centre: np.ndarray, angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return centre + (xy - centre) @ np.array([[c, s], [-s, c]])
