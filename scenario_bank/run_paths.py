"""Paths in a run's record written relative to the run's folder, so a run folder moved elsewhere resumes where it is.

A run record (a mining run's ``settings.json``, a regression or training run's ``run.json``, a DAgger checkpoint's
``progress.json``, a loop's held-out episodes) names a path inside its own run folder relative to it, after the mark
:data:`RUN_MARK` (``<run>/traces/0.json.gz``), and a path inside the loop folder that holds the run (a ``dv2s loop``
folder: one whose ``loop.json`` is a loop's record) relative to that, after :data:`LOOP_MARK` (``<loop>/bank``,
``ppo:<loop>/round_1/policy/model.zip``), whole or inside a text (a policy spec, a fingerprint's description).
Read back (:func:`read_paths`), a mark becomes that folder where it is now, so a run or loop folder moved with
``mv`` resumes there. A path outside both folders (a ``--bank`` folder elsewhere, the shipped checkpoint) is
written as it is.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any, List, Optional, Tuple

__all__ = ["RUN_MARK", "LOOP_MARK", "LOOP_RECORD", "loop_folder", "record_paths", "read_paths", "as_read",
           "resume_fix"]

RUN_MARK = "<run>"
"""How a run record writes its own run folder."""
LOOP_MARK = "<loop>"
"""How a run record (and ``loop.json``) writes the loop folder that holds the run."""
LOOP_RECORD = ("loop.json", "dv2s-loop-state")
"""The file that makes a folder a loop folder, and the schema it records."""

_SPEC_PREFIX = r"(?:[a-z0-9_]+:)?"
"""A policy spec's algorithm before a path (``ppo:``)."""


def _is_loop_folder(folder: Path) -> bool:
    path = folder / LOOP_RECORD[0]
    if not path.is_file():
        return False
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(record, dict) and record.get("schema") == LOOP_RECORD[1]


def loop_folder(folder: Any) -> Optional[Path]:
    """The loop folder holding ``folder`` (the nearest folder above it whose ``loop.json`` is a loop's record), in
    the form ``folder`` is given (relative when it is, and the loop folder lies under the working folder); ``None``
    when no loop folder holds it."""
    given = Path(folder)
    absolute = given.absolute()
    for depth, parent in enumerate(absolute.parents, start=1):
        if _is_loop_folder(parent):
            if given.is_absolute() or depth >= len(given.parts):
                return parent
            return Path(*given.parts[:len(given.parts) - depth])
    return None


def _roots(folder: Any) -> List[Tuple[str, Path]]:
    """``(mark, folder)`` for the run folder and, when one holds it, the loop folder (the run folder first: it lies
    inside the loop folder)."""
    roots = [(RUN_MARK, Path(folder))]
    loop = loop_folder(folder)
    if loop is not None:
        roots.append((LOOP_MARK, loop))
    return roots


def _patterns(root: Path) -> List[str]:
    """Where ``root`` begins a path in a text: as an absolute path (written out or resolved) anywhere a path can
    begin, and as given when relative, where a word or a policy spec begins; each followed by ``/`` or the text's
    end."""
    absolutes = sorted({str(root.absolute()), str(root.resolve())}, key=len, reverse=True)
    patterns = [rf"(^|[^\w.~/-]){re.escape(text)}(?=/|$)" for text in absolutes]
    if not root.is_absolute() and root.parts:
        patterns.append(rf"((?:^|[\s(]){_SPEC_PREFIX}){re.escape(str(root))}(?=/|$)")
    return patterns


def _map_text(value: Any, change) -> Any:
    """``value`` (JSON) with ``change`` applied to every text in it, mapping keys too."""
    if isinstance(value, dict):
        return {_map_text(key, change): _map_text(item, change) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_map_text(item, change) for item in value]
    return change(value) if isinstance(value, str) else value


def record_paths(value: Any, folder: Any) -> Any:
    """``value`` (the JSON of a record in the run folder ``folder``) with every path inside ``folder`` or inside
    the loop folder holding it written after its mark (module docstring); other values as they are."""
    steps = [(pattern, mark) for mark, root in _roots(folder) for pattern in _patterns(root)]

    def change(text: str) -> str:
        for pattern, mark in steps:
            text = re.sub(pattern, lambda found: found.group(1) + mark, text)
        return text

    return _map_text(value, change)


def read_paths(value: Any, folder: Any) -> Any:
    """``value`` (the JSON of a record read from the run folder ``folder``) with each mark read back as the folder
    it names where it is now, as an absolute path (:func:`record_paths`' inverse); a ``<loop>`` mark no loop
    folder holds stays."""
    roots = [(mark, root.absolute()) for mark, root in _roots(folder)]

    def change(text: str) -> str:
        for mark, root in roots:
            text = re.sub(rf"{re.escape(mark)}(?=/|$|\W)", lambda _: str(root), text)
        return text

    return _map_text(value, change)


def as_read(value: Any, folder: Any) -> Any:
    """``value`` as the run folder ``folder`` would read it back once recorded (:func:`read_paths` of
    :func:`record_paths`): a path inside the run or loop folder, given relative or absolute, as one absolute path, so
    what a resume asks compares equal to what the run recorded."""
    return read_paths(record_paths(value, folder), folder)


def resume_fix(folder: Any, fix: str) -> str:
    """The advice of a run in ``folder`` that refuses to resume: its own ``fix`` (e.g. "pass another --out"), or,
    when a loop folder holds the run, the loop's (the run is a step of that loop, and the user named the loop's
    ``--out``, not this folder)."""
    loop = loop_folder(folder)
    if loop is None:
        return fix
    return (f"it is a step of the loop in {loop}, which resumes it only as it began: rerun dv2s loop --out {loop} "
            f"with the loop's own settings, delete {folder} to run that step again, or start a new loop with "
            "another --out")
