"""Safety check of untrusted Scenic code, done before it is compiled or run.

Scenic is Python with extra syntax, so a generated script could do anything
Python can. The check parses the script with Scenic's own parser (no code runs)
and walks the tree against an allowlist. A script may use:

* Scenic's language (every Scenic statement, specifier and operator except
  ``simulator``) and Python's expression and statement syntax, minus imports,
  ``global``/``nonlocal``, ``async``/``await`` and generators;
* names it defines itself, the names of Scenic's driving domain and our world
  model (except the few that load modules, files or simulators:
  :data:`DENIED_NAMES`), a fixed set of safe builtins (:data:`SAFE_BUILTINS`)
  and ``math``; every other Python builtin is refused;
* ``model`` lines naming a Scenic world model (:data:`WORLD_MODELS`; every
  script is compiled against the highway-env model whatever its line says) and
  ``import math``; every other import form is refused, wherever it appears.

Nothing may start with ``_`` (but the driving domain's documented accessors
that return a road element or ``None``, :data:`SCENIC_OPTIONAL_ATTRIBUTES`): no name, attribute, argument, keyword,
property, class-pattern attribute (``case Cls(attr=x)`` reads ``subject.attr``) or string constant naming a private
attribute (``"_os"``, ``"__class__"``), so
no module, frame, code object or builtin is reached through an object's
private state. Frame and code attributes without an underscore (``gi_frame``,
``f_globals``, ``tb_frame``...), string formatting that walks attributes
(``.format``/``.format_map``), and methods that read or write files
(``fromFile``, ``dumpPickle``, ``show``...) or change the file system (``touch``,
``mkdir``, ``unlink``...) are refused too. ``param map`` is a shipped map name or a
relative ``.xodr`` path, set before the ``model`` line. A bare ``_`` (a throwaway loop
variable) is the one name starting with ``_`` that is allowed.

No script reaches the env, the simulator, Gymnasium or highway-env, whose objects lead back to the
interpreter (``spec.make`` imports and calls any function, ``change_vehicles`` imports a module, ``config``
holds the env's limits). The rule has two parts. ``simulation`` may only be called, with no arguments,
and read for one of a few data attributes (:data:`SIMULATION_ATTRIBUTES`: ``simulation().currentTime``);
binding it or its result to a name, passing it on or reading anything else is refused, so no chain of
attributes starts from the simulation. And the names of the env's, the simulator's, Gymnasium's and
highway-env's own attributes (:data:`ENV_ATTRIBUTES`: ``spec``, ``unwrapped``, ``config``...) are refused
on any object, whatever route led to it. ``param`` is a statement only (``param(...)`` called as a
function is refused), and ``localPath`` may only be the whole value of ``param map`` or of MetaDrive's
``param sumo_map`` (:data:`LOCAL_PATH_PARAMS`), with one literal relative path that stays inside the
script's folder.

Before any parse, :func:`scenario_bank.precheck.precheck_text` bounds the text (size, lines, statement
length, nesting) and refuses encodings and characters that make the code read differ from the code shown.

Every finding names the line, the construct and the reason. The check is the
first layer; :mod:`scenario_bank.sandbox` runs what passes it in a child
process with CPU, memory and wall-clock limits.
"""

from __future__ import annotations

import ast
import builtins
import re
from typing import Callable, Iterator, List, Tuple, Union

from scenario_bank.precheck import PrecheckError, SafetyFinding, UnsafeScenarioError, precheck_text
from scenario_bank.scenic_parse import parse_scenic

__all__ = [
    "SAFE_BUILTINS",
    "DENIED_NAMES",
    "SCENIC_OPTIONAL_ATTRIBUTES",
    "FILESYSTEM_ATTRIBUTES",
    "ENV_ATTRIBUTES",
    "SIMULATION_ATTRIBUTES",
    "LOCAL_PATH_PARAMS",
    "PrecheckError",
    "precheck_text",
    "WORLD_MODELS",
    "SafetyFinding",
    "UnsafeScenarioError",
    "check_script",
    "assert_safe",
]

WORLD_MODELS = frozenset({
    "envs.scenic_highway.model",
    "scenic.domains.driving.model",
    "scenic.simulators.carla.model",
    "scenic.simulators.metadrive.model",
    "scenic.simulators.newtonian.driving_model",
    "scenic.simulators.newtonian.model",
})
"""World models a ``model`` line may name (all are replaced by the highway-env model at compile time)."""

