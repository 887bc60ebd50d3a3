"""pybullet's ``random_urdfs``: 1,000 procedurally made objects, read where they are installed.

The Bullet Physics SDK ships ``pybullet_data/random_urdfs/NNN/NNN.urdf`` (``NNN`` = 000-999),
each a link whose collision and visual geometry is the mesh ``NNN.obj`` (a few convex bodies)
at a uniform scale, under the zlib licence. By pybullet's own convention the folders whose
number ends in 0 are the test objects (100), the others the training objects (900). The meshes
are read from the installed ``pybullet`` package (the ``novel`` extra: ``pip install
"mpg-grasp[novel]"``) or from a folder the user names; they are never copied into this
repository. Loading goes through :func:`~mpg_envs.simulation.meshes.load_mesh_file`, so each
object records its mesh path, its scale and the licence.
"""

from __future__ import annotations

import importlib.util
import os
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

from mpg_envs.simulation.assets import DEFAULT_FRICTION, TABLEAU_10, WOOD_DENSITY, ObjectAsset
from mpg_envs.simulation.meshes import DEFAULT_TIME_LIMIT_S, Fit, load_mesh_file

RANDOM_URDFS_LICENCE = "zlib"
"""The licence of the ``random_urdfs`` meshes (the Bullet Physics SDK's)."""

RANDOM_URDFS_SOURCE = "pybullet_data/random_urdfs (Bullet Physics SDK, https://github.com/bulletphysics/bullet3)"
"""Where the objects come from."""

RANDOM_URDFS_COUNT = 1000
"""Objects in the full set."""

TEST_SET_NAME = "random_urdfs_test"
"""The ``object_set`` name of the test split as shipped (fitted, packed convex parts beside the
test scenes: :func:`test_pack_path`); held out from training."""

PACKED_SOURCE_PREFIX = "pybullet_data/random_urdfs/"
"""The ``source`` of every packed object starts so (``pybullet_data/random_urdfs/NNN/NNN.obj``):
the set's path, not a machine's, so a scene file of the track names the pack's objects."""

TEST_PACK_FILE = "random_urdfs_test_objects.npz"
"""File name of the shipped test split's object pack in ``mpg_envs/test_scenes``."""

_NAME = re.compile(r"random_urdf_(\d{3})")
_SOURCE = re.compile(r"random_urdfs[/\\](\d{3})[/\\]\1\.obj")

Split = Literal["test", "train", "all"]
SPLITS = ("test", "train", "all")


@dataclass(frozen=True)
class RandomUrdf:
    """One object of the set: its number, URDF, collision mesh and the URDF's mesh scale."""

    number: int
    urdf: Path
    mesh: Path
    scale: float

    @property
    def name(self) -> str:
        """``"random_urdf_NNN"``."""
        return f"random_urdf_{self.number:03d}"

    @property
    def is_test(self) -> bool:
        """pybullet's convention: numbers ending in 0 are test objects."""
        return self.number % 10 == 0


def test_pack_path() -> Path:
    """Where the shipped test split's object pack lives (:mod:`~mpg_envs.simulation.object_packs`)."""
    return Path(__file__).resolve().parent.parent / "test_scenes" / TEST_PACK_FILE


def is_test_object(name: str, source: str = "") -> bool:
    """Whether an object named ``name`` (made from ``source``) is one of the set's test objects:
    named ``random_urdf_NNN`` or made from ``random_urdfs/NNN/NNN.obj`` with ``NNN`` ending in 0."""
    for match in (_NAME.fullmatch(name), _SOURCE.search(source)):
        if match is not None and int(match.group(1)) % 10 == 0:
            return True
    return False


def random_urdfs_folder() -> Path:
    """The installed ``pybullet_data/random_urdfs`` folder.

    Raises:
        ModuleNotFoundError: pybullet is not installed (says how to get it, or to pass a folder).
    """
    spec = importlib.util.find_spec("pybullet_data")  # data only: pybullet itself is not imported
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(
            "the random_urdfs objects come with pybullet, which is not installed: "
            "pip install 'mpg-grasp[novel]' (or pip install pybullet), or pass folder= a copy of "
            "pybullet_data/random_urdfs"
        )
    return Path(next(iter(spec.submodule_search_locations))) / "random_urdfs"


