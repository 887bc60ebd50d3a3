"""Each step's ``info`` as columns of one fixed structure, as a Minari dataset stores them.

Minari keeps an episode's infos as one column per key over its steps and needs every step to
have the same keys and types; MPG's ``info`` differs between the reset (``target``, no
``primitive``) and a step (``None`` for a visible fraction that was not measured or an episode
that has not ended). :data:`INFO_FIELDS` fixes the structure: every key the metrics read
(:class:`~mpg_envs.tasks.step_evaluation.StepEvaluation`'s entries, the motion's
``action_info``, ``num_motions``, ``end_reason``, the reset's ``target``), each with a type and
the value that stands for "not reported" (``None`` or a key the step lacks). Any other key
(``sim_warnings``, ``visual_randomization``, a wrapper's own) goes, with its value, into the
JSON text of the column ``other``: nothing is dropped.

Row 0 of every column is the reset's ``info``, row ``t`` the ``info`` of step ``t``, as Minari
pairs them with the ``T + 1`` observations of a ``T``-step episode.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

OTHER = "other"
"""The column holding every key outside :data:`INFO_FIELDS`, as JSON text (``"{}"`` when none)."""


@dataclass(frozen=True)
class InfoField:
    """One column: ``name``, element ``kind`` (``"bool"``, ``"int"``, ``"float"``, ``"str"``),
    ``size`` (``None``: a scalar per step, else a vector of that length) and ``missing``, the
    value stored when the step does not report it (``None`` or absent)."""

    name: str
    kind: str
    missing: Any
    size: int | None = None


INFO_FIELDS: tuple[InfoField, ...] = (
    InfoField("primitive", "str", ""),
    InfoField("rotation", "int", -1),
    InfoField("pixel", "int", -1, size=2),
    InfoField("position", "float", math.nan, size=3),
    InfoField("grasp_failure", "str", ""),
    InfoField("unreachable", "bool", False),
    InfoField("physics_steps", "int", -1),
    InfoField("lifted", "bool", False),
    InfoField("grasp_success", "bool", False),
    InfoField("target_grasped", "bool", False),
    InfoField("wrong_grasp", "bool", False),
    InfoField("change_detected", "bool", False),
    InfoField("occluded_before", "bool", False),
    InfoField("occluded", "bool", False),
    InfoField("visible_fraction", "float", math.nan),
    InfoField("move_success", "bool", False),
    InfoField("is_success", "bool", False),
    InfoField("objects_left", "int", -1),
    InfoField("target_out_of_workspace", "bool", False),
    InfoField("grasp_q_gain", "float", math.nan),
    InfoField("visible_gain", "float", math.nan),
    InfoField("num_motions", "int", -1),
    InfoField("end_reason", "str", ""),
    InfoField("target", "int", -1),
)
"""The typed columns, in order. ``pixel`` is ``(row, col)``, ``position`` the motion's
``(x, y, z)`` in metres; ``grasp_failure`` and ``end_reason`` are ``""`` where the env says
``None``; ``visible_fraction`` is NaN where the env reports none; ``target`` (the target's
object id) is reported at the reset only."""

FIELD_NAMES: tuple[str, ...] = tuple(f.name for f in INFO_FIELDS) + (OTHER,)
"""Every column of an encoded episode's infos."""

_CASTS = {"bool": bool, "int": int, "float": float, "str": str}


def _scalar(field: InfoField, value: Any, row: int) -> Any:
    """``value`` as ``field``'s Python type; a clear error for one of another type."""
    if field.kind == "str":
        if not isinstance(value, str):
            raise ValueError(f"info[{field.name!r}] of step {row} must be a string or None, got {value!r}")
        return value
    if field.kind == "bool":
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"info[{field.name!r}] of step {row} must be a bool or None, got {value!r}")
        return bool(value)
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"info[{field.name!r}] of step {row} must be a number or None, got {value!r}")
    if field.kind == "int" and float(value) != int(value):
        raise ValueError(f"info[{field.name!r}] of step {row} must be a whole number, got {value!r}")
    return _CASTS[field.kind](value)


