"""Learning: how MPGNet is trained (paper Sections III-C and III-D).

The training stages as data (:mod:`~mpg_agents.learning.training_stages`; the ablations and learned
baselines as changes of them, :mod:`~mpg_agents.learning.stage_variants`) and the algorithm's
settings (:mod:`~mpg_agents.learning.train_config`), the one gradient step
(:mod:`~mpg_agents.learning.td_step`), the replay buffer (:mod:`~mpg_agents.learning.replay`,
:mod:`~mpg_agents.learning.replay_codec`),
exploration (:mod:`~mpg_agents.learning.exploration`), oracle demonstrations
(:mod:`~mpg_agents.learning.demonstrations`), the learner of one stage
(:mod:`~mpg_agents.learning.learner`: one loop, a source of steps feeding one learning step; the
face it shows its sources and calibrations, :mod:`~mpg_agents.learning.learner_handle`; its own
actor, :mod:`~mpg_agents.learning.learner_episodes`, and its Q*_g calibrations,
:mod:`~mpg_agents.learning.stage_calibration`) and its actors (:mod:`~mpg_agents.learning.actors`,
:mod:`~mpg_agents.learning.actor_pool`, :mod:`~mpg_agents.learning.actor_feed`), its resumable state and log
(:mod:`~mpg_agents.learning.run_state`, :mod:`~mpg_agents.learning.train_log`), its run folder's
lock and resume check (:mod:`~mpg_agents.learning.run_folder`), learning curves
(:mod:`~mpg_agents.learning.plotting`), the multi-stage pipeline
(:mod:`~mpg_agents.learning.pipeline`) and independent runs as Ray tasks
(:mod:`~mpg_agents.learning.train_runs`, on evaluation's Ray session). Builds on
:mod:`mpg_agents.acting` (and :mod:`mpg_agents.evaluation` for that session); only the SB3
adapter and the command lines import it.
"""
