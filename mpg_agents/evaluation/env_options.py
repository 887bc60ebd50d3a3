"""Env options from the command line: ``--env-option KEY=VALUE``, as ``gym.make`` keywords.

A value is read as a Python literal where it is one (``3``, ``0.5``, ``True``, ``(0, 0.3)``)
and kept as text otherwise (``camera``, ``fail``): ``--env-option obs_mode=camera
--env-option wrong_grasp=fail --env-option "visible_range=(0, 0.3)"``. What an env accepts is
:class:`mpg_envs.tasks.env.MPGEnv`'s keywords; a wrong one fails when the env is made, naming it.
"""

from __future__ import annotations

import ast
import inspect
from collections.abc import Iterable
from typing import Any

RESERVED = ("num_objects",)
"""Options with a flag of their own (``--num-objects``)."""


def parse_env_option(text: str) -> tuple[str, Any]:
    """``"KEY=VALUE"`` -> ``(KEY, value)``; raises ``ValueError`` naming the malformed text."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key.isidentifier():
        raise ValueError(f"--env-option takes KEY=VALUE with KEY a keyword of the env, got {text!r}")
    if key in RESERVED:
        raise ValueError(f"--env-option {key}=... has its own flag: use --{key.replace('_', '-')}")
    return key, literal_or_text(raw)


def literal_or_text(raw: str) -> Any:
    """A command-line option's value: the Python literal ``raw`` spells (``3``, ``0.5``,
    ``True``, ``(0, 0.3)``), else ``raw`` itself as text (``camera``), stripped."""
    raw = raw.strip()
    try:
        return ast.literal_eval(raw)
    except (ValueError, SyntaxError):
        return raw


def env_keywords() -> tuple[str, ...]:
    """The keywords an MPG env takes besides its stage and object count."""
    from mpg_envs.tasks.env import MPGEnv  # noqa: PLC0415 - start-up time: it loads the simulation

    names = inspect.signature(MPGEnv.__init__).parameters
    return tuple(n for n in names if n not in ("self", "stage", *RESERVED))


def parse_env_options(texts: Iterable[str] | None) -> dict[str, Any]:
    """Every ``--env-option`` as one dict; raises ``ValueError`` for a key given twice or one
    the envs do not take (naming the valid ones)."""
    options: dict[str, Any] = {}
    valid = env_keywords()
    for text in texts or ():
        key, value = parse_env_option(text)
        if key in options:
            raise ValueError(f"--env-option {key} is given twice")
        if key not in valid:
            raise ValueError(f"--env-option {key}: not an env keyword; valid: {', '.join(valid)}")
        options[key] = value
    return options
