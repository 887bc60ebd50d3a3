"""A primitive is named in one place: no ``"move"``, ``"push"`` or ``"grasp"`` string in the
packages' code outside its record module (``mpg_envs.grid.primitive_specs``); code uses the
constants ``MOVE``, ``PUSH``, ``GRASP`` or a record's attributes. Docstrings are text, not code."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NAMES = {"move", "push", "grasp"}
RECORD_MODULE = "mpg_envs/grid/primitive_specs.py"
SOURCES = sorted(p for package in ("mpg_envs", "mpg_agents") for p in (ROOT / package).rglob("*.py"))


def _text_only(tree: ast.AST) -> set[int]:
    """The ids of the string constants that are text, not code: a module's, class's or
    function's docstring, any other bare string statement (an attribute's docstring) and the
    literal parts of an f-string."""
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            ids.update(id(part) for part in node.values if isinstance(part, ast.Constant))
        body = getattr(node, "body", None)  # a lambda's is an expression
        for statement in body if isinstance(body, list) else []:
            if isinstance(statement, ast.Expr) and isinstance(statement.value, ast.Constant):
                ids.add(id(statement.value))
    return ids


def primitive_literals(source: str) -> list[tuple[int, str]]:
    """``(line, value)`` of every string constant in code that is a primitive's name."""
    tree = ast.parse(source)
    text = _text_only(tree)
    return sorted(
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant) and type(node.value) is str and node.value in NAMES and id(node) not in text
    )


def test_the_scan_finds_code_strings_and_skips_docstrings():
    source = '''"""A module about "move"."""
X = "move"
"""X is "push"."""


def f(p):
    """Whether p is "grasp"."""
    # "push" in a comment
    return p in ('push', f"{p}grasp", "grasping")
'''
    assert primitive_literals(source) == [(2, "move"), (9, "push")]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_no_primitive_name_as_a_string_outside_its_record(path):
    rel = path.relative_to(ROOT).as_posix()
    if rel == RECORD_MODULE:
        return
    found = [f"{rel}:{line}: {value!r}" for line, value in primitive_literals(path.read_text())]
    assert not found, (
        "primitive names as strings (use MOVE/PUSH/GRASP or the record from mpg_envs.grid.primitive_specs):\n"
        + "\n".join(found)
    )


def test_the_record_module_defines_the_names():
    literals = {value for _, value in primitive_literals((ROOT / RECORD_MODULE).read_text())}
    assert literals == NAMES
