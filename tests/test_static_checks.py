"""CI's lint, format and type checks: ``.ci/run`` runs them on both packages and stops at the
first that fails, the tools are in the ``dev`` extra, and with the project's settings each one
reports a file with an error of its kind (exit status 1)."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"

CHECKS = (
    "python -m ruff check mpg_envs mpg_agents",
    "python -m ruff format --check mpg_envs mpg_agents",
    "python -m mypy",
)
"""The commands ``.ci/run`` runs, one a line."""


def test_ci_runs_the_three_checks_and_stops_on_a_failure():
    lines = (ROOT / ".ci" / "run").read_text().splitlines()
    assert "set -euo pipefail" in lines  # a failing command ends the run with its status
    for command in CHECKS:
        assert command in lines, f".ci/run lacks {command!r}"
    # Before the tests: a lint or type error fails CI before the long part starts.
    assert max(lines.index(c) for c in CHECKS) < min(i for i, line in enumerate(lines) if "pytest" in line)


def test_the_tools_and_their_settings_are_the_projects():
    project = tomllib.loads(PYPROJECT.read_text())
    dev = project["project"]["optional-dependencies"]["dev"]
    assert any(d.startswith("ruff==") for d in dev) and any(d.startswith("mypy==") for d in dev)
    ruff, mypy = project["tool"]["ruff"], project["tool"]["mypy"]
    assert ruff["line-length"] == 127
    assert {"E", "F", "W", "I", "B", "UP", "PLC0415"} <= set(ruff["lint"]["select"])
    assert mypy["files"] == ["mpg_envs", "mpg_agents"] and mypy["check_untyped_defs"] is True


def _tool(name: str) -> None:
    if importlib.util.find_spec(name) is None:
        pytest.skip(f"{name} is not installed (the dev extra)")


def test_ruff_with_the_project_settings_reports_an_unused_import_and_an_inner_import(tmp_path):
    _tool("ruff")
    bad = tmp_path / "bad.py"
    bad.write_text('"""A module."""\n\nimport os\n\n\ndef f() -> int:\n    import json\n\n    return len(json.dumps(1))\n')
    done = subprocess.run(
        [sys.executable, "-m", "ruff", "check", "--no-cache", "--config", str(PYPROJECT), "--output-format", "concise", str(bad)],
        capture_output=True, text=True, timeout=60,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert "F401" in done.stdout and "PLC0415" in done.stdout


def test_mypy_with_the_project_settings_reports_a_type_error(tmp_path):
    _tool("mypy")
    bad = tmp_path / "bad.py"
    bad.write_text("def f(x: int) -> str:\n    return x\n")
    done = subprocess.run(
        [sys.executable, "-m", "mypy", "--config-file", str(PYPROJECT), "--cache-dir", str(tmp_path / "cache"), str(bad)],
        capture_output=True, text=True, timeout=120, cwd=tmp_path,
    )
    assert done.returncode == 1, done.stdout + done.stderr
    assert 'Incompatible return value type (got "int", expected "str")' in done.stdout
