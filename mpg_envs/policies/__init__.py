"""Policies: what a policy is, and the suite's scripted baselines.

The :class:`~mpg_envs.policies.policy.Policy` protocol every policy of the suite follows
(:mod:`~mpg_envs.policies.policy`), the memory of what a policy already did on an unchanged
scene (:mod:`~mpg_envs.policies.action_memory`), the scripted oracle that reads the simulator
(:mod:`~mpg_envs.policies.oracle`; its plans by geometry, :mod:`~mpg_envs.policies.grasp_plans`),
the other scripted baselines, one module each (:mod:`~mpg_envs.policies.random_policy`,
:mod:`~mpg_envs.policies.pixel_heuristic`, :mod:`~mpg_envs.policies.exemplar_matcher`), and their
one registry by name (:mod:`~mpg_envs.policies.registry`).
Builds on the grid, perception and simulation layers; a policy meets an env only at run time,
through its observations and ``env.unwrapped``.
"""
