"""No project module reaches into another module's private names (a leading underscore): what another module needs
is public there (named without the underscore, with a docstring) or lives where it is used.

Every way in is checked: ``from module import _name``; ``module._name`` on a module imported by name, rebound to
another name (``m = module``), loaded by ``import_module("...")`` or from its file
(``importlib.util.module_from_spec(importlib.util.spec_from_file_location(...))``: the module its name or its path
names, else a module of unknown origin, :data:`FROM_A_FILE`, whose private names are all refused); ``getattr(module, "_name")`` (and hasattr, setattr,
delattr), also through a local helper that wraps one of those on its parameters (``def reach(obj, name): return
getattr(obj, name)``, then ``reach(module, "_name")``), ``vars(module)["_name"]`` and ``module.__dict__["_name"]``. A
name computed at run time and a module's whole namespace (``vars``, ``dir``, ``__dict__``) are refused too: they
cannot be told public. The modules that may share
private names are listed below with the reason.

Beside these binding-based checks, a rule by name holds whatever the spelling (:func:`private_names_by_name`): a
module writes a private name as an attribute (``x._name``, whatever ``x`` is: a parameter, a loop variable, a
``sys.modules`` entry, a class's private method) only when it defines that name itself, or when the name is a
library's listed in :data:`LIBRARY_PRIVATE_NAMES` with the reason; and a string naming a private name (the whole
string, or its part after the last ``.`` or ``:``, as given to ``getattr``, ``attrgetter``, ``__getattribute__``,
``pydoc.locate`` or ``pkgutil.resolve_name``) only when it defines that name or no other project module does.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path
from typing import Dict, Iterator, List, Optional, Tuple

import pytest

from ast_helpers import text_only_strings

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("dv2s_gym", "scenario_bank", "envs", "policies")

SHARED_PRIVATE_NAMES: Dict[Tuple[str, str], str] = {
    ("dv2s_gym.pipeline.dra.bev.", "dv2s_gym.pipeline.dra.bev."):
        "the bird's-eye analyzer is one algorithm split into files by stage (frames, detection, tracking, road, "
        "events, language, analyze); its underscore helpers are shared by those files only, and the package's "
        "interface is analyze's public functions",
    ("dv2s_gym.loop.html", "dv2s_gym.loop.report_text"):
        "the loop report in two renderings split into files by rendering: the page shows the rows, the settings "
        "sentences and the recommendation the Markdown form builds, through its underscore helpers",
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


REFLECTION = ("getattr", "hasattr", "setattr", "delattr")
"""Built-ins that reach an attribute by a name given as a string."""

NAMESPACE = "(its whole namespace)"
"""What :func:`private_uses` reports for ``vars(m)``, ``dir(m)`` or ``m.__dict__`` of another project module: every
private name of it is within reach."""

COMPUTED = "(a computed name)"
"""What :func:`private_uses` reports for a name another module's attribute is reached by, when the name is not a
literal: it cannot be told public, so it is refused like a private one."""


def _dotted(node: ast.AST) -> Optional[List[str]]:
    """``a.b.c`` -> ``["a", "b", "c"]``; anything else -> None."""
    parts: List[str] = []
    while isinstance(node, ast.Attribute):
        parts.insert(0, node.attr)
        node = node.value
    return [node.id] + parts if isinstance(node, ast.Name) else None


FROM_A_FILE = "<a module loaded from a file>"
"""What a module made by ``module_from_spec`` stands for when neither the name nor the path given to
``spec_from_file_location`` names a project module (it could be any of them)."""


def _called(node: ast.AST) -> Optional[str]:
    """The last part of the name a call calls (``importlib.util.module_from_spec(...)`` -> ``module_from_spec``)."""
    called = _dotted(node.func) if isinstance(node, ast.Call) else None
    return called[-1] if called else None


def _file_spec(node: ast.AST, known: set) -> Optional[str]:
    """The project module a ``spec_from_file_location(name, location)`` call loads: the module ``name`` names, else
    the one a string in ``location`` is the file of (``ROOT / "dv2s_gym/loop/heldout.py"``), else
    :data:`FROM_A_FILE`; ``None`` for another expression."""
    if _called(node) != "spec_from_file_location":
        return None
    if node.args and isinstance(node.args[0], ast.Constant) and node.args[0].value in known:
        return node.args[0].value
    for argument in node.args[1:] + [k.value for k in node.keywords]:
        for part in ast.walk(argument):
            if isinstance(part, ast.Constant) and isinstance(part.value, str) and part.value.endswith(".py"):
                parts = Path(part.value).with_suffix("").parts
                name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
                if name in known:
                    return name
    return FROM_A_FILE


def _loaded_by_name(node: ast.AST, specs: Optional[Dict[str, str]] = None, known: frozenset = frozenset()
                    ) -> Optional[str]:
    """The module ``importlib.import_module("a.b")`` (or ``import_module("a.b")``) returns, when named by a
    literal; or the module ``module_from_spec(spec)`` makes, its spec a ``spec_from_file_location`` call or a name
    bound to one (``specs``: name -> :func:`_file_spec`)."""
    if _called(node) == "module_from_spec" and node.args:
        spec = node.args[0]
        if isinstance(spec, ast.Name) and spec.id in (specs or {}):
            return (specs or {})[spec.id]
        return _file_spec(spec, set(known)) or FROM_A_FILE
    if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)):
        return None
    return node.args[0].value if _called(node) == "import_module" else None


def _module_named(node: ast.AST, aliases: Dict[str, str], known: set) -> Optional[str]:
    """The project module an expression stands for: a name bound to one (by an import, an assignment,
    ``import_module`` or ``module_from_spec``), a dotted path from a package, or a call of ``import_module`` with a
    literal or of ``module_from_spec`` (:data:`FROM_A_FILE` when the file is not known to be a project module)."""
    loaded = _loaded_by_name(node, aliases.get(_SPECS), frozenset(known))
    if loaded is not None:
        return loaded if loaded in known or loaded == FROM_A_FILE else None
    dotted = _dotted(node)
    if dotted is None:
        return None
    if dotted[0] in aliases and dotted[0] != _SPECS:
        if aliases[dotted[0]] == FROM_A_FILE:
            return FROM_A_FILE if len(dotted) == 1 else None
        source = ".".join([aliases[dotted[0]]] + dotted[1:])
    elif dotted[0] in PACKAGES:
        source = ".".join(dotted)
    else:
        return None
    return source if source in known else None


def _reached_names(node: ast.AST, aliases: Dict[str, str], known: set) -> Iterator[Tuple[str, str]]:
    """``(module, name)`` of each attribute of a project module a node reaches: ``m._x``, ``getattr(m, "_x")``
    (and hasattr, setattr, delattr), ``vars(m)["_x"]``, ``m.__dict__["_x"]`` and ``vars(m).get("_x")``; ``vars(m)``,
    ``dir(m)`` and ``m.__dict__`` as :data:`NAMESPACE`."""
    if isinstance(node, ast.Attribute):
        source = _module_named(node.value, aliases, known)
        if source is not None:
            yield source, NAMESPACE if node.attr == "__dict__" else node.attr
        return
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("vars", "dir")
            and node.args):
        source = _module_named(node.args[0], aliases, known)
        if source is not None:
            yield source, NAMESPACE
        return
    key, holder = None, None
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in REFLECTION and node.args:
        holder, key = node.args[0], node.args[1] if len(node.args) > 1 else None
    elif isinstance(node, ast.Subscript):
        holder, key = node.value, node.slice
    elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in ("get", "pop")
          and node.args):
        holder, key = node.func.value, node.args[0]
    if holder is None:
        return
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
        source = _module_named(holder, aliases, known)
    elif (isinstance(holder, ast.Call) and isinstance(holder.func, ast.Name) and holder.func.id == "vars"
          and holder.args):
        source = _module_named(holder.args[0], aliases, known)
    elif isinstance(holder, ast.Attribute) and holder.attr == "__dict__":
        source = _module_named(holder.value, aliases, known)
    else:
        return
    if source is None:
        return
    if isinstance(key, ast.Constant) and isinstance(key.value, str):
        yield source, key.value
    else:
        yield source, COMPUTED


Helper = Tuple[Tuple[str, int], Tuple[str, int]]
"""A reflection helper's parameters: (name, position) of the object's, then of the name's."""


