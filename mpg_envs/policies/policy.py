"""What a policy is: the one interface every policy of the suite follows.

The scripted oracle (:mod:`mpg_envs.policies.oracle`), the baselines and network policies of
``mpg_agents`` and any third-party agent run through the same evaluation when they have a
``name``, ``reset()`` at each episode's start and ``act(obs) -> flat action``.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

__all__ = ["Policy"]


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
