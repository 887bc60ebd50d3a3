"""The network: MPGNet, the move/push/grasp fully convolutional Q-networks; the bottom layer of
``mpg_agents``.

Its configuration (:mod:`~mpg_agents.network.mpgnet_config`), the MobileNetV3 trunks
(:mod:`~mpg_agents.network.mobilenet`), input checks and normalisation
(:mod:`~mpg_agents.network.inputs`), the rotation maths (:mod:`~mpg_agents.network.rotations`),
where move and grasp may act (:mod:`~mpg_agents.network.regions`), one primitive's net
(:mod:`~mpg_agents.network.primitive_net`) and the three-branch network
(:mod:`~mpg_agents.network.mpgnet`). Imports torch and ``mpg_envs``'s grid, nothing else of
``mpg_agents``.
"""
