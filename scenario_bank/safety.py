"""Safety check of untrusted Scenic code, done before it is compiled or run.

Scenic is Python with extra syntax, so a generated script could do anything
Python can. The check parses the script with Scenic's own parser (no code runs)
and walks the tree against an allowlist:

* imports and ``model`` lines only of Scenic world models and a few pure modules
  (``math``, ``random``, ``scenic.*`` driving/simulator models);
* no file, process or network access: no ``open``/``exec``/``eval``/``compile``/
  ``__import__``/``getattr``-style builtins, no names of OS-level modules;
* no dunder names or attributes (``__class__``, ``__subclasses__``, ...);
* ``param map`` is a shipped map name or a relative ``.xodr`` path, not an
  absolute path or one climbing out with ``..``.

Every finding names the line and the construct.
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from typing import List

__all__ = ["SafetyFinding", "UnsafeScenarioError", "check_script", "assert_safe"]

ALLOWED_MODULE_PREFIXES = ("scenic.domains.", "scenic.simulators.", "scenic.core.external_params")
ALLOWED_MODULES = {"math", "random", "scenic.domains.driving.model", "envs.scenic_highway.model"}
FORBIDDEN_NAMES = {
    "open", "exec", "eval", "compile", "__import__", "globals", "locals", "vars", "getattr", "setattr",
    "delattr", "input", "breakpoint", "exit", "quit", "memoryview", "help", "dir", "type", "super",
    "os", "sys", "subprocess", "socket", "shutil", "pathlib", "importlib", "pickle", "marshal", "ctypes",
    "builtins", "io", "urllib", "requests", "http", "threading", "multiprocessing", "signal", "tempfile",
    "glob", "inspect", "gc", "code", "codeop", "pty", "fcntl", "resource", "asyncio",
}


@dataclass(frozen=True)
class SafetyFinding:
    """One reason a script is unsafe."""

    line: int
    construct: str
    reason: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.construct}: {self.reason}"


class UnsafeScenarioError(ValueError):
    """A script failed the safety check; ``findings`` lists why."""

    def __init__(self, findings: List[SafetyFinding], label: str = "<script>") -> None:
        self.findings = findings
        lines = "; ".join(str(f) for f in findings[:5])
        more = f" (and {len(findings) - 5} more)" if len(findings) > 5 else ""
        super().__init__(
            f"{label} failed the safety check: {lines}{more}. Generated Scenic may only use Scenic's driving "
            "domain and world models: no imports beyond Scenic models, no file/process/network access, no "
            "exec/eval, no dunder access."
        )


def _module_allowed(module: str) -> bool:
    return module in ALLOWED_MODULES or module.startswith(ALLOWED_MODULE_PREFIXES)


def check_script(source: str) -> List[SafetyFinding]:
    """All safety findings of a Scenic script (empty list: safe to compile)."""
    # The parse (the costly part) is shared with the compiler and with repeated checks of one text.
    from scenario_bank.scenic_parse import parse_scenic

    try:
        tree = parse_scenic(source)
    except SyntaxError as error:
        # A syntax error is not unsafe by itself; Scenic's compiler reports it with its line.
        return [] if error.lineno else [SafetyFinding(0, "syntax", str(error))]
    except Exception as error:  # the parser raises its own error types on some inputs
        return [SafetyFinding(0, "syntax", f"unparsable script: {error}")]
    findings: List[SafetyFinding] = []

    def flag(node: ast.AST, construct: str, reason: str) -> None:
        findings.append(SafetyFinding(getattr(node, "lineno", 0), construct, reason))

    for node in ast.walk(tree):
        kind = type(node).__name__
        if isinstance(node, ast.Import):
            for alias in node.names:
                if not _module_allowed(alias.name):
                    flag(node, f"import {alias.name}", "only Scenic world models may be imported")
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level or not _module_allowed(module):
                flag(node, f"from {module} import ...", "only Scenic world models may be imported")
        elif kind == "Model":
            name = getattr(node, "name", "")
            if not _module_allowed(name):
                flag(node, f"model {name}", "not a Scenic world model")
        elif isinstance(node, ast.Name):
            if node.id in FORBIDDEN_NAMES:
                flag(node, node.id, "file, process, network or introspection access is not allowed")
            elif node.id.startswith("__"):
                flag(node, node.id, "dunder names are not allowed")
        elif isinstance(node, ast.Attribute):
            if node.attr.startswith("__") or node.attr.startswith("_sa"):
                flag(node, f".{node.attr}", "dunder attributes are not allowed")
        elif isinstance(node, (ast.Global, ast.Nonlocal)):
            flag(node, kind.lower(), "rebinding module globals is not allowed")
        elif kind == "Param":
            for param in getattr(node, "elts", []):
                if getattr(param, "identifier", None) == "map":
                    _check_map_value(param.value, flag)
    return findings


def _check_map_value(value: ast.AST, flag) -> None:
    if isinstance(value, ast.Constant) and isinstance(value.value, str):
        path = value.value
        if path.startswith(("/", "~")) or ".." in path.replace("\\", "/").split("/"):
            flag(value, f"param map = {path!r}", "maps must be shipped map names or relative .xodr paths")
    elif isinstance(value, ast.Call) and getattr(value.func, "id", None) == "localPath":
        return
    else:
        flag(value, "param map", "the map must be a string literal (a shipped map name)")


def assert_safe(source: str, label: str = "<script>") -> None:
    """Raise :class:`UnsafeScenarioError` if the script fails the check."""
    findings = check_script(source)
    if findings:
        raise UnsafeScenarioError(findings, label)