ALLOWED_IMPORTS = frozenset({"math"})
"""The only Python modules a script may import."""

ALLOWED_FROM_IMPORTS = {"scenic.core.external_params": frozenset({"VerifaiRange", "VerifaiDiscreteRange",
                                                                   "VerifaiOptions"})}
"""Names a ``from MODULE import NAME`` may bring in: VerifAI-sampled parameters (Scenic's external
parameters), which the failure miner drives."""

SAFE_BUILTINS = frozenset({
    "True", "False", "None", "abs", "all", "any", "bool", "chr", "dict", "divmod", "enumerate", "filter",
    "float", "frozenset", "int", "isinstance", "iter", "len", "list", "map", "max", "min", "next", "ord",
    "pow", "print", "range", "repr", "reversed", "round", "set", "slice", "sorted", "str", "sum", "tuple",
    "zip", "Exception", "ArithmeticError", "AssertionError", "IndexError", "KeyError", "LookupError",
    "NotImplementedError", "RuntimeError", "StopIteration", "TypeError", "ValueError", "ZeroDivisionError",
})
"""Python builtins a script may use; every other builtin name is refused."""

DENIED_NAMES = frozenset({
    # Scenic's namespace: these import modules, set the simulator or write files
    "model", "simulator", "File", "Files", "runTryInterrupt", "HighwayEnvSimulator", "Simulator",
    # modules, should any ever be in scope
    "os", "sys", "subprocess", "socket", "shutil", "pathlib", "importlib", "pickle", "marshal", "ctypes",
    "builtins", "io", "urllib", "requests", "http", "threading", "multiprocessing", "signal", "tempfile",
    "glob", "inspect", "gc", "code", "codeop", "pty", "fcntl", "resource", "asyncio", "random", "posix",
    "nt", "operator", "functools", "types", "typing", "weakref", "scenic", "envs", "numpy", "np",
    "highway_env", "gymnasium", "dv2s_gym", "scenario_bank", "policies", "webbrowser", "ssl", "ftplib",
})
"""Names refused even though Scenic or Python defines them."""

LOCAL_PATH_PARAMS = frozenset({"map", "sumo_map"})
"""Parameters whose value may be ``localPath('relative/file')``: the map, and MetaDrive's SUMO map (which our
models never open). Their values may not be read back through ``globalParameters``."""

SCENIC_OPTIONAL_ATTRIBUTES = frozenset({
    "_laneToLeft", "_laneToRight", "_fasterLane", "_slowerLane",  # LaneSection
    "_lane", "_laneSection", "_laneGroup", "_road", "_intersection", "_crossing", "_element",  # DrivingObject
})
"""The only attributes starting with ``_`` a script may use: the driving domain's documented accessors
that give a road-network element or ``None`` where their public twin (``laneToLeft``, ``lane``...)
would reject the sample (Scenic's docs name them for exactly that use)."""

_UNSAFE_BUILTINS = frozenset(name for name in dir(builtins) if name not in SAFE_BUILTINS)

FRAME_ATTRIBUTES = frozenset({
    "gi_frame", "gi_code", "gi_yieldfrom", "gi_running", "cr_frame", "cr_code", "cr_await", "cr_origin",
    "ag_frame", "ag_code", "ag_await", "f_back", "f_globals", "f_locals", "f_builtins", "f_code", "f_trace",
    "f_lasti", "tb_frame", "tb_next", "tb_lasti", "func_globals", "func_code", "func_closure", "im_func",
    "im_self", "im_class", "cell_contents", "mro", "with_traceback", "format", "format_map",
})
"""Attributes refused though they have no underscore: frames, code objects, formatting that walks attributes."""