def random_urdf_entries(folder: str | os.PathLike[str] | None = None, split: Split = "test") -> list[RandomUrdf]:
    """The set's objects in ``split`` (``"test"``, ``"train"`` or ``"all"``), by number.

    Args:
        folder: a ``random_urdfs`` folder (``NNN/NNN.urdf``); ``None`` uses the installed one.
        split: which objects (test: numbers ending in 0).

    Raises:
        ValueError: unknown split, a folder without ``NNN/NNN.urdf`` entries, or a URDF this
            reader cannot use (names the file and why).
        FileNotFoundError: ``folder`` does not exist.
        ModuleNotFoundError: ``folder`` is ``None`` and pybullet is not installed.
    """
    if split not in SPLITS:
        raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
    root = random_urdfs_folder() if folder is None else Path(folder).expanduser()
    if not root.is_dir():
        raise FileNotFoundError(f"random_urdfs folder {str(root)!r} does not exist")
    entries = []
    for sub in sorted(root.iterdir()):
        if not (re.fullmatch(r"\d{3}", sub.name) and (sub / f"{sub.name}.urdf").is_file()):
            continue
        number = int(sub.name)
        if split == "all" or (split == "test") == (number % 10 == 0):
            entries.append(_read_urdf(number, sub / f"{sub.name}.urdf"))
    if not entries:
        raise ValueError(f"random_urdfs folder {str(root)!r} holds no NNN/NNN.urdf objects for split {split!r}")
    return entries


def _read_urdf(number: int, urdf: Path) -> RandomUrdf:
    """The collision mesh and its scale; ValueError for anything this reader does not apply."""
    try:
        root = ET.parse(urdf).getroot()
    except (ET.ParseError, OSError) as exc:
        raise ValueError(f"URDF {str(urdf)!r}: not readable XML ({exc})") from exc
    meshes = root.findall("./link/collision/geometry/mesh")
    if len(meshes) != 1:
        raise ValueError(f"URDF {str(urdf)!r}: expected one link with one collision mesh, found {len(meshes)}")
    for origin in root.findall("./link/collision/origin"):
        values = (origin.get("xyz", "0 0 0") + " " + origin.get("rpy", "0 0 0")).split()
        if any(float(v) != 0.0 for v in values):
            raise ValueError(f"URDF {str(urdf)!r}: a collision origin other than zero is not supported")
    scales = [float(s) for s in meshes[0].get("scale", "1 1 1").split()]
    if len(scales) != 3 or len(set(scales)) != 1 or not scales[0] > 0:
        raise ValueError(f"URDF {str(urdf)!r}: the mesh scale must be uniform and positive, got {scales}")
    filename = meshes[0].get("filename", "")
    return RandomUrdf(number, urdf, urdf.parent / filename, scales[0])


def load_random_urdfs(
    folder: str | os.PathLike[str] | None = None,
    split: Split = "test",
    seed: int = 0,
    cache_dir: str | os.PathLike[str] | None = None,
    scale: float = 1.0,
    *,
    fit: Fit = "gripper",
    mass: float | None = None,
    density: float = WOOD_DENSITY,
    friction: float = DEFAULT_FRICTION,
    time_limit_s: float = DEFAULT_TIME_LIMIT_S,
) -> list[ObjectAsset]:
    """The ``random_urdfs`` objects of ``split`` (see :func:`random_urdf_entries`), fitted to the gripper.

    Each mesh is loaded at its URDF scale times ``scale``, then (``fit="gripper"``, the
    default) scaled to the blocks' extent range; colours cycle through Tableau-10 in order.
    Names are ``random_urdf_NNN``; ``source`` is the mesh path and ``licence`` ``"zlib"``.

    Raises:
        MeshLoadError: a mesh that cannot be used (names the file); to skip such meshes, load
            :func:`random_urdf_entries` one by one with :func:`load_mesh_file`.
        ModuleNotFoundError: ``folder`` is ``None`` and pybullet is not installed.
    """
    return [
        load_mesh_file(
            entry.mesh,
            seed,
            cache_dir,
            entry.scale * scale,
            mass,
            fit=fit,
            name=entry.name,
            rgba=TABLEAU_10[i % len(TABLEAU_10)],
            density=density,
            friction=friction,
            time_limit_s=time_limit_s,
            licence=RANDOM_URDFS_LICENCE,
        )  # fmt: skip
        for i, entry in enumerate(random_urdf_entries(folder, split))
    ]
