"""Scenic's parser, once per text.

Scenic's PEG parser takes 0.2-1.5 s per module, and the same texts come back
again and again in one process: the safety check parses a script that the
compiler then parses again, and Scenic purges its compiled modules after every
scenario, so each new compile re-parses the world model and the driving domain.
Parsing is a pure function of the text, so trees are kept (a bounded LRU) and
handed out as copies where the caller rewrites them.

Trees of the *library* modules every compile needs (Scenic's own ``.scenic``
files, i.e. the driving domain, and the project's world model) are also kept on
disk, in the user cache directory, so a fresh process (``dv2s convert`` of one
clip) does not parse them again (about 0.35 s). Scripts from anywhere else
(generated, user or bank scripts) are never written there. The files are
pickles that may only rebuild AST nodes (a restricted unpickler); a file that
does not load is ignored and the text parsed.
"""

from __future__ import annotations

import ast
import hashlib
import io
import os
import pickle
from collections import OrderedDict
from pathlib import Path
from typing import Any, Optional
from importlib.metadata import version

from scenario_bank.atomic import atomic_write_bytes
from scenario_bank.cache import cache_dir as user_cache_dir

__all__ = ["parse_scenic", "install_parse_cache", "cache_dir"]

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


def _rebuild(cls, state):
    node = cls.__new__(cls)
    node.__dict__.update(state)
    return node


class _TreePickler(pickle.Pickler):
    def reducer_override(self, obj):
        if isinstance(obj, ast.AST):  # Scenic's node classes take required __init__ arguments
            return _rebuild, (type(obj), dict(vars(obj)))
        return NotImplemented


class _TreeUnpickler(pickle.Unpickler):
    _BUILTINS = {"Ellipsis", "complex", "frozenset", "set", "slice"}

    def find_class(self, module, name):
        if module == __name__ and name == "_rebuild":
            return _rebuild
        if module == "builtins" and name in self._BUILTINS:
            return super().find_class(module, name)
        if module in ("ast", "_ast", "scenic.syntax.ast"):
            cls = super().find_class(module, name)
            if isinstance(cls, type) and issubclass(cls, ast.AST):
                return cls
        raise pickle.UnpicklingError(f"{module}.{name} is not an AST node")


def cache_dir() -> Path:
    """Folder of the on-disk parse cache: ``scenic-parse/`` in :func:`scenario_bank.cache.cache_dir`."""
    return user_cache_dir() / "scenic-parse"


def _library_roots():
    import scenic

    here = Path(__file__).resolve().parents[1]
    return (Path(scenic.__file__).resolve().parent, here / "envs" / "scenic_highway")


def _is_library_file(filename: str) -> bool:
    """True for a ``.scenic`` file of Scenic itself or of the project's world model."""
    if not filename.endswith(".scenic") or not os.path.isfile(filename):
        return False
    path = Path(filename).resolve()
    return any(root in path.parents for root in _library_roots())


def _disk_key(source: str) -> str:
    try:
        scenic_version = version("scenic")
    except Exception:  # pragma: no cover - scenic installed without metadata
        scenic_version = "unknown"
    return hashlib.sha256(f"{scenic_version}\0{source}".encode("utf-8")).hexdigest()


def _load_from_disk(key: str) -> Optional[Any]:
    try:
        data = (cache_dir() / f"{key}.pickle").read_bytes()
        tree = _TreeUnpickler(io.BytesIO(data)).load()
    except Exception:  # missing, unreadable, truncated or foreign: parse instead
        return None
    return tree if isinstance(tree, ast.AST) else None


def _save_to_disk(key: str, tree: Any) -> None:
    folder = cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        _TreePickler(buffer, protocol=pickle.HIGHEST_PROTOCOL).dump(tree)
        atomic_write_bytes(folder / f"{key}.pickle", buffer.getvalue(), fsync=False)
    except (OSError, pickle.PicklingError, RecursionError):
        pass  # a read-only or full cache only costs the parse next time


def _parsed(source: str, filename: str, parse) -> Any:
    # A tree holds positions, not the file name (only errors name the file, and errors are not
    # kept), so the text alone is the key: the safety check's tree serves the compiler too.
    key = hashlib.sha256(source.encode("utf-8")).hexdigest()
    tree = _PARSED.get(key)
    if tree is None:
        library = _is_library_file(filename)
        disk_key = _disk_key(source) if library else None
        tree = _load_from_disk(disk_key) if library else None
        if tree is None:
            tree = parse(source, "exec", filename=filename)
            if library:
                _save_to_disk(disk_key, tree)
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