FILESYSTEM_ATTRIBUTES = frozenset({
    "touch", "mkdir", "makedirs", "unlink", "rmdir", "rmtree", "removedirs", "rename", "renames", "symlink_to",
    "hardlink_to", "link_to", "symlink", "link", "chmod", "lchmod", "chown", "lchown", "iterdir", "glob", "rglob",
    "readlink", "truncate", "mkfifo", "mknod", "chdir", "chroot", "putenv", "unsetenv", "environ", "kill",
    "killpg", "fork", "listdir", "scandir", "utime", "expanduser", "home", "cwd",
    # pathlib.Path's other methods that reach the file system or build paths to it
    "replace", "stat", "lstat", "exists", "is_file", "is_dir", "is_symlink", "is_mount", "is_socket", "is_fifo",
    "is_block_device", "is_char_device", "resolve", "absolute", "samefile", "owner", "group", "joinpath",
    "with_name", "with_stem", "with_suffix", "relative_to", "as_uri", "as_posix", "parent", "parents", "walk",
    "chflags", "lchflags", "access", "remove", "removexattr", "setxattr", "getxattr", "listxattr", "sendfile",
    "copy", "copyfile", "copytree", "move", "abspath", "realpath",
})
"""Methods of ``pathlib.Path``, ``os`` and ``shutil`` that read, change or list the file system (or build
the path objects that do), refused on any object: whatever a script holds (a parameter's value, an item of
``globalParameters``, an object's attribute), these names never reach the file system. ``replace`` is
also ``str.replace``: scripts use string slicing and ``+`` instead."""

SIMULATION_ATTRIBUTES = frozenset({"currentTime", "currentRealTime", "timestep", "objects", "agents",
                                   "getLaneFollowingControllers"})
"""The only attributes of ``simulation()`` a script may read: the clock, the objects and the driving
domain's controllers. ``simulation`` may appear only as ``simulation().<one of these>``."""

ENV_ATTRIBUTES = frozenset({
    # Gymnasium: Env, Wrapper, EnvSpec and registration (``spec.make()`` imports and calls any function)
    "spec", "entry_point", "vector_entry_point", "runs_in_jail", "kwargs", "make", "make_vec", "register", "registry",
    "unwrapped", "env", "envs", "wrapper_spec", "get_wrapper_attr", "has_wrapper_attr", "set_wrapper_attr",
    "additional_wrappers", "disable_env_checker", "apply_api_compatibility", "order_enforce", "autoreset",
    "max_episode_steps", "reward_threshold", "nondeterministic", "np_random", "np_random_seed", "seed",
    "action_space", "observation_space", "metadata", "render", "render_mode", "reset", "step", "close",
    "from_json", "to_json", "pprint",
    # highway-env's AbstractEnv (``change_vehicles`` imports a module by name; ``config`` holds the env's limits)
    "change_vehicles", "call_vehicle_method", "set_vehicle_field", "configure", "config", "default_config",
    "define_spaces", "create_ego", "randomize_behavior", "set_preferred_lane", "set_route_at_intersection",
    "set_record_video_wrapper", "simplify", "to_finite_mdp", "get_available_actions", "update_metadata",
    "viewer", "action_type", "observation_type", "controlled_vehicles", "vehicle", "vehicles",
    "enable_auto_render", "step_time_limit",
    # Scenic's simulator and simulation, and our env's handles on them
    "simulator", "simulation", "createSimulation", "createObjectInSimulator", "executeActions",
    "updateObjects", "getProperties", "scheduleForAgents", "setup", "destroy", "currentState",
    "recordCurrentState", "getReplay", "replay", "initializeReplay", "recordSampledValue",
    "replaySampledValue", "simulate", "before_physics", "save_trace", "stepper",
})
"""Attribute names refused on any object: the names by which the env, the simulator and their Gymnasium
and highway-env parts are reached or driven. The list is the public attributes of ``gymnasium.Env``,
``Wrapper`` and ``EnvSpec``, highway-env's ``AbstractEnv``, Scenic's ``Simulator``/``Simulation`` and
dv2s-gym's env and simulator, minus the names Scenic's driving domain also defines (``road``, ``lanes``,
``objects``...) and generic ones (``id``, ``name``, ``time``); a test recomputes it."""

_IO_ATTRIBUTE = re.compile(r"file|pickle|dump|load|save|write|read|show|plot|export|replay|serial|stream|"
                           r"open|exec|eval|system|spawn|popen|import|module|global|builtin|frame|code|"
                           r"subclass|getattr|setattr|delattr", re.I)
"""Attribute names that read or write files or reach interpreter internals (``fromFile``, ``dumpPickle``...)."""

_PRIVATE_STRING = re.compile(r"^_\w*$|__\w+__|\{[^{}]*[.\[]\s*_")
"""String constants that name private attributes or format fields walking into them."""

