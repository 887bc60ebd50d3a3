"""What a scene file holds, apart from any file format: :class:`SceneFile` (the objects, their
poses and the target), :class:`SceneObject`, the checks every scene passes (:func:`check_scene`),
and :class:`SceneFileError`, the one error of a scene file that cannot be loaded.

The formats build on it: ours (JSON, :mod:`mpg_envs.scenes.scene_io`) and the peers' text files
(:mod:`mpg_envs.scenes.vpg_scenes`), whose text :func:`scene_text` reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mpg_envs.simulation.assets import ObjectAsset

BELOW_TABLE = -0.02
"""An object whose centre is this far below the table top (m) has fallen off it."""
MAX_OBJECTS = 60
"""The most objects a scene may hold: the envs' largest ``num_objects`` (far more overflow the
simulator's constraint buffer, and the objects vanish)."""
QUAT_TOLERANCE = 1e-3
"""How far from 1 the norm of an orientation quaternion in a scene may be."""
PENETRATION_TOLERANCE_M = 0.005
"""How deep (m) two objects of a scene may interpenetrate: the shipped test sets' and
challenge scenes' resting contacts reach 1.2 mm, the peers' files none."""


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
        simulated: the poses are a state this package's physics reached and left at rest (an
            env's ``current_scene()``, a shipped test scene), placed as they are without the
            interpenetration check meant for poses made elsewhere (objects of many convex
            parts can rest a few millimetres into each other). Files read from disk are not.
    """

    objects: tuple[SceneObject, ...]
    target: int | None
    source: str = ""
    stage: str | None = None
    object_set_seed: int = 0
    settle: bool = False
    target_is_first_kept: bool = False
    simulated: bool = False


# ------------------------------------------------------------------------------ checks
def check_scene(scene: SceneFile) -> None:
    """Raise a :class:`SceneFileError` naming the first object whose position is not three
    finite numbers or whose orientation is not a unit quaternion (w first, norm within
    :data:`QUAT_TOLERANCE` of 1), or a scene of more than :data:`MAX_OBJECTS` objects."""
    if len(scene.objects) > MAX_OBJECTS:
        raise SceneFileError(f"scene {scene.source!r} has {len(scene.objects)} objects; a scene holds at most {MAX_OBJECTS}")
    for i, obj in enumerate(scene.objects):
        name = obj.label or f"object {i}"
        pos, quat = np.asarray(obj.position, float), np.asarray(obj.quat, float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise SceneFileError(
                f"scene {scene.source!r}: {name} has position {pos.tolist()}; valid: three finite numbers [x, y, z] (m)"
            )
        norm = float(np.linalg.norm(quat)) if quat.shape == (4,) else math.nan
        if not abs(norm - 1.0) <= QUAT_TOLERANCE:
            raise SceneFileError(
                f"scene {scene.source!r}: {name} has orientation {quat.tolist()} (norm {norm:.6g}); valid: "
                f"a unit quaternion [w, x, y, z], norm within {QUAT_TOLERANCE:g} of 1"
            )


def scene_text(path: Path, valid: str = "a VPG test case or Grasping the Invisible preset, one object per line") -> str:
    """The text of a scene file, else a :class:`SceneFileError` naming the file: not readable,
    or not UTF-8 text (a binary file; ``valid`` says what the file should be)."""
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise SceneFileError(f"scene file {str(path)!r} cannot be read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise SceneFileError(f"scene file {str(path)!r} is not text (byte {exc.start} is not UTF-8); valid: {valid}") from exc
