"""Compiling Scenic in this process imports Python modules only from the installed packages.

Scenic compiles a script as a top-level program: it puts the current folder first on
``sys.path`` for the duration, and its driving domain imports ``attr``, ``shapely`` and the
OpenDRIVE reader on first use. A file such as ``attr.py`` in the folder a user runs ``dv2s``
from (a downloaded bank, say) would then run in the user's process. :func:`no_folder_imports`
imports those modules up front and, around a compile, keeps the current folder off
``sys.path`` and Scenic from adding it.
"""

from __future__ import annotations

import importlib
import os
import sys
from contextlib import contextmanager
from typing import Iterator, Optional

__all__ = ["PRELOADED", "no_folder_imports"]

PRELOADED = (
    "attr", "shapely", "shapely.geometry", "shapely.ops", "numpy", "scipy", "scipy.spatial",
    "scenic.domains.driving.roads", "scenic.domains.driving.actions", "scenic.domains.driving.controllers",
    "scenic.domains.driving.workspace", "scenic.formats.opendrive.xodr_parser",
    "envs.scenic_highway.model_support", "envs.scenic_highway.simulator",
)
"""Modules the compiler and the world model import on first use, imported before any compile."""

_loaded = False


def _preload() -> None:
    global _loaded
    if _loaded:
        return
    for name in PRELOADED:
        try:
            importlib.import_module(name)
        except ImportError:  # an optional part of Scenic missing here: its compile will say so
            pass
    _loaded = True


def _current_folder() -> Optional[str]:
    try:
        return os.path.realpath(os.getcwd())
    except OSError:  # the folder was removed under us: nothing to import from
        return None


def _is_current_folder(entry: str, here: Optional[str]) -> bool:
    if entry in ("", "."):
        return True
    try:
        return here is not None and os.path.realpath(entry) == here
    except (TypeError, ValueError):
        return False


@contextmanager
def _namespace_without_folder(path=None):
    """Scenic's top-level namespace of a script, without putting the script's folder on ``sys.path``."""
    namespace = {"__name__": "__main__"}
    if path is not None:
        namespace["__file__"] = path
    yield namespace


@contextmanager
def no_folder_imports() -> Iterator[None]:
    """Around a compile: no module is imported from the current folder (``sys.path`` is restored after)."""
    _preload()
    from scenic.syntax import translator

    here = _current_folder()
    saved_path = list(sys.path)
    saved_namespace = translator.topLevelNamespace
    sys.path[:] = [entry for entry in sys.path if not (isinstance(entry, str) and _is_current_folder(entry, here))]
    translator.topLevelNamespace = _namespace_without_folder
    try:
        yield
    finally:
        translator.topLevelNamespace = saved_namespace
        sys.path[:] = saved_path