def _reflection_helpers(tree: ast.AST) -> Dict[str, Helper]:
    """A module's functions that reach an attribute by reflection on two of their parameters (``def reach(obj,
    name): return getattr(obj, name)``, also through another such helper): function name -> their parameters
    (:data:`Helper`). A call of one is checked as the reflection call it wraps."""
    functions = [node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))]
    helpers: Dict[str, Helper] = {}
    changed = True
    while changed:  # a helper calling a helper, in any order
        changed = False
        for function in functions:
            order = [a.arg for a in function.args.posonlyargs + function.args.args + function.args.kwonlyargs]
            for node in ast.walk(function):
                holder, key = _wrapped_reflection(node, helpers)
                if (function.name not in helpers and isinstance(holder, ast.Name) and isinstance(key, ast.Name)
                        and holder.id in order and key.id in order):
                    helpers[function.name] = ((holder.id, order.index(holder.id)), (key.id, order.index(key.id)))
                    changed = True
    return helpers


def _wrapped_reflection(node: ast.AST, helpers: Dict[str, Helper]) -> Tuple[Optional[ast.AST], Optional[ast.AST]]:
    """``(object, name)`` of a reflection call (``getattr(object, name)`` and the like) or of a call of a helper of
    :func:`_reflection_helpers` (its arguments for those parameters); ``(None, None)`` for any other node."""
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
        return None, None
    if node.func.id in REFLECTION and len(node.args) > 1:
        return node.args[0], node.args[1]
    if node.func.id not in helpers:
        return None, None
    keywords = {k.arg: k.value for k in node.keywords if k.arg}

    def argument(name: str, position: int) -> Optional[ast.AST]:
        return keywords.get(name, node.args[position] if position < len(node.args) else None)
    return tuple(argument(*parameter) for parameter in helpers[node.func.id])  # type: ignore[return-value]


