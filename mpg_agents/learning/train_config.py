"""The algorithm's settings of a training run (``mpg-train``'s ``--config`` top level).

One :class:`TrainConfig` drives the learner (:mod:`mpg_agents.learning.learner`), and the SB3 adapter
(:mod:`mpg_agents.sb3`) takes its defaults from it, so both train with the same settings.
What a stage trains (env, branches, curriculum, alternation, ...) is its
:class:`~mpg_agents.learning.training_stages.TrainingStage`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from numbers import Integral, Real
from typing import Any

from mpg_agents.acting.grasp_threshold import UNCALIBRATED, check_in_range
from mpg_agents.acting.seeds import check_seed
from mpg_agents.learning.td_step import TDStepConfig
from mpg_envs.settings_fields import check_known_fields

ACTOR_BACKENDS = ("auto", "ray", "processes")
"""Where parallel actors run: Ray when it is installed (``auto``), Ray, or local processes (stdlib)."""


@dataclass
class TrainConfig:
    """The algorithm's settings for a stage; defaults are the paper's where it gives them."""

    steps: int | None = None  # training iterations (env steps taken, each learnt from per replay_ratio); None: the stage's
    seed: int = 0
    variant: str = "small"
    num_objects: int | None = None  # a fixed object count; None: the stage's curriculum or the env's count
    # Paper, Training Details.
    gamma: float = 0.5
    learning_rate: float = 1e-4
    weight_decay: float = 2**-5
    betas: tuple[float, float] = (0.9, 0.99)
    epsilon_start: float = 0.5
    epsilon_end: float = 0.1
    epsilon_decay_steps: int | None = None  # None: over the whole run
    # Replay and updates.
    batch_size: int = 2
    replay_capacity: int = 5000
    priority_alpha: float = 1.0
    target_update_every: int = 100
    # Gradient steps per env step (an iteration's stored trials count as one more step): 1.0 is
    # the paper's one gradient step per iteration; below 1 the learner keeps up with more actors.
    replay_ratio: float = 1.0
    grasp_symmetry: bool = True
    max_grad_norm: float | None = None  # the paper clips nothing (see td_step.TDStepConfig)
    q_bounds: tuple[float, float] | None = None  # clamp TD targets to the feasible returns (see td_step.TDStepConfig)
    # Training aids (paper, Simulation Experiments).
    heuristic_after_failed_grasps: int = 2
    # The run's starting Q*_g, overriding the starting checkpoint's; None: the checkpoint's
    # (mpg_agents.acting.grasp_threshold.starting_q_star).
    q_star: float | None = UNCALIBRATED
    # Not the paper's (pure RL): oracle episodes whose transitions seed the replay of a fresh run (0: none).
    demonstration_episodes: int = 0
    # The discriminator: the fixed Stage II grasp net that scores states for the move/push rewards.
    discriminator: str | None = None
    # Bookkeeping.
    checkpoint_every: int = 100
    window: int = 200  # grasp success rate per this many iterations (paper)
    torch_threads: int = 2
    # Networks and batches: auto (CUDA when available) | cpu | cuda; replay and envs stay on the host.
    device: str = "auto"
    net_config: dict[str, Any] = field(default_factory=dict)
    # Parallel actors (mpg_agents.learning.actors): 1 acts in the learner's process, as always;
    # N > 1 step N envs in their own processes and send their transitions to the learner's replay.
    actors: int = 1
    # Actors act with the learner's weights of at most this many gradient steps ago (and its Q*_g):
    # well inside the target net's lag (target_update_every), and the small net's weights
    # (0.4 MB) cost a few milliseconds per actor and refresh.
    weights_refresh: int = 10
    actor_backend: str = "auto"  # auto (Ray when installed, else processes) | ray | processes
    ray_address: str | None = None  # with the ray backend: join this cluster (e.g. "auto", "HOST:6379"); None: a local Ray

    def __post_init__(self) -> None:
        check_train_config(self)

    def to_dict(self) -> dict[str, Any]:
        """Plain data (tuples as lists); see :func:`json_safe` for writing it."""
        data = asdict(self)
        data["betas"] = list(self.betas)
        data["q_bounds"] = list(self.q_bounds) if self.q_bounds is not None else None
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> TrainConfig:
        """The config a :meth:`to_dict` or a ``--config`` file describes.

        Raises:
            ValueError: a key is not a field (names the valid ones).
        """
        check_known_fields(cls, data, "training settings")
        data = dict(data)
        for key in ("betas", "q_bounds"):
            if data.get(key) is not None:
                data[key] = tuple(data[key])
        return cls(**data)

    def step_config(self) -> TDStepConfig:
        """The gradient step's settings."""
        return TDStepConfig(
            gamma=self.gamma, grasp_symmetry=self.grasp_symmetry, max_grad_norm=self.max_grad_norm, target_bounds=self.q_bounds
        )

    def optimizer_kwargs(self) -> dict[str, Any]:
        """Adam's settings besides the learning rate."""
        return {"weight_decay": self.weight_decay, "betas": tuple(self.betas)}


# ------------------------------------------------------------------------------ checks
def _integer(name: str, value: Any, low: int, optional: bool = False) -> None:
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
        none = " or None" if optional else ""
        raise ValueError(f"training setting {name} must be an integer >= {low}{none}, got {value!r}")


