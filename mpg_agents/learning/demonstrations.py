"""Oracle demonstrations for the learner's replay (an optional training aid, DQfD style).

Before a stage learns, the scripted oracle (:class:`mpg_envs.policies.oracle.OraclePolicy`) may play
a few episodes on the stage's env; its transitions seed the prioritised replay and training
then runs as usual. This is not the paper's method (pure RL), so the learner does it only when
:attr:`mpg_agents.learning.learner.TrainConfig.demonstration_episodes` is set, and results obtained with
it must say so.

A transition is kept when its primitive is in ``keep_primitives`` (the net's branches: a
frozen branch simply does not learn from it, see :func:`mpg_agents.learning.td_step.td_step`) and
dropped otherwise (the net has no Q map to train for it).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym

from mpg_agents.acting.episode_loop import episode_steps
from mpg_envs.grid.actions import PixelActionSpace
from mpg_envs.policies.oracle import OraclePolicy

DEMONSTRATIONS_FILE = "demonstrations.json"
"""What a stage's run folder records of the demonstrations it collected (:meth:`DemoStats.to_dict`)."""

AddTransition = Callable[[Mapping[str, Any], Mapping[str, Any], int, float, bool], None]
"""``add(obs, next_obs, action, reward, terminated)``: stores one unbatched transition."""


@dataclass(frozen=True)
class DemoStats:
    """What a demonstration collection did."""

    episodes: int
    kept: int  # transitions passed to ``add``
    dropped: int  # transitions whose primitive is not in ``keep_primitives``
    successes: int  # episodes that ended with the env's ``is_success``
    seconds: float

    @property
    def env_steps(self) -> int:
        """The env steps the oracle took (kept and dropped transitions alike)."""
        return self.kept + self.dropped

    def to_dict(self) -> dict[str, float | int]:
        """Plain data for the stage's ``demonstrations.json``."""
        return {**asdict(self), "env_steps": self.env_steps}

    def summary(self) -> str:
        """One log line."""
        return (
            f"oracle demonstrations: {self.episodes} episodes ({self.successes} successful), "
            f"{self.kept} transitions kept, {self.dropped} dropped, {self.seconds:.1f} s"
        )


def collect_demonstrations(
    env: gym.Env, episodes: int, seed: int, keep_primitives: Sequence[str], add: AddTransition
) -> DemoStats:
    """Let the oracle play ``episodes`` episodes on ``env`` and hand its transitions to ``add``.

    Episode ``i`` is reset with ``seed + i`` (the oracle is reset at each start) and runs until
    the env terminates or truncates it. ``add`` gets each kept transition as
    ``(obs, next_obs, action, reward, terminated)``: the observations as the env returned them,
    the flat action of ``env``'s action space, the reward and the env's ``terminated`` flag
    (a truncation is no terminal state).

    Raises:
        ValueError: for a negative ``episodes``.
        TypeError: when ``env``'s action space is not an MPG pixel action space.
    """
    if episodes < 0:
        raise ValueError(f"episodes must be >= 0, got {episodes}")
    space = env.action_space
    if not isinstance(space, PixelActionSpace):
        raise TypeError(f"demonstrations need an MPG env (a PixelActionSpace), got {space}")
    keep = frozenset(keep_primitives)
    start = time.perf_counter()
    policy = OraclePolicy(env)
    kept = dropped = successes = 0
    for i in range(episodes):
        policy.reset()
        obs, _ = env.reset(seed=seed + i)
        for step in episode_steps(env, obs, lambda o: int(policy.act(o))):
            if space.decode(step.action).primitive in keep:
                add(step.obs, step.next_obs, step.action, step.reward, step.terminated)
                kept += 1
            else:
                dropped += 1
            if step.done:
                successes += int(bool(step.info["is_success"]))
    return DemoStats(episodes, kept, dropped, successes, time.perf_counter() - start)
