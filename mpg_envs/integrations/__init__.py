"""Integrations: the MPG envs for third-party RL code, the top layer of ``mpg_envs``.

Standard observation and action wrappers (:mod:`~mpg_envs.integrations.wrappers`) and the Ray
RLlib registration (:mod:`~mpg_envs.integrations.rllib`, which imports Ray only when called).
Builds on the registered ids and the action codec; nothing in the package imports it but the
package top, which re-exports the wrappers.
"""
