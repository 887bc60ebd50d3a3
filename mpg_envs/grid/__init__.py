"""The heightmap grid, pure geometry with no simulator: the bottom layer of ``mpg_envs``.

The workspace and its pixel grid (:mod:`~mpg_envs.grid.workspace`), the flat pixel-action
codec over it (:mod:`~mpg_envs.grid.actions`) and parallel-jaw grasp geometry on the grid
(:mod:`~mpg_envs.grid.grasp_geometry`). Every other layer, and ``mpg_agents``, builds on these;
they import nothing else of the package.
"""
