"""The policies ``mpg-eval``, the demo and the benchmarks ask for by name: a scripted baseline,
the shipped net or a checkpoint (:func:`make_policy`). The learned baselines of Table I are stage
tables (:data:`mpg_agents.learning.stage_variants.BASELINES`); once trained they load here as
checkpoints.

Every policy is a :class:`mpg_envs.policies.policy.Policy`: ``name``, ``reset()`` at each episode's
start and ``act(obs) -> flat action``. Network policies also have ``save_qmaps(path, obs)`` and
``primitives`` (what they act with).

- the scripted baselines, by the names of their one registry
  (:mod:`mpg_envs.policies.registry`: ``oracle``, ``random``, ``pixel-heuristic`` (formerly
  ``grasp-only``, still accepted), ``matcher``); they need no torch and ship with the envs.
- ``shipped``: the move-push-grasp MPGNet trained on this project's CPU (Stages I-V, Stage V
  under strict retrieval) that ships in ``mpg_agents/checkpoints/`` (:data:`SHIPPED_CHECKPOINT`,
  its model card beside it).
- a path: an MPGNet safetensors checkpoint (``mpg-train``'s ``weights.safetensors``).

A checkpoint lacking some of the env's primitives acts with those it has and says so in its
name, e.g. ``stage2_grasp_small.safetensors (grasp-only net)`` on ``MPG-Occluded-v0``
(the paper's Grasping-Only baseline).
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from importlib import resources
from pathlib import Path
from typing import Any, cast

import gymnasium as gym
import numpy as np

from mpg_agents.acting.device import resolve_device
from mpg_agents.acting.spaces import finger_geometry
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH
from mpg_envs.policies.action_memory import ActionMemory, RepeatRule
from mpg_envs.policies.policy import check_has_mask
from mpg_envs.policies.registry import baseline_name, make_baseline, scripted_baseline_names

SHIPPED_CHECKPOINT = "mpgnet_small.safetensors"
LEARNED = ("shipped",)
"""The learned policies by name (beside a checkpoint's path)."""
BUILTIN = (*scripted_baseline_names(), *LEARNED)
"""Every policy name that is no path: the scripted baselines' (their registry owns them), then the learned ones."""


def is_builtin(name: str) -> bool:
    """Whether ``name`` names a built-in policy (a scripted baseline, by its name or a former one, or
    a learned one), not a checkpoint path."""
    return name in LEARNED or baseline_name(name) is not None


def shipped_checkpoint() -> Path:
    """Path of the checkpoint shipped with the package."""
    path = Path(str(resources.files("mpg_agents").joinpath("checkpoints", SHIPPED_CHECKPOINT)))
    if not path.is_file():
        raise FileNotFoundError(f"the shipped checkpoint {path} is missing from this installation")
    return path


class NetworkPolicy:
    """An MPGNet checkpoint with the paper's coordination (greedy, no exploration).

    ``policy`` is the :class:`~mpg_agents.acting.agent.MPGAgent` it acts with. ``primitives`` are the
    env's primitives the network has branches for; when that is fewer than the env allows,
    ``name`` ends with e.g. ``(grasp-only net)``. The keyword settings override the
    checkpoint's: the coordination, Q*_g (:func:`~mpg_agents.acting.grasp_threshold.check_override`)
    and settings that change no weight. ``device``: where the network runs (``auto``, the
    default: CUDA when available; ``cpu``; ``cuda``).

    A greedy Q policy is a function of the observation: when an action changes nothing (a
    grasp that closes on air), it meets the same observation and takes the same action until
    the motion cap. With ``avoid_repeats`` it remembers its actions in the episode
    (:class:`mpg_envs.policies.action_memory.ActionMemory`, as the oracle does) and takes the best one
    that would not repeat an action on an unchanged scene; the name ends with ``[no repeats]``.
    A failed grasp usually nudges the scene, so it is no repeat: a target hemmed in on every
    side (a closed ring, a tight box) meets grasp after grasp. With ``grasp_retries`` ``k``,
    after ``k`` grasps in a row that did not end the episode (none took the target) the next
    motion is the best push (a move where the net has no push), then grasps may follow again;
    the name ends with ``[push after k failed grasps]``. ``None`` takes the checkpoint's
    (``mpg-export --grasp-retries``; off when it has none), 0 turns it off.
    """

    def __init__(
        self,
        path: str | Path,
        env: gym.Env,
        coordination: str | None = None,
        name: str | None = None,
        grasp_region: str | None = None,
        avoid_repeats: bool = False,
        target_margin_px: int | None = None,
        move_region: str | None = None,
        q_star: float | None = None,
        grasp_fingers: str | None = None,
        move_fingers: str | None = None,
        device: str | None = None,
        grasp_retries: int | None = None,
    ):
        # Start-up time: torch and the agent load here, so the heuristics, the oracle and the
        # command lines run without them.
        import torch  # noqa: PLC0415

        from mpg_agents.acting.agent import MPGAgent  # noqa: PLC0415
        from mpg_agents.acting.grasp_threshold import check_override  # noqa: PLC0415

        check_has_mask(env, "an MPGNet checkpoint")
        torch.set_flush_denormal(True)  # see mpg_agents.learning.learner: denormals slow CPUs down
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"checkpoint {str(path)!r} does not exist")
        overrides: dict[str, Any] = {"grasp_region": grasp_region} if grasp_region is not None else {}
        if target_margin_px is not None:
            overrides["target_margin_px"] = int(target_margin_px)
        if move_region is not None:
            overrides["move_region"] = move_region
        if grasp_fingers is not None:
            overrides["grasp_fingers"] = grasp_fingers
        if move_fingers is not None:
            overrides["move_fingers"] = move_fingers
        self.policy = MPGAgent.from_weights(
            path,
            cast(gym.spaces.Dict, env.observation_space),
            cast(gym.spaces.Discrete, env.action_space),
            net_overrides=overrides,
            geometry=finger_geometry(env),
        )
        self.policy.to(resolve_device(device if device is not None else "auto"))
        if coordination is not None:
            self.policy.set_coordination(coordination)
        if q_star is not None:
            self.policy.set_q_star(check_override(q_star))
        self.primitives: tuple[str, ...] = self.policy.usable_primitives
        if self.policy.coordination != "max_q" and {GRASP, PUSH} <= set(self.primitives) and self.policy.q_star is None:
            warnings.warn(
                f"checkpoint {path} carries no Q*_g (null: never calibrated): its {self.policy.coordination!r} "
                "coordination compares the best grasp and push Q instead; pass --q-star (mpg-calibrate measures one)",
                stacklevel=2,
            )
        self.name = (name or path.name) + net_suffix(self.primitives, self.policy.action_primitives)
        if grasp_region is not None:
            self.name += f" [grasp region: {grasp_region}]"
        if target_margin_px is not None:
            self.name += f" [target margin: {target_margin_px} px]"
        if move_region is not None:
            self.name += f" [move region: {move_region}]"
        if grasp_fingers is not None:
            self.name += f" [grasp fingers: {grasp_fingers}]"
        if move_fingers is not None:
            self.name += f" [move fingers: {move_fingers}]"
        if q_star is not None:
            self.name += f" [Q*_g: {q_star:g}]"
        if grasp_retries is None:  # the checkpoint's own (mpg-export --grasp-retries), else off
            from mpg_agents.acting.weights import read_checkpoint_header  # noqa: PLC0415 - as torch above

            grasp_retries = read_checkpoint_header(path).get("extra", {}).get("grasp_retries", 0)
        if isinstance(grasp_retries, bool) or not isinstance(grasp_retries, int) or grasp_retries < 0:
            raise ValueError(
                f"grasp_retries must be a non-negative integer (0: off) or None (the checkpoint's), got {grasp_retries!r}"
            )
        fallback = [p for p in (PUSH, MOVE) if p in self.primitives]
        self.grasp_retries = grasp_retries if grasp_retries and fallback else None  # a grasp-only net has nothing else to do
        self._instead_of_grasp = fallback[0] if fallback else None
        self._grasps_in_a_row = 0
        if self.grasp_retries is not None:
            self.name += f" [push after {grasp_retries} failed grasps]"
        self.memory = None
        if avoid_repeats:
            self.memory = ActionMemory(RepeatRule())
            self.name += " [no repeats]"

    def reset(self) -> None:
        """Forget the episode's actions (``avoid_repeats``) and grasps in a row (``grasp_retries``)."""
        self._grasps_in_a_row = 0
        if self.memory is not None:
            self.memory.clear()

    def act(self, obs: Mapping[str, np.ndarray]) -> int:
        # Called again after a grasp: that grasp did not take the target (it would have ended the episode).
        instead = (
            self._instead_of_grasp if self.grasp_retries is not None and self._grasps_in_a_row >= self.grasp_retries else None
        )
        forbidden = None
        if self.memory is not None and len(self.memory):
            depth = np.asarray(obs["depth"])
            rotations = self.policy.net_config.num_rotations
            forbidden = {p: self.memory.forbidden(p, depth, rotations) for p in self.primitives}
        decision = self.policy.decide(obs, primitive=instead, forbidden=forbidden)
        if self.memory is not None:
            self.memory.record(decision.primitive, decision.rotation, decision.row, decision.col, np.asarray(obs["depth"]))
        self._grasps_in_a_row = self._grasps_in_a_row + 1 if decision.primitive == GRASP else 0
        return int(decision.action)

    def save_qmaps(self, path: str | Path, obs: Mapping[str, np.ndarray]) -> None:
        from mpg_agents.evaluation.visualize import save_policy_qmaps  # noqa: PLC0415 - it loads torch

        save_policy_qmaps(path, self.policy, obs)  # every branch's map, not only the decision's


