"""Acting: the MPGNet agent and how it decides, on :mod:`mpg_agents.network`.

The coordination rule that picks the primitive (:mod:`~mpg_agents.acting.coordination`), Q*_g
(:mod:`~mpg_agents.acting.grasp_threshold`, whose calibration runs greedy episodes on the seeds of
:mod:`~mpg_agents.acting.seeds`), the network on an env's flat action space
(:mod:`~mpg_agents.acting.q_function`, :mod:`~mpg_agents.acting.spaces`), the greedy coordinated
decision (:mod:`~mpg_agents.acting.decision`), the weight file (:mod:`~mpg_agents.acting.weights`), the
discriminator (:mod:`~mpg_agents.acting.discriminator`) and :class:`~mpg_agents.acting.agent.MPGAgent`
(:mod:`~mpg_agents.acting.agent`). No Stable-Baselines3; nothing here imports evaluation or
learning.
"""