_SPECS = "<specs>"
"""The key of :func:`_module_aliases`' answer holding the names bound to a ``spec_from_file_location`` call."""


def _module_aliases(module: str, path: Path, tree: ast.AST, known: set) -> Dict[str, str]:
    """Local name -> the project module it is bound to: by ``import a.b as n``, ``from a import b`` (a module),
    ``n = <a module>`` or ``n = import_module("a.b")``. Scopes are not told apart: a name bound to a module anywhere
    in the file counts everywhere in it."""
    aliases: Dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            source = _absolute(module, path, node)
            if _project(source):
                for alias in node.names:
                    if f"{source}.{alias.name}" in known:
                        aliases[alias.asname or alias.name] = f"{source}.{alias.name}"
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if _project(alias.name) and alias.asname:
                    aliases[alias.asname] = alias.name
    bindings = [node for node in ast.walk(tree) if isinstance(node, (ast.Assign, ast.AnnAssign, ast.NamedExpr))]
    specs: Dict[str, str] = {}
    for node in bindings:
        spec = _file_spec(node.value, known) if node.value is not None else None
        targets = node.targets if isinstance(node, ast.Assign) else [node.target]
        specs.update({target.id: spec for target in targets if spec is not None and isinstance(target, ast.Name)})
    aliases[_SPECS] = specs  # type: ignore[assignment]  # read by _module_named, never a module name
    changed = True
    while changed:  # ``a = module; b = a`` in any order
        changed = False
        for node in bindings:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if node.value is None:
                continue
            source = _module_named(node.value, aliases, known)
            for target in targets:
                if source is not None and isinstance(target, ast.Name) and aliases.get(target.id) != source:
                    aliases[target.id], changed = source, True
    return aliases


def _through_helper(node: ast.AST, helpers: Dict[str, Helper], aliases: Dict[str, str], known: set
                    ) -> List[Tuple[str, str]]:
    """``(module, name)`` a call of a reflection helper (:func:`_reflection_helpers`) reaches, when it is given a
    project module: the name when a literal names it, else :data:`COMPUTED`."""
    if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in helpers):
        return []
    holder, key = _wrapped_reflection(node, helpers)
    source = _module_named(holder, aliases, known) if holder is not None else None
    if source is None:
        return []
    return [(source, key.value if isinstance(key, ast.Constant) and isinstance(key.value, str) else COMPUTED)]