def net_suffix(used: Sequence[str], allowed: Sequence[str]) -> str:
    """``" (grasp-only net)"`` / ``" (push+grasp net)"`` when a net uses fewer primitives than allowed."""
    if tuple(used) == tuple(allowed):
        return ""
    return f" ({used[0]}-only net)" if len(used) == 1 else f" ({'+'.join(used)} net)"


def make_policy(name: str, env: gym.Env, seed: int = 0, locator: str | Path | None = None, **kwargs: Any):
    """A policy by name (see the module docstring) for ``env``; ``seed`` seeds a scripted baseline,
    ``kwargs`` are a network policy's settings (:class:`NetworkPolicy`). On an env that names
    its target by an exemplar, a network policy acts on what a target locator finds
    (``locator``: its weights file; the shipped one when a locator ships)."""
    if baseline_name(name) is not None:  # the scripted baselines take no network settings
        return make_baseline(name, env, seed)
    if name == "shipped":
        return _located(shipped_checkpoint(), env, "shipped:" + SHIPPED_CHECKPOINT, locator, kwargs)
    path = Path(name)
    if path.suffix == ".safetensors" or path.exists():
        return _located(path, env, None, locator, kwargs)
    raise ValueError(f"unknown policy {name!r}: use one of {BUILTIN} or the path of a .safetensors checkpoint")


