"""Settings given as mappings of a dataclass's fields (a TOML table, an env option, a config
dict): the one reader of a settings file (:func:`read_settings_file`: TOML or JSON, one error
style) and the one check that every key names a field, shared by the env's and the agent's settings."""

from __future__ import annotations

import json
import os
import tomllib
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path
from typing import Any

SETTINGS_FORMATS = ("TOML", "JSON")
"""The formats a settings file may be written in."""


def read_settings_file(path: str | os.PathLike[str], what: str, kind: str | None = None) -> Any:
    """The document of the settings file ``path`` (``what`` it is, for messages: ``"config
    file"``), parsed as ``kind`` (``"TOML"`` or ``"JSON"``; ``None``: TOML for a ``.toml`` file,
    else JSON).

    Raises:
        ValueError: one line naming ``what`` and the file: it does not exist, cannot be read, is
            not UTF-8 text, or is not readable ``kind`` (with the parser's reason); or ``kind``
            is not one of :data:`SETTINGS_FORMATS`.
    """
    p = Path(path)
    kind = kind if kind is not None else "TOML" if p.suffix.lower() == ".toml" else "JSON"
    if kind not in SETTINGS_FORMATS:
        raise ValueError(f"settings format {kind!r} is unknown; valid: {', '.join(SETTINGS_FORMATS)}")
    name = f"{what} {str(path)!r}"
    if not p.is_file():
        raise ValueError(f"{name} does not exist")
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise ValueError(f"{name} cannot be read: {exc.strerror or exc}") from exc
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name} is not readable {kind}: byte {exc.start} is not UTF-8") from exc
    try:
        return tomllib.loads(text) if kind == "TOML" else json.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{name} is not readable {kind}: {exc}") from exc


def check_known_fields(cls: type, data: Mapping[str, Any], what: str) -> None:
    """``ValueError`` naming the keys of ``data`` that are not fields of dataclass ``cls``, and
    the valid ones: ``"{what} has unknown {cls} fields [...]; valid: [...]"``."""
    valid = {f.name for f in fields(cls)}
    unknown = sorted(set(data) - valid)
    if unknown:
        raise ValueError(f"{what} has unknown {cls.__name__} fields {unknown}; valid: {sorted(valid)}")
