"""The motion of each primitive, by name: what :meth:`PrimitiveExecutor.execute
<mpg_envs.simulation.primitives.PrimitiveExecutor.execute>` runs for a primitive of
:mod:`mpg_envs.grid.primitive_specs`.

A motion is a function ``(executor, rotation, row, col, depth, target) -> PrimitiveResult``;
it may use the executor's motion pieces (``teleport``, ``linear``, ``pick``, ``finish``,
``pre_height``). The paper's three are the executor's own and are registered when
:mod:`mpg_envs.simulation.primitives` is imported.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mpg_envs.grid.primitive_specs import PAPER_PRIMITIVES, primitive_spec


@dataclass
class PrimitiveResult:
    """What a primitive did."""

    primitive: str
    rotation: int
    pixel: tuple[int, int]
    position: tuple[float, float, float]  # world (x, y, z) the TCP was sent to
    lifted: bool = False  # an object came up in the fingers (a grasp or a move lifted it)
    grasped_object: int | None = None  # index of that object
    grasp_failure: str | None = None  # grasp/move that held nothing: one of primitives.GRASP_FAILURES
    placed_object: int | None = None  # move: the object put down elsewhere
    removed_objects: tuple[int, ...] = ()  # objects taken out of the scene by this primitive
    target_moved: bool = False
    physics_steps: int = 0
    physics_seconds: float = 0.0
    seconds: float = 0.0
    ik_solves: int = 0
    unreachable: bool = False  # the arm could not reach a pose of this motion: nothing moved


# The executor's type stays unnamed here: the executor imports this module for its motions.
Motion = Callable[..., PrimitiveResult]
"""``(executor, rotation, row, col, depth, target) -> PrimitiveResult``: the executor
(:class:`~mpg_envs.simulation.primitives.PrimitiveExecutor`), the action's rotation and pixel,
the depth heightmap and the target's index (or ``None``)."""

_MOTIONS: dict[str, Motion] = {}


def register_motion(name: str, motion: Motion) -> None:
    """Run ``motion`` for primitive ``name`` (registered first with
    :func:`~mpg_envs.grid.primitive_specs.register_primitive`); a name that has a motion
    already is refused."""
    primitive_spec(name)  # a one-line error for a name not registered
    if not callable(motion):
        raise TypeError(f"the motion of {name!r} must be callable, got {type(motion).__name__}")
    if name in _MOTIONS:
        raise ValueError(f"primitive {name!r} has a motion already")
    _MOTIONS[name] = motion


def unregister_motion(name: str) -> None:
    """Remove the motion :func:`register_motion` gave ``name`` (the paper's three stay)."""
    if name in PAPER_PRIMITIVES:
        raise ValueError(f"the motions of the paper's primitives {PAPER_PRIMITIVES} cannot be unregistered, got {name!r}")
    if _MOTIONS.pop(name, None) is None:
        raise ValueError(f"primitive {name!r} has no registered motion")


def motion_of(name: str) -> Motion:
    """The motion of primitive ``name``; a one-line ``ValueError`` for a primitive without one."""
    motion = _MOTIONS.get(name) if isinstance(name, str) else None
    if motion is None:
        raise ValueError(f"unknown primitive {name!r}; primitives with a motion: {tuple(_MOTIONS)}")
    return motion