def _cell(field: InfoField, info: Mapping[str, Any], row: int) -> Any:
    value = info.get(field.name)
    if field.size is None:
        return field.missing if value is None else _scalar(field, value, row)
    if value is None:
        return [field.missing] * field.size
    values = list(np.asarray(value).reshape(-1)) if isinstance(value, np.ndarray) else list(value)
    if len(values) != field.size:
        raise ValueError(f"info[{field.name!r}] of step {row} must hold {field.size} numbers, got {value!r}")
    return [_scalar(field, v, row) for v in values]


def _json_ready(value: Any, key: str) -> Any:
    """``value`` as JSON data (numpy scalars and arrays as numbers and lists); a ``ValueError``
    naming ``key`` for anything JSON cannot hold."""
    if isinstance(value, Mapping):
        return {str(k): _json_ready(v, key) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(v, key) for v in value]
    if isinstance(value, np.ndarray):
        return _json_ready(value.tolist(), key)
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise ValueError(
        f"info[{key!r}] holds a {type(value).__name__} ({value!r}), which a dataset cannot store; "
        "infos may hold numbers, strings, booleans, None, and lists, tuples, dicts and arrays of them"
    )


def other_entries(info: Mapping[str, Any]) -> str:
    """The keys of ``info`` outside :data:`INFO_FIELDS` with their values, as sorted JSON text."""
    known = {f.name for f in INFO_FIELDS}
    extra = {k: _json_ready(v, k) for k, v in info.items() if k not in known}
    return json.dumps(extra, sort_keys=True, allow_nan=True)


def encode_infos(infos: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """The columns of an episode's infos (the reset's first, then each step's).

    Scalar columns are Python lists (``bool``, ``int``, ``float``, ``str``), vector columns
    ``(len(infos), size)`` arrays (``int64`` or ``float64``); :data:`OTHER` is a list of JSON
    texts.

    Raises:
        ValueError: no infos, or a value of the wrong type or length (naming key and step).
    """
    if not infos:
        raise ValueError("an episode has at least its reset's info; got no infos")
    columns: dict[str, Any] = {}
    for field in INFO_FIELDS:
        cells = [_cell(field, info, row) for row, info in enumerate(infos)]
        if field.size is None:
            columns[field.name] = cells
        else:
            columns[field.name] = np.asarray(cells, dtype=np.int64 if field.kind == "int" else np.float64)
    columns[OTHER] = [other_entries(info) for info in infos]
    return columns


def decode_infos(columns: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The per-step dicts of :func:`encode_infos`'s columns as a loaded dataset gives them back
    (any backend: HDF5 returns text as bytes): a value equal to its field's ``missing`` is
    ``None``, the :data:`OTHER` keys are merged back in.

    Raises:
        ValueError: a column is missing, or the columns differ in length.
    """
    missing = [name for name in FIELD_NAMES if name not in columns]
    if missing:
        raise ValueError(f"the infos lack the columns {missing}; a recorded dataset has {list(FIELD_NAMES)}")
    lengths = {name: len(columns[name]) for name in FIELD_NAMES}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"the info columns differ in length: {lengths}")
    rows: list[dict[str, Any]] = [{} for _ in range(next(iter(lengths.values())))]
    for field in INFO_FIELDS:
        for row, value in zip(rows, columns[field.name]):
            row[field.name] = _decoded(field, value)
    for row, text in zip(rows, columns[OTHER]):
        row.update(json.loads(text.decode() if isinstance(text, bytes) else str(text)))
    return rows


def _decoded(field: InfoField, value: Any) -> Any:
    if field.size is not None:
        values = [_CASTS[field.kind](v) for v in np.asarray(value).reshape(-1)]
        return None if all(_is_missing(field, v) for v in values) else tuple(values)
    if isinstance(value, bytes):
        value = value.decode()
    value = _CASTS[field.kind](value.item() if isinstance(value, np.generic) else value)
    if field.kind == "bool":
        return value  # False is both "not reported" and a report: kept as False
    return None if _is_missing(field, value) else value


def _is_missing(field: InfoField, value: Any) -> bool:
    if field.kind == "float":
        return math.isnan(value)
    return value == field.missing