# Python node types a Scenic script may contain; Scenic's own nodes are allowed but for `simulator`.
_PYTHON_NODES = frozenset({
    "Module", "Expr", "Assign", "AugAssign", "AnnAssign", "Pass", "Break", "Continue", "If", "For", "While",
    "Try", "TryStar", "ExceptHandler", "Raise", "Assert", "Delete", "Return", "FunctionDef", "ClassDef",
    "Lambda", "With", "withitem", "Match", "match_case", "MatchValue", "MatchSingleton", "MatchSequence",
    "MatchMapping", "MatchClass", "MatchStar", "MatchAs", "MatchOr",
    "arguments", "arg", "keyword", "alias", "Name", "Attribute", "Subscript", "Starred", "Slice", "Constant",
    "JoinedStr", "FormattedValue", "List", "Tuple", "Set", "Dict", "ListComp", "SetComp", "DictComp",
    "GeneratorExp", "comprehension", "BoolOp", "BinOp", "UnaryOp", "Compare", "Call", "IfExp", "NamedExpr",
    "Load", "Store", "Del", "And", "Or", "Add", "Sub", "Mult", "MatMult", "Div", "Mod", "Pow", "LShift",
    "RShift", "BitOr", "BitXor", "BitAnd", "FloorDiv", "Invert", "Not", "UAdd", "USub", "Eq", "NotEq", "Lt",
    "LtE", "Gt", "GtE", "Is", "IsNot", "In", "NotIn", "Import", "ImportFrom",
})
_REFUSED_NODES = {
    "Global": "rebinding module globals is not allowed",
    "Nonlocal": "rebinding enclosing variables is not allowed",
    "AsyncFunctionDef": "async code is not part of a Scenic script",
    "AsyncFor": "async code is not part of a Scenic script",
    "AsyncWith": "async code is not part of a Scenic script",
    "Await": "async code is not part of a Scenic script",
    "Yield": "generators are not part of a Scenic script (their frames reach the interpreter)",
    "YieldFrom": "generators are not part of a Scenic script (their frames reach the interpreter)",
    "Simulator": "the simulator is fixed by dv2s-gym; a script may not choose one",
}
# Fields of Scenic's nodes that hold identifiers (Python's own are covered by _IDENTIFIER_FIELDS too).
_IDENTIFIER_FIELDS = frozenset({"id", "attr", "name", "arg", "asname", "identifier", "property", "names",
                                "vararg", "kwarg", "rest", "prop", "className", "kwd_attrs"})
# Fields whose strings are attribute names read from an object (judged like ``obj.attr``):
# ``case Cls(attr=pattern)`` reads ``subject.attr`` as ``getattr`` would.
_ATTRIBUTE_FIELDS = frozenset({("Attribute", "attr"), ("MatchClass", "kwd_attrs")})
# Fields holding free text rather than identifiers (string constants are judged by _PRIVATE_STRING).
# Any other field that holds a string is refused: a new node type must be reviewed before it is allowed.
_TEXT_FIELDS = frozenset({("Constant", "value"), ("Constant", "kind"), ("ImportFrom", "module"), ("Model", "name"),
                          ("BehaviorDef", "docstring"), ("MonitorDef", "docstring"), ("ScenarioDef", "docstring"),
                          ("Require", "name"), ("RequireMonitor", "name"), ("Record", "name"),
                          ("RecordInitial", "name"), ("RecordFinal", "name"), ("TerminateWhen", "name"),
                          ("TerminateSimulationWhen", "name")})


def _identifiers(node: ast.AST, flag: Callable[[ast.AST, str, str], None]) -> Iterator[Tuple[str, bool]]:
    """Identifier strings held by a node's fields, each with whether it is an attribute read.

    A string in a field that is neither an identifier field nor a known free-text
    field is flagged (an unreviewed construct), not silently passed.
    """
    kind = type(node).__name__
    for field_name, value in ast.iter_fields(node):
        strings = [value] if isinstance(value, str) else [v for v in value if isinstance(v, str)] \
            if isinstance(value, list) else []
        if not strings:
            continue
        if field_name in _IDENTIFIER_FIELDS:
            yield from ((text, (kind, field_name) in _ATTRIBUTE_FIELDS) for text in strings)
        elif (kind, field_name) not in _TEXT_FIELDS:
            flag(node, f"{kind}.{field_name}", "this construct names something the safety check does not "
                                               "review; it is not allowed in a scenario")


