"""The paper's reward functions (Section III-C), as pure functions of what a step did, and the
per-primitive rules by key (a primitive's record names its rule)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from mpg_envs.grid.primitive_specs import primitive_spec


@dataclass(frozen=True)
class StepOutcome:
    """The facts a reward needs about one step."""

    primitive: str
    lifted: bool = False  # any object came up in the fingers (grasp or move)
    target_grasped: bool = False  # ... and it was the target
    move_success: bool = False  # occlusion removed, target not picked up by the move
    change_detected: bool = False
    grasp_q_gain: float = 0.0  # grasp-net score after minus before (0 without a scorer)
    visible_gain: float = 0.0  # the target's visible fraction after minus before (0 without a target in view)
    covered_before: bool = False  # the target was occluded before the step
    cleared: bool = False  # ... and not after it, neither picked up nor out (any primitive)


@dataclass(frozen=True)
class RewardConfig:
    """Reward values and thresholds of the paper's equations."""

    success: float = 1.0
    improved: float = 0.5
    penalty: float = -0.5
    move_q_gain: float = 0.5  # Q_g^im threshold of R_m
    push_q_gain: float = 0.1  # Q_g^ip threshold of R_p
    # Not the paper's (default off): a move whose fingers lifted nothing earns R_m's penalty,
    # as "no change". Without it, fingers that close beside the occluder and nudge it off the
    # target earn the full move reward, and the move net learns to nudge rather than to carry.
    move_needs_lift: bool = False
    # Not the paper's (default off): a move that raises the target's visible fraction by at
    # least this much earns ``improved``, as a grasp-Q gain does. R_m pays its success only
    # when the last occluder leaves; a target under several earns nothing for the moves that
    # uncover it one by one.
    move_visible_gain: float | None = None
    # Not the paper's (default off): a push while the target is covered earns R_m, the move's
    # reward, instead of R_p, so that the push and move nets value uncovering on one scale and
    # a rule comparing their Q (coordination "uncover_max_q") weighs the move against the push
    # it would replace.
    push_uncovers: bool = False
    # Strict retrieval (the env's wrong_grasp="fail"): a grasp that lifts a non-target object
    # ends the episode with this reward instead of its primitive's.
    wrong_object: float = -1.0

    def __post_init__(self) -> None:
        gain = self.move_visible_gain
        if gain is not None and (isinstance(gain, bool) or not isinstance(gain, (int, float)) or not 0.0 < gain <= 1.0):
            raise ValueError(f"move_visible_gain must be None (off) or a visible-fraction gain in (0, 1], got {gain!r}")


def reward_grasp_any(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """R_g1 (Stage I): 1 for grasping any object."""
    return c.success if o.lifted else 0.0


def reward_grasp_target(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """R_g2 (Stage II): 1 for grasping the target; failed and wrong grasps earn 0."""
    return c.success if o.target_grasped else 0.0


def reward_move(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """R_m (Stage III): 1 move success; 0.5 grasp-Q gain > 0.5 with change (with
    ``c.move_visible_gain``, also a visible-fraction gain of at least that); -0.5 target
    picked up by the move or no change (with ``c.move_needs_lift``, also a move that lifted
    nothing); 0 otherwise."""
    if o.target_grasped or not o.change_detected or (c.move_needs_lift and not o.lifted):
        return c.penalty
    return _uncovering(o, o.move_success, c)


def _uncovering(o: StepOutcome, uncovered: bool, c: RewardConfig) -> float:
    """R_m's payment for a step that changed the scene: success when it ``uncovered`` the
    target, ``improved`` for a grasp-Q gain above ``c.move_q_gain`` (or a visible gain of at
    least ``c.move_visible_gain``), else 0."""
    if uncovered:
        return c.success
    if o.grasp_q_gain > c.move_q_gain:
        return c.improved
    if c.move_visible_gain is not None and o.visible_gain >= c.move_visible_gain:
        return c.improved
    return 0.0


def reward_push(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """R_p (Stage IV): 0.5 grasp-Q gain > 0.1 with change; -0.5 no change; 0 otherwise. With
    ``c.push_uncovers``, a push while the target is covered earns R_m instead (1 when it
    uncovered the target)."""
    if not o.change_detected:
        return c.penalty
    if c.push_uncovers and o.covered_before:
        return _uncovering(o, o.cleared, c)
    if o.grasp_q_gain > c.push_q_gain:
        return c.improved
    return 0.0


RewardRule = Callable[[StepOutcome, RewardConfig], float]
"""A reward as a pure function of a step's outcome and the reward settings."""

_REWARD_RULES: dict[str, RewardRule] = {"uncover": reward_move, "push_gain": reward_push, "grasp_target": reward_grasp_target}
PAPER_RULES: tuple[str, ...] = tuple(_REWARD_RULES)
"""The keys of the paper's per-primitive rules: R_m (``uncover``), R_p (``push_gain``) and R_g2
(``grasp_target``), a primitive record's ``reward_rule``."""


def register_reward_rule(key: str, rule: RewardRule) -> None:
    """Reward a primitive whose record's ``reward_rule`` is ``key`` with ``rule`` (in a stage
    with a reward per primitive, :func:`reward_per_primitive`); a key taken is refused."""
    if not isinstance(key, str) or not key:
        raise ValueError(f"a reward rule's key must be a non-empty string, got {key!r}")
    if not callable(rule):
        raise TypeError(f"reward rule {key!r} must be callable, got {type(rule).__name__}")
    if key in _REWARD_RULES:
        raise ValueError(f"reward rule {key!r} is already registered; registered: {tuple(_REWARD_RULES)}")
    _REWARD_RULES[key] = rule


def unregister_reward_rule(key: str) -> None:
    """Remove a rule :func:`register_reward_rule` added (the paper's stay)."""
    if key in PAPER_RULES:
        raise ValueError(f"the paper's reward rules {PAPER_RULES} cannot be unregistered, got {key!r}")
    if _REWARD_RULES.pop(key, None) is None:
        raise ValueError(f"reward rule {key!r} is not registered; registered: {tuple(_REWARD_RULES)}")


def reward_rule(key: str) -> RewardRule:
    """The reward rule registered under ``key``; a one-line ``ValueError`` for an unknown key."""
    rule = _REWARD_RULES.get(key) if isinstance(key, str) else None
    if rule is None:
        raise ValueError(f"unknown reward rule {key!r}; registered: {tuple(_REWARD_RULES)}")
    return rule


def reward_per_primitive(o: StepOutcome, c: RewardConfig = RewardConfig()) -> float:
    """Stage V and the test scenes: each primitive keeps its stage's reward, the rule its
    record names (:class:`~mpg_envs.grid.primitive_specs.PrimitiveSpec`'s ``reward_rule``)."""
    return reward_rule(primitive_spec(o.primitive).reward_rule)(o, c)
