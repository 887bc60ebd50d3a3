"""Q*_g, the grasp threshold of the coordination: how it is estimated, held, stored, overridden
and recorded. Every other module reads it through this one.

The paper's workflow grasps when the best grasp Q reaches Q*_g (:mod:`mpg_agents.acting.coordination`).
In code Q*_g has one name, ``q_star``: a number, or ``None`` (:data:`UNCALIBRATED`) before any
estimate. NaN is refused everywhere (:func:`check_q_star`); it is no way to say "none".

- **Estimate**: :func:`estimate_q_star`, a quantile of the Q of greedy grasps that took the
  target (the paper sets Q*_g from the Q of successful grasps). :func:`calibrate_q_star` measures
  it in a stage's own scenes: ``episodes`` greedy grasp-only episodes of the net, nothing learned,
  on the calibration seeds of :func:`~mpg_agents.acting.seeds.episode_seed` (clear of the training and
  evaluation seeds; the same run seed gives the same scenes, so successive calibrations of one
  run use one measuring stick). A stage with ``calibrates_q_star`` applies the same estimate to
  its own recent greedy grasps that took the target, at its end.
- **Hold**: :class:`GraspThreshold`, the value an agent decides with.
- **Store**: the ``"q_star"`` field of a checkpoint's weights header (:func:`as_record`,
  :func:`from_header`), the one place a value is kept with weights; a resumed run, the next
  stage and the pipeline's record all read it back from there.
- **Override**: a value given by hand (``mpg-train``/``mpg-eval``/``mpg-export --q-star``):
  :func:`check_override`, :func:`starting_q_star`, :func:`exported_q_star` (an export keeps
  training's value on record).
- **Range**: :func:`q_star_range`, the values a threshold on the Q of grasps can mean (from the
  rewards); a header, an override and an estimate outside it are refused (:func:`check_in_range`).
- **Record**: ``calibration.json``, every in-scene measurement of a stage
  (:func:`write_calibration`), and the one number of a pipeline's ``pipeline.json``
  (:func:`as_record`).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from numbers import Real
from pathlib import Path
from typing import Any, Protocol

import gymnasium as gym
import numpy as np
import torch
from torch import nn

from mpg_agents.acting.calibration_quantile import CALIBRATION_QUANTILE, check_quantile
from mpg_agents.acting.decision import Decision
from mpg_agents.acting.episode_loop import episode_steps
from mpg_agents.acting.seeds import episode_seed, reset_first_valid
from mpg_envs.files import write_text_whole
from mpg_envs.grid.primitive_specs import GRASP
from mpg_envs.tasks.rewards import RewardConfig
from mpg_envs.tasks.stages import STAGES

UNCALIBRATED: float | None = None
"""Q*_g before any estimate: the coordination then compares the best grasp and push Q instead."""


def check_q_star(value: float | None) -> float | None:
    """``value`` as Q*_g: a float (infinities allowed: always / never grasp), or ``None`` for none yet.

    Raises:
        ValueError: NaN (say ``None`` for "no Q*_g"), or not a number.
    """
    if value is None:
        return None
    q_star = float(value)
    if math.isnan(q_star):
        raise ValueError("Q*_g must be a number, or None for no Q*_g yet; got NaN")
    return q_star


def q_star_range(reward: RewardConfig = RewardConfig()) -> tuple[float, float]:
    """``(low, high)``: the Q*_g values that mean a threshold, ``low < q_star <= high``.

    Q*_g is compared with the Q of grasps, and a grasp's Q lies in what the rewards allow. A
    grasp earns ``reward.success`` or 0, or (strict retrieval) ``reward.wrong_object``, which ends
    the episode; a failed grasp's 0 is followed by a discounted best Q no lower. So no grasp's Q
    lies below ``low = min(0, wrong_object)`` (-1): a Q*_g there passes every grasp. A Q
    estimates a return: at most the highest reward (``success``, ``improved``) for every motion
    of the longest episode of the registered stages, whatever the discount: ``high`` = 15 x 1.
    (The paper's discount 0.5 bounds returns at 2, but learned Q overshoots it: calibrations of
    this code's runs gave up to 6.3.)
    """
    low = min(0.0, reward.wrong_object)
    high = max(reward.success, reward.improved) * max(stage.max_motions for stage in STAGES.values())
    return float(low), float(high)


def check_in_range(q_star: float | None, what: str = "Q*_g") -> float | None:
    """``q_star`` (``None`` passes: no Q*_g) when it lies in :func:`q_star_range`; else a
    ``ValueError`` saying ``what`` it is (e.g. ``"--q-star"``) and the valid range."""
    if q_star is None:
        return None
    low, high = q_star_range()
    if isinstance(q_star, bool) or not isinstance(q_star, Real) or not low < q_star <= high:
        raise ValueError(
            f"{what} is {q_star!r}; valid: a number in ({low:g}, {high:g}] (a grasp's Q lies in what the rewards "
            f"allow: at or below {low:g} every grasp passes, and no return exceeds {high:g})"
        )
    return float(q_star)


def format_q_star(q_star: float | None) -> str:
    """Q*_g for a log line: ``"none"`` before any estimate."""
    return "none" if q_star is None else f"{q_star:.4g}"


class GraspThreshold(nn.Module):
    """The Q*_g (``q_star``) an agent decides with.

    A module with one float64 buffer, so the value travels with state dicts (SB3's ``save``)
    and a calibrated value such as 1.85 round-trips exactly. The buffer stores "none yet" as
    NaN (a tensor holds no ``None``); :meth:`get` and :meth:`set` speak ``None``.
    """

    value: torch.Tensor  # the buffer

    def __init__(self, q_star: float | None = UNCALIBRATED) -> None:
        super().__init__()
        self.register_buffer("value", torch.tensor(math.nan, dtype=torch.float64))
        self.set(q_star)

    def get(self) -> float | None:
        """The Q*_g held, ``None`` before any."""
        value = float(self.value)
        return None if math.isnan(value) else value

    def set(self, q_star: float | None) -> None:
        """Hold ``q_star`` from now on (``None``: none)."""
        q_star = check_q_star(q_star)
        self.value.fill_(math.nan if q_star is None else q_star)

    @property
    def calibrated(self) -> bool:
        """Whether a value is held."""
        return self.get() is not None

    def extra_repr(self) -> str:
        return f"q_star={format_q_star(self.get())}"


# -------------------------------------------------------------------------------- estimate
def estimate_q_star(target_grasp_q: Sequence[float], quantile: float = CALIBRATION_QUANTILE) -> float:
    """Q*_g from the Q of greedy grasps that took the target: their ``quantile``.

    0.5 is the median (where the Q of successful grasps settles, the paper's reading); a lower
    quantile lets the workflow take more of the grasps that do succeed.

    Raises:
        ValueError: ``quantile`` outside [0, 1], no grasp to take a quantile of, or a quantile
            outside :func:`q_star_range` (a diverged grasp net: no weights header may carry it).
    """
    check_quantile(quantile)
    if len(target_grasp_q) == 0:
        raise ValueError("Q*_g needs the Q of at least one grasp that took the target")
    q_star = float(np.quantile(target_grasp_q, quantile))
    check_in_range(
        q_star, f"the Q*_g estimated from {len(target_grasp_q)} grasps that took the target (a diverged grasp net?)"
    )
    return q_star


@dataclass(frozen=True)
class Calibration:
    """One measurement of Q*_g in a stage's scenes.

    Attributes:
        q_star: the ``quantile`` of ``target_grasp_q``.
        quantile: 0.5 is the median (the paper's reading), 0.25 the lower quartile.
        episodes: grasp-only episodes run.
        grasps: grasps taken in them.
        target_grasp_q: the Q of each grasp that took the target, in the order taken.
    """

    q_star: float
    quantile: float
    episodes: int
    grasps: int
    target_grasp_q: tuple[float, ...]


class GraspDecider(Protocol):
    """What Q*_g calibration asks of an agent (an :class:`~mpg_agents.acting.agent.MPGAgent` is one)."""

    @property
    def usable_primitives(self) -> tuple[str, ...]:
        """The env's primitives it has a branch for."""
        ...

    @property
    def branches(self) -> tuple[str, ...]:
        """Its network's branches."""
        ...

    def decide(self, observation: Mapping[str, Any], primitive: str | None = None) -> Decision:
        """Its greedy decision on ``observation`` (with ``primitive`` instead of the coordination's choice)."""
        ...


def calibrate_q_star(
    agent: GraspDecider,
    env: gym.Env,
    episodes: int,
    seed: int,
    quantile: float = CALIBRATION_QUANTILE,
    on_episode: Callable[[int, int, int], None] | None = None,
    on_skip: Callable[[int, Exception], None] | None = None,
) -> Calibration:
    """Measure Q*_g of ``agent`` in ``env``'s scenes (greedy grasps only, nothing learned).

    Args:
        agent: the net (an :class:`~mpg_agents.acting.agent.MPGAgent`, or any :class:`GraspDecider`);
            only its grasp branch acts.
        env: the scenes; episode ``k`` is reset with ``episode_seed(seed, k, calibration=True)``,
            a seed that gives no valid scene passing to the next
            (:func:`~mpg_agents.acting.seeds.reset_first_valid`).
        episodes: how many episodes (>= 1).
        seed: the run seed that picks the calibration scenes.
        quantile: which quantile of the successful grasps' Q becomes Q*_g, in [0, 1].
        on_episode: called after each episode with (episode, grasps so far, target grasps so far).
        on_skip: called with (seed index, error) for each calibration seed passed over.

    Raises:
        ValueError: the net has no grasp branch, ``episodes`` < 1 or ``quantile`` outside [0, 1].
        RuntimeError: no grasp took the target (there is nothing to take a quantile of).
    """
    if GRASP not in agent.usable_primitives:
        raise ValueError(f"Q*_g calibration needs a grasp branch; the net has {agent.branches}")
    if episodes < 1:
        raise ValueError(f"calibration needs at least one episode, got {episodes}")
    check_quantile(quantile)
    taken: list[float] = []
    grasps = 0
    k = -1
    for n in range(episodes):
        # A seed without a valid scene passes to the next one: the same scenes every calibration.
        obs, _, k = reset_first_valid(env, lambda j: episode_seed(seed, j, calibration=True), k + 1, on_skip=on_skip)
        for step in episode_steps(env, obs, lambda o: agent.decide(o, GRASP), lambda decision: decision.action):
            grasps += 1
            if step.info["target_grasped"] and math.isfinite(step.choice.q_value):
                taken.append(float(step.choice.q_value))
        if on_episode is not None:
            on_episode(n, grasps, len(taken))
    if not taken:
        raise RuntimeError(f"no grasp took the target in {episodes} calibration episodes ({grasps} grasps)")
    return Calibration(estimate_q_star(taken, quantile), quantile, episodes, grasps, tuple(taken))


# ------------------------------------------------------------------ store and record
def as_record(q_star: float | None) -> float | None:
    """Q*_g as a weights header, ``calibration.json`` or ``pipeline.json`` holds it (JSON
    ``null`` when none)."""
    return check_q_star(q_star)


def from_record(value: float | None) -> float | None:
    """The inverse of :func:`as_record` (``null``: none)."""
    return check_q_star(value)


def from_header(header: Mapping[str, Any]) -> float | None:
    """The Q*_g a checkpoint's weights header stores (``None`` when it has none)."""
    return from_record(header.get("q_star"))


def write_calibration(
    path: str | Path,
    calibration: Calibration,
    iteration: int,
    q_star_before: float | None,
    continue_history: bool,
) -> dict[str, Any]:
    """Write ``calibration.json``: the latest measurement whole, and one line per calibration.

    With ``continue_history`` the lines already in ``path`` are kept (a stage calibrating again);
    otherwise the history starts with this one. Returns what was written. A ``q_star_before``
    of ``None`` (no Q*_g yet) is written as ``null``.
    """
    path = Path(path)
    history: list[dict[str, Any]] = []
    if continue_history and path.is_file():
        history = json.loads(path.read_text()).get("history", [])
    c = calibration
    history.append({"iteration": iteration, "q_star": c.q_star, "target_grasps": len(c.target_grasp_q), "grasps": c.grasps})
    record = {
        "iteration": iteration,
        "episodes": c.episodes,
        "grasps": c.grasps,
        "target_grasps": len(c.target_grasp_q),
        "quantile": c.quantile,
        "q_star_before": as_record(q_star_before),
        "q_star": c.q_star,
        "target_grasp_q": list(c.target_grasp_q),
        "history": history,
    }
    write_text_whole(path, json.dumps(record, indent=1))  # a full disk keeps the old history
    return record


def calibration_dict(calibration: Calibration) -> dict[str, Any]:
    """The measurement as plain JSON types."""
    data = asdict(calibration)
    data["target_grasp_q"] = list(calibration.target_grasp_q)
    return data


# ------------------------------------------------------------------------- override
def check_override(q_star: float) -> float:
    """A Q*_g given by hand (``--q-star``), as a float.

    Raises:
        ValueError: it is not a number in :func:`q_star_range`.
    """
    if isinstance(q_star, bool) or not isinstance(q_star, Real):
        raise ValueError(f"q_star must be a number, got {q_star!r}")
    return check_in_range(float(q_star), "q_star")


def starting_q_star(override: float | None, checkpoint: float | None) -> float | None:
    """The Q*_g a training run starts with: the ``override`` (``TrainConfig.q_star``) unless it
    is ``None``, else the starting checkpoint's (``None``: none)."""
    return check_q_star(checkpoint) if override is None else check_q_star(override)


def exported_q_star(
    header: Mapping[str, Any], override: float | None, extra: Mapping[str, Any]
) -> tuple[float | None, dict[str, Any]]:
    """The Q*_g of an exported copy of a checkpoint, and the copy's header ``extra``.

    Without ``override`` the copy keeps the checkpoint's value. An ``override`` (e.g. one
    measured under settings changed after training) replaces it, and ``extra`` keeps training's
    as ``q_star_from_training`` (a copy of a copy keeps the first).

    Raises:
        ValueError: ``override`` is not a number in :func:`q_star_range`.
    """
    extra = dict(extra)
    if override is None:
        return from_header(header), extra
    q_star = check_override(override)
    extra.setdefault("q_star_from_training", header.get("q_star"))
    return q_star, extra
