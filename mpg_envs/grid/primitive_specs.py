"""The primitives as records: one :class:`PrimitiveSpec` per primitive, registered in one place.

A primitive's name, its place in the action codec, its symmetry under the wrappers' rotation
grids, the key of its reward rule and how MPGNet treats it are data here; the motion that
runs it is looked up by name in :mod:`mpg_envs.simulation.motions`, its reward rule by key in
:mod:`mpg_envs.tasks.rewards`. The paper's three (``move``, ``push``, ``grasp``) are
registered at import, in the action codec's order; a primitive registered later
(:func:`register_primitive`) comes after them, so every existing action space keeps its
integer layout.

Code names a primitive by the constants :data:`MOVE`, :data:`PUSH` and :data:`GRASP` (or a
record's ``name``), never by a string of its own.
"""

from __future__ import annotations

from dataclasses import dataclass

MOVE = "move"
"""Grasp an occluder and put it down elsewhere (the paper's move)."""
PUSH = "push"
"""Slide the closed fingers along the table (the paper's push)."""
GRASP = "grasp"
"""Grasp an object and take it out of the scene (the paper's grasp)."""


@dataclass(frozen=True)
class PrimitiveSpec:
    """What a primitive is, as data.

    Attributes:
        name: the primitive's name (an env's ``primitives``, ``info["primitive"]``).
        half_turn_symmetric: rotation ``k`` and ``k + 8`` are the same motion (a parallel-jaw
            grasp closes along a line); the wrappers then spread a coarse rotation grid over
            180 degrees, and a repeated action is recognised modulo a half turn.
        lifts: the fingers close to lift an object (grasp and move): the step reports what
            it lifted, and why it held nothing (``grasp_failure``).
        retrieves: an object it lifts leaves the scene (grasp): lifting the target is the
            task's success, lifting another object a mis-pick.
        reward_rule: key of the rule that rewards it in a stage with a reward per primitive
            (:data:`mpg_envs.tasks.rewards.REWARD_RULES`).
        rough_masked: MPGNet restricts its Q map to the rough target region (the paper's
            Training Details: move and grasp).
    """

    name: str
    half_turn_symmetric: bool = False
    lifts: bool = False
    retrieves: bool = False
    reward_rule: str = ""
    rough_masked: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ValueError(f"a primitive's name must be a Python identifier (it names its motion), got {self.name!r}")
        if not isinstance(self.reward_rule, str) or not self.reward_rule:
            raise ValueError(f"primitive {self.name!r} needs a reward_rule key (a non-empty string), got {self.reward_rule!r}")
        if self.retrieves and not self.lifts:
            raise ValueError(f"primitive {self.name!r}: retrieves=True needs lifts=True (only a lifted object can leave)")


MOVE_SPEC = PrimitiveSpec(MOVE, half_turn_symmetric=True, lifts=True, reward_rule="uncover", rough_masked=True)
PUSH_SPEC = PrimitiveSpec(PUSH, reward_rule="push_gain")
GRASP_SPEC = PrimitiveSpec(
    GRASP, half_turn_symmetric=True, lifts=True, retrieves=True, reward_rule="grasp_target", rough_masked=True
)

PAPER_PRIMITIVES: tuple[str, ...] = (MOVE, PUSH, GRASP)
"""The paper's three, in the fixed order of the action codec."""

_REGISTRY: dict[str, PrimitiveSpec] = {s.name: s for s in (MOVE_SPEC, PUSH_SPEC, GRASP_SPEC)}


def register_primitive(spec: PrimitiveSpec) -> PrimitiveSpec:
    """Add ``spec`` after the primitives already registered (its place in the action codec);
    returns it. Its motion (:func:`mpg_envs.simulation.motions.register_motion`) and reward
    rule (:func:`mpg_envs.tasks.rewards.register_reward_rule`) are registered under its name
    and rule key. A name already taken is refused."""
    if not isinstance(spec, PrimitiveSpec):
        raise TypeError(f"register_primitive takes a PrimitiveSpec, got {type(spec).__name__}")
    if spec.name in _REGISTRY:
        raise ValueError(f"primitive {spec.name!r} is already registered; registered: {registered_primitives()}")
    _REGISTRY[spec.name] = spec
    return spec


def unregister_primitive(name: str) -> None:
    """Remove a primitive :func:`register_primitive` added (the paper's three stay)."""
    if name in PAPER_PRIMITIVES:
        raise ValueError(f"the paper's primitives {PAPER_PRIMITIVES} cannot be unregistered, got {name!r}")
    if name not in _REGISTRY:
        raise ValueError(f"primitive {name!r} is not registered; registered: {registered_primitives()}")
    del _REGISTRY[name]


def registered_primitives() -> tuple[str, ...]:
    """Every registered primitive's name, in action-codec order (the paper's three first)."""
    return tuple(_REGISTRY)


def primitive_spec(name: str) -> PrimitiveSpec:
    """The record of primitive ``name``; a one-line ``ValueError`` for a name not registered."""
    spec = _REGISTRY.get(name) if isinstance(name, str) else None
    if spec is None:
        raise ValueError(f"unknown primitive {name!r}; registered: {registered_primitives()}")
    return spec


def half_turn_symmetric(name: str) -> bool:
    """Whether primitive ``name``'s rotations ``k`` and ``k + 8`` are one motion."""
    return primitive_spec(name).half_turn_symmetric
