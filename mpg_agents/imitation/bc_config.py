"""The settings of a behaviour-cloning run (``mpg-train --baseline bc``): how many demonstrations,
how many gradient steps on what batches, and which MPGNet.

The net is MPGNet's (:class:`~mpg_agents.network.mpgnet_config.MPGNetConfig`) with the branches
the dataset's env acts with, every pixel a class: no rough target mask and no finger masks, so
the policy acts where its softmax puts the most mass (:func:`bc_net_config`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from numbers import Integral, Real
from typing import Any

from mpg_agents.acting.device import DEVICES
from mpg_agents.acting.seeds import check_seed
from mpg_agents.network.mpgnet_config import GRASP_FINGERS, MPGNetConfig
from mpg_envs.grid.workspace import NUM_ROTATIONS
from mpg_envs.settings_fields import check_known_fields

DEMO_BUDGETS: tuple[int, ...] = (10, 100, 1000)
"""The numbers of demonstrations behaviour cloning is reported with."""


@dataclass(frozen=True)
class BCConfig:
    """Behaviour cloning's settings, each checked when made.

    Attributes:
        demo_episodes: train on the dataset's first this many episodes (``None``: all of them).
        steps: gradient steps (Adam) in all, counted across resumes.
        batch_size: recorded (observation, action) samples per gradient step, drawn without
            replacement from the seeded generator (with replacement when the samples are fewer).
        learning_rate: Adam's step size.
        seed: seeds the sample draws and the net's initial weights.
        variant: MobileNetV3 trunks, ``"small"`` (stride 8, as the shipped checkpoint) or ``"large"``.
        color_input: the nets read the colour heightmap too. Off by default, as in the shipped
            checkpoint: each branch then runs a depth trunk beside the shared mask trunk, half the
            cost of a step (the target is named by its mask).
        rotations_per_sample: rotations the softmax of a step runs per sample. ``16`` (every one)
            is the exact loss; fewer is a sampled softmax (the recorded rotation and ``K - 1``
            others drawn each step, :func:`~mpg_agents.imitation.bc_loss.sampled_rotations`), about
            ``K / 16`` of the cost of a step. Default 4: a step of the hard track's three branches
            at batch 4 takes about 0.8 s on 2 CPU cores instead of 5.
        quarter_turns: turn each drawn sample's heightmaps and action by 0-3 quarter turns
            (drawn each step; :mod:`~mpg_agents.imitation.augment`), four scenes from each record
            (default on).
        grasp_fingers: which grasps the trained policy acts with, written in its checkpoint:
            ``"clear"`` (default: only those whose open fingers land least blocked, as the learned
            baselines of the tables act) or ``"any"``. Training is the same either way (every action
            is a class of the softmax), so a resume may change it.
        save_every: steps between saved run states (and ``weights.safetensors``); the last step
            always saves.
        device: ``auto`` (CUDA when available), ``cpu`` or ``cuda``.
    """

    demo_episodes: int | None = None
    steps: int = 1000
    batch_size: int = 4
    learning_rate: float = 1e-3
    seed: int = 0
    variant: str = "small"
    color_input: bool = False
    rotations_per_sample: int = 4
    quarter_turns: bool = True
    grasp_fingers: str = "clear"
    save_every: int = 25
    device: str = "auto"

    def __post_init__(self) -> None:
        if self.demo_episodes is not None:
            _positive_int(self.demo_episodes, "demo_episodes (--demo-episodes)")
        _positive_int(self.steps, "steps (--steps)")
        _positive_int(self.batch_size, "batch_size")
        _positive_int(self.save_every, "save_every")
        _positive_int(self.rotations_per_sample, "rotations_per_sample")
        if self.rotations_per_sample > NUM_ROTATIONS:
            raise ValueError(f"rotations_per_sample must lie in 1..{NUM_ROTATIONS}, got {self.rotations_per_sample}")
        if isinstance(self.learning_rate, bool) or not isinstance(self.learning_rate, Real) or not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be a number > 0, got {self.learning_rate!r}")
        check_seed(self.seed, "seed (--seed)")
        if self.variant not in ("small", "large"):
            raise ValueError(f"variant must be 'small' or 'large', got {self.variant!r}")
        if self.grasp_fingers not in GRASP_FINGERS:
            raise ValueError(f"grasp_fingers must be one of {GRASP_FINGERS}, got {self.grasp_fingers!r}")
        if not isinstance(self.quarter_turns, bool):
            raise ValueError(f"quarter_turns must be true or false, got {self.quarter_turns!r}")
        if not isinstance(self.color_input, bool):
            raise ValueError(f"color_input must be true or false, got {self.color_input!r}")
        if self.device not in DEVICES and not (self.device.startswith("cuda:") and self.device[5:].isdigit()):
            raise ValueError(f"device must be one of {DEVICES} (or cuda:N), got {self.device!r}")

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BCConfig:
        """The settings a mapping (a ``--config`` file) names.

        Raises:
            ValueError: a key is not a field (names the valid ones), or a value is out of range.
        """
        check_known_fields(cls, data, "behaviour-cloning settings")
        return cls(**dict(data))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready settings."""
        return asdict(self)

    def run_record(self) -> dict[str, Any]:
        """The settings a resumed run must share with its saved state: all but where it runs,
        how often it saves, the number of steps (a resume may run longer) and how the policy acts."""
        return {k: v for k, v in self.to_dict().items() if k not in ("device", "save_every", "steps", "grasp_fingers")}


def _positive_int(value: Any, what: str) -> None:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < 1:
        raise ValueError(f"{what} must be an integer >= 1, got {value!r}")


def bc_acting_config(config: BCConfig, trained: MPGNetConfig) -> MPGNetConfig:
    """The configuration a behaviour-cloning checkpoint acts with: the ``trained`` net's, with
    ``config``'s ``grasp_fingers`` (a setting without weights)."""
    return MPGNetConfig.from_checkpoint(trained.to_dict(), grasp_fingers=config.grasp_fingers)


def bc_net_config(config: BCConfig, primitives: Sequence[str]) -> MPGNetConfig:
    """The MPGNet a behaviour-cloning run trains: ``config``'s variant and colour input, one branch
    per primitive of the dataset's env, its last layer zero at the start (every action equally
    likely: the first loss is ``log`` of the number of actions), and its maps unmasked (every
    primitive, rotation and pixel is a class of the softmax, and the policy acts at their argmax)."""
    return MPGNetConfig.for_variant(
        config.variant,
        primitives=tuple(primitives),
        color_input=config.color_input,
        head_init="zero",
        rough_mask=False,
        grasp_fingers="any",
        move_fingers="any",
    )


BC_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(BCConfig))
"""The fields a ``--config`` file of ``mpg-train --baseline bc`` may set."""