def _check_import(node: ast.AST, kind: str, flag: Callable[[ast.AST, str, str], None]) -> None:
    if kind == "Import":
        for alias in node.names:
            if alias.name not in ALLOWED_IMPORTS:
                flag(node, f"import {alias.name}",
                     "only `import math` is allowed; Scenic world models come in through a `model` line")
    else:
        module = node.module or ""
        allowed_names = ALLOWED_FROM_IMPORTS.get(module)
        if not node.level and allowed_names is not None:
            for alias in node.names:
                if alias.name not in allowed_names or (alias.asname and alias.asname.startswith("_")):
                    flag(node, f"from {module} import {alias.name}",
                         f"only {', '.join(sorted(allowed_names))} may be imported from {module}")
            return
        if node.level or module not in ALLOWED_IMPORTS:
            flag(node, f"from {'.' * node.level}{module} import ...",
                 "only `math` (and VerifAI ranges from scenic.core.external_params) may be imported; Scenic "
                 "world models come in through a `model` line")
        for alias in node.names:
            if alias.name == "*":
                flag(node, f"from {module} import *", "star imports are not allowed")


def _check_identifier(node: ast.AST, ident: str, is_attribute: bool,
                      flag: Callable[[ast.AST, str, str], None]) -> None:
    shown = (f"case {_pattern_class(node)}({ident}=...)" if isinstance(node, ast.MatchClass)
             else f".{ident}") if is_attribute else ident
    if is_attribute and ident in SCENIC_OPTIONAL_ATTRIBUTES:
        return
    if not ident.isascii():
        # Python's own parser folds identifiers by NFKC (``ｅval`` is ``eval``, ``＿`` is ``_``); Scenic's
        # does not today, but the check must not depend on which parser compiles the script.
        flag(node, shown, "identifiers must be ASCII (Unicode look-alikes can normalise to other names)")
        return
    if ident.startswith("_") and (is_attribute or ident != "_"):  # a bare `_` is a throwaway loop variable
        flag(node, shown, "names and attributes starting with '_' are not allowed (private or dunder access)")
    elif is_attribute:
        if ident in FRAME_ATTRIBUTES:
            flag(node, shown, "frame, code-object and attribute-formatting attributes are not allowed")
        elif ident in FILESYSTEM_ATTRIBUTES:
            flag(node, shown, "file-system methods (of paths or os) are not allowed")
        elif ident in ENV_ATTRIBUTES:
            flag(node, shown, "this attribute reaches the env, the simulator, Gymnasium or highway-env (whose "
                              "objects lead back to the interpreter); scripts use Scenic's driving domain only")
        elif _IO_ATTRIBUTE.search(ident):
            flag(node, shown, "methods that read or write files or reach interpreter internals are not allowed")
    elif isinstance(node, (ast.alias, ast.ImportFrom, ast.Import)):
        return  # the import itself is judged by _check_import
    elif ident in DENIED_NAMES:
        flag(node, ident, "this name loads modules, files or simulators; it is not allowed in a scenario")
    elif ident in _UNSAFE_BUILTINS:
        flag(node, ident, "this Python builtin is not in the safe set (file, process, introspection or "
                          "code-execution access)")