def private_uses(modules: Optional[List[Tuple[str, Path]]] = None,
                 only: Optional[str] = None) -> List[Tuple[str, int, str, str]]:
    """``(module, line, imported module, private name)`` of every private name one project module (or the module
    ``only``) takes from another (:data:`COMPUTED` for a name computed at run time)."""
    modules = list(_modules()) if modules is None else modules
    known = {name for name, _ in modules}
    found = []
    for module, path in modules:
        if only is not None and module != only:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                source = _absolute(module, path, node)
                if _project(source):
                    found += [(module, node.lineno, source, alias.name) for alias in node.names
                              if _is_private(alias.name)]
        aliases = _module_aliases(module, path, tree, known)
        helpers = _reflection_helpers(tree)
        for node in ast.walk(tree):
            for source, name in list(_reached_names(node, aliases, known)) + _through_helper(node, helpers, aliases,
                                                                                              known):
                if (name in (COMPUTED, NAMESPACE) or _is_private(name)) and source != module:
                    found.append((module, node.lineno, source, name))
    return [use for use in found if use[2] != use[0]]



# --- Private names by name, whatever the spelling --------------------------------------------------------------
#
# The rules above follow how a module is bound to a name; these hold whatever the spelling: a module may write a
# private name as an attribute (``x._name``, whatever ``x`` is) only when it defines that name itself, and a string
# naming one (the whole string, or its part after the last ``.`` or ``:``) only when no other project module defines
# it without this one doing so too. A name defined by a module that may share private names with this one
# (:data:`SHARED_PRIVATE_NAMES`) counts as its own.

LIBRARY_PRIVATE_NAMES: Dict[str, Tuple[Tuple[str, ...], str]] = {
    "_actions": (("dv2s_gym.cli.parser",),
                 "argparse keeps a parser's arguments there; the CLI lists them to describe every command's options"),
    "_option_string_actions": (("dv2s_gym.cli.parser",),
                               "argparse's map from an option string to its action; the CLI finds the options a "
                               "command already has"),
    "_SubParsersAction": (("dv2s_gym.cli.parser",), "argparse's class of a parser's subcommands, found by isinstance"),
    "_run_exitfuncs": (("dv2s_gym.cli",), "atexit's call of the exit handlers before the CLI leaves with os._exit"),
    "_exit": (("dv2s_gym.cli", "scenario_bank.jail.zygote_server"),
              "os._exit: a forked child leaves without running its parent's cleanup"),
    "_getframe": (("envs.scenic_highway.carla.actions",), "sys._getframe: Scenic's actions read their caller's frame"),
    "_globalParameters": (("envs.scenic_highway.model_support",), "Scenic's global parameters of a compiled scenario"),
    "_simulatorProvidedProperties": (("envs.scenic_highway.readback",),
                                     "Scenic's properties a simulator writes back to an object"),
    "_specify": (("envs.scenic_highway.readback",), "Scenic's setter of an object's property during read-back"),
    "_recomputeDynamicFinals": (("envs.scenic_highway.readback",),
                                "Scenic's recomputation of an object's derived properties after read-back"),
    "_replayOut": (("envs.scenic_highway.simulator",), "Scenic's record of a simulation for replay"),
    "_isRunning": (("envs.scenic_highway.simulator",), "Scenic's flag of a simulation still running"),
    "_stop": (("envs.scenic_highway.simulator",), "Scenic's end of a simulation"),
    "_setup_lr_schedule": (("policies.training.fine_tuning",),
                           "Stable-Baselines3's rebuild of a model's learning-rate schedule after its rate is set"),
}
"""Private names of the standard library or a third-party library a project module uses as an attribute:
name -> (the modules that may, why)."""

_STRING_METHODS = ("startswith", "endswith", "removeprefix", "removesuffix")
"""String methods whose argument is a part of a string, not a name (``action.endswith("_pending")``)."""


