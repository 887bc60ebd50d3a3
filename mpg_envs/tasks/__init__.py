"""Tasks: what an episode asks and how a step is judged; the Gymnasium env itself.

The paper's rewards as pure functions (:mod:`~mpg_envs.tasks.rewards`), the stages and test envs
as data (:mod:`~mpg_envs.tasks.stages`: one :class:`~mpg_envs.tasks.stages.StageSpec` per
registered id; tracks, a stage with fixed keywords: :mod:`~mpg_envs.tasks.tracks`), what one step
did (:mod:`~mpg_envs.tasks.step_evaluation`), the settings every env shares and its observation
space (:mod:`~mpg_envs.tasks.config`), the checks of its other keywords
(:mod:`~mpg_envs.tasks.env_keywords`), the episode's simulation as one public handle
(:mod:`~mpg_envs.tasks.episode_sim`), where a reset's scene comes
from (:mod:`~mpg_envs.tasks.scene_source`), ``MPGEnv`` (:mod:`~mpg_envs.tasks.env`) and the
physical ceiling of its grasp task (:mod:`~mpg_envs.tasks.grasp_ceiling`). Builds on the grid,
perception, simulation and scenes layers.
"""