def check_script(source: Union[str, bytes], *, absolute_maps: bool = False) -> List[SafetyFinding]:
    """All safety findings of a Scenic script (empty list: safe to compile).

    The text first goes through :func:`~scenario_bank.precheck.precheck_text` (size, encoding, nesting...):
    a text it refuses is not parsed, and its one finding is returned. ``source`` may be a file's bytes.

    ``absolute_maps`` allows ``param map`` to be an absolute ``.xodr`` path (a script the
    user runs from their own disk); scripts kept in a bank must name shipped maps or
    paths relative to themselves, so that the bank can be moved.

    A script Scenic's parser cannot read yields no finding when the parser
    gives a line (the compiler reports it then, before anything runs), else one
    ``syntax`` finding.
    """
    # The parse (the costly part) is shared with the compiler and with repeated checks of one text.

    try:
        source = precheck_text(source)
    except PrecheckError as error:
        return list(error.findings)
    try:
        tree = parse_scenic(source)
    except SyntaxError as error:
        # A syntax error is not unsafe by itself; Scenic's compiler reports it with its line.
        return [] if error.lineno else [SafetyFinding(0, "syntax", str(error))]
    except Exception as error:  # the parser raises its own error types on some inputs
        return [SafetyFinding(0, "syntax", f"unparsable script: {error}")]
    findings: List[SafetyFinding] = []

    def flag(node: ast.AST, construct: str, reason: str) -> None:
        finding = SafetyFinding(getattr(node, "lineno", 0), construct, reason)
        if finding not in findings:
            findings.append(finding)

    map_calls = _map_local_paths(tree, flag, absolute_maps)
    parents = {id(child): parent for parent in ast.walk(tree) for child in ast.iter_child_nodes(parent)}
    for node in ast.walk(tree):
        kind = type(node).__name__
        if kind == "Name" and node.id in _ROOTED_NAMES:
            _check_rooted_name(node, parents.get(id(node)), parents, flag)
        if kind == "Name" and node.id == "localPath" and id(node) not in map_calls:
            flag(node, "localPath", "localPath returns a file-system path object; it may only be the whole "
                                    "value of a top-level `param` line (`param map = localPath('my_map.xodr')` "
                                    "before the `model` line)")
            continue
        scenic_node = type(node).__module__.startswith("scenic.")
        if kind in _REFUSED_NODES:
            flag(node, kind.lower(), _REFUSED_NODES[kind])
        elif not scenic_node and kind not in _PYTHON_NODES:
            flag(node, kind, "this Python construct is not part of the Scenic scripts dv2s-gym accepts")
        if kind in ("Import", "ImportFrom"):
            _check_import(node, kind, flag)
        elif kind == "Model":
            name = getattr(node, "name", "")
            if name not in WORLD_MODELS:
                flag(node, f"model {name}", f"not a Scenic world model (use one of {', '.join(sorted(WORLD_MODELS))})")
            continue
        elif kind == "ClassDef" and node.keywords:
            flag(node, f"class {node.name}(...{node.keywords[0].arg}=...)", "class keywords (metaclasses) are not allowed")
        elif kind == "Constant" and isinstance(node.value, (str, bytes)):
            text = node.value.decode("latin-1") if isinstance(node.value, bytes) else node.value
            if _PRIVATE_STRING.search(text):
                flag(node, repr(text[:40]), "strings naming private or dunder attributes are not allowed")
        elif kind == "Record" and getattr(node, "recorder", None) is not None:
            flag(node, "record ... to ...", "records may not be written to files or recorders")
        for ident, is_attribute in _identifiers(node, flag):
            _check_identifier(node, ident, is_attribute, flag)
    findings.sort(key=lambda f: f.line)
    return findings


_ROOTED_NAMES = frozenset({"simulation", "param", "globalParameters"})


def _check_rooted_name(node: ast.Name, parent, parents: dict, flag) -> None:
    """``simulation``, ``param`` and ``globalParameters`` are allowed in one shape each (see the module docstring)."""
    if node.id == "param":
        flag(node, "param(...)", "`param` is a statement (`param name = value` at top level); calling it as a "
                                 "function is not allowed")
    elif node.id == "simulation":
        call = parent
        attribute = parents.get(id(call)) if call is not None else None
        if not (isinstance(call, ast.Call) and call.func is node and not call.args and not call.keywords
                and isinstance(attribute, ast.Attribute) and attribute.value is call):
            flag(node, "simulation", "`simulation` may only be used as `simulation().<attribute>` with one of "
                                     f"{', '.join(sorted(SIMULATION_ATTRIBUTES))}; the simulation object itself "
                                     "leads to the env and the interpreter")
        elif attribute.attr not in SIMULATION_ATTRIBUTES or not isinstance(attribute.ctx, ast.Load):
            flag(attribute, f"simulation().{attribute.attr}",
                 f"a script may only read {', '.join(sorted(SIMULATION_ATTRIBUTES))} of the simulation")
    elif not (isinstance(parent, ast.Attribute) and parent.value is node and isinstance(parent.ctx, ast.Load)):
        flag(node, "globalParameters", "`globalParameters` may only be read as `globalParameters.<name>` "
                                       "(set parameters with `param` lines)")
    elif parent.attr in LOCAL_PATH_PARAMS:
        flag(parent, f"globalParameters.{parent.attr}", "the map parameters may hold file-system paths; a "
                                                        "script may not read them back")


