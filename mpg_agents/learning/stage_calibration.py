"""Q*_g calibrated during a training stage, for the learner (a :class:`~mpg_agents.learning.learner_handle.LearnerHandle`).

Q*_g (:mod:`mpg_agents.acting.grasp_threshold`) starts as ``TrainConfig.q_star`` or the starting
checkpoint's. A stage with ``calibration_episodes`` calibrates it in its own scenes before it
trains (:func:`calibrate_in_scenes`), with ``calibrate_every`` again while it learns
(:func:`calibrate_if_due`) and at its end; a ``calibrates_q_star`` stage estimates it at its end
from its own greedy grasps that took the target (:func:`calibrate_from_own_grasps`). Each saves
the learner's state; the weights carry Q*_g.
"""

from __future__ import annotations

from typing import Any

from mpg_agents.acting.grasp_threshold import calibrate_q_star, estimate_q_star, format_q_star, write_calibration
from mpg_agents.learning.actors import make_training_env
from mpg_agents.learning.learner_handle import LearnerHandle

CALIBRATION_FILE = "calibration.json"
"""Every in-scene calibration of a stage, in its run folder (:func:`~mpg_agents.acting.grasp_threshold.write_calibration`)."""


def calibrate_in_scenes(learner: LearnerHandle, episodes: int) -> float:
    """Calibrate ``learner``'s Q*_g in its stage's scenes
    (:func:`~mpg_agents.acting.grasp_threshold.calibrate_q_star`, at the stage's
    ``calibration_quantile``) and save the state (a resumed run keeps it); ``calibration.json``
    in the run folder keeps every value of the stage. Returns Q*_g.

    Raises:
        RuntimeError: no grasp took the target.
    """
    if learner.calibration_env is None:  # its own env: a training episode in progress is left as it is
        unwrapped: Any = learner.env.unwrapped
        learner.calibration_env = make_training_env(learner.stage, learner.config, unwrapped.num_objects, learner.device)
    try:
        measured = calibrate_q_star(
            learner.policy,
            learner.calibration_env,
            episodes,
            learner.config.seed,
            learner.stage.calibration_quantile,
            on_skip=lambda k, error: learner.log(
                f"{learner.stage.name}: calibration episode {k} skipped, no valid scene ({error})"
            ),
        )
    except (ValueError, RuntimeError) as exc:
        raise type(exc)(f"stage {learner.stage.name}: {exc}") from exc
    before = learner.policy.q_star
    learner.policy.set_q_star(measured.q_star)
    c = learner.counters
    write_calibration(learner.out / CALIBRATION_FILE, measured, c.iteration, before, continue_history=c.calibrated_at >= 0)
    learner.log(
        f"{learner.stage.name}: Q*_g {format_q_star(before)} -> {measured.q_star:.4g} "
        f"in its scenes at iteration {c.iteration} "
        f"({len(measured.target_grasp_q)} of {measured.grasps} "
        f"greedy grasps took the target in {episodes} episodes)"
    )
    c.calibrated_at = c.iteration
    learner.save_state()
    return measured.q_star


def calibrate_from_own_grasps(learner: LearnerHandle) -> float | None:
    """``learner``'s ``calibrates_q_star`` stage at its end: Q*_g estimated from the Q of its recent
    greedy grasps that took the target (:func:`~mpg_agents.acting.grasp_threshold.estimate_q_star`
    at the stage's ``calibration_quantile``), and the state saved; unchanged when no greedy
    grasp took the target. Returns Q*_g (``None``: none yet)."""
    taken = learner.counters.successful_grasp_q
    if not taken:
        learner.log(
            f"{learner.stage.name}: no greedy grasp took the target; Q*_g stays {format_q_star(learner.policy.q_star)}"
        )
        return learner.policy.q_star
    before = learner.policy.q_star
    learner.policy.set_q_star(estimate_q_star(taken, learner.stage.calibration_quantile))
    learner.log(
        f"{learner.stage.name}: Q*_g {format_q_star(before)} -> {format_q_star(learner.policy.q_star)} "
        f"from its last {len(taken)} "
        "greedy grasps that took the target"
    )
    learner.save_state()
    return learner.policy.q_star


def calibrate_if_due(learner: LearnerHandle) -> None:
    """At an episode's end: the stage's periodic Q*_g calibration, once every ``calibrate_every`` iterations."""
    c, every = learner.counters, learner.stage.calibrate_every
    if every and c.iteration < learner.steps and c.iteration // every > max(c.calibrated_at, 0) // every:
        calibrate_in_scenes(learner, learner.stage.calibration_episodes)
