"""Simulation: the MuJoCo world and what moves in it.

The objects (the asset type and its mesh maths, :mod:`~mpg_envs.simulation.assets`; the block
set, mesh folders with their convex decomposition and its disk cache; object sets,
:mod:`~mpg_envs.simulation.objects`; their MuJoCo bodies), the UR5e with the Robotiq 2F-85 and
its inverse kinematics (:mod:`~mpg_envs.simulation.robot`), the world composed of both and
stepped (:mod:`~mpg_envs.simulation.world`), and the move, push and grasp motion primitives
(:mod:`~mpg_envs.simulation.primitives`; the free space they read,
:mod:`~mpg_envs.simulation.free_space`). Builds on :mod:`mpg_envs.grid` (and the footprint of
:mod:`mpg_envs.perception`); knows nothing of scenes, rewards or envs.
"""
