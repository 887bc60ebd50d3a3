"""The packages' layers: imports flow one way, from a subpackage to the ones below it.

Every ``import`` of every module is read from its source (at module level, inside functions and
under ``TYPE_CHECKING`` alike) and checked against the order below, the one ``ARCHITECTURE.md``
describes: a module may import its own layer and the layers below, never one above.
``mpg_envs`` never imports ``mpg_agents``. Each package's ``__init__`` is its facade: it may
import any of its layers, and only the layers named in ``TOP_USERS`` import it back.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

LAYERS = {
    "mpg_envs": ("_version", "threads", "settings_fields", "files", "grid", "perception", "simulation", "scenes", "tasks", "policies", "integrations"),
    "mpg_agents": ("network", "acting", "locator", "evaluation", "learning", "sb3", "cli_input", "cli_net_settings", "cli_eval", "demos", "imitation", "cli", "demo"),
}
"""Each package's layers, lowest first: a subpackage, or a module at the package's top."""

TOP_USERS = {"mpg_envs": ("integrations",), "mpg_agents": ()}
"""The layers that import their own package's top (``mpg_envs.integrations.rllib`` reads the
registered ``ENV_IDS`` and ``make`` from it)."""


def _modules() -> list[tuple[str, Path]]:
    found = []
    for package in LAYERS:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found.append((".".join(parts[:-1] if parts[-1] == "__init__" else parts), path))
    return found


def _imports(module: str, path: Path) -> set[str]:
    """The ``mpg_envs`` / ``mpg_agents`` modules ``module`` imports (a name imported from a
    package counts as that package's submodule when there is one)."""
    names = set()
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".") if is_package else module.split(".")[:-1]
                base = ".".join(anchor[: len(anchor) - node.level + 1] + ([base] if base else []))
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                names.add(sub if (ROOT / Path(*sub.split("."))).with_suffix(".py").is_file() or (ROOT / Path(*sub.split("."))).is_dir() else base)
    return {n for n in names if n.split(".")[0] in LAYERS}


def _layer(module: str) -> tuple[str, int | None]:
    """``(package, rank)``; rank ``None`` for the package's top (its facade)."""
    parts = module.split(".")
    if len(parts) == 1:
        return parts[0], None
    return parts[0], LAYERS[parts[0]].index(parts[1])


MODULES = _modules()


def test_every_module_belongs_to_a_layer():
    for module, _ in MODULES:
        package, rank = _layer(module)
        assert rank is not None or module == package, module


@pytest.mark.parametrize("module, path", MODULES, ids=[m for m, _ in MODULES])
def test_imports_flow_down_the_layers(module, path):
    package, rank = _layer(module)
    for target in sorted(_imports(module, path)):
        target_package, target_rank = _layer(target)
        if target_package != package:
            assert (package, target_package) == ("mpg_agents", "mpg_envs"), f"{module} imports {target}"
            continue
        if rank is None:
            continue  # the facade re-exports any layer
        if target_rank is None:
            assert LAYERS[package][rank] in TOP_USERS[package], f"{module} imports its package's top"
            continue
        assert target_rank <= rank, (
            f"{module} ({LAYERS[package][rank]}) imports {target} ({LAYERS[package][target_rank]}), a higher layer"
        )
