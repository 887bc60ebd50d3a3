"""The settings an MPGNet agent is built with, listed once: :class:`AgentSettings`.

:meth:`mpg_agents.acting.agent.MPGAgent.build` and the SB3 adapter's ``MPGNetPolicy`` both take
these keywords and resolve them against an env's spaces here (:meth:`AgentSettings.resolve`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any, NamedTuple

from gymnasium import spaces

from mpg_agents.acting.coordination import check_coordination
from mpg_agents.acting.grasp_threshold import UNCALIBRATED, check_q_star
from mpg_agents.acting.q_function import check_action_space
from mpg_agents.acting.spaces import check_observation_space, finger_geometry, resolve_primitives
from mpg_agents.network.finger_geometry import FingerGeometry
from mpg_agents.network.mpgnet_config import MPGNetConfig
from mpg_envs.grid.actions import check_primitives


def agent_net_config(
    variant: str, net_config: MPGNetConfig | Mapping[str, Any] | None, branches: Sequence[str]
) -> MPGNetConfig:
    """The network an agent builds: ``net_config`` (a config, or a dict overriding
    ``variant``'s defaults) with ``branches`` as its primitives.

    Raises:
        ValueError: ``net_config`` names another variant.
    """
    if isinstance(net_config, MPGNetConfig):
        return MPGNetConfig.from_dict({**net_config.to_dict(), "primitives": list(branches)})
    overrides = dict(net_config or {})
    overrides["primitives"] = tuple(branches)
    named = overrides.pop("variant", variant)
    if named != variant:
        raise ValueError(f"net_config variant {named!r} contradicts variant={variant!r}")
    return MPGNetConfig.for_variant(variant, **overrides)


class ResolvedSettings(NamedTuple):
    """:class:`AgentSettings` checked against an env's spaces: what the network is built from."""

    action_primitives: tuple[str, ...]  # the env's primitives, in its action order
    net_config: MPGNetConfig  # with the branches as its primitives
    geometry: FingerGeometry | None  # None: the network makes no finger masks


@dataclass(frozen=True)
class AgentSettings:
    """How an agent is built for an env's spaces.

    Attributes:
        variant: ``"small"`` (CPU-friendly, ``mpg-train``'s default) or ``"large"`` (paper)
            MobileNetV3 trunks.
        primitives: the action space's primitives when it does not carry ``.primitives``.
        branches: the nets to build (default: the action primitives); a superset keeps e.g.
            the grasp net as Stage III's discriminator next to the move net.
        coordination: one of :data:`~mpg_agents.acting.coordination.COORDINATIONS`
            (``"workflow"``: the paper's; ``"max_q"``: its ablation).
        q_star: Q*_g, the best grasp Q at which the coordination grasps; ``None``: none yet.
        net_config: ``MPGNetConfig`` or its dict overriding the variant's defaults.
        imagenet_weights: optional torchvision MobileNetV3 checkpoint to initialise every trunk.
        geometry: the grasp geometry of the env it acts on, for finger masks
            (:func:`~mpg_agents.acting.spaces.finger_geometry`; default: the default env's).
    """

    variant: str = "small"
    primitives: Sequence[str] | None = None
    branches: Sequence[str] | None = None
    coordination: str = "workflow"
    q_star: float | None = UNCALIBRATED
    net_config: MPGNetConfig | Mapping[str, Any] | None = None
    imagenet_weights: str | None = None
    geometry: FingerGeometry | None = None

    def __post_init__(self) -> None:
        check_coordination(self.coordination)
        object.__setattr__(self, "q_star", check_q_star(self.q_star))
        if self.branches is not None:
            object.__setattr__(self, "branches", check_primitives(self.branches))

    def resolve(self, observation_space: spaces.Space, action_space: spaces.Space) -> ResolvedSettings:
        """The network these settings build for an env's spaces.

        Raises:
            ValueError: the spaces are not MPG's, or a setting is unknown.
        """
        action_primitives = resolve_primitives(action_space, self.primitives)
        cfg = agent_net_config(
            self.variant, self.net_config, self.branches if self.branches is not None else action_primitives
        )
        check_observation_space(observation_space, cfg.heightmap_size)
        check_action_space(action_space, action_primitives, cfg)  # type: ignore[arg-type]
        geometry = self.geometry
        if geometry is None and cfg.uses_finger_masks:
            geometry = finger_geometry()
        return ResolvedSettings(action_primitives, cfg, geometry)

    def replace(self, **changes: Any) -> AgentSettings:
        """A copy with ``changes``."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """The settings as keywords (a configuration as its dict)."""
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        if isinstance(self.net_config, MPGNetConfig):
            data["net_config"] = self.net_config.to_dict()
        return data