def defined_names(tree: ast.AST) -> set:
    """Every name a module defines itself: by def, class, assignment (any target, also ``for``, ``with``, ``match``,
    comprehensions), attribute store, argument or import (its alias)."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, (ast.Store, ast.Del)):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, (ast.Store, ast.Del)):
            names.add(node.attr)
        elif isinstance(node, ast.arg):
            names.add(node.arg)
        elif isinstance(node, ast.alias):
            names.add((node.asname or node.name).split(".")[0])
        elif isinstance(node, (ast.MatchAs, ast.MatchStar)) and node.name:
            names.add(node.name)
        elif isinstance(node, ast.MatchMapping) and node.rest:
            names.add(node.rest)
    return names


def _plain_strings(tree: ast.AST) -> Iterator[ast.Constant]:
    """The string constants of a module that may name something: not docstrings, not the literal parts of an
    f-string, not the argument of :data:`_STRING_METHODS`."""
    skipped = text_only_strings(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _STRING_METHODS:
            skipped.update(id(argument) for argument in node.args)
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skipped:
            yield node


def _private_in_string(text: str) -> Optional[str]:
    """The private name a string names: the whole string, or its part after the last ``.`` or ``:``
    (``"pkg.mod:_name"``); not a name made of underscores only."""
    for part in (text, text.replace(":", ".").rsplit(".", 1)[-1]):
        if part.isidentifier() and _is_private(part) and part.strip("_"):
            return part
    return None


@functools.lru_cache(maxsize=None)
def _parsed(path: Path) -> ast.AST:
    return ast.parse(path.read_text(encoding="utf-8"))


@functools.lru_cache(maxsize=None)
def _defined_in(path: Path) -> frozenset:
    return frozenset(defined_names(_parsed(path)))


def private_names_by_name(modules: Optional[List[Tuple[str, Path]]] = None, only: Optional[str] = None
                          ) -> List[Tuple[str, int, str]]:
    """``(module, line, name)`` of each private name a module writes as an attribute without defining it (nor
    listed in :data:`LIBRARY_PRIVATE_NAMES` for it), or in a string while another project module defines it and
    this one does not."""
    modules = list(_modules()) if modules is None else modules
    trees = {module: _parsed(path) for module, path in modules}
    defined = {module: _defined_in(path) for module, path in modules}
    owners: Dict[str, set] = {}
    for module, names in defined.items():
        for name in names:
            if _is_private(name):
                owners.setdefault(name, set()).add(module)
    found = []
    for module, tree in trees.items():
        if only is not None and module != only:
            continue
        own = set(defined[module])
        for other, names in defined.items():
            if other != module and _shared(module, other) is not None:
                own |= names
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and _is_private(node.attr) and node.attr not in own
                    and module not in LIBRARY_PRIVATE_NAMES.get(node.attr, ((), ""))[0]):
                found.append((module, node.lineno, node.attr))
        for node in _plain_strings(tree):
            name = _private_in_string(node.value)
            if name is not None and name not in own and owners.get(name, set()) - {module}:
                found.append((module, node.lineno, name))
    return found


def test_no_module_writes_a_private_name_it_does_not_define():
    offending = [f"{module}:{line} uses {name}, which it does not define" for module, line, name
                 in private_names_by_name()]
    assert not offending, ("private names used by a module that does not define them (make them public where they "
                           "are defined, or list a library's private name in LIBRARY_PRIVATE_NAMES with the reason):"
                           "\n" + "\n".join(offending))


def test_every_listed_library_private_name_is_still_used_where_listed():
    modules = list(_modules())
    used = {(module, node.attr) for module, path in modules for node in ast.walk(_parsed(path))
            if isinstance(node, ast.Attribute) and node.attr in LIBRARY_PRIVATE_NAMES
            and node.attr not in _defined_in(path)}
    listed = {(module, name) for name, (where, _) in LIBRARY_PRIVATE_NAMES.items() for module in where}
    assert listed == used


PLANTS_BY_NAME = {
    "parameter default": "def _planted(module=heldout):\n    return module._relative_drop\n",
    "for target": "def _planted():\n    for module in (heldout,):\n        return module._relative_drop\n",
    "with target": "def _planted():\n    with contextlib.nullcontext(heldout) as module:\n        return module._relative_drop\n",
    "tuple unpacking": "def _planted():\n    module, other = heldout, None\n    return module._relative_drop\n",
    "starred unpacking": "def _planted():\n    [module] = [heldout]\n    return module._relative_drop\n",
    "dict holder": "def _planted():\n    return {'m': heldout}['m']._relative_drop\n",
    "list index": "def _planted():\n    return [heldout][0]._relative_drop\n",
    "lambda parameter": "def _planted():\n    return (lambda module: module._relative_drop)(heldout)\n",
    "__getattribute__": "def _planted():\n    return heldout.__getattribute__('_relative_drop')\n",
    "object.__getattribute__": "def _planted():\n    return object.__getattribute__(heldout, '_relative_drop')\n",
    "operator.attrgetter": "def _planted():\n    return operator.attrgetter('_relative_drop')(heldout)\n",
    "inspect.getmembers": "def _planted():\n    return dict(inspect.getmembers(heldout))['_relative_drop']\n",
    "class attribute holder": "class _Holder:\n    module = heldout\n\n\ndef _planted():\n"
                              "    return _Holder.module._relative_drop\n",
    "sys.modules": "def _planted():\n    return sys.modules['dv2s_gym.loop.heldout']._relative_drop\n",
    "pydoc.locate": "def _planted():\n    return pydoc.locate('dv2s_gym.loop.heldout._relative_drop')\n",
    "match capture": "def _planted():\n    match heldout:\n        case module:\n            return module._relative_drop\n",
    "comprehension variable": "def _planted():\n    return [module._relative_drop for module in [heldout]]\n",
    "functools.partial(getattr)": "def _planted():\n    return functools.partial(getattr, heldout)('_relative_drop')\n",
    "builtins.getattr": "def _planted():\n    return builtins.getattr(heldout, '_relative_drop')\n",
    "__import__ with fromlist": "def _planted():\n"
                                "    return __import__('dv2s_gym.loop.heldout', fromlist=['x'])._relative_drop\n",
    "pkgutil.resolve_name": "def _planted():\n    return pkgutil.resolve_name('dv2s_gym.loop.heldout:_relative_drop')\n",
    "a class's private method": "def _planted(record):\n    return heldout.HeldOutStore._relative_drop(record)\n",
}
"""Ways to reach ``heldout``'s private ``_relative_drop`` from another module that no binding-based rule follows."""


