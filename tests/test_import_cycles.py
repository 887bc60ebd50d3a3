"""No import circles: no two modules of ``mpg_envs`` and ``mpg_agents`` import each other, nor do
longer chains of imports come back to where they started.

Every ``import`` is read from the source (at module level, inside functions and under
``TYPE_CHECKING`` alike, as ``tests/test_layers.py`` reads them): a lazy import hides a circle
from Python, not from the design. A module that needs what another one needs takes it from a
module below both, or is handed it.
"""

from __future__ import annotations

from test_layers import MODULES, _imports


def import_graph() -> dict[str, set[str]]:
    """Each module's imports of other modules of the two packages."""
    graph = {module: _imports(module, path) - {module} for module, path in MODULES}
    return {module: {t for t in targets if t in graph} for module, targets in graph.items()}


def mutual_pairs(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The pairs of modules that import each other, each once, sorted."""
    return sorted({(a, b) if a < b else (b, a) for a, targets in graph.items() for b in targets if a in graph.get(b, ())})


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The groups of modules that reach each other through imports (strongly connected
    components of more than one module; Tarjan's algorithm, without recursion), sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, targets = work[-1]
            target = next(targets, None)
            if target is not None:
                if target not in index:
                    index[target] = low[target] = len(index)
                    stack.append(target)
                    on_stack.add(target)
                    work.append((target, iter(sorted(graph[target]))))
                elif target in on_stack:
                    low[node] = min(low[node], index[target])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    found.append(sorted(group))
    return sorted(found)


def test_mutual_pairs_and_circles_are_found_in_a_hand_made_graph():
    graph = {"a": {"b"}, "b": {"a", "c"}, "c": {"d"}, "d": {"e"}, "e": {"c"}, "f": {"a"}}
    assert mutual_pairs(graph) == [("a", "b")]
    assert circles(graph) == [["a", "b"], ["c", "d", "e"]]
    assert mutual_pairs({"a": {"b"}, "b": set()}) == [] and circles({"a": {"b"}, "b": set()}) == []


def test_the_scan_sees_lazy_and_type_checking_imports():
    graph = import_graph()
    # seeds.reset_first_valid imports the generators inside the function; the tasks import
    # scene_io, which imports vpg_scenes at module level.
    assert "mpg_envs.scenes.generators" in graph["mpg_agents.acting.seeds"]
    assert "mpg_envs.scenes.vpg_scenes" in graph["mpg_envs.scenes.scene_io"]


def test_no_two_modules_import_each_other():
    pairs = mutual_pairs(import_graph())
    assert not pairs, "modules that import each other: " + "; ".join(f"{a} <-> {b}" for a, b in pairs)


def test_no_longer_circle_of_imports():
    found = circles(import_graph())
    assert not found, "modules that import each other through others: " + "; ".join(" / ".join(g) for g in found)