def _number(
    name: str, value: Any, low: float, high: float, valid: str, optional: bool = False, above_low: bool = False
) -> None:
    """``value`` a finite real number in ``[low, high]``, or ``(low, high]`` with ``above_low``
    (not a bool, not a string). A strict bound, not ``low = math.ulp(0.0)``: a process that
    flushes denormals to zero reads the smallest positive float as 0 and would let 0 pass."""
    if optional and value is None:
        return
    number = not isinstance(value, bool) and isinstance(value, Real) and math.isfinite(value)
    if not number or not (low < value if above_low else low <= value) or value > high:
        raise ValueError(f"training setting {name} must be {valid}{' or None' if optional else ''}, got {value!r}")


def _pair(name: str, value: Any, valid: str, ok: Callable[[float, float], bool]) -> None:
    """``value`` two real numbers that pass ``ok``."""
    numbers = (
        not isinstance(value, (str, bytes))
        and hasattr(value, "__len__")
        and len(value) == 2
        and all(isinstance(v, Real) and not isinstance(v, bool) for v in value)
    )
    if not numbers or not ok(float(value[0]), float(value[1])):
        raise ValueError(f"training setting {name} must be {valid}, got {value!r}")


def check_train_config(cfg: TrainConfig) -> None:
    """Every setting's type and range (a ``--config`` file's values and ``mpg-train``'s flags).

    Raises:
        ValueError: naming the first bad setting, its value and what is valid.
    """
    inf = math.inf
    _integer("steps", cfg.steps, 0, optional=True)
    _integer("seed", cfg.seed, 0)
    check_seed(cfg.seed, "training setting seed")  # the upper bound (torch's)
    if cfg.variant not in ("small", "large"):
        raise ValueError(f"training setting variant must be 'small' or 'large', got {cfg.variant!r}")
    _integer("num_objects", cfg.num_objects, 1, optional=True)
    _number("gamma", cfg.gamma, 0.0, 1.0, "a number in [0, 1]")
    _number("learning_rate", cfg.learning_rate, 0.0, inf, "a positive finite number", above_low=True)
    _number("weight_decay", cfg.weight_decay, 0.0, inf, "a finite number >= 0")
    _pair("betas", cfg.betas, "two numbers in [0, 1)", lambda a, b: 0 <= a < 1 and 0 <= b < 1)
    _number("epsilon_start", cfg.epsilon_start, 0.0, 1.0, "a number in [0, 1]")
    _number("epsilon_end", cfg.epsilon_end, 0.0, 1.0, "a number in [0, 1]")
    _integer("epsilon_decay_steps", cfg.epsilon_decay_steps, 1, optional=True)
    _integer("batch_size", cfg.batch_size, 1)
    _integer("replay_capacity", cfg.replay_capacity, 1)
    _number("priority_alpha", cfg.priority_alpha, 0.0, inf, "a finite number >= 0")
    _integer("target_update_every", cfg.target_update_every, 1)
    _number(
        "replay_ratio", cfg.replay_ratio, 0.0, inf, "a positive finite number (gradient steps per env step)", above_low=True
    )
    if not isinstance(cfg.grasp_symmetry, bool):
        raise ValueError(f"training setting grasp_symmetry must be true or false, got {cfg.grasp_symmetry!r}")
    _number("max_grad_norm", cfg.max_grad_norm, 0.0, inf, "a positive finite number", optional=True, above_low=True)
    if cfg.q_bounds is not None:
        _pair(
            "q_bounds",
            cfg.q_bounds,
            "two finite numbers [low, high] with low < high",
            lambda a, b: math.isfinite(a) and math.isfinite(b) and a < b,
        )
    _integer("heuristic_after_failed_grasps", cfg.heuristic_after_failed_grasps, 0)
    check_in_range(cfg.q_star, "training setting q_star (None: the starting weights')")
    _integer("demonstration_episodes", cfg.demonstration_episodes, 0)
    if cfg.discriminator is not None and not isinstance(cfg.discriminator, str):
        raise ValueError(f"training setting discriminator must be a checkpoint path or None, got {cfg.discriminator!r}")
    _integer("checkpoint_every", cfg.checkpoint_every, 1)
    _integer("window", cfg.window, 1)
    _integer("torch_threads", cfg.torch_threads, 1)
    _integer("actors", cfg.actors, 1)
    _integer("weights_refresh", cfg.weights_refresh, 1)
    if cfg.actor_backend not in ACTOR_BACKENDS:
        raise ValueError(
            f"training setting actor_backend must be one of {', '.join(ACTOR_BACKENDS)}, got {cfg.actor_backend!r}"
        )
    if cfg.ray_address is not None and (
        not isinstance(cfg.ray_address, str) or cfg.actors == 1 or cfg.actor_backend == "processes"
    ):
        raise ValueError(
            f"training setting ray_address is the Ray cluster the actors run on: a string with actors > 1 and "
            f"actor_backend 'ray' or 'auto', got {cfg.ray_address!r} with "
            f"actors={cfg.actors}, actor_backend={cfg.actor_backend!r}"
        )
    if not isinstance(cfg.net_config, dict):
        raise ValueError(f"training setting net_config must be a table of MPGNetConfig fields, got {cfg.net_config!r}")


def json_safe(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` with NaN floats (an uncalibrated Q*_g) as ``None``, which JSON can hold."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in data.items()}
