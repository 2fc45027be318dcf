"""Scenic's parser, once per text.

Scenic's PEG parser takes 0.2-1.5 s per module, and the same texts come back
again and again in one process: the safety check parses a script that the
compiler then parses again, and Scenic purges its compiled modules after every
scenario, so each new compile re-parses the world model and the driving domain.
Parsing is a pure function of the text, so trees are kept (a bounded LRU) and
handed out as copies where the caller rewrites them.
"""

from __future__ import annotations

import ast
import hashlib
from collections import OrderedDict
from typing import Any

__all__ = ["parse_scenic", "install_parse_cache"]

_PARSED: "OrderedDict[str, Any]" = OrderedDict()
_MAX_TREES = 64


def _copy_tree(node: Any) -> Any:
    """A deep copy of a Scenic AST (Scenic's node classes cannot go through copy.deepcopy)."""
    if isinstance(node, ast.AST):
        new = node.__class__.__new__(node.__class__)
        for key, value in vars(node).items():
            setattr(new, key, _copy_tree(value))
        return new
    if isinstance(node, list):
        return [_copy_tree(item) for item in node]
    if isinstance(node, tuple):
        return tuple(_copy_tree(item) for item in node)
    return node


def _parsed(source: str, filename: str, parse) -> Any:
    # A tree holds positions, not the file name (only errors name the file, and errors are not
    # kept), so the text alone is the key: the safety check's tree serves the compiler too.
    key = hashlib.sha256(source.encode("utf-8")).hexdigest()
    tree = _PARSED.get(key)
    if tree is None:
        tree = parse(source, "exec", filename=filename)
        _PARSED[key] = tree
        if len(_PARSED) > _MAX_TREES:
            _PARSED.popitem(last=False)
    else:
        _PARSED.move_to_end(key)
    return tree


def parse_scenic(source: str, filename: str = "<string>") -> ast.AST:
    """The Scenic AST of ``source`` (shared: read it, do not modify it); raises like Scenic's parser."""
    from scenic.syntax.parser import parse_string

    return _parsed(source, filename, parse_string)


def install_parse_cache() -> None:
    """Make Scenic's compiler take its module trees from the cache (idempotent)."""
    from scenic.syntax import translator

    if getattr(translator.parse_string, "dv2s_cached", False):
        return
    parse = translator.parse_string

    def cached_parse(source, mode, *args, **kwargs):
        if mode != "exec" or args or set(kwargs) - {"filename"}:
            return parse(source, mode, *args, **kwargs)
        # the compiler rewrites the tree it is given: hand it a copy
        return _copy_tree(_parsed(source, str(kwargs.get("filename", "<unknown>")), parse))

    cached_parse.dv2s_cached = True
    translator.parse_string = cached_parse
