"""The layout of ARCHITECTURE.md: which top-level folder may import which, and no import cycle.

Every ``import`` and ``from ... import`` in the four packages counts, also those inside functions.
An import of ``a.b`` (or ``from a import b`` where ``b`` is a module) is an edge to the module
``a.b``; that Python also runs the ``__init__`` of ``a`` on the way is not counted, so a package
whose ``__init__`` imports its submodules does not form a cycle with them.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, List, Optional, Set

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dv2s_gym", "envs", "policies", "scenario_bank")


def _modules() -> Dict[str, Path]:
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            modules[".".join(parts)] = path
    return modules


MODULES = _modules()


def _module_of(name: str) -> Optional[str]:
    """The module of ours that ``name`` (a module, or a name inside one) lives in; None if not ours."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _imports(module: str) -> Set[str]:
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: Set[Optional[str]] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found.update(_module_of(alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                found.add(submodule if submodule in MODULES else _module_of(source))
    found.discard(None)
    found.discard(module)
    return found  # type: ignore[return-value]


GRAPH = {module: _imports(module) for module in MODULES}


def _violations(source: str, forbidden: tuple) -> List[str]:
    return sorted(f"{module} imports {target}" for module, targets in GRAPH.items()
                  if module == source or module.startswith(source + ".")
                  for target in targets if any(target == f or target.startswith(f + ".") for f in forbidden))


def test_the_graph_sees_the_imports():
    """A check that finds nothing because it reads nothing would pass every rule below."""
    assert len(GRAPH) > 100
    assert "dv2s_gym.workers.pool" in GRAPH["dv2s_gym.regress.runner"]
    assert "dv2s_gym.workers.tasks" in GRAPH["dv2s_gym.mining.tasks"]
    assert any(t.startswith("scenario_bank.") for m, ts in GRAPH.items() if m.startswith("envs.") for t in ts)


@pytest.mark.parametrize("source, forbidden", [
    ("envs", ("policies", "dv2s_gym")),
    ("scenario_bank", ("envs", "policies", "dv2s_gym")),
    ("policies", ("dv2s_gym",)),
    ("dv2s_gym.regress", ("dv2s_gym.mining",)),
    ("dv2s_gym.workers", ("dv2s_gym.regress", "dv2s_gym.mining")),
])
def test_imports_point_one_way(source, forbidden):
    assert _violations(source, forbidden) == []


def _cycles() -> List[List[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    cycles: List[List[str]] = []
    for root in sorted(GRAPH):
        if root in index:
            continue
        work = [(root, iter(sorted(GRAPH[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(GRAPH[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_no_import_cycle():
    assert _cycles() == []


def test_the_cycle_check_finds_a_cycle(monkeypatch):
    monkeypatch.setitem(GRAPH, "dv2s_gym.workers.tasks", GRAPH["dv2s_gym.workers.tasks"] | {"dv2s_gym.workers.pool"})
    assert ["dv2s_gym.workers.pool", "dv2s_gym.workers.tasks"] in _cycles()