@pytest.mark.parametrize("family", sorted(PLANTS_BY_NAME))
def test_a_private_name_is_refused_whatever_the_spelling(tmp_path, family):
    """A copy of a real module (which imports ``heldout`` and does not define ``_relative_drop``) with a function appended
    that reaches ``_relative_drop``: the by-name rule reports it on the planted lines, and only there."""
    modules = list(_modules())
    index = next(i for i, (module, _) in enumerate(modules) if module == "dv2s_gym.loop.steps")
    source = modules[index][1].read_text(encoding="utf-8")
    assert "from dv2s_gym.loop import heldout\n" in source and "_relative_drop" not in defined_names(ast.parse(source))
    assert "_relative_drop" in defined_names(ast.parse((ROOT / "dv2s_gym/loop/heldout.py").read_text(encoding="utf-8")))
    header = "\n\nimport builtins\nimport contextlib\nimport functools\nimport inspect\nimport operator\n" \
             "import pkgutil\nimport pydoc\nimport sys\n\n\n"
    copy = tmp_path / "loop.py"
    copy.write_text(source + header + PLANTS_BY_NAME[family], encoding="utf-8")
    before = set(private_names_by_name(modules, only="dv2s_gym.loop.steps"))
    assert not before
    modules[index] = ("dv2s_gym.loop.steps", copy)
    added = set(private_names_by_name(modules, only="dv2s_gym.loop.steps"))
    first = len((source + header).splitlines())
    assert added and all(name == "_relative_drop" and line > first for _, line, name in added)


def test_a_string_rule_leaves_suffixes_and_a_modules_own_names_alone(tmp_path):
    """Strings that are parts of names (an f-string's literal, a suffix tested by endswith) and strings naming a
    private name the module defines itself are not uses of another module's private name."""
    modules = list(_modules())
    index = next(i for i, (module, _) in enumerate(modules) if module == "dv2s_gym.loop.steps")
    copy = tmp_path / "loop.py"
    copy.write_text(modules[index][1].read_text(encoding="utf-8") + "\n\n\n_own = 1\n\n\n"
                    "def _planted(name):\n    return f'{name}_relative_drop', name.endswith('_relative_drop'), getattr(_planted, '_own')\n",
                    encoding="utf-8")
    modules[index] = ("dv2s_gym.loop.steps", copy)
    assert private_names_by_name(modules, only="dv2s_gym.loop.steps") == []


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


