"""The package version, in one place: ``pyproject.toml`` reads it (``tool.setuptools.dynamic``),
and ``mpg_envs.__version__`` and ``mpg_agents.__version__`` are this value."""

__version__ = "0.2.0"
