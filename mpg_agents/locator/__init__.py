"""The target locator: where an exemplar's object shows in the heightmaps, and whether it shows at all.

- :mod:`~mpg_agents.locator.features`: the network's inputs from an observation (pure numpy).
- :mod:`~mpg_agents.locator.net`: :class:`~mpg_agents.locator.net.LocatorNet`, the network.
- :mod:`~mpg_agents.locator.samples`: labelled training samples drawn from simulated episodes.
- :mod:`~mpg_agents.locator.training`: the training loop and ``mpg-train-locator``.
- :mod:`~mpg_agents.locator.locator`: :class:`~mpg_agents.locator.locator.TargetLocator`, the
  trained locator as a policy uses it (weights file, threshold, ``locate(obs)``).
"""