@pytest.mark.parametrize("planted, name", [
    ('getattr(heldout, "_relative_drop")', "_relative_drop"),
    ('getattr(heldout, "_relative_drop", None)', "_relative_drop"),
    ('hasattr(heldout, "_relative_drop")', "_relative_drop"),
    ('vars(heldout)["_relative_drop"]', "_relative_drop"),
    ('vars(heldout).get("_relative_drop")', "_relative_drop"),
    ('heldout.__dict__["_relative_drop"]', "_relative_drop"),
    ("dir(heldout)", NAMESPACE),
    ('getattr(heldout, "_" + "rate")', COMPUTED),
    ('def reach(obj, name):\n        return getattr(obj, name)\n    return reach(heldout, "_RATE".lower())', COMPUTED),
    ('def reach(obj, name):\n        return getattr(obj, name)\n    return reach(name="_relative_drop", obj=heldout)', "_relative_drop"),
    ('def reach(obj, name):\n        return getattr(obj, name)\n\n    def through(name, obj):\n'
     '        return reach(obj, name)\n    return through("_RA" + "TE".lower(), heldout)', COMPUTED),
    ("module = heldout\n    return module._relative_drop", "_relative_drop"),
    ("module = dv2s_gym.loop.heldout\n    return module._relative_drop", "_relative_drop"),
    ('module = importlib.import_module("dv2s_gym.loop.heldout")\n    return module._relative_drop', "_relative_drop"),
    ('return import_module("dv2s_gym.loop.heldout")._relative_drop', "_relative_drop"),
    ('spec = importlib.util.spec_from_file_location("dv2s_gym.loop.heldout", where)\n'
     '    return importlib.util.module_from_spec(spec)._relative_drop', "_relative_drop"),
    ('module = importlib.util.module_from_spec(importlib.util.spec_from_file_location(\n'
     '        "copy", ROOT / "dv2s_gym/loop/heldout.py"))\n    return module._relative_drop', "_relative_drop"),
])
def test_the_check_sees_private_names_reached_by_reflection_or_a_rebound_name(tmp_path, planted, name):
    """A copy of a real module (which imports ``heldout``) with a function appended that reaches ``heldout``'s
    private ``_relative_drop`` another way than ``from ... import _relative_drop`` or ``heldout._relative_drop``."""
    modules = list(_modules())
    index = next(i for i, (module, _) in enumerate(modules) if module == "dv2s_gym.loop.steps")
    source = modules[index][1].read_text(encoding="utf-8")
    assert "from dv2s_gym.loop import heldout\n" in source
    copy = tmp_path / "loop.py"
    body = planted if "return" in planted else f"return {planted}"
    copy.write_text(source + "\n\nimport importlib\nfrom importlib import import_module\nimport dv2s_gym.loop\n\n\n"
                    f"def _planted():\n    {body}\n", encoding="utf-8")
    before = private_uses(modules, only="dv2s_gym.loop.steps")
    modules[index] = ("dv2s_gym.loop.steps", copy)
    added = sorted(set(private_uses(modules, only="dv2s_gym.loop.steps")) - set(before))
    last = len(copy.read_text(encoding="utf-8").splitlines())
    planted_uses = {(module, source, found) for module, line, source, found in added if line == last}
    assert ("dv2s_gym.loop.steps", "dv2s_gym.loop.heldout", name) in planted_uses
    assert {module for module, _, _ in planted_uses} == {"dv2s_gym.loop.steps"}


def test_the_check_refuses_private_names_of_a_module_loaded_from_an_unknown_file(tmp_path):
    """A module made by ``module_from_spec`` from a file neither its name nor its path tells could be any project
    module: a private name taken from it is refused."""
    modules = list(_modules())
    index = next(i for i, (module, _) in enumerate(modules) if module == "dv2s_gym.loop.steps")
    copy = tmp_path / "loop.py"
    copy.write_text(modules[index][1].read_text(encoding="utf-8") + "\n\nimport importlib.util\n\n\n"
                    "def _planted(where):\n    spec = importlib.util.spec_from_file_location('anything', where)\n"
                    "    loaded = importlib.util.module_from_spec(spec)\n    return loaded._hidden, loaded.public\n",
                    encoding="utf-8")
    before = private_uses(modules, only="dv2s_gym.loop.steps")
    modules[index] = ("dv2s_gym.loop.steps", copy)
    added = set(private_uses(modules, only="dv2s_gym.loop.steps")) - set(before)
    last = len(copy.read_text(encoding="utf-8").splitlines())
    assert added == {("dv2s_gym.loop.steps", last, FROM_A_FILE, "_hidden")}
