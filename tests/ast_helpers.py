"""Strings of a parsed module that are text, not names: shared by the structure and private-name rules."""

from __future__ import annotations

import ast
from typing import Set


def text_only_strings(tree: ast.AST) -> Set[int]:
    """``id`` of every string constant of ``tree`` that is prose, never a name: docstrings (of the module, classes
    and functions) and the literal parts of f-strings."""
    skipped: Set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                skipped.add(id(first.value))
        elif isinstance(node, ast.JoinedStr):
            skipped.update(id(value) for value in node.values)
    return skipped
