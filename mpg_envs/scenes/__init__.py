"""Scenes: how the objects of an episode's start are made, written, read and shipped.

The drop generators of each stage and their buried variants
(:mod:`~mpg_envs.scenes.generators`), MPG's scene files (:mod:`~mpg_envs.scenes.scene_io`) and
the peers' (:mod:`~mpg_envs.scenes.vpg_scenes`), loading a scene file into a world
(:mod:`~mpg_envs.scenes.scene_loading`), the fixed, versioned test sets
(:mod:`~mpg_envs.scenes.test_sets`, data in ``mpg_envs/test_scenes/``) and the case sets
(:mod:`~mpg_envs.scenes.cases`, the shipped challenge set in ``mpg_envs/challenge/``). Builds on
:mod:`mpg_envs.simulation`; knows nothing of the envs that reset with these scenes.
"""
