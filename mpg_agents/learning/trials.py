"""Counterfactual trials: actions the learner did not take, tried in the simulation and undone.

Each trial is :meth:`~mpg_envs.tasks.env.MPGEnv.try_step` (the world, motion count and
generators are put back afterwards) and goes into the replay as a labelled transition from the
same observation, so one executed step labels several actions. Privileged, like oracle
demonstrations: a simulator's counterfactual, not the paper's pure RL; off by default.

- Grasp trials (``TrainingStage.grasp_trials``): the grasp's pixel at other gripper
  orientations. In clutter a grasp is decided by its angle, and one grasp labels one angle.
- Move trials (``TrainingStage.move_trials``): the move net's best moves at other places
  (:func:`~mpg_agents.acting.decision.spaced_best`, :data:`MOVE_TRIAL_SPACING_PX` apart and
  from the move taken). The workflow moves whenever the target is covered, so what a move
  buys rests on the move map's ranking; a move that frees nothing labels only its own place,
  and the places the net ranks next stay unlabelled and over-valued.
- Rival trials (``TrainingStage.rival_trials``): while the target is covered, a move is also
  tried as the push net's best push and a push as the move net's best move, so the value of
  each uncovering step is learnt beside the one it would replace.
- Covered-grasp trials (``TrainingStage.covered_grasp_trials``): while the target is covered,
  a move or push is also tried as the grasp net's best grasp. The workflow never grasps a
  covered target, so without them the grasp net's Q on covered targets is never labelled and
  cannot tell a graspable one (what a rule grasping before uncovering needs).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from mpg_agents.acting.agent import MPGAgent
from mpg_envs.grid.grasp_geometry import GRASP_ROTATIONS, other_grasp_angles
from mpg_envs.grid.primitive_specs import GRASP, MOVE, PUSH

MOVE_TRIAL_SPACING_PX = 10.0
"""How far apart (heightmap pixels, 2 mm each) the places of a move's trials are, from each
other and from the move taken: about a block's short side, so each trial lifts at another
object or another part of one."""

TRIAL_COUNTERS: dict[str, tuple[str, ...]] = {
    "grasp_trials": ("grasp_trials", "grasp_trial_targets"),
    "move_trials": ("move_trials", "move_trial_successes"),
    "rival_trials": ("rival_trials", "rival_trial_clears"),
    "covered_grasp_trials": ("covered_grasp_trials", "covered_grasp_trial_targets"),
}
"""Each kind of trial (a ``TrainingStage`` field that switches it on) and the run counters
(:class:`~mpg_agents.learning.run_state.Counters` fields) a stage's summary reports for it."""

Store = Callable[[Mapping[str, Any], Mapping[str, Any], int, float, bool], None]


def grasp_trial_actions(env: Any, action: int, trials: int, rng: np.random.Generator) -> list[int]:
    """``trials`` grasps at the pixel of grasp ``action`` at other orientations, drawn without
    repeats from the other ``GRASP_ROTATIONS - 1`` angles, each in either of its two rotations."""
    primitive, rotation, row, col = env.action_space.decode(action)
    chosen = rng.choice(other_grasp_angles(rotation), size=trials, replace=False)
    return [env.action_space.encode(primitive, int(k) + GRASP_ROTATIONS * int(rng.integers(2)), row, col) for k in chosen]


def move_trial_actions(env: Any, policy: MPGAgent, obs: Mapping[str, Any], action: int, trials: int) -> list[int]:
    """Up to ``trials`` moves at the move net's best places away from move ``action``'s."""
    _, _, row, col = env.action_space.decode(action)
    return policy.alternatives(obs, MOVE, trials, MOVE_TRIAL_SPACING_PX, taken=(row, col))


RIVALS = {MOVE: PUSH, PUSH: MOVE}
"""The primitive each uncovering primitive is weighed against by a rival trial."""


def rival_trial_actions(policy: MPGAgent, obs: Mapping[str, Any], primitive: str) -> list[int]:
    """The best action of ``primitive``'s rival (:data:`RIVALS`) when the target is covered in
    ``obs`` and the policy has that branch; else none."""
    rival = RIVALS.get(primitive)
    if rival is None or rival not in policy.usable_primitives or not bool(obs["occluded"][0]):
        return []
    return policy.alternatives(obs, rival, 1, 0.0)


def covered_grasp_trial_actions(policy: MPGAgent, obs: Mapping[str, Any], primitive: str) -> list[int]:
    """The grasp net's best grasp when the target is covered in ``obs``, the step taken uncovers
    (a move or a push) and the policy has a grasp branch; else none."""
    if primitive not in RIVALS or GRASP not in policy.usable_primitives or not bool(obs["occluded"][0]):
        return []
    return policy.alternatives(obs, GRASP, 1, 0.0)


def run_trials(env: Any, obs: Mapping[str, Any], actions: list[int], store: Store) -> list[dict[str, Any]]:
    """Try each action from the current state (undone after each) and ``store`` its transition
    from ``obs``; returns the trials' ``info`` dicts."""
    infos = []
    for action in actions:
        next_obs, reward, terminated, _, info = env.try_step(action)
        store(obs, next_obs, action, float(reward), bool(terminated))
        infos.append(info)
    return infos


def try_alternatives(
    env: Any,
    policy: MPGAgent,
    stage: Any,
    counters: Any,
    obs: Mapping[str, Any],
    choice: Any,
    rng: np.random.Generator,
    store: Store,
) -> list[int]:
    """The trials ``stage`` (a :class:`~mpg_agents.learning.training_stages.TrainingStage`) asks for
    around ``choice`` (the step's :class:`~mpg_agents.learning.exploration.TakenAction` on ``obs``):
    tried, stored and counted in ``counters`` (the learner's
    :class:`~mpg_agents.learning.run_state.Counters`); returns their actions."""
    c = counters
    tried: list[int] = []
    if choice.primitive == GRASP and stage.grasp_trials:
        actions = grasp_trial_actions(env, choice.action, stage.grasp_trials, rng)
        infos = run_trials(env, obs, actions, store)
        c.grasp_trials += len(infos)
        c.grasp_trial_targets += sum(int(i["target_grasped"]) for i in infos)
        tried += actions
    if choice.primitive == MOVE and stage.move_trials:
        actions = move_trial_actions(env, policy, obs, choice.action, stage.move_trials)
        infos = run_trials(env, obs, actions, store)
        c.move_trials += len(infos)
        c.move_trial_successes += sum(int(i["move_success"]) for i in infos)
        tried += actions
    if stage.rival_trials:
        actions = rival_trial_actions(policy, obs, choice.primitive)
        infos = run_trials(env, obs, actions, store)
        c.rival_trials += len(infos)
        c.rival_trial_clears += sum(int(not i["occluded"] and not i["target_grasped"]) for i in infos)
        tried += actions
    if stage.covered_grasp_trials:
        actions = covered_grasp_trial_actions(policy, obs, choice.primitive)
        infos = run_trials(env, obs, actions, store)
        c.covered_grasp_trials += len(infos)
        c.covered_grasp_trial_targets += sum(int(i["target_grasped"]) for i in infos)
        tried += actions
    return tried
