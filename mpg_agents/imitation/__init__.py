"""Imitation: MPGNet's fully convolutional nets trained to copy a policy's recorded actions
(behaviour cloning, ``mpg-train --baseline bc``) from a Minari dataset made by ``mpg-demos``.

- :mod:`mpg_agents.imitation.demo_samples`: the (observation, flat action) samples of a
  dataset's first N episodes, and where they come from.
- :mod:`mpg_agents.imitation.bc_loss`: the loss, one softmax over every primitive, rotation and
  pixel, and the cross-entropy of the recorded action (pure).
- :mod:`mpg_agents.imitation.bc_config`: the settings of a behaviour-cloning run.
- :mod:`mpg_agents.imitation.bc_training`: the training loop, its run folder, log and checkpoint.
- :mod:`mpg_agents.imitation.bc_command`: ``mpg-train --baseline bc``.

Reading datasets needs the optional ``demos`` extra (Minari).
"""
