"""Settings given as mappings of a dataclass's fields (a TOML table, an env option, a config
dict): the one check that every key names a field, shared by the env's and the agent's settings."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any


def check_known_fields(cls: type, data: Mapping[str, Any], what: str) -> None:
    """``ValueError`` naming the keys of ``data`` that are not fields of dataclass ``cls``, and
    the valid ones: ``"{what} has unknown {cls} fields [...]; valid: [...]"``."""
    valid = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - valid)
    if unknown:
        raise ValueError(f"{what} has unknown {cls.__name__} fields {unknown}; valid: {sorted(valid)}")