def _pattern_class(node: ast.MatchClass) -> str:
    cls = node.cls
    return cls.id if isinstance(cls, ast.Name) else getattr(cls, "attr", "...")


def _map_local_paths(tree: ast.AST, flag, absolute_maps: bool = False) -> set:
    """Check every ``param map`` line; the ids of the ``localPath`` names allowed as a map's whole value.

    A map set after the ``model`` line would not be the map loaded, and would leave a path object in
    ``globalParameters``, so it is refused.
    """
    allowed, model_seen = set(), False
    for statement in getattr(tree, "body", []):
        kind = type(statement).__name__
        if kind == "Model":
            model_seen = True
        for node in ast.walk(statement):
            if type(node).__name__ != "Param":
                continue
            for param in getattr(node, "elts", []):
                name = getattr(param, "identifier", None)
                if name != "map":
                    if name in LOCAL_PATH_PARAMS and node is statement and _is_literal_local_path(param.value):
                        if _local_path_escapes(param.value.args[0].value):
                            flag(param.value, f"param {name} = localPath({param.value.args[0].value!r})",
                                 "localPath must name a file inside the script's folder (a relative path "
                                 "without '..')")
                        allowed.add(id(param.value.func))  # MetaDrive's `param sumo_map = localPath(...)`
                    continue
                if model_seen or node is not statement:
                    flag(param.value, "param map", "the map must be set at top level before the `model` line")
                _check_map_value(param.value, flag, absolute_maps)
                value = param.value
                if isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "localPath":
                    allowed.add(id(value.func))
    return allowed


def _is_literal_local_path(value: ast.AST) -> bool:
    """``localPath('<string literal>')``: a path the script names, as a whole parameter value.

    Only the model reads parameters, and ours opens none but ``map``; a path object left in
    another parameter can only be reached through attributes and names the check refuses.
    """
    return (isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and value.func.id == "localPath"
            and len(value.args) == 1 and not value.keywords and isinstance(value.args[0], ast.Constant)
            and isinstance(value.args[0].value, str))


def _local_path_escapes(path: str) -> bool:
    """Whether a ``localPath`` argument may leave the script's folder (absolute, ``~``, ``..``, a drive)."""
    parts = path.replace("\\", "/").split("/")
    return (not path or path.startswith(("/", "~")) or ":" in path or ".." in parts
            or any(not part.isprintable() for part in parts))


def _check_map_value(value: ast.AST, flag, absolute_maps: bool = False) -> None:
    if isinstance(value, ast.Constant) and isinstance(value.value, str):
        path = value.value
        if absolute_maps and path.startswith("/") and path.endswith(".xodr"):
            return
        if path.startswith(("/", "~")) or ".." in path.replace("\\", "/").split("/"):
            flag(value, f"param map = {path!r}", "maps must be shipped map names or relative .xodr paths")
        elif ("/" in path or "\\" in path or "." in path) and not path.endswith(".xodr"):
            flag(value, f"param map = {path!r}", "a map path must name an OpenDRIVE .xodr file")
    elif isinstance(value, ast.Call) and getattr(value.func, "id", None) == "localPath":
        args = value.args
        if len(args) != 1 or value.keywords or not (isinstance(args[0], ast.Constant) and isinstance(args[0].value, str)):
            flag(value, "param map = localPath(...)", "localPath takes one string literal, a relative .xodr path")
        elif _local_path_escapes(args[0].value):
            flag(value, f"param map = localPath({args[0].value!r})", "localPath must name a file inside the "
                                                                     "script's folder (a relative path without '..')")
        else:
            _check_map_value(args[0], flag, absolute_maps)
    else:
        flag(value, "param map", "the map must be a string literal (a shipped map name)")


def assert_safe(source: str, label: str = "<script>", *, absolute_maps: bool = False) -> None:
    """Raise :class:`UnsafeScenarioError` if the script fails the check (see :func:`check_script`)."""
    findings = check_script(source, absolute_maps=absolute_maps)
    if findings:
        raise UnsafeScenarioError(findings, label)