def _located(path: Path, env: gym.Env, name: str | None, locator: str | Path | None, kwargs: dict[str, Any]):
    """A :class:`NetworkPolicy`; on an env that names its target by an exemplar, run on what the
    target locator at ``locator`` (the shipped one when there is one) finds
    (:class:`mpg_agents.locator.finding_policy.FindingPolicy`).

    Raises:
        ValueError: an exemplar env, no ``locator`` given and none shipped with this installation.
    """
    if getattr(env.unwrapped, "target_spec", "mask") != "exemplar":
        return NetworkPolicy(path, env, name=name, **kwargs)
    from mpg_agents.locator.finding_policy import FindingPolicy, MaskedView  # noqa: PLC0415 - it loads torch
    from mpg_agents.locator.locator import SHIPPED_LOCATOR, TargetLocator  # noqa: PLC0415

    if locator is None and not SHIPPED_LOCATOR.is_file():
        raise ValueError(
            "an MPGNet checkpoint needs the target's mask in the observation; this env names the target by an "
            "exemplar (target_spec='exemplar'), so the net acts through a target locator, and none ships with this "
            "installation: give one (make_policy(..., locator=PATH), mpg-eval --locator PATH; mpg-train-locator "
            "trains one), or use the matcher, oracle or random policy"
        )
    found = TargetLocator.load(SHIPPED_LOCATOR if locator is None else locator)
    return FindingPolicy(NetworkPolicy(path, MaskedView(env), name=name, **kwargs), found)


def make_network_policy(name: str, env: gym.Env, **kwargs: Any) -> NetworkPolicy:
    """:func:`make_policy` for a name that must give an MPGNet checkpoint (``shipped`` or a path).

    Raises:
        ValueError: ``name`` is a built-in baseline without a network, or unknown.
    """
    policy = make_policy(name, env, **kwargs)
    if not isinstance(policy, NetworkPolicy):
        raise ValueError(f"--policy must be an MPGNet checkpoint (or 'shipped'), got {name!r}")
    return policy
