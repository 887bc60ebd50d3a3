"""Perception: what the env sees of the scene, on the grid of :mod:`mpg_envs.grid`.

Ray-cast heightmaps (:mod:`~mpg_envs.perception.heightmap`), the target's footprint mask
(:mod:`~mpg_envs.perception.footprint`), occlusion, visible fraction and change detection
(:mod:`~mpg_envs.perception.occlusion`), the optional RGB-D camera mode and its back-projection
(:mod:`~mpg_envs.perception.camera`, :mod:`~mpg_envs.perception.frames`,
:mod:`~mpg_envs.perception.rgbd`), the colour convention both paths share and the seeded visual
randomization (:mod:`~mpg_envs.perception.appearance`,
:mod:`~mpg_envs.perception.visual_randomization`, :mod:`~mpg_envs.perception.depth_noise`) and pictures for people
(:mod:`~mpg_envs.perception.render`). These modules read a MuJoCo model and data they are given;
they import only the grid (and the package's thread settings), never the simulation or the tasks.
"""
