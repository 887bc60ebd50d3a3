"""The benchmarks folder stays small and indexed: at most 300 tracked files, every result file
named by the index (``benchmarks/results/README.md``) and every net a table evaluates present."""

from __future__ import annotations

import fnmatch
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from mpg_agents.evaluation.policy_zoo import is_builtin
from mpg_agents.evaluation.table_runs import read_policy_specs

ROOT = Path(__file__).resolve().parents[1]
MAX_FILES = 300


def tracked(path: str) -> list[str]:
    """The files git tracks under ``path`` (skips the test outside a git checkout)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    done = subprocess.run(["git", "ls-files", path], cwd=ROOT, capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"git ls-files failed: {done.stderr.strip()}")
    return done.stdout.split()


def index_entries(text: str) -> list[str]:
    """The paths (relative to ``benchmarks/results``) that the index's first column names:
    each backticked name of a row's first cell; a name ending in ``/`` is a folder, ``*`` a glob."""
    entries = []
    for line in text.splitlines():
        if not line.startswith("| `"):
            continue
        first = line.split(" | ")[0]
        entries += re.findall(r"`([^`]+)`", first)
    return entries


def covered(path: str, entries: list[str]) -> bool:
    """Whether ``path`` is one of ``entries``, inside a folder of them, or matched by a glob of them."""
    return any(path == e or (e.endswith("/") and path.startswith(e)) or fnmatch.fnmatch(path, e) for e in entries)


def test_index_entries_are_read_from_the_first_column():
    text = "| entry | backs |\n| --- | --- |\n| `a/`, `b.json` | `not/this` |\n| `c_*.json` | x |\nprose `d`\n"
    assert index_entries(text) == ["a/", "b.json", "c_*.json"]
    assert covered("a/x/y.json", ["a/"]) and covered("c_15.json", ["c_*.json"]) and not covered("ab.json", ["a/"])


def test_the_benchmarks_folder_holds_at_most_300_tracked_files():
    files = tracked("benchmarks")
    assert len(files) <= MAX_FILES, f"benchmarks/ tracks {len(files)} files, more than {MAX_FILES}"


def test_every_result_file_is_in_the_index():
    files = [f.removeprefix("benchmarks/results/") for f in tracked("benchmarks/results")]
    entries = index_entries((ROOT / "benchmarks" / "results" / "README.md").read_text())
    missing = [f for f in files if f != "README.md" and not covered(f, entries)]
    assert not missing, f"result files the index does not name: {missing}"
    absent = [e for e in entries if "*" not in e and not (ROOT / "benchmarks" / "results" / e).exists()]
    assert not absent, f"index entries with no file: {absent}"


@pytest.mark.parametrize("name", ["tables.toml", "tracks.toml", "finding.toml"])
def test_every_net_a_table_evaluates_is_in_the_repository(name):
    specs = read_policy_specs(ROOT / "benchmarks" / name)
    assert all(is_builtin(s.policy) or (ROOT / s.policy).is_file() for s in specs), name


def test_the_results_tables_nets_live_in_the_checkpoints_folder():
    # No config that ships points into results/: every net a table evaluates is a checkpoint.
    for name in ("tables.toml", "tracks.toml", "finding.toml"):
        for spec in read_policy_specs(ROOT / "benchmarks" / name):
            if not is_builtin(spec.policy):
                assert spec.policy.startswith("benchmarks/checkpoints/"), (name, spec.policy)