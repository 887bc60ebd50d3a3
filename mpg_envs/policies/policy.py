"""What a policy is: the one interface every policy of the suite follows.

The scripted oracle (:mod:`mpg_envs.policies.oracle`), the baselines and network policies of
``mpg_agents`` and any third-party agent run through the same evaluation when they have a
``name``, ``reset()`` at each episode's start and ``act(obs) -> flat action``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import gymnasium as gym

__all__ = ["Policy", "check_has_mask"]


@runtime_checkable
class Policy(Protocol):
    """What every policy in the suite is: a name, a per-episode reset and ``act(obs) -> action``.

    ``act`` returns a flat action index of the env's action space (see
    :class:`mpg_envs.grid.actions.PixelActionSpace`). Privileged policies (the oracle) may also read
    the env they were built with; learned ones read ``obs`` alone.
    """

    name: str

    def reset(self) -> None:
        """Forget per-episode memory; called at the start of every episode."""
        ...

    def act(self, obs: Any) -> int:
        """The flat action index to take for observation ``obs``."""
        ...


def check_has_mask(env: gym.Env, policy: str) -> None:
    """Raise ``ValueError`` when ``env``'s observations have no target ``mask`` (an env that names
    its target by an exemplar), which ``policy`` needs."""
    if "mask" not in getattr(env.observation_space, "spaces", {}):
        raise ValueError(
            f"{policy} needs the target's mask in the observation; this env names the target by an exemplar "
            "(target_spec='exemplar'): use target_spec='mask' or 'visible', or the matcher, oracle or random policy"
        )
