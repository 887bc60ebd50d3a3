"""Demonstrations: any policy's episodes recorded as a Minari dataset (``mpg-demos``).

- :mod:`mpg_agents.demos.step_info`: each step's ``info`` as columns of one fixed structure.
- :mod:`mpg_agents.demos.recording`: recording episodes, on worker processes, in seed order.
- :mod:`mpg_agents.demos.dataset`: the Minari dataset on disk: writing, loading, digest, replay.
- :mod:`mpg_agents.demos.cli`: the ``mpg-demos`` command.

Writing and reading datasets needs the optional ``demos`` extra (Minari); recording and the
info columns do not.
"""
