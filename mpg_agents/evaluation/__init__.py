"""Evaluation: policies on episodes, and what their records say.

The policies by name (:mod:`~mpg_agents.evaluation.policy_zoo`), episodes and the paper's
metrics (:mod:`~mpg_agents.evaluation.evaluate`, the records and their summary in
:mod:`~mpg_agents.evaluation.eval_result`, with ``--env-option`` parsing in
:mod:`~mpg_agents.evaluation.env_options`), evaluation jobs on Ray or a process pool
(:mod:`~mpg_agents.evaluation.eval_runner`), episodes that raised, kept beside those that finished
(:mod:`~mpg_agents.evaluation.failures`), intervals (:mod:`~mpg_agents.evaluation.stats`),
paired comparisons (:mod:`~mpg_agents.evaluation.comparison`), the results tables and their runs
(:mod:`~mpg_agents.evaluation.tables`, :mod:`~mpg_agents.evaluation.table_runs`, the track table
cell by cell: :mod:`~mpg_agents.evaluation.track_table`, its cells and their files in
:mod:`~mpg_agents.evaluation.track_cells`, cells reused from earlier runs in
:mod:`~mpg_agents.evaluation.reused_cells`), case sets
(:mod:`~mpg_agents.evaluation.case_runs`), and diagnostics: Q-map pictures
(:mod:`~mpg_agents.evaluation.visualize`) and what a checkpoint's grasps and moves do
(:mod:`~mpg_agents.evaluation.grasp_outcomes`, :mod:`~mpg_agents.evaluation.move_outcomes`).
Builds on :mod:`mpg_agents.acting`; imports nothing of learning.
"""
