"""Which MuJoCo a result was measured with, and which results may be compared.

MuJoCo 4.0 settles a seed's cluttered drop into other poses than MuJoCo 3.x does (a single box
on a plane agrees to 1e-15; fifteen blocks dropped together come to rest elsewhere), and each
contact-rich motion can end differently too: an episode, and so a result, depends on MuJoCo's
major version. Every evaluation, test set and checkpoint records the MuJoCo version beside the
package version, and results are compared (paired, or side by side in one table) only within
one major version.

MuJoCo 4.0.0's sparse Cholesky factorization gives the Newton solver a wrong Hessian factor
when the constraint Jacobian is sparse (fixed in 4.0.1: MuJoCo issue 3767), and MuJoCo picks
the sparse Jacobian from 60 degrees of freedom, which every scene of 15 objects has: the arm or
the fingers diverge in some motions (``mjWARN_BADQACC``, 3 of 100 held-out blocks episodes).
:func:`constraint_jacobian` gives the dense Jacobian on that release and MuJoCo's own choice on
every other.

A record written before the field existed says nothing: every such file was measured on
MuJoCo 3.x (the package required ``mujoco<4`` until then), and reads as
:data:`UNRECORDED_MUJOCO`, ``"3.x"``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import mujoco

UNRECORDED_MUJOCO = "3.x"
"""The MuJoCo version of a record that does not name one (written when only 3.x ran)."""

MUJOCO_KEY = "mujoco"
"""The key of the MuJoCo version in an evaluation's ``versions`` entry."""


SPARSE_CHOLESKY_BROKEN = frozenset({"4.0.0"})
"""MuJoCo releases whose Newton solver diverges with a sparse constraint Jacobian."""


class MuJoCoVersionError(ValueError):
    """Results of different MuJoCo major versions were to be compared or pooled."""


def running_mujoco() -> str:
    """The version of the MuJoCo this process runs, e.g. ``"3.17.0"``."""
    return str(mujoco.__version__)


def mujoco_major(version: str) -> int:
    """The major version of ``"3.17.0"``, ``"4.0.0"`` or ``"3.x"``; ``ValueError`` otherwise."""
    head = str(version).split(".", 1)[0]
    if not head.isdigit():
        raise ValueError(f"a MuJoCo version starts with its major number (3.17.0, 4.0.0, 3.x), got {version!r}")
    return int(head)


def constraint_jacobian(version: str | None = None) -> mujoco.mjtJacobian:
    """The constraint Jacobian a world compiles with on MuJoCo ``version`` (default: the running
    one): dense on :data:`SPARSE_CHOLESKY_BROKEN`, else ``mjJAC_AUTO`` (MuJoCo's default: dense
    below 60 degrees of freedom, sparse above), so 3.x runs as it always did."""
    broken = (running_mujoco() if version is None else version) in SPARSE_CHOLESKY_BROKEN
    return mujoco.mjtJacobian.mjJAC_DENSE if broken else mujoco.mjtJacobian.mjJAC_AUTO


def recorded_mujoco(versions: Mapping[str, Any] | None) -> str:
    """The MuJoCo version a record's ``versions`` entry names; :data:`UNRECORDED_MUJOCO`
    (``"3.x"``) for a record written before it was recorded, or with no ``versions`` at all."""
    value = (versions or {}).get(MUJOCO_KEY)
    return UNRECORDED_MUJOCO if value in (None, "") else str(value)


def check_one_mujoco(versions: Mapping[str, str], what: str) -> int:
    """The one MuJoCo major version of ``versions`` (source -> MuJoCo version).

    Raises :class:`MuJoCoVersionError` naming each source's version when they span major
    versions: ``what`` says what was to be made of them (``"a paired comparison"``).
    """
    majors = {source: mujoco_major(version) for source, version in versions.items()}
    if len(set(majors.values())) > 1:
        named = ", ".join(f"{source} on MuJoCo {versions[source]}" for source in versions)
        raise MuJoCoVersionError(
            f"{what} mixes MuJoCo major versions ({named}): a seed's scene and its motions differ "
            "between MuJoCo major versions, so results compare only within one"
        )
    return next(iter(majors.values())) if majors else mujoco_major(running_mujoco())
