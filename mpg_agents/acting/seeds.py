"""Which env seed each episode of a training run resets with.

A run with seed ``s`` resets its ``k``-th training episode with ``s * 1_000_003 + k`` and its
``i``-th demonstration episode with ``s * 1_000_003 + 800_000 + i`` and its ``j``-th Q*_g
calibration episode with ``s * 1_000_003 + 900_000 + j``. The prime stride keeps the runs of
nearby seeds apart; the offsets keep demonstrations and calibrations clear of the run's
training episodes and, for seed 0, of the Table I held-out seeds (500000-) and the tuning
seeds (700000-) that evaluations use.
"""

from __future__ import annotations

from collections.abc import Callable
from numbers import Integral
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import gymnasium as gym

RUN_SEED_STRIDE = 1_000_003
"""Env seeds of one run lie in ``[s * RUN_SEED_STRIDE, (s + 1) * RUN_SEED_STRIDE)``."""

DEMONSTRATION_SEED_OFFSET = 800_000
"""Where a run's demonstration episodes start inside its seed range."""

CALIBRATION_SEED_OFFSET = 900_000
"""Where a run's Q*_g calibration episodes start inside its seed range."""

MAX_SEED = 2**64 - 1
"""The largest seed a run or an evaluation takes (``--seed``, ``TrainConfig.seed``): a run seeds
torch with it (``torch.manual_seed`` takes at most 2**64 - 1), and numpy's generators with it."""


def check_seed(seed: int, what: str = "seed") -> int:
    """``seed`` as an int in ``0..MAX_SEED``; else a ``ValueError`` naming ``what`` (e.g.
    ``"--seed"``) and the valid range (a negative one: ``"--seed must be >= 0, got -5"``)."""
    if isinstance(seed, bool) or not isinstance(seed, Integral) or seed < 0:
        raise ValueError(f"{what} must be >= 0, got {seed!r}")
    if seed > MAX_SEED:
        raise ValueError(f"{what} must be an integer in 0..{MAX_SEED} (2**64 - 1), got {seed}")
    return int(seed)


def episode_seed(run_seed: int, k: int, demonstration: bool = False, calibration: bool = False) -> int:
    """The env seed of episode ``k`` (>= 0) of the run seeded ``run_seed``: a training
    episode, with ``demonstration`` an oracle demonstration episode, with ``calibration`` a
    Q*_g calibration episode."""
    if k < 0:
        raise ValueError(f"episode index must be >= 0, got {k}")
    if demonstration and calibration:
        raise ValueError("an episode is a demonstration or a calibration, not both")
    offset = DEMONSTRATION_SEED_OFFSET if demonstration else CALIBRATION_SEED_OFFSET if calibration else 0
    return run_seed * RUN_SEED_STRIDE + offset + k


MAX_SKIPPED_SEEDS = 50
"""How many seeds in a row :func:`reset_first_valid` passes over before it gives up."""


def reset_first_valid(
    env: gym.Env,
    seed_of: Callable[[int], int],
    k: int,
    options: dict[str, Any] | None = None,
    on_skip: Callable[[int, Exception], None] | None = None,
) -> tuple[dict[str, Any], dict[str, Any], int]:
    """Reset ``env`` with the seed of episode ``k``, or of the next episodes when a seed gives
    no valid scene (a strict start condition, e.g. a target at most 30% visible among few
    objects, is sometimes not met in ``EnvConfig.scene_tries`` draws).

    Returns ``(obs, info, k_used)``; ``on_skip(k, error)`` is called for each skipped episode so
    the caller can count and log it (nothing is skipped silently).

    Raises:
        InvalidSceneError: :data:`MAX_SKIPPED_SEEDS` seeds in a row gave no valid scene.
    """
    # Start-up time: the generators load the simulation (mujoco, trimesh, CoACD), this module does not.
    from mpg_envs.scenes.generators import InvalidSceneError  # noqa: PLC0415

    for attempt in range(MAX_SKIPPED_SEEDS + 1):
        try:
            obs, info = env.reset(seed=seed_of(k + attempt), **({} if options is None else {"options": options}))
            return obs, info, k + attempt
        except InvalidSceneError as exc:
            if attempt == MAX_SKIPPED_SEEDS:
                raise InvalidSceneError(
                    f"{MAX_SKIPPED_SEEDS + 1} seeds in a row from episode {k} gave no valid scene: {exc}"
                ) from exc
            if on_skip is not None:
                on_skip(k + attempt, exc)
    raise AssertionError("unreachable")
