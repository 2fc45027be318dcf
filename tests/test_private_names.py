"""No project module reaches into another module's private names (a leading underscore): what another module needs
is public there (named without the underscore, with a docstring) or lives where it is used.

Both ways in are checked: ``from module import _name`` and ``module._name`` on a module imported by name. The modules
that may share private names are listed below with the reason.
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("dv2s_gym", "scenario_bank", "envs", "policies")

SHARED_PRIVATE_NAMES: Dict[Tuple[str, str], str] = {
    ("dv2s_gym.pipeline.dra.bev.", "dv2s_gym.pipeline.dra.bev."):
        "the bird's-eye analyzer is one algorithm split into files by stage (frames, detection, tracking, road, "
        "events, language, analyze); its underscore helpers are shared by those files only, and the package's "
        "interface is analyze's public functions",
}
"""``(importing module, imported module)`` -> why the first may use the second's private names; a name ending in a
dot stands for every module of that package."""


def _modules() -> Iterator[Tuple[str, Path]]:
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            yield ".".join(parts[:-1] if parts[-1] == "__init__" else parts), path


def _is_private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


def _absolute(module: str, path: Path, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    base = package[:len(package) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def _project(name: str) -> bool:
    return name.split(".")[0] in PACKAGES


def _matches(pattern: str, module: str) -> bool:
    return module.startswith(pattern) if pattern.endswith(".") else module == pattern


def _shared(importer: str, imported: str) -> Optional[str]:
    for (left, right), reason in SHARED_PRIVATE_NAMES.items():
        if _matches(left, importer) and _matches(right, imported):
            return reason
    return None


def private_uses() -> List[Tuple[str, int, str, str]]:
    """``(module, line, imported module, private name)`` of every private name one project module takes from
    another."""
    known = {name for name, _ in _modules()}
    found = []
    for module, path in _modules():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        aliases: Dict[str, str] = {}  # a local name bound to a project module
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _absolute(module, path, node)
                if not _project(source):
                    continue
                for alias in node.names:
                    if _is_private(alias.name):
                        found.append((module, node.lineno, source, alias.name))
                    elif f"{source}.{alias.name}" in known:
                        aliases[alias.asname or alias.name] = f"{source}.{alias.name}"
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if _project(alias.name) and alias.asname:
                        aliases[alias.asname] = alias.name
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and _is_private(node.attr):
                target = node.value
                dotted = []
                while isinstance(target, ast.Attribute):
                    dotted.insert(0, target.attr)
                    target = target.value
                if not isinstance(target, ast.Name):
                    continue
                if target.id in aliases:
                    source = ".".join([aliases[target.id]] + dotted)
                elif target.id in PACKAGES:
                    source = ".".join([target.id] + dotted)
                else:
                    continue
                if source in known and source != module:
                    found.append((module, node.lineno, source, node.attr))
    return [use for use in found if use[2] != use[0]]


def test_no_module_imports_another_modules_private_names():
    offending = [f"{module}:{line} takes {name} from {source}" for module, line, source, name in private_uses()
                 if _shared(module, source) is None]
    assert not offending, ("private names used across modules (make them public where they are defined, or move "
                           "them to where they are used):\n" + "\n".join(offending))


def test_every_listed_exception_is_still_used():
    used = {pair for pair in SHARED_PRIVATE_NAMES
            if any(_matches(pair[0], module) and _matches(pair[1], source)
                   for module, _, source, _ in private_uses())}
    assert used == set(SHARED_PRIVATE_NAMES)


def test_the_check_sees_both_ways_in(tmp_path, monkeypatch):
    package = tmp_path / "dv2s_gym"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("_hidden = 1\n")
    (package / "b.py").write_text("from dv2s_gym.a import _hidden\nfrom dv2s_gym import a as alias\n"
                                  "value = alias._hidden\nfrom . import a\nother = a._hidden\n")
    monkeypatch.setitem(globals(), "ROOT", tmp_path)
    assert sorted(private_uses()) == [("dv2s_gym.b", 1, "dv2s_gym.a", "_hidden"),
                                      ("dv2s_gym.b", 3, "dv2s_gym.a", "_hidden"),
                                      ("dv2s_gym.b", 5, "dv2s_gym.a", "_hidden")]
